"""Automatic centred paths of tubular objects, in patient mm.

:func:`centreline`: a minimal path between the object's two extremities through the
cost ``1 / d**p + eps`` where ``d`` is the distance (mm) to the object's border (as
fast marching on a distance map does), computed by Dijkstra on the 26-connected voxel
graph with mm steps (scikit-image's ``MCP_Geometric``), smoothed by a spline, moved
onto the centroids of its own normal sections (:func:`recentre_path`; sections that
are not cross-sections of the tube - caps, branches - do not pull it), and ended at
the object's end caps: the bent ends of the voxel route (and any thin sheet of mask
stuck to an end) are replaced by the axis' straight continuation up to where it
leaves the object, and the path stops there, inside (both the voxel mask and the
smoothed border the sections measure). On a helical tube with side branches in
3 mm x 0.8 mm voxels the path is within 1% of the helix's length and 0.2 mm (median)
of its axis; on an aorta-like tube cut by the slice planes, within 1% of the length
between the planes (tests/engine/measure/test_centreline.py).

The path helpers (:func:`~ctui.engine.measure.paths.path_from_points`,
:func:`~ctui.engine.measure.paths.parse_points`, arc lengths, resampling, voxel <->
mm) live in :mod:`ctui.engine.measure.paths` and are re-exported here.
"""

from __future__ import annotations

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.measure import DEFAULT_SECTION_STEP_MM
from ctui.engine.measure.fields import ObjectField, object_field
from ctui.engine.measure.flags import OK
from ctui.engine.measure.paths import (  # noqa: F401  (public path API, re-exported)
    arc_length,
    index_to_mm,
    mm_to_index,
    parse_points,
    path_from_points,
    path_length,
    resample_path,
    spline_resample,
)
from ctui.engine.measure.sections import sections_along_path


def _crop(mask: np.ndarray, margin: int = 1):
    idx = np.nonzero(mask)
    lo = [max(int(i.min()) - margin, 0) for i in idx]
    hi = [min(int(i.max()) + margin + 1, n) for i, n in zip(idx, mask.shape)]
    sl = tuple(slice(a, b) for a, b in zip(lo, hi))
    return sl, np.array(lo)


def _farthest(cost: np.ndarray, start, spacing, allowed: np.ndarray) -> tuple[int, ...]:
    """The ``allowed`` voxel farthest from ``start`` along paths through finite ``cost``."""
    from skimage.graph import MCP_Geometric

    m = MCP_Geometric(cost, fully_connected=True, sampling=tuple(spacing))
    acc, _ = m.find_costs([tuple(int(v) for v in start)])
    acc = np.where(np.isfinite(acc) & allowed, acc, -1.0)
    return tuple(int(v) for v in np.unravel_index(int(np.argmax(acc)), acc.shape))


def _component_and_ends(sub: np.ndarray, sp: np.ndarray, endpoints, endpoints_voxel, lo, origin, direction):
    """(component mask, [end a, end b] crop indices) of the object part the path runs in."""
    from scipy import ndimage as ndi

    lab, n = ndi.label(sub, structure=np.ones((3, 3, 3)))
    if endpoints is None:
        if n > 1:
            sizes = np.bincount(lab.ravel())
            sizes[0] = 0
            sub = lab == int(np.argmax(sizes))
        return sub, None
    e = np.asarray(endpoints, dtype=np.float64).reshape(2, 3)
    e_idx = e if endpoints_voxel else mm_to_index(e, spacing=sp, origin=origin, direction=direction)
    e_idx = np.rint(e_idx).astype(int) - lo
    if np.any(e_idx < 0) or np.any(e_idx >= np.array(sub.shape)):
        raise CtuiError("centreline: an endpoint lies outside the object's bounding box")
    ends = []
    for p in e_idx:
        if not sub[tuple(p)]:  # snap to the nearest object voxel
            _, ind = ndi.distance_transform_edt(~sub, sampling=sp, return_indices=True)
            p = ind[:, p[0], p[1], p[2]]
        ends.append(tuple(int(v) for v in p))
    if lab[ends[0]] != lab[ends[1]]:
        raise CtuiError("centreline: the two endpoints are in different parts of the object")
    return lab == lab[ends[0]], ends


def _open_ends(sub: np.ndarray, dist: np.ndarray, lo: np.ndarray, full_shape, sp: np.ndarray) -> list[tuple]:
    """Crop indices of the object's open ends: where it is cut by the volume's boundary.

    Each patch of object on a face of the volume (8-connected in the face) at least as
    deep as 1.5 voxels and 0.3 times the object's deepest point is a cut through the
    tube; its voxel nearest the patch centroid is the end. The two largest, by area."""
    from scipy import ndimage as ndi

    hi = lo + np.asarray(sub.shape)
    floor = max(1.5 * float(sp.max()), 0.3 * float(dist.max()))  # a sheet of mask one slice thick is no cut
    found = []
    for ax in range(3):
        for at_start in (True, False):
            if (lo[ax] != 0) if at_start else (hi[ax] != full_shape[ax]):
                continue
            k = 0 if at_start else sub.shape[ax] - 1
            face = np.take(sub, k, axis=ax)
            if not face.any():
                continue
            depth = np.take(dist, k, axis=ax)
            lab, n = ndi.label(face, structure=np.ones((3, 3)))
            for j in range(1, n + 1):
                pts = np.argwhere(lab == j)
                if float(depth[lab == j].max()) < floor:
                    continue
                c = pts[int(np.argmin(((pts - pts.mean(axis=0)) ** 2).sum(axis=1)))]
                found.append((len(pts) * float(np.prod(np.delete(sp, ax))), tuple(int(v) for v in np.insert(c, ax, k))))
    found.sort(key=lambda f: -f[0])
    return [f[1] for f in found[:2]]


def _voxel_route(sub: np.ndarray, dist: np.ndarray, ends, sp: np.ndarray, power: float, eps: float,
                 open_ends: list | None = None) -> np.ndarray:
    """Minimal path (k, 3) crop indices between the ends (the extremities when None; an
    open end, where the object is cut by the volume's boundary, is one of them)."""
    if ends is None and open_ends:
        unit = np.where(sub, 1.0, np.inf)
        core = dist > float(sp.max())
        if core.sum() < max(8, 0.05 * sub.sum()):
            core = sub
        ends = list(open_ends) if len(open_ends) == 2 else [open_ends[0], _farthest(unit, open_ends[0], sp, core)]
    if ends is None:
        # the extremities among the core voxels (deeper than the largest voxel side), so
        # the route does not end in a sheet of mask one slice thick stuck to the object
        core = dist > float(sp.max())
        if core.sum() < max(8, 0.05 * sub.sum()):
            core = sub
        unit = np.where(sub, 1.0, np.inf)
        deepest = np.unravel_index(int(np.argmax(dist)), dist.shape)
        a = _farthest(unit, deepest, sp, core)
        ends = [a, _farthest(unit, a, sp, core)]
    if ends[0] == ends[1]:
        raise CtuiError("centreline: the object has no two distinct ends (too small)")
    cost = np.full(sub.shape, np.inf)
    cost[sub] = 1.0 / np.power(dist[sub], power) + eps
    return minimal_route(cost, ends[0], ends[1], sp)  # start -> end


def minimal_route(cost: np.ndarray, a, b, spacing) -> np.ndarray:
    """The minimal path (k, 3) float voxel indices (z, y, x) from voxel ``a`` to voxel ``b``
    through ``cost`` (per mm; inf: not crossed) on the 26-connected grid with mm steps (Dijkstra,
    scikit-image ``MCP_Geometric``). The one route solver of ctui's centrelines: this module's
    and ``ctui vessel``'s (:mod:`ctui.engine.vessel.path`)."""
    from skimage.graph import MCP_Geometric

    a, b = tuple(int(v) for v in a), tuple(int(v) for v in b)
    mcp = MCP_Geometric(cost, fully_connected=True, sampling=tuple(float(s) for s in spacing))
    mcp.find_costs([a], [b])
    return np.asarray(mcp.traceback(b), dtype=np.float64)


def centreline(
    mask: np.ndarray,
    *,
    spacing=(1.0, 1.0, 1.0),
    origin=(0.0, 0.0, 0.0),
    direction=None,
    endpoints=None,
    endpoints_voxel: bool = False,
    power: float = 2.0,
    eps: float = 1e-3,
    step_mm: float = DEFAULT_SECTION_STEP_MM,
    smooth_mm: float | None = None,
    recentre: int = 2,
    straight_ends: bool = True,
) -> np.ndarray:
    """Automatic centred path of a tubular object, in patient mm.

    Parameters
    ----------
    mask : ndarray bool (z, y, x)
        The object (its largest 26-connected component is used when no endpoints
        are given; the component holding the endpoints otherwise).
    spacing, origin, direction
        Geometry (see :class:`~ctui.engine.core.volume.Volume`).
    endpoints : (2, 3) array or None
        The two ends: patient mm (x, y, z), or voxel indices (z, y, x) when
        ``endpoints_voxel``. None: the two extremities, found as the voxel farthest
        (geodesic distance inside the object) from the deepest voxel, then the voxel
        farthest from that one, both among the voxels deeper than the largest voxel
        side when there are any (a sheet of mask one slice thick does not hold an end).
    power, eps
        Cost per mm of travel: ``1 / d**power + eps`` with ``d`` the distance (mm,
        ``distance_transform_edt`` with the voxel spacing) to the border.
    step_mm : float
        Arc-length step of the returned path.
    smooth_mm : float or None
        Spline smoothing (expected deviation of the voxel path from the smooth
        centre line); default max(half the largest voxel, a quarter of the median
        distance to the border along the route).
    recentre : int
        Iterations of :func:`recentre_path` (points moved to their normal sections'
        centroids); 0 to skip.
    straight_ends : bool
        With automatic endpoints, replace the path's ends, which bend towards the
        extremity voxels on the border, by the straight continuation of the centred
        path up to the end caps, and end the path there, inside the object (so the
        path length is the tube's length and the last sections are not tilted).

    Returns
    -------
    path : ndarray (n, 3) float64
        Patient positions (x, y, z) mm at a uniform ``step_mm`` arc-length step,
        from the first end to the second.
    """
    from scipy import ndimage as ndi

    m = np.asarray(mask).astype(bool, copy=False)
    if m.ndim != 3:
        raise CtuiError(f"centreline needs a 3D mask, got shape {m.shape}")
    if not m.any():
        raise CtuiError("centreline: the object is empty")
    sp = np.asarray(spacing, dtype=np.float64)
    sl, lo = _crop(m, 1)
    sub, ends = _component_and_ends(m[sl], sp, endpoints, endpoints_voxel, lo, origin, direction)
    dist = ndi.distance_transform_edt(sub, sampling=sp)
    opened = _open_ends(sub, dist, lo, m.shape, sp) if endpoints is None else []
    route = _voxel_route(sub, dist, ends, sp, power, eps, opened)
    open_at = (len(opened) >= 1, len(opened) == 2)  # the path starts (and ends) at a cut by the boundary
    pts = index_to_mm(route + lo, spacing=sp, origin=origin, direction=direction)
    if smooth_mm is None:
        # the voxel route wanders inside the flat top of the distance map: smooth
        # over about a quarter of the typical radius (at least half a voxel)
        r_med = float(np.median(dist[tuple(np.asarray(route, dtype=int).T)]))
        smooth_mm = max(0.5 * float(sp.max()), 0.25 * r_med)
    path = spline_resample(pts, step_mm, smooth_mm=smooth_mm)  # a smoothing spline may overshoot the ends
    ends_free = straight_ends and endpoints is None
    inside = _Inside(sub, lo, None, spacing=sp, origin=origin, direction=direction)
    path = _inside_part(path, inside(path))
    if ends_free:  # before recentring, so bent ends do not tilt the end sections
        path = _end_at_caps(path, dist, inside, step_mm, open_at=open_at)
    if (recentre and path_length(path) > 4 * step_mm) or ends_free:
        inside.field = object_field(m, spacing=sp, origin=origin, direction=direction)
    if recentre and path_length(path) > 4 * step_mm:
        path = recentre_path(path, field=inside.field, step_mm=step_mm, iterations=recentre,
                             bounds=m.shape if any(open_at) else None)
    if ends_free:
        path = _end_at_caps(path, dist, inside, step_mm, open_at=open_at)
    return path


class _Inside:
    """Point-in-object test in mm: the nearest voxel is in the component and (with a
    field) the smoothed indicator is at least one half (the border the sections measure)."""

    def __init__(self, sub, lo, field: ObjectField | None, *, spacing, origin, direction):
        self.sub, self.lo, self.field = sub, lo, field
        self.geo = {"spacing": spacing, "origin": origin, "direction": direction}
        self.lim = np.asarray(sub.shape) - 1

    def index(self, q: np.ndarray) -> np.ndarray:
        """Fractional crop indices (..., 3) of positions (..., 3) mm."""
        return mm_to_index(q, **self.geo) - self.lo

    def __call__(self, q: np.ndarray) -> np.ndarray:
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        k = np.rint(self.index(q)).astype(int)
        ok = np.all((k >= 0) & (k <= self.lim), axis=1)
        kk = np.where(ok[:, None], k, 0)
        ok &= self.sub[kk[:, 0], kk[:, 1], kk[:, 2]]
        return ok if self.field is None else ok & (self.field.sample(q) >= 0.5)


def _extend(p0: np.ndarray, t: np.ndarray, inside: _Inside, reach: float, fine: float) -> np.ndarray:
    """Points (k, 3) from p0 (excluded) along unit t every ``fine`` mm while inside, the
    last one on the border (found by bisection, a hundredth of ``fine`` inside)."""
    steps = p0 + np.outer(np.arange(1, int(reach / fine) + 2) * fine, t)
    ok = inside(steps)
    k = len(ok) if ok.all() else int(np.argmin(ok))
    out = steps[:k]
    a = 0.0 if k == 0 else k * fine  # inside at a, outside at a + fine (when k < len)
    if k < len(ok):
        b = a + fine
        for _ in range(8):
            mid = 0.5 * (a + b)
            if inside(p0 + mid * t)[0]:
                a = mid
            else:
                b = mid
        if a > 0.01 * fine:
            out = np.vstack([out, p0 + (a - 0.01 * fine) * t])
    return out


def _inside_part(p: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """The path without its leading and trailing points where ``ok`` is False."""
    if not ok.any():
        return p
    return p[int(np.argmax(ok)) : len(ok) - int(np.argmax(ok[::-1]))]


def _tube_part(s: np.ndarray, r: np.ndarray) -> tuple[int, int]:
    """(i0, i1): the first and last path points that are on the tube's axis.

    From each end, a point is still in the bent end of the voxel route while it is
    nearer the end than its own inscribed radius ``r`` (mm), or thinner (under 0.85
    times) than the tube over the next two typical radii inwards: near a flat cap ``r``
    is the distance to the cap, and a sheet of mask stuck to the end (where the
    extremity voxel may lie) is thinner still. ``r`` is first smoothed by a running
    median over a typical radius (the distance map of thick slices is uneven)."""
    from scipy import ndimage as ndi

    n = len(s)
    med = float(np.median(r))
    step = float(s[-1]) / max(n - 1, 1)
    rs = ndi.median_filter(r, size=max(3, round(med / max(step, 1e-9)) | 1), mode="nearest")
    w = 2.0 * med
    good = np.zeros(n, bool)
    for i in range(n):
        if s[i] < 0.5 * s[-1]:  # inwards = towards the middle of the path
            ahead = rs[i : np.searchsorted(s, s[i] + w, side="right")]
        else:
            ahead = rs[np.searchsorted(s, s[i] - w) : i + 1]
        good[i] = rs[i] >= 0.85 * float(ahead.max()) and min(s[i], s[-1] - s[i]) >= r[i]
    if not good.any():
        return 0, n - 1
    return int(np.argmax(good)), n - 1 - int(np.argmax(good[::-1]))


def _end_at_caps(path: np.ndarray, dist: np.ndarray, inside: _Inside, step_mm: float,
                 open_at: tuple[bool, bool] = (False, False)) -> np.ndarray:
    """Replace each end of a centred path, where it bends towards the extremity voxel on
    the object's border (:func:`_tube_part`), by the straight continuation of the path's
    axis part until it leaves the object through the end cap; the path ends there,
    inside the object. An open end (``open_at``: the start / the end is where the volume's
    boundary cuts the object) keeps its centred points and runs on to the boundary."""
    from scipy import ndimage as ndi

    p = _inside_part(np.asarray(path, dtype=np.float64), inside(path))
    if len(p) < 8:
        return p
    r = ndi.map_coordinates(dist, inside.index(p).T, order=1, mode="constant", cval=0.0)
    i0, i1 = _tube_part(arc_length(p), r)
    i0, i1 = (0 if open_at[0] else i0), (len(p) - 1 if open_at[1] else i1)
    if i1 - i0 < 4:
        return p
    fine = 0.25 * float(min(inside.geo["spacing"]))
    voxels = _Inside(inside.sub, inside.lo, None, **inside.geo)  # the boundary, not the smoothed border
    parts = []
    s = arc_length(p)
    span = np.maximum(r, 2 * step_mm)
    for i, j, is_open in ((i0, int(np.searchsorted(s, s[i0] + span[i0])), open_at[0]),
                          (i1, int(np.searchsorted(s, s[i1] - span[i1])), open_at[1])):
        t = p[i] - p[min(max(j, 0), len(p) - 1)]  # the axis' direction over one radius inwards
        t /= np.linalg.norm(t)
        parts.append(_extend(p[i], t, voxels if is_open else inside, (2 * float(max(inside.geo["spacing"])) if is_open
                                                                      else 4 * r[i]) + 8 * fine, fine))
    return resample_path(np.concatenate([parts[0][::-1], p[i0 : i1 + 1], parts[1]]), step_mm)


def _clipped(row: dict, field: ObjectField, bounds) -> bool:
    """True when the section's contour runs along the volume's boundary (``bounds``: the
    grid's (z, y, x) shape): the boundary cuts the section, its centroid is off the axis."""
    c = row.get("contour_mm")
    if bounds is None or c is None or not len(c):
        return False
    k = mm_to_index(np.asarray(c), spacing=field.spacing, origin=field.origin, direction=field.direction)
    return bool(np.any(k < 0.75) or np.any(k > np.asarray(bounds) - 1.75))


def recentre_path(path_mm: np.ndarray, *, field: ObjectField, step_mm: float = DEFAULT_SECTION_STEP_MM,
                  iterations: int = 2, smooth_mm: float | None = None, bounds=None) -> np.ndarray:
    """Move each path point to the centroid of its cross-section, then re-fit a spline.

    Sections normal to a path that is off-centre or tilted are themselves off; a
    couple of iterations bring a voxel-level minimal path onto the object's axis
    (centroids of normal sections). Sections that are not cross-sections of the tube
    ("cap", "branch", "outside", "open": :mod:`ctui.engine.measure.flags`) do not pull
    the path towards the cap or the branch: their points move as their neighbours do.

    Sections are taken every max(step_mm, 1 mm). ``bounds``: the grid's (z, y, x) shape
    when the object is cut by the volume's boundary; sections the boundary cuts do not
    pull either. Returns the new path (n, 3) mm at a uniform ``step_mm`` arc-length step.
    """
    p = np.asarray(path_mm, dtype=np.float64)
    if smooth_mm is None:
        # section centroids are precise (~0.05 voxel): a loose spline would cut bends
        smooth_mm = 0.15 * float(min(field.spacing))
    for _ in range(iterations):
        rows = sections_along_path(None, p, field=field, step_mm=max(step_mm, 1.0))
        pts = np.array([r["point_mm"] for r in rows])
        s = np.array([r["s_mm"] for r in rows])
        move = np.zeros_like(pts)
        good = np.zeros(len(rows), bool)
        for i, r in enumerate(rows):
            if r.get("status") != OK or _clipped(r, field, bounds):
                continue
            mv = r["centroid_mm"] - r["point_mm"]
            lim = 0.25 * r["eq_diameter_mm"]  # half the equivalent radius per iteration
            n = float(np.linalg.norm(mv))
            move[i] = mv if n <= lim else mv * (lim / n)
            good[i] = True
        if good.sum() >= 2:
            for k in range(3):  # the others move as their neighbours (held at the ends)
                move[~good, k] = np.interp(s[~good], s[good], move[good, k])
        p = spline_resample(pts + move, step_mm, smooth_mm=smooth_mm)
        p = _inside_part(p, field.sample(p) >= 0.5)  # moved ends may leave the object
    return p
