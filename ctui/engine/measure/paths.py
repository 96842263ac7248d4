"""Path geometry in patient mm: arc length, resampling, splines, user paths, frames.

A path is an array ``(n, 3)`` of patient positions (x, y, z) in mm (the coordinates
of :class:`~ctui.engine.core.volume.Volume` and of meshes), usually sampled at a
uniform arc-length step. Voxel <-> mm conversions go through
:class:`~ctui.engine.core.geometry.Geometry` (``spacing`` (dz, dy, dx) mm, ``origin``
(x, y, z) mm of voxel (0, 0, 0), ``direction`` 3x3 with columns the x, y, z index axes).

This module is the bottom of the measure package: it imports only ``core``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.core.geometry import Geometry


# ---------------------------------------------------------------- voxel <-> mm
def geometry_of(spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), direction=None, shape=(1, 1, 1)) -> Geometry:
    """A :class:`Geometry` from the loose (spacing, origin, direction) arguments of the
    measure functions (``shape`` only matters for bounds checks)."""
    return Geometry(tuple(shape), tuple(spacing), tuple(origin), direction)


def index_matrix(spacing, direction=None) -> np.ndarray:
    """3x3 matrix M with ``mm = origin + M @ (z, y, x)`` (indices in z, y, x order)."""
    return geometry_of(spacing, direction=direction).affine[:3, :3][:, ::-1].copy()


def index_to_mm(zyx, *, spacing, origin=(0.0, 0.0, 0.0), direction=None) -> np.ndarray:
    """Voxel indices (..., 3) in (z, y, x) -> patient mm (..., 3) in (x, y, z)."""
    return geometry_of(spacing, origin, direction).index_to_mm(zyx)


def mm_to_index(xyz, *, spacing, origin=(0.0, 0.0, 0.0), direction=None) -> np.ndarray:
    """Patient mm (..., 3) in (x, y, z) -> fractional voxel indices (..., 3) in (z, y, x)."""
    return geometry_of(spacing, origin, direction).mm_to_index(xyz)


# ---------------------------------------------------------------- arc length
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


def spline_resample(points: np.ndarray, step_mm: float, *, smooth_mm: float = 0.0) -> np.ndarray:
    """Fit a parametric cubic spline (chord-length parameter) and resample it uniformly.

    ``smooth_mm`` is the expected deviation of the points from the curve (0 =
    interpolation); splprep's smoothing factor is then n * smooth_mm**2.
    """
    from scipy.interpolate import CubicSpline, splev, splprep

    p = np.asarray(points, dtype=np.float64)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-9])  # no zero chords
    p = p[keep]
    if len(p) < 2:
        return p.copy()
    chord = arc_length(p)
    total = chord[-1]
    n_dense = max(200, int(total / min(step_mm, 0.5) * 4) + 1)
    if smooth_mm > 0 and len(p) > 4:
        tck, _ = splprep(p.T, u=chord / total, s=len(p) * smooth_mm**2, k=3)
        dense = np.stack(splev(np.linspace(0.0, 1.0, n_dense), tck), axis=1)
    elif len(p) >= 3:
        dense = CubicSpline(chord, p, bc_type="natural")(np.linspace(0.0, total, n_dense))
    else:
        dense = p
    return resample_path(dense, step_mm)


# ---------------------------------------------------------------- user paths
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
    return spline_resample(p, step_mm)


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
        if not all(np.isfinite(v) and abs(v) <= 1e6 for v in vals):
            raise CtuiError(f"bad path point {chunk!r}: expected finite coordinates within +-1e6 mm")
        pts.append(vals)
    if len(pts) < 2:
        raise CtuiError(f"a path needs at least 2 points 'x,y,z;x,y,z', got {text!r}")
    return np.asarray(pts, dtype=np.float64)


# ---------------------------------------------------------------- sampling a path
def path_spline(path_mm: np.ndarray):
    """(spline s -> (3,) mm, total length mm) of a polyline: natural cubic through its
    points on arc length (linear for fewer than 4 points)."""
    from scipy.interpolate import CubicSpline, make_interp_spline

    p = np.asarray(path_mm, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2:
        raise CtuiError(f"a path needs at least 2 points (n, 3), got shape {p.shape}")
    s = arc_length(p)
    keep = np.concatenate([[True], np.diff(s) > 1e-9])
    p, s = p[keep], s[keep]
    if len(p) < 2:
        raise CtuiError("the path has zero length")
    if len(p) >= 4:
        return CubicSpline(s, p, bc_type="natural"), float(s[-1])
    return make_interp_spline(s, p, k=1), float(s[-1])


def path_points(path_mm: np.ndarray, s_mm: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Positions (k, 3) mm and unit tangents (k, 3) of a path at arc lengths ``s_mm``."""
    spl, total = path_spline(path_mm)
    s = np.clip(np.asarray(s_mm, dtype=np.float64), 0.0, total)
    pts = spl(s)
    tan = spl(s, 1)
    norm = np.linalg.norm(tan, axis=1, keepdims=True)
    return pts, tan / np.where(norm > 0, norm, 1.0)


def rotation_minimising_frames(points: np.ndarray, tangents: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plane bases (u, v), each (k, 3), carried along a path without twisting.

    Double-reflection method (Wang, Juettler, Zheng, Liu 2008). ``u`` and ``v`` are
    unit, orthogonal to each other and to the tangent; ``(u, v, t)`` is right-handed.
    """
    x = np.asarray(points, dtype=np.float64)
    t = np.asarray(tangents, dtype=np.float64)
    k = len(t)
    u = np.zeros((k, 3))
    if k == 0:
        return u, u.copy()
    a = np.eye(3)[int(np.argmin(np.abs(t[0])))]  # the axis least aligned with the tangent
    u0 = a - np.dot(a, t[0]) * t[0]
    u[0] = u0 / np.linalg.norm(u0)
    for i in range(k - 1):
        v1 = x[i + 1] - x[i]
        c1 = float(v1 @ v1)
        if c1 < 1e-18:
            rl, tl = u[i], t[i]
        else:
            rl = u[i] - (2.0 / c1) * float(v1 @ u[i]) * v1
            tl = t[i] - (2.0 / c1) * float(v1 @ t[i]) * v1
        v2 = t[i + 1] - tl
        c2 = float(v2 @ v2)
        r = rl if c2 < 1e-18 else rl - (2.0 / c2) * float(v2 @ rl) * v2
        r = r - float(r @ t[i + 1]) * t[i + 1]
        n = np.linalg.norm(r)
        if n < 1e-12:
            a = np.eye(3)[int(np.argmin(np.abs(t[i + 1])))]
            r = a - np.dot(a, t[i + 1]) * t[i + 1]
            n = np.linalg.norm(r)
        u[i + 1] = r / n
    return u, np.cross(t, u)


# ---------------------------------------------------------------- a line through a point
#: The axes a section through a point can be normal to: the object's longest axis or an index axis.
LINE_AXES = ("object", "z", "y", "x")


def principal_direction(mask: np.ndarray, *, spacing, origin=(0.0, 0.0, 0.0), direction=None) -> np.ndarray:
    """Unit vector (x, y, z) patient mm of the object's longest principal axis (of its
    voxel centres in mm). CtuiError for an object of fewer than 2 voxels."""
    zyx = np.argwhere(mask)
    if len(zyx) < 2:
        raise CtuiError("the object has fewer than 2 voxels: it has no axis")
    if len(zyx) > 200_000:  # the axis of a large object from an even subsample: bounded work
        zyx = zyx[:: len(zyx) // 200_000 + 1]
    pts = index_to_mm(zyx.astype(np.float64), spacing=spacing, origin=origin, direction=direction)
    _w, vecs = np.linalg.eigh(np.cov((pts - pts.mean(axis=0)).T))
    return vecs[:, -1] / np.linalg.norm(vecs[:, -1])


def line_through(point_zyx: Sequence[float], axis: str | Sequence[float], *, half_mm: float, step_mm: float = 0.5,
                 mask: np.ndarray | None = None, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0),
                 direction=None) -> np.ndarray:
    """A straight path (n, 3) patient mm through voxel ``point_zyx`` (z, y, x), ``half_mm``
    each side, along ``axis``: "object" (its longest axis; needs ``mask``), "z", "y", "x"
    (the index axis: "z" gives the plane of the file's slice through the point) or a
    vector (x, y, z) mm. Its middle (s = ``half_mm``) is the point: sections at a step
    dividing ``half_mm`` have one through it."""
    if not half_mm > 0:
        raise CtuiError(f"the half length must be positive, got {half_mm}")
    if isinstance(axis, str):
        if axis not in LINE_AXES:
            raise CtuiError(f"unknown axis {axis!r}: one of {', '.join(LINE_AXES)}")
        if axis == "object":
            if mask is None:
                raise CtuiError("the object's axis needs its mask")
            d = principal_direction(mask, spacing=spacing, origin=origin, direction=direction)
        else:
            d = index_matrix(spacing, direction)[:, "zyx".index(axis)]
    else:
        d = np.asarray(axis, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(d))
    if not np.isfinite(n) or n == 0:
        raise CtuiError("the line's direction has no length")
    centre = index_to_mm(np.asarray(point_zyx, dtype=np.float64), spacing=spacing, origin=origin, direction=direction)
    return path_from_points(np.stack([centre - d / n * half_mm, centre + d / n * half_mm]), step_mm=step_mm)
