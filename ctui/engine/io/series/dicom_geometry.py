"""DICOM geometry: dominant slice size/orientation, sorting along the slice normal,
spacing, gantry tilt and uneven gaps, and the regular grid the volume is put on."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ctui.engine.core.assumptions import Assumption
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



def _orientation(frames: list[Frame], warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Unit row and column vectors (patient x, y, z) from the first ImageOrientationPatient."""
    f0 = frames[0]
    iop = next((f.iop for f in frames if f.iop is not None), None)
    if iop is not None:
        row, col = iop[:3], iop[3:]
        nr, nc = np.linalg.norm(row), np.linalg.norm(col)
        if not (np.isfinite(nr) and np.isfinite(nc)) or nr < 1e-6 or nc < 1e-6:
            warnings.append(Assumption("ImageOrientationPatient has a zero or invalid vector: axial orientation "
                                       "assumed", "orientation"))
            iop = None
        else:
            if abs(nr - 1) > 1e-3 or abs(nc - 1) > 1e-3:
                warnings.append(Assumption(f"ImageOrientationPatient vectors are not unit length ({nr:.4g}, {nc:.4g}): "
                                           "normalised", "orientation"))
            row, col = row / nr, col / nc
            if abs(float(row @ col)) > 1e-3:
                col = col - (col @ row) * row
                nc = float(np.linalg.norm(col))
                if nc < 1e-3:
                    warnings.append(Assumption("ImageOrientationPatient row and column vectors are parallel "
                                               "(invalid): axial orientation assumed", "orientation"))
                    iop = None
                else:
                    col = col / nc
                    warnings.append(Assumption("ImageOrientationPatient row and column vectors are not "
                                               "orthogonal; made orthogonal", "orientation"))
    elif any(f.ipp is not None for f in frames) and f0.sop_class != "1.2.840.10008.5.1.4.1.1.7":
        warnings.append(Assumption("no ImageOrientationPatient: axial orientation assumed", "orientation"))
    if iop is None:
        return np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    return row, col


#: a gap this many times the median gap (and at least OUTLIER_MIN_MM) splits a stack
OUTLIER_FACTOR = 10.0
OUTLIER_MIN_MM = 10.0


def split_outliers(d_sorted: np.ndarray) -> tuple[slice, str]:
    """The run of sorted positions kept when some lie far from the rest.

    A gap larger than ``OUTLIER_FACTOR`` times the median gap (and than
    ``OUTLIER_MIN_MM``) splits the stack; the run with most slices is kept (a slice
    1e7 mm away would otherwise make the regular grid millions of slices long).
    Returns (slice of ``d_sorted`` kept, warning or "").
    """
    n = len(d_sorted)
    if n < 3:
        return slice(0, n), ""
    gaps = np.diff(d_sorted)
    med = float(np.median(gaps))
    cut = np.flatnonzero(gaps > max(OUTLIER_FACTOR * med, OUTLIER_MIN_MM))
    if len(cut) == 0:
        return slice(0, n), ""
    bounds = [0, *(cut + 1).tolist(), n]
    runs = [(bounds[i + 1] - bounds[i], -i) for i in range(len(bounds) - 1)]
    size, neg_i = max(runs)
    keep = slice(bounds[-neg_i], bounds[-neg_i] + size)
    dropped = n - size
    far = float(max(gaps[cut]))
    msg = (f"{dropped} slice{'s' * (dropped != 1)} lie{'s' * (dropped == 1)} far from the rest of the series "
           f"(a gap of {far:.4g} mm where the median gap is {med:.4g} mm): skipped as outliers; "
           f"kept {size} contiguous slices")
    return keep, msg


def _geometry(frames: list[Frame], *, quiet: bool = False) -> dict[str, Any]:
    """Order, spacing and orientation of a series' frames.

    Returns dict: order (indices into frames), positions (mm along normal, sorted, or
    None), dz, row, col, normal, origin, tilt_shifts (mm, per sorted frame, (n,3)) or
    None, tilt_deg, uneven (bool), gaps, warnings, outliers (indices dropped as far
    from the rest), duplicates.
    """
    warnings: list[str] = []
    row, col = _orientation(frames, warnings)
    normal = np.cross(row, col)
    have_pos = [f.ipp is not None for f in frames]
    result: dict[str, Any] = {"row": row, "col": col, "normal": normal, "tilt_shifts": None, "tilt_deg": 0.0,
                              "uneven": False, "gaps": None, "duplicates": [], "warnings": warnings,
                              "missing_positions": False, "outliers": []}
    n = len(frames)
    if n and all(have_pos):
        return _positioned(frames, result)
    if any(have_pos) and sum(have_pos) >= n / 2:
        # positions on most slices: the others are dropped by the caller
        keepi = [i for i in range(n) if have_pos[i]]
        sub = _geometry([frames[i] for i in keepi], quiet=quiet)
        sub["order"] = [keepi[i] for i in sub["order"]]
        sub["outliers"] = [keepi[i] for i in sub["outliers"]]
        sub["dropped_no_position"] = [i for i in range(n) if not have_pos[i]]
        return sub
    return _unpositioned(frames, result)


def _header_dz(f0: Frame) -> tuple[float | None, str | None]:
    """Slice step from SpacingBetweenSlices or SliceThickness (absolute value; a negative
    SpacingBetweenSlices only says the direction), or (None, None)."""
    for value, name in ((f0.spacing_between, "SpacingBetweenSlices"), (f0.thickness, "SliceThickness")):
        if value is not None and np.isfinite(value) and 1e-3 <= abs(value) <= 1e4:
            return abs(float(value)), name
    return None, None


def _positioned(frames: list[Frame], result: dict[str, Any]) -> dict[str, Any]:
    """_geometry for frames that all have ImagePositionPatient."""
    warnings, normal = result["warnings"], result["normal"]
    f0 = frames[0]
    n = len(frames)
    d = np.array([float(f.ipp @ normal) for f in frames])
    inst = [f.instance if f.instance is not None else 0 for f in frames]
    order = sorted(range(n), key=lambda i: (d[i], inst[i], f0.file))
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
    result["duplicates"] = dup
    kept, msg = split_outliers(d[keep])
    if msg:
        result["outliers"] = keep[: kept.start] + keep[kept.stop :]
        warnings.append(msg)
        keep = keep[kept]
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
        dz = _header_dz(f0)[0] or 1.0
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


def _unpositioned(frames: list[Frame], result: dict[str, Any]) -> dict[str, Any]:
    """_geometry without ImagePositionPatient: InstanceNumber / frame / file-name order."""
    f0 = frames[0]
    n = len(frames)
    result["missing_positions"] = True
    if all(f.instance is not None for f in frames) and len({f.instance for f in frames}) == n:
        order = sorted(range(n), key=lambda i: frames[i].instance)
        how = "InstanceNumber"
    elif f0.nframes > 1 and all(f.file == f0.file for f in frames):
        order = list(range(n))
        how = "frame order"
    else:
        order = sorted(range(n), key=lambda i: (frames[i].instance or 0, natural_key(frames[i].file), frames[i].frame))
        how = "InstanceNumber and file name" if any(f.instance is not None for f in frames) else "file name"
    dz, src = _header_dz(f0)
    if dz is None:
        dz = 1.0
    text = (f"no ImagePositionPatient: slices ordered by {how}; slice spacing "
            + (f"{dz:g} mm from {src}" if src else "unknown, default spacing 1 mm"))
    result["warnings"].append(text if src else Assumption(text, "spacing"))
    result.update(order=order, positions=None, dz=float(dz), origin=f0.ipp if f0.ipp is not None else np.zeros(3))
    return result


def _uneven(gaps: np.ndarray) -> bool:
    """Gaps between slices differ by more than 5% of the median gap (and 0.01 mm):
    header rounding of positions stays below that, a missing slice is far above."""
    if len(gaps) == 0:
        return False
    dz = float(np.median(gaps))
    return float(gaps.max() - gaps.min()) > max(0.05 * abs(dz), 0.01)


def equal_step(gaps: np.ndarray) -> tuple[float, str]:
    """The slice step for an unevenly spaced series, as dcm2niix chooses it
    (``nii_saveNII3Deq``): the smallest gap, coarsened when the grid would hold more than
    :data:`EQ_GRID_FACTOR` times the series' slices. Returns (step mm, the rule in words).

    The closely spaced part keeps its resolution (a GE head CT with gaps of 1.08 to
    6.99 mm: 2.62 mm, as dcm2niix; the smallest recurring gap gave 4.00 mm)."""
    g = np.asarray(gaps, float)
    pos = g[g > 1e-3]
    if len(pos) == 0:
        return 1.0, "no positive gap"
    dz, span, n = float(pos.min()), float(g.sum()), len(g) + 1
    if span / dz + 1 > EQ_GRID_FACTOR * n:
        return span / (EQ_GRID_FACTOR * n - 1), (f"the smallest gap {dz:.4g} mm coarsened to {EQ_GRID_FACTOR}x the "
                                                 f"series' {n} slices, as dcm2niix does")
    return dz, "the smallest gap, as dcm2niix chooses"


#: the regular grid may have at most this many times the slices of the series
MAX_GRID_FACTOR = 4
#: dcm2niix's bound on an equalised grid: at most this many times the series' slices
EQ_GRID_FACTOR = 2
#: a tilted series' in-plane grid may grow to at most this many times its rows/columns
MAX_GROWTH = 2.0


@dataclass
class GridPlan:
    """How slices at uneven positions and/or with in-plane offsets (gantry tilt) are put
    on a regular orthogonal grid.

    shifts_yx : (n, 2) in-plane shift of each slice in pixels (rows, columns), or None
    pad_yx : (rows, cols) added before the first row/column (the grid's origin moves
        back by that many pixels along the column / row vectors)
    shape_yx : (ny, nx) of the grid
    positions : (n,) mm along the normal of the input slices
    grid : (m,) mm along the normal of the output slices, or None (kept as is)
    dz : output slice step (mm)
    warnings : what was done, for Volume.warnings
    """

    shifts_yx: np.ndarray | None
    pad_yx: tuple[int, int]
    shape_yx: tuple[int, int]
    positions: np.ndarray | None
    grid: np.ndarray | None
    dz: float
    warnings: list[str] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)

    def out_shape(self, n_in: int) -> tuple[int, int, int]:
        return (len(self.grid) if self.grid is not None else n_in, *self.shape_yx)


def _tilt_plan(offs: np.ndarray, row: np.ndarray, col: np.ndarray, dy: float, dx: float, ny: int, nx: int,
               tilt_deg: float) -> tuple[np.ndarray, tuple[int, int], tuple[int, int], list[str]]:
    """Per-slice pixel shifts and the grown in-plane grid that keeps every pixel."""
    sh = np.column_stack([offs @ col / dy, offs @ row / dx])
    lo = np.floor(np.minimum(sh.min(axis=0), 0.0) + 1e-6).astype(int)
    hi = np.ceil(np.maximum(sh.max(axis=0), 0.0) - 1e-6).astype(int)
    grow = hi - lo
    cap = np.array([int(MAX_GROWTH * ny) - ny, int(MAX_GROWTH * nx) - nx])
    msg = (f"gantry tilt {tilt_deg:.2f} deg: slices shifted in-plane onto an orthogonal grid along the slice "
           f"normal (linear interpolation)")
    if np.all(grow <= cap):
        pad = (int(-lo[0]), int(-lo[1]))
        shape = (ny + int(grow[0]), nx + int(grow[1]))
        if tuple(shape) != (ny, nx):
            msg += f"; grid grown from {ny}x{nx} to {shape[0]}x{shape[1]} pixels to keep every pixel"
        return sh, pad, shape, [msg]
    # implausible offsets (not a gantry tilt): keep the slice's field of view and say what is cut
    area = np.clip(ny - np.abs(sh[:, 0]), 0, None) * np.clip(nx - np.abs(sh[:, 1]), 0, None)
    cut = 1.0 - float(area.sum()) / (len(sh) * ny * nx)
    msg += (f"; the offsets would grow the grid past {MAX_GROWTH:g}x: kept the {ny}x{nx} field of view, "
            f"{100 * cut:.1f}% of the pixels fall outside it and are cut")
    return sh, (0, 0), (ny, nx), [msg]


def plan_grid(geo: dict[str, Any], zsel: list[int], *, dy: float, dx: float, ny: int, nx: int,
              dz_user: float | None = None, resample: bool = True) -> GridPlan:
    """The regular grid for the slices ``zsel`` (indices into geo's sorted order).

    Tilt: every slice is shifted onto the first one's in-plane grid, which grows to
    keep every pixel. Uneven gaps: resampled along the normal at ``dz_user`` (the
    user's spacing; on at most MAX_GRID_FACTOR times the series' slice count) or at
    :func:`equal_step` (dcm2niix's choice: the smallest gap, at most EQ_GRID_FACTOR times
    the slices); ``meta["z_grid"]`` records the step, the rule and the slice counts.
    """
    positions = geo["positions"][zsel] if geo["positions"] is not None else None
    warnings: list[str] = []
    meta: dict[str, Any] = {}
    shifts, pad, shape = None, (0, 0), (ny, nx)
    if geo["tilt_shifts"] is not None:
        shifts, pad, shape, w = _tilt_plan(geo["tilt_shifts"][zsel], geo["row"], geo["col"], dy, dx, ny, nx,
                                           geo["tilt_deg"])
        warnings += w
        meta["gantry_tilt_deg"] = round(geo["tilt_deg"], 4)
        meta["tilt_grid_pad_yx"] = list(pad)
    dz = float(geo["dz"])
    grid = None
    if positions is not None and len(positions) > 1:
        gaps = np.diff(positions)
        dz = float(np.median(gaps))
        if _uneven(gaps) or (dz_user and shifts is not None and resample):
            # uneven: always onto a regular grid; tilted: onto the user's dz when one is given
            grid, dz, w = _z_grid(positions, gaps, dz_user=dz_user, resample=resample,
                                  why="" if _uneven(gaps) else "tilted series")
            warnings += w
            meta["resampled"] = grid is not None
            if grid is not None:
                meta["z_grid"] = {"step_mm": round(dz, 6), "slices": len(grid), "source_slices": len(positions),
                                  "gaps_mm": [round(float(gaps.min()), 4), round(float(gaps.max()), 4)],
                                  "rule": "--spacing" if dz_user else equal_step(gaps)[1]}
        elif dz_user:
            warnings.append(f"spacing dz {dz_user:g} mm not used: the series is evenly spaced at {dz:.4g} mm "
                            f"(from its slice positions)")
    elif dz_user:  # no positions (or one slice): the user's dz is the slice step
        dz = float(dz_user)
        warnings.append(f"slice step {dz:g} mm from the spacing asked for")
    return GridPlan(shifts_yx=shifts, pad_yx=pad, shape_yx=shape, positions=positions, grid=grid, dz=dz,
                    warnings=warnings, meta=meta)


def _z_grid(positions: np.ndarray, gaps: np.ndarray, *, dz_user: float | None,
            resample: bool, why: str = "") -> tuple[np.ndarray | None, float, list[str]]:
    msg = why or f"uneven slice spacing (gaps {gaps.min():.3g} to {gaps.max():.3g} mm)"
    if not resample:
        return None, float(np.median(gaps)), [msg + ": kept as is (resample=False); slice_positions gives each "
                                                    "slice's position"]
    span = float(positions[-1] - positions[0])
    if dz_user:
        dz, why = float(dz_user), "the spacing asked for"
    else:
        dz, why = equal_step(gaps)
    most = MAX_GRID_FACTOR * len(positions)
    if span / dz + 1 > most:
        dz = span / (most - 1)
        why += f", coarsened to keep the grid within {MAX_GRID_FACTOR}x the series' {len(positions)} slices"
    m = int(round(span / dz)) + 1
    grid = positions[0] + dz * np.arange(m)
    return grid, dz, [msg + f": resampled to a regular {dz:.4g} mm grid ({why}; {m} slices) along the slice "
                            f"normal (linear)"]


def apply_grid(out: np.ndarray, plan: GridPlan, *, check: Callable[[int, str], None]) -> np.ndarray:
    """Put ``out`` (n, ny, nx) slices on the plan's grid; ``check(nbytes, what)`` is called
    before each new array is allocated (raises when it would not fit)."""
    if plan.shifts_yx is not None:
        out = _tilt_correct(out, plan, check)
    if plan.grid is not None:
        m = len(plan.grid)
        check(m * out.shape[1] * out.shape[2] * out.dtype.itemsize, f"the regular {m}-slice grid")
        out = _resample_z(out, plan.positions, plan.grid)
    return out


def _tilt_correct(out: np.ndarray, plan: GridPlan, check: Callable[[int, str], None]) -> np.ndarray:
    """Shift each slice by its in-plane offset onto the (grown) orthogonal grid."""
    from scipy import ndimage

    ny2, nx2 = plan.shape_yx
    py, px = plan.pad_yx
    n, ny, nx = out.shape
    grown = (ny2, nx2) != (ny, nx)
    if grown:
        check(n * ny2 * nx2 * out.dtype.itemsize, f"the tilt-corrected {n}x{ny2}x{nx2} grid")
        res = np.empty((n, ny2, nx2), out.dtype)
    else:
        res = out
    fill = float(out.min()) if out.size else 0.0
    buf = np.empty((ny2, nx2), np.float32)
    for k in range(n):
        sy, sx = (float(v) for v in plan.shifts_yx[k])
        sy, sx = sy + py, sx + px
        iy, ix = int(np.floor(sy)), int(np.floor(sx))
        fy, fx = sy - iy, sx - ix
        buf.fill(fill)
        # integer part by placement (clipped to the grid), fraction by linear interpolation
        y0, x0 = max(iy, 0), max(ix, 0)
        y1, x1 = min(iy + ny, ny2), min(ix + nx, nx2)
        if y1 > y0 and x1 > x0:
            buf[y0:y1, x0:x1] = out[k, y0 - iy : y1 - iy, x0 - ix : x1 - ix]
        if fy > 1e-3 or fx > 1e-3:
            src = buf.copy()
            ndimage.shift(src, (fy, fx), output=buf, order=1, mode="constant", cval=fill)
        res[k] = np.rint(buf) if res.dtype.kind in "iu" else buf
    return res


def _resample_z(out: np.ndarray, positions: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Linear resampling of slices at ``positions`` (mm, increasing) onto ``grid`` (mm)."""
    n = len(grid)
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
