"""Centrelines of tubular objects and user paths, in mm.

A path is an array ``(n, 3)`` of patient positions (x, y, z) in mm (the coordinates
of :class:`~ctui.engine.core.volume.Volume` and of meshes), sampled at a uniform arc-length
step.

* :func:`centreline` - automatic centred path of a tubular mask: a minimal path
  between the object's two extremities through the cost ``1 / d**p + eps`` where
  ``d`` is the distance (mm) to the object's border (as fast marching on a distance
  map does), computed by Dijkstra on the 26-connected voxel graph with mm steps
  (scikit-image's ``MCP_Geometric``), then smoothed by a spline and resampled.
* :func:`path_from_points` - a user path through given points (mm or voxel indices),
  interpolated by a cubic spline on chord length and resampled.
* :func:`resample_path`, :func:`path_length`, :func:`arc_length`.

Geometry arguments are those of :class:`Volume`: ``spacing`` (dz, dy, dx) mm,
``origin`` (x, y, z) mm of voxel (0, 0, 0), ``direction`` 3x3 (columns = x, y, z
index axes).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ctui.engine.core.errors import CtuiError


# ---------------------------------------------------------------- geometry helpers
def index_matrix(spacing, direction=None) -> np.ndarray:
    """3x3 matrix M with ``mm = origin + M @ (z, y, x)`` (indices in z, y, x order)."""
    d = np.eye(3) if direction is None else np.asarray(direction, dtype=np.float64).reshape(3, 3)
    sxyz = np.asarray(spacing, dtype=np.float64)[::-1]
    m_xyz = d * sxyz[None, :]  # columns: x, y, z index axes
    return m_xyz[:, ::-1]  # columns: z, y, x index axes


def index_to_mm(zyx, *, spacing, origin=(0.0, 0.0, 0.0), direction=None) -> np.ndarray:
    """Voxel indices (..., 3) in (z, y, x) -> patient mm (..., 3) in (x, y, z)."""
    m = index_matrix(spacing, direction)
    return np.asarray(zyx, dtype=np.float64) @ m.T + np.asarray(origin, dtype=np.float64)


def mm_to_index(xyz, *, spacing, origin=(0.0, 0.0, 0.0), direction=None) -> np.ndarray:
    """Patient mm (..., 3) in (x, y, z) -> fractional voxel indices (..., 3) in (z, y, x)."""
    m = index_matrix(spacing, direction)
    p = np.asarray(xyz, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    return p @ np.linalg.inv(m).T


def arc_length(path: np.ndarray) -> np.ndarray:
    """Cumulative arc length (n,) in mm of a polyline (n, 3), starting at 0."""
    p = np.asarray(path, dtype=np.float64)
    if len(p) == 0:
        return np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def path_length(path: np.ndarray) -> float:
    """Length (mm) of a polyline (n, 3)."""
    s = arc_length(path)
    return float(s[-1]) if len(s) else 0.0


def resample_path(path: np.ndarray, step_mm: float = 0.5) -> np.ndarray:
    """Resample a dense polyline (n, 3) at a uniform arc-length step (mm), keeping both ends.

    The last interval is shortened so the path still ends at its last point.
    """
    p = np.asarray(path, dtype=np.float64)
    s = arc_length(p)
    if len(p) < 2 or s[-1] <= 0:
        return p.copy()
    n = max(int(np.floor(s[-1] / step_mm + 1e-9)), 1)
    t = np.append(np.arange(n + 1) * step_mm, s[-1]) if n * step_mm < s[-1] - 1e-6 else np.arange(n + 1) * step_mm
    t = np.minimum(t, s[-1])
    keep = np.concatenate([[True], np.diff(s) > 0])
    return np.stack([np.interp(t, s[keep], p[keep, k]) for k in range(3)], axis=1)


def _spline_resample(points: np.ndarray, step_mm: float, *, smooth_mm: float = 0.0) -> np.ndarray:
    """Fit a parametric cubic spline (chord-length parameter) and resample it uniformly.

    ``smooth_mm`` is the expected deviation of the points from the curve (0 =
    interpolation); splprep's smoothing factor is then n * smooth_mm**2.
    """
    from scipy.interpolate import CubicSpline, splev, splprep

    p = np.asarray(points, dtype=np.float64)
    # drop repeated points (zero chord)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-9])
    p = p[keep]
    if len(p) < 2:
        return p.copy()
    chord = arc_length(p)
    total = chord[-1]
    if smooth_mm > 0 and len(p) > 4:
        tck, _ = splprep(p.T, u=chord / total, s=len(p) * smooth_mm**2, k=3)
        dense_t = np.linspace(0.0, 1.0, max(200, int(total / min(step_mm, 0.5) * 4) + 1))
        dense = np.stack(splev(dense_t, tck), axis=1)
    elif len(p) >= 3:
        cs = CubicSpline(chord, p, bc_type="natural")
        dense = cs(np.linspace(0.0, total, max(200, int(total / min(step_mm, 0.5) * 4) + 1)))
    else:
        dense = p
    return resample_path(dense, step_mm)


def path_from_points(
    points: Sequence[Sequence[float]] | np.ndarray,
    *,
    step_mm: float = 0.5,
    voxel: bool = False,
    spacing=(1.0, 1.0, 1.0),
    origin=(0.0, 0.0, 0.0),
    direction=None,
) -> np.ndarray:
    """A user path through ``points``, interpolated by a cubic spline on chord length.

    Parameters
    ----------
    points : (k, 3) array
        Patient positions (x, y, z) in mm, or voxel indices (z, y, x) when ``voxel``.
    step_mm : float
        Arc-length step of the output, mm.
    voxel, spacing, origin, direction
        Geometry used to convert voxel indices to mm.

    Returns
    -------
    path : ndarray (n, 3) float64, patient mm (x, y, z), uniform arc-length step.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2:
        raise CtuiError(f"a path needs at least 2 points of 3 coordinates, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise CtuiError("path points must be finite numbers")
    if voxel:
        p = index_to_mm(p, spacing=spacing, origin=origin, direction=direction)
    return _spline_resample(p, step_mm)


def parse_points(text: str) -> np.ndarray:
    """Parse ``"x,y,z;x,y,z;..."`` into a (k, 3) float array (raises CtuiError)."""
    pts = []
    for chunk in str(text).replace("|", ";").split(";"):
        chunk = chunk.strip()
        if not chunk:
            continue
        try:
            vals = [float(v) for v in chunk.replace(" ", ",").split(",") if v.strip()]
        except ValueError:
            raise CtuiError(f"bad path point {chunk!r}: expected x,y,z numbers") from None
        if len(vals) != 3:
            raise CtuiError(f"bad path point {chunk!r}: expected 3 numbers, got {len(vals)}")
        pts.append(vals)
    if len(pts) < 2:
        raise CtuiError(f"a path needs at least 2 points 'x,y,z;x,y,z', got {text!r}")
    return np.asarray(pts, dtype=np.float64)


# ------------------------------------------------------------------ centreline
def _crop(mask: np.ndarray, margin: int = 1):
    idx = np.nonzero(mask)
    lo = [max(int(i.min()) - margin, 0) for i in idx]
    hi = [min(int(i.max()) + margin + 1, n) for i, n in zip(idx, mask.shape)]
    sl = tuple(slice(a, b) for a, b in zip(lo, hi))
    return sl, np.array(lo)


def _farthest(mcp_cls, cost: np.ndarray, start, spacing) -> tuple[tuple[int, ...], np.ndarray]:
    m = mcp_cls(cost, fully_connected=True, sampling=tuple(spacing))
    acc, _ = m.find_costs([tuple(int(v) for v in start)])
    acc = np.where(np.isfinite(acc), acc, -1.0)
    far = np.unravel_index(int(np.argmax(acc)), acc.shape)
    return tuple(int(v) for v in far), acc


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
    step_mm: float = 0.5,
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
        farthest from that one.
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
        Iterations of :func:`ctui.engine.measure.sections.recentre_path` (points moved to
        their normal sections' centroids); 0 to skip.
    straight_ends : bool
        With automatic endpoints, replace the path's ends, which bend towards the
        extremity voxels on the border, by the straight continuation of the centred
        path up to the end caps (so the path length is the tube's length and the
        last sections are not tilted).

    Returns
    -------
    path : ndarray (n, 3) float64
        Patient positions (x, y, z) mm at a uniform ``step_mm`` arc-length step,
        from the first end to the second.
    """
    from scipy import ndimage as ndi
    from skimage.graph import MCP_Geometric

    m = np.asarray(mask).astype(bool, copy=False)
    if m.ndim != 3:
        raise CtuiError(f"centreline needs a 3D mask, got shape {m.shape}")
    if not m.any():
        raise CtuiError("centreline: the object is empty")
    sp = np.asarray(spacing, dtype=np.float64)
    sl, lo = _crop(m, 1)
    sub = m[sl]
    if endpoints is not None:
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
        lab, _ = ndi.label(sub, structure=np.ones((3, 3, 3)))
        if lab[ends[0]] != lab[ends[1]]:
            raise CtuiError("centreline: the two endpoints are in different parts of the object")
        sub = lab == lab[ends[0]]
    else:
        lab, n = ndi.label(sub, structure=np.ones((3, 3, 3)))
        if n > 1:
            sizes = np.bincount(lab.ravel())
            sizes[0] = 0
            sub = lab == int(np.argmax(sizes))
    dist = ndi.distance_transform_edt(sub, sampling=sp)
    if endpoints is None:
        unit = np.where(sub, 1.0, np.inf)
        deepest = np.unravel_index(int(np.argmax(dist)), dist.shape)
        a, _ = _farthest(MCP_Geometric, unit, deepest, sp)
        b, _ = _farthest(MCP_Geometric, unit, a, sp)
        ends = [a, b]
    if ends[0] == ends[1]:
        raise CtuiError("centreline: the object has no two distinct ends (too small)")
    cost = np.full(sub.shape, np.inf)
    cost[sub] = 1.0 / np.power(dist[sub], power) + eps
    mcp = MCP_Geometric(cost, fully_connected=True, sampling=tuple(sp))
    mcp.find_costs([ends[0]], [ends[1]])
    route = np.asarray(mcp.traceback(ends[1]), dtype=np.float64)  # start -> end
    pts = index_to_mm(route + lo, spacing=sp, origin=origin, direction=direction)
    if smooth_mm is None:
        # the voxel route wanders inside the flat top of the distance map: smooth
        # over about a quarter of the typical radius (at least half a voxel)
        r_med = float(np.median(dist[tuple(np.asarray(route, dtype=int).T)]))
        smooth_mm = max(0.5 * float(sp.max()), 0.25 * r_med)
    path = _spline_resample(pts, step_mm, smooth_mm=smooth_mm)
    if recentre and path_length(path) > 4 * step_mm:
        from ctui.engine.measure.sections import object_field, recentre_path

        field = object_field(m, spacing=sp, origin=origin, direction=direction)
        path = recentre_path(path, field=field, step_mm=step_mm, iterations=recentre)
    if straight_ends and endpoints is None:
        path = _straighten_ends(path, sub, dist, lo, step_mm, spacing=sp, origin=origin, direction=direction)
    return path


def _straighten_ends(path, sub, dist, lo, step_mm, *, spacing, origin, direction) -> np.ndarray:
    """Replace each end of a centred path, where it bends towards the extremity voxel
    on the object's border, by the straight continuation of the path until it leaves
    the object (through the end cap).

    The bent part is where the arc length from the end is shorter than the local
    distance to the border (the inscribed radius)."""
    from scipy import ndimage as ndi

    p = np.asarray(path, dtype=np.float64)
    if len(p) < 8:
        return p
    idx = mm_to_index(p, spacing=spacing, origin=origin, direction=direction) - lo
    r = ndi.map_coordinates(dist, idx.T, order=1, mode="constant", cval=0.0)
    s = arc_length(p)
    total = s[-1]
    lim = np.asarray(sub.shape) - 1

    def inside(q):
        k = np.rint(mm_to_index(q, spacing=spacing, origin=origin, direction=direction) - lo).astype(int)
        return bool(np.all(k >= 0) and np.all(k <= lim) and sub[tuple(k)])

    ok_a = np.nonzero(s >= r)[0]
    ok_b = np.nonzero(total - s >= r)[0]
    if len(ok_a) == 0 or len(ok_b) == 0:
        return p
    i0, i1 = int(ok_a[0]), int(ok_b[-1])
    if i1 - i0 < 4:
        return p
    fine = 0.25 * float(min(spacing))

    def extend(i, j):
        t = p[i] - p[j]
        t /= np.linalg.norm(t)
        pts = []
        q = p[i].copy()
        for _ in range(int(4 * r[i] / fine) + 8):
            q = q + fine * t
            if not inside(q):
                break
            pts.append(q.copy())
        return pts

    head = extend(i0, min(i0 + 2, len(p) - 1))[::-1]
    tail = extend(i1, max(i1 - 2, 0))
    parts = [np.asarray(head).reshape(-1, 3), p[i0 : i1 + 1], np.asarray(tail).reshape(-1, 3)]
    return resample_path(np.concatenate(parts), step_mm)
