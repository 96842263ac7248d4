"""Image stacks (PNG/BMP/TIFF/JPEG, multi-page TIFF), raw volumes, per-slice raw
files and MetaImage (.mhd/.mha).

None of these formats has patient geometry (MetaImage aside): spacing comes from the
``spacing`` option, default 1 mm with a warning "default spacing".
"""

from __future__ import annotations

import io
import os
import re
import zlib
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ctui.engine.core.errors import CtuiError, LoadError
from ctui.engine.core.volume import Volume
from ctui.engine.io.series._common import check_memory, make_plan, natural_key, rel, run_parallel, to_grey


# --------------------------------------------------------------------- options
def parse_spacing(spacing: Any, path: Any) -> tuple[float, float, float] | None:
    """None, a number (isotropic), one value or three (dz, dy, dx) in mm -> (dz, dy, dx) or None."""
    if spacing is None:
        return None
    if isinstance(spacing, str):
        spacing = [s for s in spacing.replace("x", ",").split(",") if s.strip()]
    if isinstance(spacing, (int, float, np.number)):
        vals = [float(spacing)] * 3
    else:
        try:
            vals = [float(s) for s in spacing]
        except (TypeError, ValueError):
            raise CtuiError(f"spacing must be numbers (dz, dy, dx) in mm, got {spacing!r}", path=path) from None
        if len(vals) == 1:
            vals = vals * 3
    if len(vals) != 3 or not all(np.isfinite(vals)) or min(vals) <= 0:
        raise CtuiError(f"spacing must be three positive numbers (dz, dy, dx) in mm, got {spacing!r}", path=path)
    return tuple(vals)  # type: ignore[return-value]


def parse_shape(shape: Any, path: Any) -> tuple[int, ...] | None:
    if shape is None:
        return None
    if isinstance(shape, str):
        shape = [s for s in shape.replace("x", ",").split(",") if s.strip()]
    try:
        vals = tuple(int(s) for s in shape)
    except (TypeError, ValueError):
        raise CtuiError(f"shape must be integers (z, y, x) or (y, x), got {shape!r}", path=path) from None
    if len(vals) not in (2, 3) or min(vals) < 1:
        raise CtuiError(f"shape must be 2 or 3 positive integers (z, y, x) or (y, x), got {shape!r}", path=path)
    return vals


def parse_dtype(dtype: Any, path: Any) -> np.dtype:
    if dtype is None:
        raise CtuiError("raw data needs a dtype (e.g. uint8, int16, '>u2' for big-endian uint16, float32)", path=path)
    aliases = {"uchar": "u1", "char": "i1", "ushort": "u2", "short": "i2", "uint": "u4", "int": "i4", "float": "f4", "double": "f8"}
    try:
        dt = np.dtype(aliases.get(str(dtype), dtype))
    except TypeError:
        raise CtuiError(f"unknown dtype {dtype!r} (try uint8, int16, '>u2', float32)", path=path) from None
    if dt.kind not in "uif" or dt.itemsize > 8:
        raise CtuiError(f"unsupported dtype {dtype!r}: use an integer or float type", path=path)
    return dt


def _default_spacing_warning(what: str) -> str:
    return (f"default spacing 1 mm: {what} has no voxel size; give spacing=(dz, dy, dx) "
            f"(--spacing dz,dy,dx) for true measurements")


def _finish(data, *, spacing, given, warnings, source, path, meta, skipped, modality="OT", origin=(0.0, 0.0, 0.0),
            direction=None, plan_steps=(1, 1, 1), what="an image stack") -> Volume:
    if spacing is None:
        spacing = (1.0, 1.0, 1.0)
        if not given:
            warnings.insert(0, _default_spacing_warning(what))
    spacing = tuple(s * st for s, st in zip(spacing, plan_steps))
    return Volume(
        data=data,
        spacing=spacing,
        origin=origin,
        direction=np.eye(3) if direction is None else direction,
        modality=modality,
        window=None,
        source=source,
        series=[],
        skipped=skipped,
        warnings=warnings,
        meta=meta,
    )


# --------------------------------------------------------------------- image stacks
MAX_RATIO = 1100  # pixels per stored byte an image header may claim
SMALL_FILE = 64 << 20  # image files up to this size are decoded from memory
def _image_mode_dtype(mode: str) -> np.dtype:
    if mode in ("I;16", "I;16L", "I;16B", "I;16N"):
        return np.dtype(np.uint16)
    if mode == "I;16S":
        return np.dtype(np.int16)
    if mode == "I":
        return np.dtype(np.int32)
    if mode == "F":
        return np.dtype(np.float32)
    return np.dtype(np.uint8)


def image_entries(files: Sequence[Path], base: Path | None) -> tuple[list[tuple[Path, int, int, int, str]], list[dict[str, str]]]:
    """(file, page, height, width, mode) for every page of every readable image file."""
    from PIL import Image, UnidentifiedImageError

    Image.MAX_IMAGE_PIXELS = None  # size is validated by the memory check instead
    entries: list[tuple[Path, int, int, int, str]] = []
    skipped: list[dict[str, str]] = []
    for p in files:
        try:
            fsize = p.stat().st_size
            with Image.open(p) as im:
                # never trust the header's size beyond what the file can hold: the best
                # lossless image codecs (PNG's deflate) stay below ~1032:1
                if im.width * im.height > MAX_RATIO * fsize + (1 << 22):
                    skipped.append({"file": rel(p, base), "reason": f"header claims {im.width}x{im.height} pixels, "
                                    f"too many for a {fsize}-byte file"})
                    continue
                n = int(getattr(im, "n_frames", 1) or 1)
                if n == 1:
                    entries.append((p, 0, im.height, im.width, im.mode))
                else:
                    for i in range(n):
                        im.seek(i)
                        entries.append((p, i, im.height, im.width, im.mode))
        except UnidentifiedImageError:
            skipped.append({"file": rel(p, base), "reason": "not an image file"})
        except OSError as exc:
            skipped.append({"file": rel(p, base), "reason": f"cannot read ({exc.strerror or exc})"})
        except Exception as exc:
            skipped.append({"file": rel(p, base), "reason": f"broken image ({type(exc).__name__})"})
    return entries, skipped


def load_images(
    files: Sequence[Path],
    *,
    path: Any,
    base: Path | None,
    skipped: list[dict[str, str]],
    spacing: Any = None,
    crop: Any = None,
    downsample: Any = None,
    progress: Callable[[int, int], Any] | None = None,
    memory_limit: int | None = None,
) -> Volume:
    """A stack of 2D images (natural file order) or multi-page TIFF pages -> Volume."""
    from PIL import Image

    files = sorted(files, key=lambda p: natural_key(rel(p, base)))
    entries, skip2 = image_entries(files, base)
    skipped.extend(skip2)
    if not entries:
        raise LoadError("no readable image in " + ("the folder" if len(files) > 1 else "the file"), path=path)
    from collections import Counter

    (h, w), _ = Counter((e[2], e[3]) for e in entries).most_common(1)[0]
    keep = []
    for e in entries:
        if (e[2], e[3]) != (h, w):
            skipped.append({"file": rel(e[0], base) + (f" page {e[1]}" if e[1] else ""),
                            "reason": f"image size {e[2]}x{e[3]} differs from the stack's {h}x{w}"})
        else:
            keep.append(e)
    colour = any(e[4] not in ("L", "1", "I", "F") and not e[4].startswith("I;16") for e in keep)
    dtype = np.result_type(*[_image_mode_dtype(e[4]) for e in keep])
    full = (len(keep), h, w)
    plan = make_plan(full, crop=crop, downsample=downsample, path=path)
    oshape = plan.out_shape(full)
    check_memory(int(np.prod(oshape)) * dtype.itemsize, shape=oshape, path=path, limit=memory_limit)
    out = np.empty(oshape, dtype=dtype)
    zsel = list(range(*plan.z.indices(full[0])))

    def work(k: int, zi: int) -> str | None:
        p, page, _, _, mode = keep[zi]
        # decode from memory when the file is small: a corrupt chunk length then cannot
        # make the decoder's file reads allocate more than the file holds (CPython's
        # buffered read(n) allocates n up front; BytesIO.read(n) only what is there)
        src: Any = p
        if p.stat().st_size <= SMALL_FILE:
            src = io.BytesIO(p.read_bytes())
        with Image.open(src) as im:
            if page:
                im.seek(page)
            if mode in ("P", "PA", "1", "CMYK", "YCbCr", "LAB", "HSV"):
                im = im.convert("RGB") if mode != "1" else im.convert("L")
            arr = np.asarray(im)
        if arr.ndim == 3:
            arr = to_grey(arr)
        if arr.shape != (h, w):
            return f"decoded size {arr.shape} differs from {h}x{w}"
        out[k] = arr[plan.y, plan.x]
        return None

    failures = run_parallel(zsel, work, progress=progress)
    bad = {k for k, _ in failures}
    for k, reason in failures:
        p, page = keep[zsel[k]][:2]
        skipped.append({"file": rel(p, base) + (f" page {page}" if page else ""), "reason": reason})
    if bad:
        good = [k for k in range(len(zsel)) if k not in bad]
        if not good:
            raise LoadError("no image could be decoded" + (f" ({failures[0][1]})" if failures else ""), path=path)
        for j, k in enumerate(good):
            out[j] = out[k]
        out = out[: len(good)]
    warnings: list[str] = []
    if colour:
        warnings.append("colour images converted to grey (luminance)")
    sp = parse_spacing(spacing, path)
    multipage = len({e[0] for e in keep}) == 1 and len(keep) > 1
    kind = "multi-page TIFF" if multipage else ("image" if len(keep) == 1 else "image stack")
    zs, ys, xs = plan.steps()
    z0, y0, x0 = plan.starts(full)
    s = sp or (1.0, 1.0, 1.0)
    vol = _finish(
        out,
        spacing=sp,
        given=sp is not None,
        warnings=warnings,
        source=f"{kind}, {len(keep)} slice{'s' * (len(keep) != 1)} from {path}",
        path=path,
        meta={"format": "image-stack" if not multipage else "tiff", "files": len({e[0] for e in keep})},
        skipped=skipped,
        origin=(x0 * s[2], y0 * s[1], z0 * s[0]),
        plan_steps=(zs, ys, xs),
        what="an image stack",
    )
    return vol


# --------------------------------------------------------------------- raw
def _read_slices_into(out: np.ndarray, reader: Callable[[int], np.ndarray], zsel: list[int], plan, progress) -> list[tuple[int, str]]:
    def work(k: int, zi: int) -> str | None:
        arr = reader(zi)
        out[k] = arr[plan.y, plan.x]
        return None

    return run_parallel(zsel, work, progress=progress)


def load_raw(
    path: Path,
    files: Sequence[Path] | None,
    *,
    shape: Any,
    dtype: Any,
    spacing: Any = None,
    offset: int | None = None,
    base: Path | None = None,
    skipped: list[dict[str, str]],
    crop: Any = None,
    downsample: Any = None,
    progress: Callable[[int, int], Any] | None = None,
    memory_limit: int | None = None,
    modality: str = "OT",
    origin: Sequence[float] = (0.0, 0.0, 0.0),
    direction: Any = None,
    source_kind: str = "raw",
    zlib_compressed: bool = False,
    warnings: list[str] | None = None,
    keep_order: bool = False,
) -> Volume:
    """Headerless raw data: one file holding a (z, y, x) volume, or per-slice files.

    ``files`` None: ``path`` is one file; shape (z, y, x), or (y, x) with z taken from
    the file size. Otherwise every file is one (y, x) slice (natural name order); files
    of another size are skipped with a reason. ``offset``: header bytes to skip
    (default: none, or the surplus at the start of a single file, with a warning).
    ``keep_order``: per-slice files in the order given (a MetaImage LIST), not sorted.
    """
    shp = parse_shape(shape, path)
    if shp is None:
        raise CtuiError("raw data needs a shape: (z, y, x) for one file, (y, x) for one file per slice "
                        "(--shape z,y,x), plus --dtype", path=path)
    dt = parse_dtype(dtype, path)
    warnings = list(warnings or [])
    native = dt.newbyteorder("=")
    if files is None:
        try:
            size = path.stat().st_size
        except OSError as exc:
            raise LoadError(f"cannot read ({exc.strerror or exc})", path=path) from None
        ny, nx = shp[-2:]
        slice_bytes = ny * nx * dt.itemsize
        raw_bytes = None
        if zlib_compressed:
            nz = shp[0] if len(shp) == 3 else 1
            raw_bytes = _inflate(path, offset or 0, nz * slice_bytes)
            size_avail = len(raw_bytes)
            off = 0
        else:
            off = int(offset or 0)
            size_avail = size - off
        if len(shp) == 2:
            if size_avail < slice_bytes or size_avail % slice_bytes:
                raise LoadError(f"file size {size_avail} bytes is not a whole number of {ny}x{nx} {dt} slices "
                                f"({slice_bytes} bytes each)", path=path)
            nz = size_avail // slice_bytes
        else:
            nz = shp[0]
        need = nz * slice_bytes
        if size_avail < need:
            raise LoadError(f"file has {size_avail} bytes of data but shape {nz}x{ny}x{nx} {dt} needs {need}", path=path)
        if size_avail > need and offset is None and not zlib_compressed:
            off = size_avail - need
            warnings.append(f"file is {off} bytes larger than the data: the first {off} bytes taken as a header")
        full = (nz, ny, nx)
        plan = make_plan(full, crop=crop, downsample=downsample, path=path)
        oshape = plan.out_shape(full)
        check_memory(int(np.prod(oshape)) * native.itemsize, shape=oshape, path=path, limit=memory_limit)
        out = np.empty(oshape, dtype=native)
        zsel = list(range(*plan.z.indices(nz)))

        def reader(zi: int) -> np.ndarray:
            if raw_bytes is not None:
                return np.frombuffer(raw_bytes, dtype=dt, count=ny * nx, offset=zi * slice_bytes).reshape(ny, nx)
            buf = np.empty(ny * nx, dtype=dt)
            with open(path, "rb") as fh:
                fh.seek(off + zi * slice_bytes)
                got = fh.readinto(memoryview(buf).cast("B"))
            if got != slice_bytes:
                raise CtuiError(f"truncated at slice {zi}")
            return buf.reshape(ny, nx)

        failures = _read_slices_into(out, reader, zsel, plan, progress)
        if failures:
            raise LoadError(f"cannot read slice {zsel[failures[0][0]]}: {failures[0][1]}", path=path)
        n_src = 1
    else:
        ny, nx = shp[-2:]
        slice_bytes = ny * nx * dt.itemsize
        off = int(offset or 0)
        good_files = []
        for p in (list(files) if keep_order else sorted(files, key=lambda p: natural_key(rel(p, base)))):
            try:
                size = p.stat().st_size
            except OSError as exc:
                skipped.append({"file": rel(p, base), "reason": f"cannot read ({exc.strerror or exc})"})
                continue
            if size - off != slice_bytes:
                skipped.append({"file": rel(p, base), "reason": f"size {size} bytes, expected {slice_bytes + off} "
                                f"for a {ny}x{nx} {dt} slice"})
                continue
            if not os.access(p, os.R_OK):
                skipped.append({"file": rel(p, base), "reason": "cannot read (permission denied)"})
                continue
            good_files.append(p)
        if len(shp) == 3 and shp[0] != len(good_files):
            warnings.append(f"shape says {shp[0]} slices, {len(good_files)} slice files found: loaded those")
        if not good_files:
            raise LoadError(f"no file of {slice_bytes} bytes (one {ny}x{nx} {dt} slice)", path=path)
        nz = len(good_files)
        full = (nz, ny, nx)
        plan = make_plan(full, crop=crop, downsample=downsample, path=path)
        oshape = plan.out_shape(full)
        check_memory(int(np.prod(oshape)) * native.itemsize, shape=oshape, path=path, limit=memory_limit)
        out = np.empty(oshape, dtype=native)
        zsel = list(range(*plan.z.indices(nz)))

        def reader(zi: int) -> np.ndarray:
            buf = np.empty(ny * nx, dtype=dt)
            with open(good_files[zi], "rb") as fh:
                fh.seek(off)
                got = fh.readinto(memoryview(buf).cast("B"))
            if got != slice_bytes:
                raise CtuiError(f"truncated ({got} of {slice_bytes} bytes)")
            return buf.reshape(ny, nx)

        failures = _read_slices_into(out, reader, zsel, plan, progress)
        bad = {k for k, _ in failures}
        for k, reason in failures:
            skipped.append({"file": rel(good_files[zsel[k]], base), "reason": reason})
        if bad:
            good = [k for k in range(len(zsel)) if k not in bad]
            if not good:
                raise LoadError("no slice file could be read", path=path)
            for j, k in enumerate(good):
                out[j] = out[k]
            out = out[: len(good)]
        n_src = nz
    sp = parse_spacing(spacing, path)
    zs, ys, xs = plan.steps()
    z0, y0, x0 = plan.starts(full)
    s = sp or (1.0, 1.0, 1.0)
    d = np.eye(3) if direction is None else np.asarray(direction, float)
    org = np.asarray(origin, float) + d @ (np.array([x0 * s[2], y0 * s[1], z0 * s[0]]))
    kind = f"{source_kind} {dt.str}" if files is None else f"{n_src} raw slice files ({dt.str})"
    return _finish(
        out,
        spacing=sp,
        given=sp is not None,
        warnings=warnings,
        source=f"{kind}, {nz}x{ny}x{nx}, from {path}",
        path=path,
        meta={"format": source_kind if files is None else "raw-slices", "dtype": dt.str, "files": n_src},
        skipped=skipped,
        modality=modality,
        origin=tuple(org),
        direction=d,
        plan_steps=(zs, ys, xs),
        what="raw data",
    )


def _inflate(path: Path, offset: int, expected: int) -> bytes:
    """zlib-decompress a MetaImage's data, never producing more than ``expected`` bytes."""
    d = zlib.decompressobj()
    out = bytearray()
    try:
        with open(path, "rb") as fh:
            fh.seek(offset)
            while True:
                chunk = fh.read(1 << 20)
                if not chunk:
                    break
                out += d.decompress(chunk, max(0, expected - len(out)) or 1)
                if len(out) >= expected:
                    break
    except zlib.error as exc:  # corrupted stream (found by FMT's tests/test_fuzz_stacks.py)
        raise LoadError(f"corrupted compressed data ({exc})", path=path) from None
    return bytes(out[:expected])


# --------------------------------------------------------------------- MetaImage
_MET_TYPES = {
    "MET_UCHAR": "u1", "MET_CHAR": "i1", "MET_USHORT": "u2", "MET_SHORT": "i2", "MET_UINT": "u4",
    "MET_INT": "i4", "MET_ULONG": "u4", "MET_LONG": "i4", "MET_ULONG_LONG": "u8", "MET_LONG_LONG": "i8",
    "MET_FLOAT": "f4", "MET_DOUBLE": "f8",
}


def read_mhd_header(path: Path) -> tuple[dict[str, str], int]:
    """Key/value header of a .mhd/.mha and the byte offset where it ends."""
    hdr: dict[str, str] = {}
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    pos = 0
    for line in head.split(b"\n"):
        pos += len(line) + 1
        text = line.decode("latin-1").strip()
        if not text:
            continue
        if "=" not in text:
            raise CtuiError("not a MetaImage header (expected 'Key = value' lines)", path=path)
        k, v = text.split("=", 1)
        hdr[k.strip()] = v.strip()
        if k.strip() == "ElementDataFile":
            break
    else:
        if "ElementDataFile" not in hdr:
            raise CtuiError("MetaImage header has no ElementDataFile", path=path)
    return hdr, pos


_PATTERN_FIELD = re.compile(r"%0?\d*d")
_MAX_SLICE_FILES = 100_000


def _mhd_slice_files(path: Path, datafile: str, header_end: int, nz: int) -> list[Path]:
    """The per-slice data files of a MetaImage header, in slice order.

    ``ElementDataFile = LIST [2D]`` is followed by one file name per line;
    ``ElementDataFile = name%03d.raw first last step`` numbers them (MetaIO's two
    multi-file forms). Names are relative to the header's folder; at most ``nz``
    (the header's slice count) are taken.
    """
    if nz > _MAX_SLICE_FILES:
        raise LoadError(f"MetaImage header asks for {nz} slice files (at most {_MAX_SLICE_FILES})", path=path)
    if datafile.upper().startswith("LIST"):
        size = path.stat().st_size
        with open(path, "rb") as fh:
            fh.seek(header_end)
            tail = fh.read(max(0, min(size - header_end, nz * 4096 + 65536)))
        names = [ln.decode("latin-1").strip() for ln in tail.splitlines()]
        names = [n for n in names if n][:nz]
    else:
        parts = datafile.split()
        if len(parts) not in (3, 4) or len(_PATTERN_FIELD.findall(parts[0])) != 1 or parts[0].count("%") != 1:
            raise CtuiError(f"MetaImage file pattern {datafile!r}: expected 'name%03d.raw first last [step]'",
                            path=path)
        try:
            first, last = int(parts[1]), int(parts[2])
            step = int(parts[3]) if len(parts) == 4 else 1
        except ValueError:
            raise CtuiError(f"MetaImage file pattern {datafile!r}: first/last/step must be integers", path=path) from None
        if step == 0 or (last - first) / step < 0:
            raise CtuiError(f"MetaImage file pattern {datafile!r}: empty range", path=path)
        count = min((last - first) // step + 1, nz)
        names = [parts[0] % (first + k * step) for k in range(count)]
    if not names:
        raise LoadError("MetaImage header lists no slice files", path=path)
    files = []
    for n in names:
        if "\x00" in n:
            raise LoadError(f"slice file name {n!r} holds a NUL byte", path=path)
        files.append(path.parent / n)
    return files


def mhd_spacing(hdr: dict[str, str]) -> tuple[list[float], list[str]]:
    """(dx, dy, dz) mm from a MetaImage header's ElementSpacing (or ElementSize), and the
    warnings: none given -> 1 mm (default spacing); a negative value -> its size; NaN,
    inf, 0 or an unreadable value -> 1 mm along that axis. Never NaN."""
    text = hdr.get("ElementSpacing") or hdr.get("ElementSize")
    if not text:
        return [1.0, 1.0, 1.0], [_default_spacing_warning("the MetaImage header")]
    vals: list[float] = []
    for v in text.split()[:3]:
        try:
            vals.append(float(v))
        except ValueError:
            vals.append(float("nan"))
    vals += [1.0] * (3 - len(vals))  # 2D image: one slice of 1 mm
    out, negative, invalid = [], [], []
    for a, v in enumerate(vals):
        if np.isfinite(v) and -1e5 < v < 0:
            negative.append(f"{'xyz'[a]} ({v:g})")
            v = -v
        if not (np.isfinite(v) and 1e-6 < v < 1e5):
            invalid.append(f"{'xyz'[a]} ({v:g})")
            v = 1.0
        out.append(float(v))
    warnings = []
    if negative:
        warnings.append(f"the MetaImage header gives a negative ElementSpacing along {', '.join(negative)}: "
                        f"its size used")
    if invalid:
        warnings.append(f"the MetaImage header gives an invalid ElementSpacing along {', '.join(invalid)}: 1 mm "
                        f"used instead; give spacing=(dz, dy, dx) (--spacing dz,dy,dx) for true measurements")
    return out, warnings


def load_mhd(path: Path, *, skipped: list[dict[str, str]], crop: Any = None, downsample: Any = None,
             progress: Any = None, memory_limit: int | None = None, spacing: Any = None) -> Volume:
    hdr, header_end = read_mhd_header(path)
    try:
        ndims = int(hdr.get("NDims", "3"))
        dims = [int(v) for v in hdr["DimSize"].split()]
        hsize = int(hdr.get("HeaderSize", "0") or 0)
        channels = int(hdr.get("ElementNumberOfChannels", "1") or 1)
    except (KeyError, ValueError):
        raise CtuiError("MetaImage header lacks a valid DimSize", path=path) from None
    if ndims not in (2, 3) or len(dims) != ndims or min(dims) < 1:
        raise CtuiError(f"MetaImage with NDims={ndims}, DimSize={dims} is not a 2D/3D image", path=path)
    et = hdr.get("ElementType", "")
    if et not in _MET_TYPES:
        raise CtuiError(f"unsupported MetaImage ElementType {et!r}", path=path)
    if channels != 1:
        raise CtuiError("multi-channel MetaImage is not supported", path=path)
    msb = (hdr.get("ElementByteOrderMSB") or hdr.get("BinaryDataByteOrderMSB") or "False").lower() == "true"
    dt = np.dtype(_MET_TYPES[et]).newbyteorder(">" if msb else "<")
    if ndims == 2:
        dims = dims + [1]
    nx, ny, nz = dims
    def floats(text: str | None, n: int, default: float) -> list[float] | None:
        try:
            vals = [float(v) for v in (text or "").split()]
        except ValueError:
            return None
        if not all(np.isfinite(vals)) or any(abs(v) > 1e6 for v in vals):
            return None
        return (vals + [default] * n)[:n] if text else [default] * n

    sp_x, sp_warnings = mhd_spacing(hdr)
    org = floats(hdr.get("Offset") or hdr.get("Position") or hdr.get("Origin"), 3, 0.0) or [0.0, 0.0, 0.0]
    tm = hdr.get("TransformMatrix") or hdr.get("Rotation") or hdr.get("Orientation")
    direction = np.eye(3)
    if tm:
        v = floats(tm, 9, 0.0)
        if v is not None and abs(np.linalg.det(np.array(v).reshape(3, 3))) > 1e-6:
            direction = np.array(v).reshape(3, 3).T  # each triple: one index axis (ITK MetaImageIO)
    datafile = hdr["ElementDataFile"]
    compressed = hdr.get("CompressedData", "False").lower() == "true"
    modality = {"MET_MOD_CT": "CT", "MET_MOD_MR": "MR"}.get(hdr.get("Modality", ""), "OT")
    files = None  # per-slice data files (LIST / pattern), else one data file
    if datafile.upper() == "LOCAL":
        data_path, offset = path, header_end
    elif datafile.upper().startswith("LIST") or "%" in datafile:
        if compressed:
            raise CtuiError("compressed per-slice MetaImage data (LIST / pattern) is not supported", path=path)
        files = _mhd_slice_files(path, datafile, header_end, nz)
        data_path, offset = path, (hsize if hsize > 0 else 0)
    else:
        try:
            data_path = (path.parent / datafile).resolve()
            ok = data_path.is_file()
        except (OSError, ValueError):  # embedded NUL, name too long, link loop
            ok = False
        if not ok:
            raise LoadError(f"data file {datafile!r} named by the header is missing", path=path)
        offset = None
        if hsize > 0:
            offset = hsize
        elif hsize == -1:
            offset = None  # data at the end of the file
        else:
            offset = 0
    slice_bytes = nx * ny * dt.itemsize
    if files is None and not compressed and offset is not None:
        size = data_path.stat().st_size
        if size - offset < nz * slice_bytes:
            raise LoadError(f"{data_path.name} has {size - offset} bytes of data, {nz * slice_bytes} expected for "
                            f"{nz}x{ny}x{nx} {dt}", path=path)
    sp = parse_spacing(spacing, path) if spacing is not None else (sp_x[2], sp_x[1], sp_x[0])
    return load_raw(
        data_path,
        files,
        shape=(nz, ny, nx),
        dtype=dt,
        spacing=sp,
        offset=offset,
        base=path.parent if files is not None else None,
        skipped=skipped,
        crop=crop,
        downsample=downsample,
        progress=progress,
        memory_limit=memory_limit,
        modality=modality,
        origin=org,
        direction=direction,
        keep_order=files is not None,
        source_kind="MetaImage" if files is None else "MetaImage slices",
        zlib_compressed=compressed,
        warnings=[] if spacing is not None else sp_warnings,
    )
