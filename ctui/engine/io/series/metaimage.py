"""MetaImage (.mhd + data file, .mha): header parsing, per-slice data files (LIST,
numbered pattern), spacing checks; the data is read by :func:`~ctui.engine.io.series.raw.load_raw`."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.core.assumptions import Assumption
from ctui.engine.core.errors import CtuiError, LoadError
from ctui.engine.io.series._common import orthonormal
from ctui.engine.core.volume import Volume
from ctui.engine.io.series.raw import load_raw
from ctui.engine.io.series.stacks import _default_spacing_warning, parse_spacing


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
        if not (np.isfinite(v) and 1e-3 <= v <= 1e5):  # core.limits MIN/MAX_SPACING_MM
            invalid.append(f"{'xyz'[a]} ({v:g})")
            v = 1.0
        out.append(float(v))
    warnings = []
    if negative:
        warnings.append(f"the MetaImage header gives a negative ElementSpacing along {', '.join(negative)}: "
                        f"its size used")
    if invalid:
        warnings.append(Assumption(f"the MetaImage header gives an invalid ElementSpacing along {', '.join(invalid)}: "
                                   f"1 mm used instead; give spacing=(dz, dy, dx) (--spacing dz,dy,dx) for true "
                                   "measurements", "spacing"))
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
    geo_warnings: list[str] = []
    if tm:
        v = floats(tm, 9, 0.0)
        if v is not None and abs(np.linalg.det(np.array(v).reshape(3, 3))) > 1e-6:
            direction = np.array(v).reshape(3, 3).T  # each triple: one index axis (ITK MetaImageIO)
            direction, sheared = orthonormal(direction, what="the MetaImage TransformMatrix")
            geo_warnings = sheared
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
        warnings=([] if spacing is not None else sp_warnings) + geo_warnings,
    )
