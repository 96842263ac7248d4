"""Slice drift check: per-slice object centroids, deviation from a smooth fit, correction.

If the patient (or the phantom) moved during a sequential scan, a few slices are
displaced in-plane: the centroid of every object jumps on those slices and comes back.
:func:`analyze_drift` computes each object's centroid on each slice, fits a smooth
curve along the slices (running median of ``window`` slices, robust to a run of up to
``window // 2`` displaced slices, then a 3-slice mean; or a robust polynomial with
``method="poly"``), and takes slices whose in-plane deviation from the fit exceeds
``threshold_mm`` as candidates.

A candidate is flagged only when it looks like a jolt, not like the object changing
shape (an organ's centroid wanders near its poles in a breath-hold scan with no motion
at all):

* **all objects shift together**: on that slice at least two objects deviate by more
  than half the threshold in the same direction (within 45 degrees); or
* **a shift that returns**: a run of at most ``window // 2`` candidate slices, with
  slices of the object on both sides, whose centroid is off the straight line joining
  the centroids just before and just after the run by more than the threshold, on a
  slice where the object has at least a quarter of its median area (the thin caps of
  an organ change shape fastest).

and, in both cases, only when the section is **moved, not reshaped**: the translation
that best lays the object's section on its neighbours (interpolated between the nearest
slices outside the run) is over half the threshold and points the way the centroid
must go back (an organ changing shape moves its centroid but not its outline: its best
translation is near zero); and at least half of the objects on the slice are moved the
same way (motion moves everything in the slice together). On TotalSegmentator's labels
of a still breath-hold CT (all 30 classes) this flags no slice, where centroids alone
flagged 27 of 30; a 4-pixel jolt of one slice there is flagged alone.

Other candidates are reported as ``shape_change`` (not flagged). ``confirm=False``
flags every candidate (centroids alone).

Units: centroids are reported in pixels (x, y) and in patient mm (x, y, z, through the
volume geometry); deviations are in mm along the x and y index axes (pixel offset
times the pixel spacing); corrections are in pixels.

A correction (:func:`corrections_from_report`) is data: a list of
``{"slice": z, "dx": px, "dy": px}`` giving the shift that moves the slice back onto
the fit (by centroid alignment, or by phase correlation against the neighbouring
unflagged slices with ``estimate="phase"``). It is stored in the project and applied
to a copy with :func:`apply_corrections` (image and labels); the original data are
never modified, so undo is dropping entries from the list and re-applying.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.core.atomic import atomic_path
from ctui.engine.core.colors import object_color_float


@dataclass
class ObjectDrift:
    """Drift analysis of one object. Arrays are per slice in ``slices`` order."""

    object_id: int
    slices: np.ndarray  # int (n,)
    centroid_px: np.ndarray  # (n, 2) x, y
    centroid_mm: np.ndarray  # (n, 3) patient x, y, z
    fit_px: np.ndarray  # (n, 2)
    deviation_mm: np.ndarray  # (n, 2) along x and y index axes
    distance_mm: np.ndarray  # (n,)
    flagged: list[int] = field(default_factory=list)
    shape_change: list[int] = field(default_factory=list)  # over the threshold, but not a jolt
    area: np.ndarray | None = None  # pixels (n,)

    def to_dict(self) -> dict[str, Any]:
        return {
            "object_id": int(self.object_id),
            "slices": [int(z) for z in self.slices],
            "centroid_px": np.round(self.centroid_px, 3).tolist(),
            "centroid_mm": np.round(self.centroid_mm, 3).tolist(),
            "fit_px": np.round(self.fit_px, 3).tolist(),
            "deviation_mm": np.round(self.deviation_mm, 3).tolist(),
            "distance_mm": np.round(self.distance_mm, 3).tolist(),
            "flagged": [int(z) for z in self.flagged],
            "shape_change": [int(z) for z in self.shape_change],
        }


@dataclass
class DriftReport:
    """Result of :func:`analyze_drift`: per-object analyses and the flagged slices (union)."""

    objects: list[ObjectDrift]
    flagged: list[int]
    threshold_mm: float
    spacing: tuple[float, float, float]
    method: str
    window: int

    def to_dict(self) -> dict[str, Any]:
        return {"threshold_mm": self.threshold_mm, "method": self.method, "window": self.window,
                "flagged": [int(z) for z in self.flagged], "objects": [o.to_dict() for o in self.objects]}

    def plot_data(self) -> dict[str, Any]:
        """Series for a TUI plot: per object ``{id, z, x_mm, y_mm, fit_x_mm, fit_y_mm, dist_mm}``
        (x/y in mm along the index axes) plus ``threshold_mm`` and ``flagged``."""
        dy, dx = self.spacing[1], self.spacing[2]
        objs = []
        for o in self.objects:
            objs.append({"id": o.object_id, "z": o.slices.tolist(),
                         "x_mm": (o.centroid_px[:, 0] * dx).tolist(), "y_mm": (o.centroid_px[:, 1] * dy).tolist(),
                         "fit_x_mm": (o.fit_px[:, 0] * dx).tolist(), "fit_y_mm": (o.fit_px[:, 1] * dy).tolist(),
                         "dist_mm": o.distance_mm.tolist(), "flagged": list(o.flagged)})
        return {"objects": objs, "threshold_mm": self.threshold_mm, "flagged": list(self.flagged)}


def slice_centroids(labels: np.ndarray, object_id: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroid of ``object_id`` on each slice holding it.

    Returns (slices int (n,), centroid_px float (n, 2) as (x, y), area int (n,)).
    """
    m = labels == object_id
    area = np.count_nonzero(m, axis=(1, 2))
    zs = np.flatnonzero(area)
    if zs.size == 0:
        return zs, np.zeros((0, 2)), area[zs]
    ny, nx = labels.shape[1:]
    xs = np.arange(nx, dtype=np.float64)
    ys = np.arange(ny, dtype=np.float64)
    sub = m[zs]
    cx = (sub.sum(axis=1) @ xs) / area[zs]
    cy = (sub.sum(axis=2) @ ys) / area[zs]
    return zs, np.column_stack([cx, cy]), area[zs]


def smooth_fit(values: np.ndarray, *, method: str = "median", window: int = 9, degree: int = 3) -> np.ndarray:
    """Smooth trend of a 1D series (n,) or of each column of (n, k).

    ``median``: running median over ``window`` samples (edges: nearest), then a 3-sample
    mean; ignores runs of up to ``window // 2`` outliers. ``poly``: polynomial of
    ``degree`` fitted with iterative Tukey-biweight reweighting (robust to jolts).
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim == 1:
        return smooth_fit(v[:, None], method=method, window=window, degree=degree)[:, 0]
    n = len(v)
    if n < 3:
        return v.copy()
    if method == "median":
        from scipy import ndimage

        w = max(3, min(int(window) | 1, n if n % 2 else n - 1))
        med = ndimage.median_filter(v, size=(w, 1), mode="nearest")
        return ndimage.uniform_filter1d(med, size=3, axis=0, mode="nearest")
    if method == "poly":
        t = np.linspace(-1.0, 1.0, n)
        deg = min(int(degree), n - 1)
        out = np.empty_like(v)
        for j in range(v.shape[1]):
            w = np.ones(n)
            coef = np.polyfit(t, v[:, j], deg)
            for _ in range(10):
                r = v[:, j] - np.polyval(coef, t)
                s = 1.4826 * np.median(np.abs(r - np.median(r))) + 1e-9
                u = r / (4.685 * s)
                w = np.where(np.abs(u) < 1, (1 - u**2) ** 2, 0.0)
                if w.sum() < deg + 1:
                    break
                coef = np.polyfit(t, v[:, j], deg, w=np.sqrt(w))
            out[:, j] = np.polyval(coef, t)
        return out
    raise ValueError(f"unknown fit method {method!r} (median or poly)")


def analyze_drift(labels: np.ndarray, volume: Any = None, *, spacing: tuple[float, float, float] | None = None,
                  object_ids: list[int] | None = None, threshold_mm: float | None = None, method: str = "median",
                  window: int = 9, min_area: int = 5, confirm: bool = True) -> DriftReport:
    """Centroids per slice, deviation from a smooth fit, flagged slices.

    Parameters
    ----------
    labels : uint8 (nz, ny, nx)
    volume : Volume for geometry (centroids in patient mm); or give ``spacing``
    object_ids : objects to analyse (default: all present)
    threshold_mm : flag slices deviating more than this (default: max(1 mm, 0.75 pixel))
    method, window : see :func:`smooth_fit`
    min_area : slices where the object has fewer pixels are ignored (noisy centroids)
    confirm : flag only candidates that look like a jolt (see the module docstring)
    """
    if volume is not None:
        spacing = tuple(volume.spacing)
    if spacing is None:
        spacing = (1.0, 1.0, 1.0)
    dz, dy, dx = (float(s) for s in spacing)
    if threshold_mm is None:
        threshold_mm = max(1.0, 0.75 * max(dx, dy))
    if object_ids is None:
        object_ids = [int(i) for i in np.flatnonzero(np.bincount(labels.ravel(), minlength=256)[1:]) + 1]
    results = []
    flagged: set[int] = set()
    for oid in object_ids:
        zs, c, area = slice_centroids(labels, oid)
        keep = area >= min_area
        zs, c, area = zs[keep], c[keep], area[keep]
        if zs.size == 0:
            continue
        fit = smooth_fit(c, method=method, window=window)
        dev = (c - fit) * np.array([dx, dy])
        dist = np.hypot(dev[:, 0], dev[:, 1])
        if volume is not None:
            cmm = volume.index_to_mm(np.column_stack([zs.astype(float), c[:, 1], c[:, 0]]))
        else:
            cmm = np.column_stack([c[:, 0] * dx, c[:, 1] * dy, zs * dz])
        fl = [int(z) for z, d in zip(zs, dist) if d > threshold_mm]
        results.append(ObjectDrift(object_id=int(oid), slices=zs, centroid_px=c, centroid_mm=cmm, fit_px=fit,
                                   deviation_mm=dev, distance_mm=dist, flagged=fl, area=area))
    if confirm:
        _confirm(results, float(threshold_mm), max_run=max(1, int(window) // 2), spacing_yx=(dy, dx))
        _confirm_rigid(results, labels, float(threshold_mm), spacing_yx=(dy, dx))
    for o in results:
        flagged.update(o.flagged)
    return DriftReport(objects=results, flagged=sorted(flagged), threshold_mm=float(threshold_mm),
                       spacing=(dz, dy, dx), method=method, window=int(window))


def _confirm(objects: list[ObjectDrift], threshold: float, *, max_run: int, spacing_yx: tuple[float, float]) -> None:
    """Keep in each object's ``flagged`` only the jolts; move the rest to ``shape_change``."""
    together: set[int] = set()
    devs: dict[int, list[np.ndarray]] = {}
    for o in objects:
        for z, d in zip(o.slices, o.deviation_mm):
            if np.hypot(*d) > threshold / 2:
                devs.setdefault(int(z), []).append(d)
    for z, ds in devs.items():
        for i in range(len(ds)):
            for j in range(i + 1, len(ds)):
                a, b = ds[i], ds[j]
                if float(a @ b) > np.cos(np.pi / 4) * np.hypot(*a) * np.hypot(*b):
                    together.add(z)
    scale = np.array([spacing_yx[1], spacing_yx[0]])
    for o in objects:
        if not o.flagged:
            continue
        med = float(np.median(o.area)) if o.area is not None and len(o.area) else 0.0
        cand = set(o.flagged)
        idx = [k for k, z in enumerate(o.slices) if int(z) in cand]
        keep: set[int] = {int(o.slices[k]) for k in idx if int(o.slices[k]) in together}
        for run in _runs(idx, o.slices):
            a, b = run[0] - 1, run[-1] + 1
            if len(run) > max_run or a < 0 or b >= len(o.slices):
                continue
            for k in run:
                t = (o.slices[k] - o.slices[a]) / max(o.slices[b] - o.slices[a], 1)
                line = (1 - t) * o.centroid_px[a] + t * o.centroid_px[b]
                off = float(np.hypot(*((o.centroid_px[k] - line) * scale)))
                if off > threshold and (o.area is None or o.area[k] >= 0.25 * med):
                    keep.add(int(o.slices[k]))
        o.shape_change = sorted(cand - keep)
        o.flagged = sorted(keep)


def _confirm_rigid(objects: list[ObjectDrift], labels: np.ndarray, threshold: float, *,
                   spacing_yx: tuple[float, float]) -> None:
    """Keep a flagged slice only when the object's section there is *moved*, not reshaped.

    Motion translates the whole section: shifted back by a translation it lies on the
    sections around it (interpolated between the nearest slices outside the run of
    candidates). An organ changing shape moves its centroid but not its outline: the
    best translation onto its neighbours is near zero. A slice stays flagged when that
    best translation (:func:`_rigid_shift`) is over half the threshold and over half the
    centroid's deviation, within 45 degrees of moving the centroid back onto the fit."""
    scale = np.array([spacing_yx[1], spacing_yx[0]])  # (x, y) mm per px
    shifts: dict[int, dict[int, np.ndarray]] = {}
    for o in objects:
        shifts[o.object_id] = {}
        if not o.flagged:
            continue
        cand = set(o.flagged)
        idx = [k for k, z in enumerate(o.slices) if int(z) in cand]
        moved: dict[int, np.ndarray] = {}
        for run in _runs(idx, o.slices):
            a, b = run[0] - 1, run[-1] + 1
            ma = labels[int(o.slices[a])] == o.object_id if a >= 0 else None
            mb = labels[int(o.slices[b])] == o.object_id if b < len(o.slices) else None
            if ma is None and mb is None:
                continue
            for k in run:
                if ma is not None and mb is not None:
                    t = (o.slices[k] - o.slices[a]) / max(o.slices[b] - o.slices[a], 1)
                    ref = (1 - t) * ma + t * mb
                else:
                    ref = (ma if ma is not None else mb).astype(np.float64)
                back = (o.fit_px[k] - o.centroid_px[k]) * scale  # mm that would put the centroid on the fit
                reach = int(np.ceil(np.abs(o.fit_px[k] - o.centroid_px[k]).max())) + 2
                r = _rigid_shift(labels[int(o.slices[k])] == o.object_id, ref, min(reach, 16)) * scale
                nr, nb = float(np.hypot(*r)), float(np.hypot(*back))
                if nr > threshold / 2 and nr > 0.5 * nb and float(r @ back) > np.cos(np.pi / 4) * nr * nb:
                    moved[int(o.slices[k])] = r
        o.shape_change = sorted(set(o.shape_change) | (cand - set(moved)))
        o.flagged = sorted(cand & set(moved))
        shifts[o.object_id] = moved
    _vote(objects, labels, threshold, shifts, scale)


def _vote(objects: list[ObjectDrift], labels: np.ndarray, threshold: float, shifts: dict[int, dict[int, np.ndarray]],
          scale: np.ndarray) -> None:
    """Motion moves everything in the slice: a slice stays flagged when at least half of the
    objects on it are translated (:func:`_rigid_shift` onto their neighbouring sections)
    the same way (over half the threshold, within 45 degrees of the flagged objects' median)."""
    moved = {z for o in objects for z in o.flagged}
    for z in sorted(moved):
        ref = np.median([shifts[o.object_id][z] for o in objects if z in o.flagged], axis=0)
        nref = float(np.hypot(*ref))
        votes = []
        for o in objects:
            still = [int(q) for q in o.slices if int(q) == z or int(q) not in moved]  # neighbours that did not move
            if z not in still or not 0 < still.index(z) < len(still) - 1:
                continue
            k = still.index(z)
            r = shifts[o.object_id].get(z)
            if r is None:
                near = 0.5 * ((labels[still[k - 1]] == o.object_id).astype(np.float64)
                              + (labels[still[k + 1]] == o.object_id))
                reach = min(int(np.ceil(nref / scale.min())) + 2, 16)
                r = _rigid_shift(labels[z] == o.object_id, near, reach) * scale
            nr = float(np.hypot(*r))
            votes.append(nr > threshold / 2 and float(r @ ref) > np.cos(np.pi / 4) * nr * nref)
        if votes and sum(votes) < 0.5 * len(votes):
            for o in objects:
                if z in o.flagged:
                    o.flagged.remove(z)
                    o.shape_change = sorted(set(o.shape_change) | {z})


def _rigid_shift(mask: np.ndarray, ref: np.ndarray, reach: int) -> np.ndarray:
    """The translation (dx, dy) px, within ``reach``, that best lays the bool ``mask`` (y, x)
    on ``ref`` (float, same shape): the peak of their cross-correlation, refined to a
    fraction of a pixel by a parabola through the peak and its neighbours."""
    both = mask | (ref > 0)
    ys, xs = np.flatnonzero(both.any(axis=1)), np.flatnonzero(both.any(axis=0))
    if not ys.size:
        return np.zeros(2)
    y0, y1 = max(ys[0] - reach, 0), min(ys[-1] + reach + 1, mask.shape[0])
    x0, x1 = max(xs[0] - reach, 0), min(xs[-1] + reach + 1, mask.shape[1])
    from scipy.signal import correlate

    a = mask[y0:y1, x0:x1].astype(np.float64)
    b = ref[y0:y1, x0:x1].astype(np.float64)
    n = 2 * reach + 1
    full = correlate(b, a, mode="full", method="fft")  # [k] = sum a(p - s) b(p), s = k - (shape - 1)
    full = np.pad(full, reach, constant_values=-np.inf)  # shifts past the image: never the best
    cy, cx = a.shape[0] - 1 + reach, a.shape[1] - 1 + reach
    score = full[cy - reach:cy + reach + 1, cx - reach:cx + reach + 1]
    i, j = np.unravel_index(int(np.argmax(score)), score.shape)
    if score[i, j] <= score[reach, reach] * (1 + 1e-9):  # no better than staying: no shift
        i, j = reach, reach

    def peak(lo: float, mid: float, hi: float) -> float:
        d = lo - 2 * mid + hi
        return 0.0 if d >= 0 else float(np.clip(0.5 * (lo - hi) / d, -0.5, 0.5))

    fy = peak(score[i - 1, j], score[i, j], score[i + 1, j]) if 0 < i < n - 1 and np.isfinite(
        score[i - 1:i + 2, j]).all() else 0.0
    fx = peak(score[i, j - 1], score[i, j], score[i, j + 1]) if 0 < j < n - 1 and np.isfinite(
        score[i, j - 1:j + 2]).all() else 0.0
    return np.array([j - reach + fx, i - reach + fy])


def _runs(idx: list[int], slices: np.ndarray) -> list[list[int]]:
    """Consecutive candidate indices that are also consecutive slices."""
    runs: list[list[int]] = []
    for k in idx:
        if runs and runs[-1][-1] == k - 1 and slices[k] == slices[k - 1] + 1:
            runs[-1].append(k)
        else:
            runs.append([k])
    return runs


def corrections_from_report(report: DriftReport, *, estimate: str = "centroid", volume: Any = None,
                            slices: list[int] | None = None) -> list[dict[str, float]]:
    """Shifts that move the flagged slices back onto the fit: list of ``{slice, dx, dy}`` (pixels).

    ``estimate="centroid"``: the median over objects of (fit - centroid).
    ``estimate="phase"``: cv2.phaseCorrelate of the slice against the mean of the
    nearest unflagged slices above and below (needs ``volume``; whole-slice shift).
    """
    todo = report.flagged if slices is None else list(slices)
    out = []
    for z in todo:
        if estimate == "phase":
            if volume is None:
                raise ValueError("phase correlation needs the volume")
            dxv, dyv = _phase_shift(volume, int(z), set(report.flagged))
        elif estimate == "centroid":
            shifts = []
            for o in report.objects:
                hit = np.flatnonzero(o.slices == z)
                if hit.size:
                    i = hit[0]
                    shifts.append(o.fit_px[i] - o.centroid_px[i])
            if not shifts:
                continue
            dxv, dyv = np.median(np.array(shifts), axis=0)
        else:
            raise ValueError(f"unknown estimate {estimate!r} (centroid or phase)")
        out.append({"slice": int(z), "dx": round(float(dxv), 3), "dy": round(float(dyv), 3)})
    return out


def _phase_shift(volume: Any, z: int, flagged: set[int]) -> tuple[float, float]:
    import cv2

    nz = volume.data.shape[0]
    refs = []
    for step in (-1, 1):
        k = z + step
        while 0 <= k < nz and k in flagged:
            k += step
        if 0 <= k < nz:
            refs.append(volume.data[k].astype(np.float32))
    if not refs:
        return 0.0, 0.0
    ref = np.mean(refs, axis=0).astype(np.float32)
    cur = volume.data[z].astype(np.float32)
    win = cv2.createHanningWindow(cur.shape[::-1], cv2.CV_32F)
    (sx, sy), _ = cv2.phaseCorrelate(cur, ref, win)
    # phaseCorrelate(a, b) gives the shift of b relative to a: moving `cur` by it aligns it with ref
    return float(sx), float(sy)


def apply_corrections(data: np.ndarray, corrections: list[dict[str, float]], *, interpolation: str = "linear",
                      fill_value: float | None = None) -> np.ndarray:
    """Copy of ``data`` (nz, ny, nx) with each corrected slice shifted by (dx, dy) pixels.

    ``interpolation``: "linear" (images) or "nearest" (label volumes; also used
    automatically for integer shifts, which are exact). ``fill_value``: value for
    pixels shifted in from outside (default: the slice minimum; 0 for labels).
    """
    import cv2

    out = data.copy()
    if not corrections:
        return out
    ny, nx = data.shape[1:]
    for c in corrections:
        z = int(c["slice"])
        dxv, dyv = float(c.get("dx", 0.0)), float(c.get("dy", 0.0))
        if not 0 <= z < data.shape[0] or (dxv == 0 and dyv == 0):
            continue
        src = data[z]
        fill = fill_value if fill_value is not None else (0 if interpolation == "nearest" else float(src.min()))
        if float(dxv).is_integer() and float(dyv).is_integer() or interpolation == "nearest":
            ix, iy = int(round(dxv)), int(round(dyv))
            sl = np.full_like(src, fill)
            ys0, ys1 = max(0, -iy), min(ny, ny - iy)
            xs0, xs1 = max(0, -ix), min(nx, nx - ix)
            if ys1 > ys0 and xs1 > xs0:
                sl[ys0 + iy:ys1 + iy, xs0 + ix:xs1 + ix] = src[ys0:ys1, xs0:xs1]
            out[z] = sl
        else:
            m = np.float32([[1, 0, dxv], [0, 1, dyv]])
            warped = cv2.warpAffine(src.astype(np.float32), m, (nx, ny), flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_CONSTANT, borderValue=float(fill))
            out[z] = np.rint(warped).astype(data.dtype) if np.issubdtype(data.dtype, np.integer) else warped.astype(data.dtype)
    return out


def invert_corrections(corrections: list[dict[str, float]]) -> list[dict[str, float]]:
    """The opposite shifts (exact for integer shifts away from the slice edges)."""
    return [{"slice": int(c["slice"]), "dx": -float(c["dx"]), "dy": -float(c["dy"])} for c in corrections]


def plot_drift(report: DriftReport, path: Any, *, title: str | None = None) -> None:
    """Write a PNG plot (matplotlib Agg) of centroids, fits and deviations, atomically."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    data = report.plot_data()
    fig = Figure(figsize=(8, 7), dpi=100)
    axx, axy, axd = fig.subplots(3, 1, sharex=True)
    for o in data["objects"]:
        col = object_color_float(o["id"])
        z = np.array(o["z"])
        axx.plot(z, o["x_mm"], ".", color=col, label=f"object {o['id']}")
        axx.plot(z, o["fit_x_mm"], "-", color=col, lw=1)
        axy.plot(z, o["y_mm"], ".", color=col)
        axy.plot(z, o["fit_y_mm"], "-", color=col, lw=1)
        axd.plot(z, o["dist_mm"], "-o", color=col, ms=3)
        fl = np.isin(z, o["flagged"])
        if fl.any():
            axx.plot(z[fl], np.array(o["x_mm"])[fl], "x", color="k", ms=8)
            axy.plot(z[fl], np.array(o["y_mm"])[fl], "x", color="k", ms=8)
    axd.axhline(data["threshold_mm"], color="k", ls="--", lw=1, label="threshold")
    axx.set_ylabel("centroid x (mm)")
    axy.set_ylabel("centroid y (mm)")
    axd.set_ylabel("deviation (mm)")
    axd.set_xlabel("slice")
    for z in data["flagged"]:
        for ax in (axx, axy, axd):
            ax.axvspan(z - 0.5, z + 0.5, color="red", alpha=0.12, lw=0)
    axx.legend(loc="best", fontsize=7)
    fig.suptitle(title or f"slice drift ({len(data['flagged'])} flagged, threshold {data['threshold_mm']:.2f} mm)")
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png")


def correct_segmentation(segmentation: Any, corrections: list[dict[str, float]], *, label: str = "drift correction") -> int:
    """Shift the corrected slices of ``segmentation.labels`` as ONE undo step.

    Only the slab between the first and last corrected slice is stored for undo (not
    the whole volume). Shifts are rounded to whole pixels (labels stay exact). Returns
    the number of voxels that changed; ``segmentation.undo()`` reverts it.
    """
    todo = [c for c in corrections if 0 <= int(c["slice"]) < segmentation.labels.shape[0]]
    if not todo:
        return 0
    z0 = min(int(c["slice"]) for c in todo)
    z1 = max(int(c["slice"]) for c in todo) + 1
    slab = segmentation.labels[z0:z1]
    local = [{"slice": int(c["slice"]) - z0, "dx": round(float(c.get("dx", 0))), "dy": round(float(c.get("dy", 0)))} for c in todo]
    new = apply_corrections(slab, local, interpolation="nearest", fill_value=0)
    changed = int(np.count_nonzero(new != slab))
    segmentation.apply_region((slice(z0, z1), slice(None), slice(None)), new, label=label)
    return changed


def corrected_volume(volume: Any, corrections: list[dict[str, float]], *, interpolation: str = "linear") -> Any:
    """A copy of ``volume`` (same geometry) whose data has the corrections applied.

    The original is untouched: undo is keeping/using the original volume (or applying
    a shorter list of corrections to it).
    """
    out = dataclasses.replace(volume, data=apply_corrections(volume.data, corrections, interpolation=interpolation))
    out.meta = {**volume.meta, "drift_corrections": [dict(c) for c in corrections]}
    return out
