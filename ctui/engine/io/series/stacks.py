"""Image stacks (PNG/BMP/TIFF/JPEG, multi-page TIFF), raw volumes, per-slice raw
files and MetaImage (.mhd/.mha).

None of these formats has patient geometry (MetaImage aside): spacing comes from the
``spacing`` option, default 1 mm with a warning "default spacing".
"""

from __future__ import annotations

import io
from collections import Counter
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ctui.engine.core.assumptions import Assumption
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
    if len(vals) != 3 or not all(np.isfinite(vals)) or min(vals) < 1e-3 or max(vals) > 1e5:
        raise CtuiError(f"spacing must be three numbers from 0.001 to 1e5 (dz, dy, dx) in mm, got {spacing!r}",
                        path=path)
    return tuple(vals)  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


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
    return Assumption(f"default spacing 1 mm: {what} has no voxel size; give spacing=(dz, dy, dx) "
                      f"(--spacing dz,dy,dx) for true measurements", "spacing")


def _finish(data, *, spacing, given, warnings, source, path, meta, skipped, plan, full, modality="OT",
            origin=(0.0, 0.0, 0.0), direction=None, what="an image stack") -> Volume:
    """The Volume of ``data`` read through ``plan`` (crop, downsampling) from the full
    (nz, ny, nx) grid ``full`` whose first voxel is at ``origin`` (mm, along ``direction``):
    the spacing (default 1 mm, with a warning unless ``given``) grows by the plan's steps
    and the origin moves to the first voxel read."""
    if spacing is None:
        spacing = (1.0, 1.0, 1.0)
        if not given:
            warnings.insert(0, _default_spacing_warning(what))
    d = np.eye(3) if direction is None else np.asarray(direction, float)
    z0, y0, x0 = plan.starts(full)
    origin = np.asarray(origin, float) + d @ np.array([x0 * spacing[2], y0 * spacing[1], z0 * spacing[0]])
    return Volume(
        data=data,
        spacing=tuple(s * st for s, st in zip(spacing, plan.steps())),
        origin=tuple(float(v) for v in origin),
        direction=d,
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
    meta = {"format": "image-stack" if not multipage else "tiff", "files": len({e[0] for e in keep})}
    return _finish(out, spacing=sp, given=sp is not None, warnings=warnings, path=path, meta=meta, skipped=skipped,
                   source=f"{kind}, {len(keep)} slice{'s' * (len(keep) != 1)} from {path}", plan=plan, full=full,
                   what="an image stack")
