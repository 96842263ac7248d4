"""DICOM geometry: dominant slice size/orientation, sorting along the slice normal,
spacing, gantry tilt and uneven gaps, and the regular grid the volume is put on."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.io.series._common import natural_key, rel
from ctui.engine.io.series.dicom_headers import Frame


def _dominant(frames: list[Frame], skipped: list[dict[str, str]], base: Path | None) -> list[Frame]:
    """Keep the frames sharing the most common size and orientation; skip the rest with a reason."""
    sizes = Counter((f.rows, f.cols) for f in frames)
    (r, c), _ = sizes.most_common(1)[0]
    keep = []
    for f in frames:
        if (f.rows, f.cols) != (r, c):
            skipped.append({"file": rel(f.file, base) + (f" frame {f.frame}" if f.nframes > 1 else ""),
                            "reason": f"slice size {f.rows}x{f.cols} differs from the series' {r}x{c}"})
        else:
            keep.append(f)
    with_iop = [f for f in keep if f.iop is not None]
    if with_iop:
        keys = Counter(tuple(np.round(f.iop, 3)) for f in with_iop)
        ref = np.array(keys.most_common(1)[0][0])
        out = []
        for f in keep:
            if f.iop is not None and np.max(np.abs(f.iop - ref)) > 1e-2:
                skipped.append({"file": rel(f.file, base) + (f" frame {f.frame}" if f.nframes > 1 else ""),
                                "reason": "image orientation differs from the rest of the series"})
            else:
                out.append(f)
        keep = out
    return keep



def _geometry(frames: list[Frame], *, quiet: bool = False) -> dict[str, Any]:
    """Order, spacing and orientation of a series' frames.

    Returns dict: order (indices into frames), positions (mm along normal, sorted, or
    None), dz, row, col, normal, origin, tilt_shifts (mm, per sorted frame, (n,3)) or
    None, tilt_deg, uneven (bool), gaps, warnings, duplicates (indices dropped).
    """
    warnings: list[str] = []
    f0 = frames[0]
    iop = next((f.iop for f in frames if f.iop is not None), None)
    if iop is not None:
        row, col = iop[:3], iop[3:]
        nr, nc = np.linalg.norm(row), np.linalg.norm(col)
        if nr < 1e-6 or nc < 1e-6:
            iop = None
        else:
            row, col = row / nr, col / nc
            if abs(float(row @ col)) > 1e-3:
                col = col - (col @ row) * row
                nc = float(np.linalg.norm(col))
                if nc < 1e-3:
                    warnings.append("ImageOrientationPatient row and column vectors are parallel (invalid): "
                                    "axial orientation assumed")
                    iop = None
                else:
                    col = col / nc
                    warnings.append("ImageOrientationPatient row and column vectors are not orthogonal; made orthogonal")
    elif any(f.ipp is not None for f in frames) and f0.sop_class != "1.2.840.10008.5.1.4.1.1.7":
        warnings.append("no ImageOrientationPatient: axial orientation assumed")
    if iop is None:
        row, col = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    normal = np.cross(row, col)
    have_pos = [f.ipp is not None for f in frames]
    result: dict[str, Any] = {"row": row, "col": col, "normal": normal, "tilt_shifts": None, "tilt_deg": 0.0,
                              "uneven": False, "gaps": None, "duplicates": [], "warnings": warnings,
                              "missing_positions": False}
    n = len(frames)
    if n and all(have_pos):
        d = np.array([float(f.ipp @ normal) for f in frames])
        inst = [f.instance if f.instance is not None else 0 for f in frames]
        order = sorted(range(n), key=lambda i: (d[i], inst[i], f0.file))
        ds = d[order]
        # duplicate positions (multiple echoes/phases in one series): keep the first
        keep = [order[0]]
        dup = []
        for i in order[1:]:
            if abs(d[i] - d[keep[-1]]) < 1e-3:
                dup.append(i)
            else:
                keep.append(i)
        if dup:
            warnings.append(f"{len(dup)} slices share a position with another slice (several echoes, phases or "
                            f"acquisitions in one series?); kept the first at each position")
        order = keep
        ds = d[order]
        gaps = np.diff(ds)
        if len(gaps):
            dz = float(np.median(gaps))
            if dz <= 0:
                dz = 1.0
            if _uneven(gaps):
                result["uneven"] = True
                result["gaps"] = (float(gaps.min()), float(gaps.max()))
        else:
            dz = f0.spacing_between or f0.thickness or 1.0
        # gantry tilt: in-plane offset of each slice's position from the first one's
        p0 = frames[order[0]].ipp
        offs = np.array([frames[i].ipp - p0 - (d[i] - d[order[0]]) * normal for i in order])
        inplane = np.linalg.norm(offs, axis=1)
        psz = min(f0.pixel_spacing or (1.0, 1.0))
        span = ds[-1] - ds[0]
        tilt = float(np.degrees(np.arctan2(np.linalg.norm(offs[-1]), span))) if span > 0 else 0.0
        # rounding of positions in the header gives tiny offsets: only a stack whose
        # positions move by more than a quarter pixel in-plane (and > 0.1 deg) is tilted
        if len(order) > 1 and inplane.max() > max(0.25 * psz, 0.05) and tilt > 0.1:
            result["tilt_shifts"] = offs
            result["tilt_deg"] = tilt
        result.update(order=order, positions=ds, dz=dz, origin=p0)
        return result
    # ---- no (or partial) positions
    if any(have_pos) and sum(have_pos) >= n / 2:
        # positions on most slices: the others are dropped by the caller
        keepi = [i for i in range(n) if have_pos[i]]
        sub = _geometry([frames[i] for i in keepi], quiet=quiet)
        sub["order"] = [keepi[i] for i in sub["order"]]
        sub["dropped_no_position"] = [i for i in range(n) if not have_pos[i]]
        return sub
    result["missing_positions"] = True
    dz = f0.spacing_between or f0.thickness
    if all(f.instance is not None for f in frames) and len({f.instance for f in frames}) == n:
        order = sorted(range(n), key=lambda i: frames[i].instance)
        how = "InstanceNumber"
    elif f0.nframes > 1 and all(f.file == f0.file for f in frames):
        order = list(range(n))
        how = "frame order"
    else:
        order = sorted(range(n), key=lambda i: (frames[i].instance or 0, natural_key(frames[i].file), frames[i].frame))
        how = "InstanceNumber and file name" if any(f.instance is not None for f in frames) else "file name"
    src = "SpacingBetweenSlices" if f0.spacing_between else ("SliceThickness" if f0.thickness else None)
    if not dz or dz <= 0:
        dz = 1.0
        src = None
    warnings.append(
        f"no ImagePositionPatient: slices ordered by {how}; slice spacing "
        + (f"{dz:g} mm from {src}" if src else "unknown, default spacing 1 mm")
    )
    result.update(order=order, positions=None, dz=float(dz), origin=f0.ipp if f0.ipp is not None else np.zeros(3))
    return result


def _uneven(gaps: np.ndarray) -> bool:
    """Gaps between slices differ by more than 5% of the median gap (and 0.01 mm):
    header rounding of positions stays below that, a missing slice is far above."""
    if len(gaps) == 0:
        return False
    dz = float(np.median(gaps))
    return float(gaps.max() - gaps.min()) > max(0.05 * abs(dz), 0.01)


def _tilt_correct(out: np.ndarray, offs: np.ndarray, row: np.ndarray, col: np.ndarray, dy: float, dx: float) -> None:
    """Shift each slice in place by its in-plane offset (mm, (nz, 3)), in pixel units."""
    from scipy import ndimage

    fill = float(out.min()) if out.size else 0.0
    for k in range(out.shape[0]):
        sy, sx = float(offs[k] @ col) / dy, float(offs[k] @ row) / dx
        if abs(sy) < 1e-3 and abs(sx) < 1e-3:
            continue
        src = out[k].astype(np.float32)
        shifted = ndimage.shift(src, (sy, sx), order=1, mode="constant", cval=fill)
        if out.dtype.kind in "iu":
            shifted = np.rint(shifted)
        out[k] = shifted


def _resample_z(out: np.ndarray, positions: np.ndarray, dz: float) -> np.ndarray:
    """Linear resampling of slices at ``positions`` (mm, increasing) onto a regular grid."""
    p0 = positions[0]
    n = int(round((positions[-1] - p0) / dz)) + 1
    grid = p0 + dz * np.arange(n)
    res = np.empty((n, *out.shape[1:]), dtype=out.dtype)
    idx = np.clip(np.searchsorted(positions, grid, side="right") - 1, 0, len(positions) - 2)
    for k in range(n):
        i = idx[k]
        a, b = positions[i], positions[i + 1]
        t = 0.0 if b == a else float(np.clip((grid[k] - a) / (b - a), 0.0, 1.0))
        if t < 1e-6:
            res[k] = out[i]
        elif t > 1 - 1e-6:
            res[k] = out[i + 1]
        else:
            v = out[i].astype(np.float32) * (1 - t) + out[i + 1].astype(np.float32) * t
            res[k] = np.rint(v) if res.dtype.kind in "iu" else v
    return res

