"""Research volume formats: NIfTI (.nii, .nii.gz) and NRRD (.nrrd, .nhdr).

Geometry is converted to ctui's convention: data (z, y, x), LPS patient mm (NIfTI's
RAS affine and NRRD's RAS spaces are flipped in x and y).

Memory: uncompressed data (NIfTI .nii, NRRD raw encoding, including detached per-slice
data files such as ``data file: quarter.%d 1 93 1``) is read slice by slice into the
preallocated array through :func:`~ctui.engine.io.series.stacks.load_raw` (crop and
downsample applied while reading). Compressed files are decompressed whole first by
nibabel / pynrrd (peak: the array plus the compressed stream; crop and downsample
apply after).
"""

from __future__ import annotations

import logging
import re
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.core.assumptions import Assumption
from ctui.engine.core.errors import CtuiError, LoadError
from ctui.engine.core.volume import Volume
from ctui.engine.io.series._common import allocate, check_memory, checked_axes, make_plan
from ctui.engine.io.series.nrrd_data import HEADER_LIMIT, header_end, read_payload, regular_file
from ctui.engine.io.series.raw import load_raw
from ctui.engine.io.series.stacks import parse_spacing
from ctui.engine.io.suffixes import NIFTI_SUFFIXES

_LPS_FROM_RAS = np.diag([-1.0, -1.0, 1.0])


def _geometry_from_matrix(m: np.ndarray) -> tuple[tuple[float, float, float], np.ndarray]:
    """3x3 matrix with columns = (x, y, z) index axis steps in mm -> (spacing zyx, direction)."""
    sp = np.linalg.norm(m, axis=0)
    sp[sp == 0] = 1.0
    return (float(sp[2]), float(sp[1]), float(sp[0])), m / sp[None, :]


def _finish(data: np.ndarray, spacing, direction, origin, *, path, fmt, skipped, warnings, plan=None, full=None) -> Volume:
    if plan is not None and full is not None:
        z0, y0, x0 = plan.starts(full)
        zs, ys, xs = plan.steps()
        origin = np.asarray(origin, float) + direction @ (np.array([x0 * spacing[2], y0 * spacing[1], z0 * spacing[0]]))
        spacing = (spacing[0] * zs, spacing[1] * ys, spacing[2] * xs)
    nz, ny, nx = data.shape
    return Volume(
        data=data,
        spacing=spacing,
        origin=tuple(float(v) for v in origin),
        direction=direction,
        modality="OT",
        window=None,
        source=f"{fmt}, {nz}x{ny}x{nx}, from {path}",
        series=[],
        skipped=skipped,
        warnings=warnings,
        meta={"format": fmt.lower().split()[0], "files": 1},
    )


# --------------------------------------------------------------------- NIfTI
def _nib():
    import nibabel as nib

    # nibabel logs header repairs to stderr; ctui reports problems itself
    logging.getLogger("nibabel").setLevel(logging.ERROR)
    return nib


def _raw_pixdim(nib: Any, path: Path, hdr: Any) -> np.ndarray:
    """pixdim[1:4] as stored in the file (before nibabel's repair of zero values)."""
    try:
        with nib.openers.ImageOpener(str(path)) as fh:
            raw = type(hdr).from_fileobj(fh, check=False)
        return np.asarray(raw["pixdim"][1:4], float)
    except Exception:  # noqa: BLE001 - the header was read once already; fall back to it
        return np.asarray(hdr["pixdim"][1:4], float)


def load_nifti(path: Path, **options: Any) -> Volume:
    """A NIfTI volume; ``meta["content_hint"]``: its free-text fields (descrip,
    intent_name, aux_file), which may name the modality (CT recognition)."""
    vol = _load_nifti(path, **options)
    try:
        hdr = _nib().load(str(path)).header
        vol.meta["content_hint"] = " ".join(
            bytes(np.asarray(hdr[k]).item()).decode("latin-1", "replace").strip("\x00 ")
            for k in ("descrip", "intent_name", "aux_file")).strip()
    except Exception:  # noqa: BLE001 - a hint only; the volume loaded
        pass
    return vol


def _load_nifti(path: Path, *, skipped: list, crop=None, downsample=None, progress=None, memory_limit=None,
                spacing=None) -> Volume:
    nib = _nib()

    try:
        img = nib.load(str(path))
    except Exception as exc:
        raise LoadError(f"not a readable NIfTI file ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})", path=path) from None
    hdr = img.header
    shape = tuple(int(s) for s in img.shape)
    warnings: list[str] = []
    if len(shape) < 2 or len(shape) > 5 or min(shape) < 1:
        raise LoadError(f"NIfTI image of shape {shape} is not a 2D/3D volume", path=path)
    if len(shape) > 3 and int(np.prod(shape[3:])) > 1:
        warnings.append(f"NIfTI has {int(np.prod(shape[3:]))} volumes (shape {shape}): loaded the first")
    nx, ny = shape[0], shape[1]
    nz = shape[2] if len(shape) > 2 else 1
    affine = img.affine
    m, origin, bad = checked_axes(_LPS_FROM_RAS @ affine[:3, :3], _LPS_FROM_RAS @ affine[:3, 3],
                                  what="the NIfTI header", spacing_given=spacing is not None)
    if not bad and spacing is None and int(hdr.get("sform_code", 0)) == 0:
        # nibabel turns a zero pixdim into 1 mm on loading (only a log line): say so
        pix = _raw_pixdim(nib, path, hdr)
        zero = [a for a in range(min(3, len(shape))) if not (np.isfinite(pix[a]) and pix[a] != 0)]
        if zero:
            bad = [Assumption(f"the NIfTI header gives an invalid voxel size along "
                              f"{', '.join(f'{chr(120 + a)} ({pix[a]:g})' for a in zero)}: 1 mm used instead; give "
                              f"spacing=(dz, dy, dx) (--spacing dz,dy,dx) for true measurements", "spacing")]
    warnings += bad
    voff = int(getattr(img.dataobj, "offset", 352))  # (img.header's vox_offset is reset by nibabel)
    if str(path).lower().endswith(NIFTI_SUFFIXES) and voff < 348:
        warnings.append(f"the NIfTI header's vox_offset {voff} lies inside its 348-byte header: the first voxels "
                        "read are header bytes")
    sp, direction = _geometry_from_matrix(m)
    try:
        pix = _raw_pixdim(nib, path, hdr)
    except Exception:  # noqa: BLE001 - a warning only
        pix = np.ones(3)
    neg = [a for a in range(min(3, len(shape))) if np.isfinite(pix[a]) and pix[a] < 0]
    if neg and spacing is None:
        warnings.append("the NIfTI header gives a negative pixdim along "
                        f"{', '.join(f'{chr(120 + a)} ({pix[a]:g})' for a in neg)}: the voxel size of its affine "
                        f"({', '.join(f'{v:g}' for v in sp[::-1])} mm, x y z) is used")
    if spacing is not None:
        sp = parse_spacing(spacing, path)
    full = (nz, ny, nx)
    plan = make_plan(full, crop=crop, downsample=downsample, path=path)
    proxy = img.dataobj
    dt = np.dtype(getattr(proxy, "dtype", hdr.get_data_dtype()))
    slope, inter = getattr(proxy, "slope", 1.0), getattr(proxy, "inter", 0.0)
    scaled = not (slope is None or slope == 1.0 or not np.isfinite(slope)) or not (
        inter is None or inter == 0.0 or not np.isfinite(inter))
    compressed = str(path).lower().endswith(".gz")
    if not compressed and not scaled and dt.kind in "uif" and len(shape) <= 4 and hasattr(proxy, "offset"):
        off = int(getattr(proxy, "offset", hdr.get_data_offset()))
        if getattr(proxy, "order", "F") != "F":
            raise LoadError("NIfTI data not in Fortran order", path=path)
        vol = load_raw(path, None, shape=full, dtype=dt, spacing=sp, offset=off, skipped=skipped, crop=crop,
                       downsample=downsample, progress=progress, memory_limit=memory_limit, origin=origin,
                       direction=direction, source_kind="NIfTI", warnings=warnings)
        vol.meta["format"] = "nifti"
        return vol
    if dt.kind not in "buif" or (dt.kind == "V" and dt.fields is None):
        if dt.kind == "c":
            warnings.append(f"NIfTI of complex values ({dt.name}): the magnitude is loaded")
        elif dt.fields is not None and len(dt.fields) in (3, 4):
            warnings.append("NIfTI of RGB colour voxels: the luminance (0.299 R + 0.587 G + 0.114 B) is loaded")
        else:
            raise LoadError(f"NIfTI of {dt} voxels is not a scalar volume", path=path)
    out_dt = np.dtype(np.float32) if scaled or dt.kind in "fcV" else dt.newbyteorder("=")
    oshape = plan.out_shape(full)
    if dt.kind in "iuf" and dt.fields is None and hasattr(proxy, "offset") and getattr(proxy, "order", "F") == "F":
        data = _stream_nifti(path, nib, proxy, dt, full, plan, scaled=scaled, progress=progress,
                             memory_limit=memory_limit)
        return _finish(data, sp, direction, origin, path=path, fmt="NIfTI", skipped=skipped, warnings=warnings,
                       plan=plan, full=full)
    # the proxy is sliced (crop, downsample, the first of several volumes): a gzip stream is
    # decompressed as it is read, never held whole (ctui info samples slices this way)
    check_memory(int(np.prod(oshape)) * (max(dt.itemsize, out_dt.itemsize) + out_dt.itemsize),
                 shape=oshape, path=path, limit=memory_limit)
    idx = (plan.x, plan.y) + ((plan.z,) if len(shape) > 2 else ()) + (0,) * max(0, len(shape) - 3)
    try:
        arr = np.asanyarray(img.dataobj[idx])
    except Exception as exc:
        raise LoadError(f"cannot read the NIfTI data ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})", path=path) from None
    if arr.ndim == 2:
        arr = arr[:, :, None]
    data = arr.T  # (i, j, k) Fortran -> (k, j, i), already cropped
    if data.dtype.kind == "c":
        data = np.abs(data)
    elif data.dtype.fields is not None:  # RGB(A) records
        r, g, b = (data[n].astype(np.float32) for n in data.dtype.names[:3])
        data = r * 0.299 + g * 0.587 + b * 0.114
    data = np.ascontiguousarray(data, dtype=out_dt)
    return _finish(data, sp, direction, origin, path=path, fmt="NIfTI", skipped=skipped, warnings=warnings, plan=plan, full=full)


def _integral(v: Any) -> bool:
    return v is None or (np.isfinite(float(v)) and float(v) == round(float(v)))


def _stream_nifti(path: Path, nib: Any, proxy: Any, dt: np.dtype, full: tuple[int, int, int], plan: Any, *,
                  scaled: bool, progress: Any, memory_limit: int | None) -> np.ndarray:
    """The (cropped, downsampled) first volume of a NIfTI file read slice by slice from its
    (possibly gzip) stream into the preallocated output: no full-size copy, no float copy
    of integers. Scaled data is computed as nibabel does (``apply_read_scaling`` with the
    proxy's slope and intercept, then float32), slice by slice; integers with an integral
    slope and intercept are kept as int16 while every slice fits (the same values as
    float32: |v| < 2**24), else the array becomes float32 once."""
    from nibabel.volumeutils import apply_read_scaling

    nz, ny, nx = full
    oshape = plan.out_shape(full)
    slope, inter = np.asanyarray(proxy.slope), np.asanyarray(proxy.inter)
    as_int = scaled and dt.kind in "iu" and _integral(proxy.slope) and _integral(proxy.inter)
    out_dt = np.dtype(np.int16) if as_int else np.dtype(np.float32) if scaled or dt.kind == "f" else dt.newbyteorder("=")
    check_memory(int(np.prod(oshape)) * out_dt.itemsize, shape=oshape, path=path, limit=memory_limit)
    out = allocate(oshape, out_dt)
    zsel = range(*plan.z.indices(nz))
    zstop = max(zsel) + 1 if len(zsel) else 0
    buf = np.empty(ny * nx, dtype=dt)
    raw = memoryview(buf).cast("B")
    k = 0
    try:
        with nib.openers.ImageOpener(proxy.file_like) as fh:
            fh.seek(int(proxy.offset))
            for z in range(zstop):
                got = fh.readinto(raw)
                if got != raw.nbytes:
                    raise LoadError(f"the NIfTI data ends in slice {z} of {nz}", path=path)
                if z not in zsel:
                    continue
                sl = buf.reshape(ny, nx)[plan.y, plan.x]
                if scaled:
                    sl = apply_read_scaling(sl, slope, inter)
                    if as_int and out.dtype == np.int16 and sl.size and (sl.min() < -32768 or sl.max() > 32767):
                        out = out.astype(np.float32)  # a value beyond int16: float32 from here on
                out[k] = sl
                k += 1
                if progress is not None:
                    progress(k, len(zsel))
    except LoadError:
        raise
    except Exception as exc:
        raise LoadError(f"cannot read the NIfTI data ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})",
                        path=path) from None
    return out


# --------------------------------------------------------------------- NRRD
_NRRD_TYPES = {
    "i1": ("signed char", "int8", "int8_t"),
    "u1": ("uchar", "unsigned char", "uint8", "uint8_t"),
    "i2": ("short", "short int", "signed short", "signed short int", "int16", "int16_t"),
    "u2": ("ushort", "unsigned short", "unsigned short int", "uint16", "uint16_t"),
    "i4": ("int", "signed int", "int32", "int32_t"),
    "u4": ("uint", "unsigned int", "uint32", "uint32_t"),
    "i8": ("longlong", "long long", "long long int", "signed long long", "signed long long int", "int64", "int64_t"),
    "u8": ("ulonglong", "unsigned long long", "unsigned long long int", "uint64", "uint64_t"),
    "f4": ("float",),
    "f8": ("double",),
}
_TYPE = {name: code for code, names in _NRRD_TYPES.items() for name in names}


def load_nrrd(path: Path, **options: Any) -> Volume:
    """An NRRD volume; ``meta["content_hint"]``: its ``content`` field (CT recognition)."""
    vol = _load_nrrd(path, **options)
    vol.meta["content_hint"] = str(_read_nrrd_header(path).get("content", "") or "")
    return vol


def _load_nrrd(path: Path, *, skipped: list, crop=None, downsample=None, progress=None, memory_limit=None,
               spacing=None) -> Volume:
    hdr = _read_nrrd_header(path)
    dim = int(hdr.get("dimension", 0))
    sizes = [int(s) for s in np.atleast_1d(hdr.get("sizes", []))]
    if dim not in (2, 3) or len(sizes) != dim or min(sizes) < 1:
        raise LoadError(f"NRRD of dimension {dim} sizes {sizes} is not a 2D/3D scalar volume", path=path)
    code = _TYPE.get(str(hdr.get("type", "")).strip().lower())
    if code is None:
        raise LoadError(f"unsupported NRRD type {hdr.get('type')!r}", path=path)
    dt = np.dtype(code)
    if dt.itemsize > 1:
        dt = dt.newbyteorder(">" if str(hdr.get("endian", "little")).lower() == "big" else "<")
    nx, ny = sizes[0], sizes[1]
    nz = sizes[2] if dim == 3 else 1
    # geometry
    space = str(hdr.get("space", "")).lower()
    ras = space in ("right-anterior-superior", "ras", "3d-right-handed")
    warnings: list[str] = []
    m, origin = _nrrd_axes(hdr, dim, warnings)
    if ras and space != "3d-right-handed":
        m = _LPS_FROM_RAS @ m
        origin = _LPS_FROM_RAS @ origin
    m, origin, bad = checked_axes(m, origin, what="the NRRD header", spacing_given=spacing is not None)
    warnings += bad
    sp, direction = _geometry_from_matrix(m)
    if "space directions" not in hdr and "spacings" not in hdr:
        warnings.append(Assumption("default spacing 1 mm: the NRRD header gives no spacing", "spacing"))
    if spacing is not None:
        sp = parse_spacing(spacing, path)
    encoding = str(hdr.get("encoding", "raw")).lower()
    datafile = hdr.get("data file") or hdr.get("datafile")
    full = (nz, ny, nx)
    if encoding == "raw" and int(hdr.get("line skip", 0) or 0) == 0:
        skip = int(hdr.get("byte skip", 0) or 0)
        if datafile is None:
            # attached: data right after the header's blank line
            files, target, off = None, path, header_end(path) + max(skip, 0)
        else:
            files, target, off = _nrrd_data_files(path, str(datafile), nz), None, max(skip, 0)
            if files is None:
                try:
                    target = (path.parent / str(datafile)).resolve()
                    ok = target.is_file()
                except (OSError, ValueError):  # embedded NUL, name too long, link loop
                    ok = False
                if not ok:
                    raise LoadError(f"data file {datafile!r} named by the NRRD header is missing", path=path)
            if skip == -1:
                off = None
        if files is not None:
            vol = load_raw(path.parent, files, shape=(ny, nx), dtype=dt, spacing=sp, offset=off or 0,
                           base=path.parent, skipped=skipped, crop=crop, downsample=downsample, progress=progress,
                           memory_limit=memory_limit, origin=origin, direction=direction, warnings=warnings)
        else:
            vol = load_raw(target, None, shape=full, dtype=dt, spacing=sp, offset=off, skipped=skipped, crop=crop,
                           downsample=downsample, progress=progress, memory_limit=memory_limit, origin=origin,
                           direction=direction, source_kind="NRRD", warnings=warnings)
        vol.meta["format"] = "nrrd"
        vol.source = f"NRRD ({encoding}), {vol.shape[0]}x{ny}x{nx}, from {path}"
        return vol
    plan = make_plan(full, crop=crop, downsample=downsample, path=path)
    zstop = max(range(*plan.z.indices(nz))) + 1  # slices after the crop are never decoded (info samples slice 0)
    check_memory(2 * zstop * ny * nx * dt.itemsize, shape=full, path=path, limit=memory_limit)
    if datafile is not None and _nrrd_data_files(path, str(datafile), nz) is not None:
        raise LoadError(f"NRRD {encoding} data in several data files is not supported (raw only)", path=path)
    data = read_payload(path, hdr, dtype=dt, full=full, datafile=None if datafile is None else str(datafile),
                        zstop=zstop)
    data = data[plan.z, plan.y, plan.x]
    data = np.ascontiguousarray(data, dtype=dt.newbyteorder("="))
    return _finish(data, sp, direction, origin, path=path, fmt=f"NRRD ({encoding})", skipped=skipped, warnings=warnings,
                   plan=plan, full=full)


def _read_nrrd_header(path: Path) -> dict:
    """The NRRD header, read from at most 1 MB of lines (a file of one endless line is refused)."""
    import nrrd

    def lines(fh):
        total = 0
        while True:
            line = fh.readline(HEADER_LIMIT - total + 1)
            total += len(line)
            if not line or total > HEADER_LIMIT:
                return
            yield line.decode("latin-1")

    try:
        regular_file(path, what="the file", owner=path)
        with open(path, "rb") as fh:
            return nrrd.read_header(lines(fh))
    except LoadError:
        raise
    except Exception as exc:
        raise LoadError(f"not a readable NRRD header ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})", path=path) from None


def _nrrd_axes(hdr: dict, dim: int, warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Index-axis matrix (columns: steps in mm) and origin as the NRRD header states them
    (unchecked: NaN, 0 or inf are left for :func:`checked_axes`). A negative ``spacings``
    value is taken as its size, with a warning."""
    m = np.eye(3)
    try:
        if hdr.get("space directions") is not None:
            sd = np.asarray(hdr["space directions"], dtype=float)
            for a in range(min(dim, sd.shape[0])):
                m[:, a] = np.r_[sd[a], 0, 0][:3]
        elif "spacings" in hdr:
            spc = [float(v) for v in np.atleast_1d(hdr["spacings"])]
            for a in range(min(dim, len(spc))):
                if np.isfinite(spc[a]) and spc[a] < 0:
                    warnings.append(f"the NRRD header gives a negative spacing {spc[a]:g} along {'xyz'[a]}: "
                                    f"{-spc[a]:g} mm used")
                    spc[a] = -spc[a]
                m[a, a] = spc[a]
    except (TypeError, ValueError, IndexError):
        m = np.full((3, 3), np.nan)
    origin = np.zeros(3)
    if hdr.get("space origin") is not None:
        try:
            o = np.asarray(hdr["space origin"], float).reshape(-1)
            origin[: min(3, len(o))] = o[:3]
        except (TypeError, ValueError):
            origin[:] = np.nan
    return m, origin


def _nrrd_data_files(path: Path, spec: str, nz: int) -> list[Path] | None:
    """Files of a 'data file: <format> <min> <max> <step> [<subdim>]' or 'LIST' spec, else None."""
    parts = spec.split()
    if parts and parts[0].upper() == "LIST":
        lines = path.read_text(errors="replace").split("\n")
        idx = next((i for i, ln in enumerate(lines) if re.match(r"\s*data ?file\s*:", ln, re.I)), None)
        if idx is None:
            return None
        return [path.parent / ln.strip() for ln in lines[idx + 1 :] if ln.strip()]
    if len(parts) >= 4 and "%" in parts[0]:
        try:
            lo, hi, step = int(parts[1]), int(parts[2]), int(parts[3])
        except ValueError:
            raise CtuiError(f"bad NRRD data file list {spec!r}", path=path) from None
        if step == 0 or abs(hi - lo) // abs(step) + 1 > 100_000:
            raise CtuiError(f"bad NRRD data file list {spec!r}", path=path)
        return [path.parent / (parts[0] % i) for i in range(lo, hi + (1 if step > 0 else -1), step)]
    return None


def header_info(path: Path) -> dict[str, Any]:
    """scan() entry of a NIfTI or NRRD file, from its header only."""
    name = path.name.lower()
    if name.endswith(NIFTI_SUFFIXES):
        nib = _nib()

        try:
            img = nib.load(str(path))
        except Exception as exc:
            raise LoadError(f"not a readable NIfTI file ({type(exc).__name__})", path=path) from None
        shp = (list(img.shape) + [1, 1])[:3]
        m, _, _ = checked_axes(_LPS_FROM_RAS @ img.affine[:3, :3], np.zeros(3), what="NIfTI")
        sp, _ = _geometry_from_matrix(m)
        kind = "nifti"
    else:
        hdr = _read_nrrd_header(path)
        shp = ([int(s) for s in np.atleast_1d(hdr.get("sizes", []))] + [1, 1])[:3]
        m, _ = _nrrd_axes(hdr, int(hdr.get("dimension", 3) or 3), [])
        m, _, _ = checked_axes(m, np.zeros(3), what="NRRD")
        sp, _ = _geometry_from_matrix(m)
        kind = "nrrd"
    return {"uid": "", "description": kind, "modality": "OT", "files": 1, "shape_zyx": [shp[2], shp[1], shp[0]],
            "spacing_zyx_mm": [round(v, 6) for v in sp], "kind": kind}
