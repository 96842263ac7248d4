"""Cross-sections along a path and the volume between two planes (thesis ch. 7.2).

Both tools work on a *smooth function of the object* rather than on its binary mask,
computed once on the object's bounding box plus a margin (:func:`object_field`):

* ``indicator`` - the mask smoothed by a Gaussian of ``sigma_vox`` voxels per axis
  (default 0.7), in [0, 1]; its 0.5 level is the smoothed object border and its
  integral over a plane is the (partial-volume) area of the section;
* ``sdf`` - an approximate signed distance in mm (negative inside) whose zero level is
  the 0.5 level of the indicator corrected to first order for the inward shift that
  Gaussian smoothing causes on curved borders (one backward heat step,
  ``f - sum_i sigma_i**2 / 2 * d2f/dx_i2``); linear across the border, which suits
  trilinear interpolation and the half-space distances of the volume tool.

Sections (:func:`sections_along_path`): for each point of the path at ``step_mm``, the
tangent is the plane normal, an orthonormal plane basis (u, v) is carried along the path
by rotation-minimising frames (double reflection, Wang et al. 2008) so it does not
flip, a square grid centred on the point is sampled by trilinear interpolation
(``map_coordinates(order=1)``, all planes in one call per batch), marching squares
(``skimage.measure.find_contours``) extracts the 0.5 contour and the contour that
encloses the path point is kept. Reported per section:

* ``area_mm2`` - the partial-volume area: integral of the sampled indicator over the
  plane region that belongs to the enclosing contour (its connected blur footprint,
  split from neighbours by nearest contour). Gaussian smoothing preserves mass, so this
  estimate has no curvature bias; on binary analytic cylinders it is more accurate
  than the shoelace area of the 0.5 contour (see tests/test_sections.py);
* ``contour_area_mm2`` - the shoelace (2D Gauss theorem) area of the enclosing contour;
* ``eq_diameter_mm`` = 2 sqrt(area / pi); ``min_diameter_mm`` / ``max_diameter_mm`` -
  minimum and maximum Feret diameters (rotating calipers on the contour's convex hull),
  scaled by sqrt(area_mm2 / contour_area_mm2) so they agree with the area.

Volume between two planes (:func:`volume_between`): the planes normal to the path at
arc lengths s1 < s2 bound a slab; the region is grown (26-connectivity) from the path
voxels between the two points through object voxels inside the slab only, so parallel
structures the planes also cut are excluded; the function ``max(sdf, psi1, psi2)``
(psi = signed distances to the half-spaces, mm) restricted to that region is meshed at
its zero level with MESH's ``isosurface`` (flat, exact caps) and the volume is measured
by the Gauss theorem.

Paths are (n, 3) patient positions (x, y, z) in mm; geometry arguments are those of
:class:`~ctui.engine.core.volume.Volume`.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field as dc_field
from typing import Any, Iterable, Sequence

import numpy as np

from ctui.engine.measure.centreline import arc_length, index_matrix
from ctui.engine.core.errors import CtuiError

SECTION_KEYS = ("s_mm", "area_mm2", "eq_diameter_mm", "min_diameter_mm", "max_diameter_mm")


# ------------------------------------------------------------------ the field
@dataclass
class ObjectField:
    """A smooth function of one object on its bounding box plus a margin.

    Attributes
    ----------
    indicator : ndarray float32 (z, y, x)
        Gaussian-smoothed mask in [0, 1] (0.5 = border).
    sdf : ndarray float32 (z, y, x)
        Approximate signed distance in mm, negative inside (see module docstring).
    offset : ndarray int (3,)
        Index (z, y, x) in the full volume of the crop's first voxel.
    spacing, origin, direction
        Geometry of the full volume.
    sigma_vox : float
        Gaussian sigma in voxels (per axis).
    """

    indicator: np.ndarray
    offset: np.ndarray
    spacing: tuple[float, float, float]
    origin: tuple[float, float, float]
    direction: np.ndarray
    sigma_vox: float
    mask: np.ndarray | None = None  # cropped binary mask
    meta: dict[str, Any] = dc_field(default_factory=dict)
    source: np.ndarray | None = None  # cropped (padded) float mask the fields come from
    _sdf: np.ndarray | None = None

    @property
    def sdf(self) -> np.ndarray:
        """Approximate signed distance (mm, negative inside), computed on first use."""
        if self._sdf is None:
            self._sdf = _corrected_sdf(self.source, self.indicator, self.sigma_vox, self.spacing)
        return self._sdf

    @property
    def matrix(self) -> np.ndarray:
        """3x3: mm offset -> (z, y, x) index offset."""
        return np.linalg.inv(index_matrix(self.spacing, self.direction))

    @property
    def crop_origin(self) -> np.ndarray:
        """Patient mm (x, y, z) of the crop's voxel (0, 0, 0)."""
        return index_matrix(self.spacing, self.direction) @ self.offset.astype(np.float64) + np.asarray(self.origin)

    def to_index(self, xyz: np.ndarray) -> np.ndarray:
        """Patient mm (..., 3) -> fractional crop indices (..., 3) in (z, y, x)."""
        return (np.asarray(xyz, dtype=np.float64) - self.crop_origin) @ self.matrix.T


def _bbox(occ: np.ndarray):
    """(lo, hi) inclusive index bounds (z, y, x) of the non-zero voxels, or (None, None).

    Projections with ``np.any`` on shrinking slabs: much cheaper than ``np.nonzero``
    on a large mostly empty volume."""
    z = np.flatnonzero(occ.any(axis=(1, 2)))
    if len(z) == 0:
        return None, None
    slab = occ[z[0] : z[-1] + 1]
    y = np.flatnonzero(slab.any(axis=(0, 2)))
    slab = slab[:, y[0] : y[-1] + 1]
    x = np.flatnonzero(slab.any(axis=(0, 1)))
    return np.array([z[0], y[0], x[0]]), np.array([z[-1], y[-1], x[-1]])


def object_field(
    mask: np.ndarray,
    *,
    spacing=(1.0, 1.0, 1.0),
    origin=(0.0, 0.0, 0.0),
    direction=None,
    sigma_vox: float = 0.7,
    margin_vox: int | None = None,
) -> ObjectField:
    """Smooth functions of a binary object on its bounding box + margin.

    Parameters
    ----------
    mask : ndarray (z, y, x)
        The object (non-zero = inside). A float mask in [0, 1] (partial-volume
        fractions) is accepted and smoothed the same way.
    spacing, origin, direction
        Geometry (see :class:`~ctui.engine.core.volume.Volume`).
    sigma_vox : float
        Gaussian sigma in voxels along each axis (0.7 keeps the aliasing of the
        binary mask low while shifting curved borders little).

    Returns
    -------
    ObjectField
    """
    from scipy import ndimage as ndi

    m = np.asarray(mask)
    if m.ndim != 3:
        raise CtuiError(f"expected a 3D mask, got shape {m.shape}")
    soft = m.dtype.kind == "f"
    occ = m > 0 if (soft or m.dtype != bool) else m
    bb_lo, bb_hi = _bbox(occ)
    if bb_lo is None:
        raise CtuiError("the object is empty")
    if margin_vox is None:
        margin_vox = int(math.ceil(4 * sigma_vox)) + 3
    lo = np.maximum(bb_lo - margin_vox, 0)
    hi = np.minimum(bb_hi + margin_vox + 1, m.shape)
    sl = tuple(slice(a, b) for a, b in zip(lo, hi))
    sub = m[sl].astype(np.float32) if soft else occ[sl].astype(np.float32)
    pad = [(max(margin_vox - int(a), 0), max(int(b) + margin_vox + 1 - n, 0)) for a, b, n in zip(bb_lo, bb_hi, m.shape)]
    if any(p for pp in pad for p in pp):  # the object touches the volume's edge
        sub = np.pad(sub, pad)
        lo = lo - np.array([p[0] for p in pad])
    f = ndi.gaussian_filter(sub, float(sigma_vox), mode="constant", truncate=4.0)
    sp = np.asarray(spacing, dtype=np.float64)
    d = np.eye(3) if direction is None else np.asarray(direction, dtype=np.float64).reshape(3, 3)
    return ObjectField(
        indicator=f.astype(np.float32, copy=False),
        offset=lo.astype(np.int64),
        spacing=tuple(float(s) for s in sp),
        origin=tuple(float(o) for o in origin),
        direction=d,
        sigma_vox=float(sigma_vox),
        mask=(sub > 0.5),
        source=sub,
    )


def _corrected_sdf(sub: np.ndarray, f: np.ndarray, sigma_vox: float, spacing) -> np.ndarray:
    """Signed-distance-like field (mm, negative inside) from the smoothed indicator ``f``.

    The 0.5 level of a Gaussian-smoothed shape moves inwards by about sigma**2 times the
    mean curvature; one backward heat step ``f - sum_i sigma_i**2/2 d2f/dx_i2`` (exact
    second derivatives of the Gaussian) undoes it to first order. Scaled by the slope of
    a smoothed straight edge (1 / (sqrt(2 pi) sigma_mm)) to read in mm near the border.
    """
    from scipy import ndimage as ndi

    sig = [float(sigma_vox)] * 3
    corr = np.zeros_like(f)
    for ax in range(3):
        order = [0, 0, 0]
        order[ax] = 2
        corr += (sig[ax] ** 2 / 2.0) * ndi.gaussian_filter(sub, sig, order=order, mode="constant", truncate=4.0)
    fc = f - corr
    sigma_mm = float(sigma_vox * np.exp(np.mean(np.log(np.asarray(spacing, dtype=np.float64)))))
    return ((0.5 - fc) * (math.sqrt(2 * math.pi) * sigma_mm)).astype(np.float32)


# ------------------------------------------------------------------ path sampling
def _path_spline(path_mm: np.ndarray):
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
    spl, total = _path_spline(path_mm)
    s = np.clip(np.asarray(s_mm, dtype=np.float64), 0.0, total)
    pts = spl(s)
    tan = spl(s, 1)
    norm = np.linalg.norm(tan, axis=1, keepdims=True)
    tan = tan / np.where(norm > 0, norm, 1.0)
    return pts, tan


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
    # initial u: the axis least aligned with the tangent, made orthogonal
    a = np.eye(3)[int(np.argmin(np.abs(t[0])))]
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
    v = np.cross(t, u)
    return u, v


# ------------------------------------------------------------------ 2D geometry
def shoelace_area(poly: np.ndarray) -> float:
    """Signed area of a closed polygon (n, 2) by the 2D Gauss theorem (CCW > 0)."""
    p = np.asarray(poly, dtype=np.float64)
    if len(p) < 3:
        return 0.0
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


_FERET_DIRS = None


def feret_diameters(poly: np.ndarray, *, exact: bool = False) -> tuple[float, float]:
    """(min, max) Feret (caliper) diameters of a 2D point set (n, 2).

    Default (points in polygon order): caliper widths on 360 directions 0.5 degree
    apart and on every polygon edge's normal. The maximum (a smooth maximum of the
    width function) is then within 1e-5 relative; the minimum is exact when the
    narrowest caliper rests on a polygon edge (always for convex contours), else
    within the 0.5 degree sampling. About 5x faster than building the convex hull
    with Qhull (0.3 ms vs 1.5 ms on a 200-point contour), which matters with hundreds
    of sections. ``exact=True``: rotating calipers on the convex hull
    (minimum width is attained with a caliper flush with a hull edge; maximum = the
    largest distance between hull vertices).
    """
    global _FERET_DIRS
    p = np.asarray(poly, dtype=np.float64)
    if len(p) > 1 and np.array_equal(p[0], p[-1]):
        p = p[:-1]  # closed contour: drop the repeated point
    if len(p) < 3:
        d = float(np.linalg.norm(p[-1] - p[0])) if len(p) == 2 else 0.0
        return 0.0, d
    if not exact:
        if _FERET_DIRS is None:
            t = np.arange(360) * (np.pi / 360.0)
            _FERET_DIRS = np.stack([np.cos(t), np.sin(t)])  # (2, 360)
        q = p - p.mean(axis=0)
        proj = q @ _FERET_DIRS
        w = proj.max(axis=0) - proj.min(axis=0)
        # the minimum sits at a kink of the width function (a caliper flush with an
        # edge): also try every polygon edge's normal exactly
        e = np.roll(q, -1, axis=0) - q
        el = np.hypot(e[:, 0], e[:, 1])
        ok = el > 0
        nrm = np.stack([-e[ok, 1], e[ok, 0]]) / el[ok]
        pe = q @ nrm
        we = pe.max(axis=0) - pe.min(axis=0)
        return float(min(w.min(), we.min())), float(w.max())
    from scipy.spatial import ConvexHull, QhullError
    from scipy.spatial.distance import pdist

    try:
        h = p[ConvexHull(p).vertices]
    except QhullError:  # collinear points
        d = p - p.mean(axis=0)
        return 0.0, float(np.ptp(d @ np.linalg.svd(d, full_matrices=False)[2][0]))
    e = np.roll(h, -1, axis=0) - h
    el = np.linalg.norm(e, axis=1)
    ok = el > 0
    nrm = np.stack([-e[ok, 1], e[ok, 0]], axis=1) / el[ok, None]
    proj = h @ nrm.T  # (points, edges): extent of the hull across each edge
    widths = proj.max(axis=0) - proj.min(axis=0)
    return float(widths.min()), float(pdist(h).max())


def _points_in_poly(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    from skimage.measure import points_in_poly

    return points_in_poly(np.asarray(points, dtype=np.float64), np.asarray(poly, dtype=np.float64))


# ------------------------------------------------------------------ sections
def _default_half_size(field: ObjectField, path_len: float) -> float:
    sp = np.asarray(field.spacing)
    vol = float(field.indicator.sum()) * float(np.prod(sp))
    r = math.sqrt(vol / (math.pi * max(path_len, 1e-6)))
    return float(np.clip(2.0 * r, 4 * sp.max(), 80.0))


def _section_of_plane(g: np.ndarray, h: float, tail: int = 4) -> dict[str, Any]:
    """Measure the section around the centre of one sampled plane ``g`` (n, n).

    ``tail``: cells beyond the 0.5 level where the smoothed indicator is still
    noticeable (about 3.3 sigma). Work is restricted to the box of the centre's 0.5
    region grown by ``tail`` (2 ``tail`` when looking for neighbours sharing it).
    """
    from scipy import ndimage as ndi
    from skimage.measure import find_contours

    n = g.shape[0]
    c = (n - 1) // 2
    out: dict[str, Any] = {"inside": bool(g[c, c] >= 0.5), "needs_larger": False}
    if not out["inside"]:
        return out
    hi_lab, nhi = ndi.label(g >= 0.5)
    me = int(hi_lab[c, c])
    box = ndi.find_objects(hi_lab, max_label=me)[me - 1]
    r0, r1, c0, c1 = box[0].start, box[0].stop, box[1].start, box[1].stop
    if r0 == 0 or c0 == 0 or r1 == n or c1 == n:
        out["needs_larger"] = True
        return out
    # footprint box: the region's box grown by the blur tail; a larger box to look for neighbours
    R0, R1, C0, C1 = max(r0 - tail, 0), min(r1 + tail, n), max(c0 - tail, 0), min(c1 + tail, n)
    sub = g[R0:R1, C0:C1]
    foot = sub > 0.001  # the tail beyond 0.001 holds < 0.03% of a 1 mm section
    if nhi > 1:
        Q0, Q1, K0, K1 = max(r0 - 2 * tail, 0), min(r1 + 2 * tail, n), max(c0 - 2 * tail, 0), min(c1 + 2 * tail, n)
        big = hi_lab[Q0:Q1, K0:K1]
        if np.any((big > 0) & (big != me)):
            # split a blur footprint shared with neighbours by nearest 0.5 region
            _, ind = ndi.distance_transform_edt(big == 0, return_indices=True)
            near = big[ind[0], ind[1]]
            foot &= near[R0 - Q0 : R1 - Q0, C0 - K0 : C1 - K0] == me
    fg = np.where(foot, sub, 0.0)
    if (R0 == 0 and fg[0].max() > 0.05) or (R1 == n and fg[-1].max() > 0.05) or \
            (C0 == 0 and fg[:, 0].max() > 0.05) or (C1 == n and fg[:, -1].max() > 0.05):
        out["needs_larger"] = True
        return out
    pv_area = float(fg.sum()) * h * h
    # contours on the region's box + 1 cell (closed there); back to full-grid indices
    g2 = g[r0 - 1 : r1 + 1, c0 - 1 : c1 + 1]
    off = np.array([r0 - 1, c0 - 1], dtype=np.float64)
    best = None
    for cont in find_contours(g2, 0.5):
        if len(cont) < 4 or np.any(np.abs(cont[0] - cont[-1]) > 1e-9):
            continue
        cont = cont + off
        if _points_in_poly([[c, c]], cont)[0]:
            a = abs(shoelace_area(cont))
            if best is None or a < best[0]:
                best = (a, cont)
    if best is None:
        out["inside"] = False
        return out
    a_c, cont = best
    a_c *= h * h
    pts = (cont - c) * h  # (row=u, col=v) mm in the plane
    dmin, dmax = feret_diameters(pts)
    # polygon centroid (2D Gauss theorem), used to re-centre paths
    x, y = pts[:, 0], pts[:, 1]
    cr = x * np.roll(y, -1) - np.roll(x, -1) * y
    a2 = cr.sum()
    cen = np.array([((x + np.roll(x, -1)) * cr).sum(), ((y + np.roll(y, -1)) * cr).sum()]) / (3.0 * a2) if a2 else pts.mean(axis=0)
    scale = math.sqrt(pv_area / a_c) if a_c > 0 else 1.0
    out.update(
        pv_area_mm2=pv_area,
        contour_area_mm2=a_c,
        min_diameter_mm=dmin * scale,
        max_diameter_mm=dmax * scale,
        contour_uv=pts,
        centroid_uv=cen,
    )
    return out


def sections_along_path(
    mask: np.ndarray | None,
    path_mm: np.ndarray,
    *,
    spacing=(1.0, 1.0, 1.0),
    step_mm: float = 0.5,
    origin=(0.0, 0.0, 0.0),
    direction=None,
    field: ObjectField | None = None,
    at_s: Sequence[float] | None = None,
    half_size_mm: float | None = None,
    grid_step_mm: float | None = None,
    max_grid: int = 129,
    area: str = "pv",
    batch: int = 96,
    timings: dict | None = None,
    average_mm: float = 0.0,
) -> list[dict[str, Any]]:
    """Cross-sections of an object in planes normal to a path.

    Parameters
    ----------
    mask : ndarray (z, y, x) or None
        The object (ignored when ``field`` is given).
    path_mm : ndarray (n, 3)
        The path, patient mm (x, y, z); a dense polyline (e.g. from
        :func:`~ctui.engine.measure.centreline.centreline`).
    spacing, origin, direction
        Geometry of ``mask``.
    step_mm : float
        Distance along the path between sections (from s = 0).
    field : ObjectField, optional
        Precomputed :func:`object_field` (reuse it for several calls).
    at_s : sequence of float, optional
        Explicit arc lengths (mm) instead of a regular step.
    half_size_mm : float, optional
        Initial half side of the square grid (grown automatically when the
        section does not fit).
    grid_step_mm : float, optional
        Grid spacing; default a quarter of the smallest voxel size, coarsened so the
        grid has at most ``max_grid`` points a side.
    area : "pv" or "contour"
        Which estimate ``area_mm2`` reports (see module docstring).
    timings : dict, optional
        Filled with seconds spent in "field", "sampling", "contours".
    average_mm : float
        0 (default): each section is one plane, as in the thesis. > 0: area and
        diameters are the mean over planes spread evenly over
        [s - average_mm/2, s + average_mm/2] (every 0.25 mm at most): a thin-slab
        average that halves the aliasing scatter of binary masks of small tubes at
        the cost of blurring changes along the path over that length.

    Returns
    -------
    list of dict, one per section, with keys ``s_mm``, ``area_mm2``,
    ``eq_diameter_mm``, ``min_diameter_mm``, ``max_diameter_mm``,
    ``contour_area_mm2``, ``pv_area_mm2``, ``point_mm`` (3,), ``normal`` (3,),
    ``contour_mm`` (k, 3) patient mm or None; area and diameters are NaN where the path
    point lies outside the object.
    """
    import time

    from scipy import ndimage as ndi

    t0 = time.perf_counter()
    if field is None:
        if mask is None:
            raise CtuiError("sections_along_path needs a mask or a field")
        field = object_field(mask, spacing=spacing, origin=origin, direction=direction)
    t1 = time.perf_counter()
    if average_mm and average_mm > 0:
        _, total = _path_spline(path_mm)
        targets = np.arange(0.0, total + 1e-9, step_mm) if at_s is None else np.asarray(at_s, dtype=np.float64)
        k = max(3, int(math.ceil(average_mm / 0.25)) + 1)
        k += (k + 1) % 2
        offs = np.linspace(-average_mm / 2, average_mm / 2, k)
        all_s = np.clip(targets[:, None] + offs[None, :], 0.0, total)
        sub = sections_along_path(None, path_mm, field=field, at_s=all_s.ravel(), half_size_mm=half_size_mm,
                                  grid_step_mm=grid_step_mm, max_grid=max_grid, area=area, batch=batch, timings=timings)
        rows = []
        keys = ("area_mm2", "eq_diameter_mm", "min_diameter_mm", "max_diameter_mm", "contour_area_mm2", "pv_area_mm2")
        for i, s_i in enumerate(targets):
            grp = sub[i * k : (i + 1) * k]
            row = dict(grp[k // 2])
            row["s_mm"] = float(s_i)
            for key in keys:
                vals = np.array([g[key] for g in grp], dtype=np.float64)
                row[key] = float(np.nanmean(vals)) if np.isfinite(vals).any() else float("nan")
            if math.isfinite(row["area_mm2"]):
                row["eq_diameter_mm"] = 2.0 * math.sqrt(row["area_mm2"] / math.pi)
            row["averaged_mm"] = float(average_mm)
            rows.append(row)
        return rows
    spl, total = _path_spline(path_mm)
    if at_s is None:
        if step_mm <= 0:
            raise CtuiError(f"step must be positive, got {step_mm}")
        s = np.arange(0.0, total + 1e-9, step_mm)
    else:
        s = np.asarray(at_s, dtype=np.float64)
        if np.any(s < -1e-6) or np.any(s > total + 1e-6):
            raise CtuiError(f"section positions must lie on the path (0 to {total:.1f} mm)")
    pts, tan = path_points(path_mm, s)
    u, v = rotation_minimising_frames(pts, tan)
    sp = np.asarray(field.spacing)
    h0 = grid_step_mm if grid_step_mm else float(sp.min()) / 4.0
    half0 = half_size_mm if half_size_mm else _default_half_size(field, total)
    minv = field.matrix
    c_idx = field.to_index(pts)  # (k, 3)
    u_idx = u @ minv.T
    v_idx = v @ minv.T
    k = len(s)
    results: list[dict[str, Any] | None] = [None] * k
    half = np.full(k, half0)
    todo = np.arange(k)
    t_sample = 0.0
    t_cont = 0.0
    for _round in range(5):
        if len(todo) == 0:
            break
        retry = []
        # group planes by half-size so each batch shares one grid
        for hs in np.unique(half[todo]):
            grp = todo[half[todo] == hs]
            n = int(min(max_grid, math.ceil(2 * hs / h0) + 1))
            n += (n + 1) % 2  # odd: a grid node on the path point
            h = 2 * hs / (n - 1)
            t = (np.arange(n) - (n - 1) / 2) * h
            for b0 in range(0, len(grp), batch):
                ids = grp[b0 : b0 + batch]
                ta = time.perf_counter()
                coords = (
                    c_idx[ids][:, :, None, None]
                    + u_idx[ids][:, :, None, None] * t[None, None, :, None]
                    + v_idx[ids][:, :, None, None] * t[None, None, None, :]
                )  # (b, 3, n, n)
                coords = np.moveaxis(coords, 1, 0).reshape(3, -1)
                vals = ndi.map_coordinates(field.indicator, coords, order=1, mode="constant", cval=0.0)
                vals = vals.reshape(len(ids), n, n)
                tb = time.perf_counter()
                t_sample += tb - ta
                tail = int(math.ceil(3.3 * field.sigma_vox * float(sp.max()) / h)) + 1
                for j, i in enumerate(ids):
                    r = _section_of_plane(vals[j], h, tail)
                    if r.get("needs_larger") and _round < 4:
                        retry.append(i)
                        continue
                    results[i] = r
                t_cont += time.perf_counter() - tb
        todo = np.array(sorted(retry), dtype=int)
        half[todo] *= 2.0
    rows = []
    for i in range(k):
        r = results[i] or {"inside": False}
        row: dict[str, Any] = {"s_mm": float(s[i])}
        if "pv_area_mm2" in r:
            a = r["pv_area_mm2"] if area == "pv" else r["contour_area_mm2"]
            cuv = r["contour_uv"]
            row.update(
                area_mm2=a,
                eq_diameter_mm=2.0 * math.sqrt(a / math.pi),
                min_diameter_mm=r["min_diameter_mm"] if area == "pv" else r["min_diameter_mm"] * math.sqrt(r["contour_area_mm2"] / r["pv_area_mm2"]),
                max_diameter_mm=r["max_diameter_mm"] if area == "pv" else r["max_diameter_mm"] * math.sqrt(r["contour_area_mm2"] / r["pv_area_mm2"]),
                contour_area_mm2=r["contour_area_mm2"],
                pv_area_mm2=r["pv_area_mm2"],
                contour_mm=pts[i] + cuv[:, :1] * u[i] + cuv[:, 1:2] * v[i],
                centroid_mm=pts[i] + r["centroid_uv"][0] * u[i] + r["centroid_uv"][1] * v[i],
            )
        else:
            nan = float("nan")
            row.update(area_mm2=nan, eq_diameter_mm=nan, min_diameter_mm=nan, max_diameter_mm=nan,
                       contour_area_mm2=nan, pv_area_mm2=nan, contour_mm=None, centroid_mm=None)
        row["point_mm"] = pts[i]
        row["normal"] = tan[i]
        rows.append(row)
    if timings is not None:
        timings["field"] = timings.get("field", 0.0) + (t1 - t0)
        timings["sampling"] = timings.get("sampling", 0.0) + t_sample
        timings["contours"] = timings.get("contours", 0.0) + t_cont
    return rows


def recentre_path(path_mm: np.ndarray, *, field: ObjectField, step_mm: float = 0.5, iterations: int = 2,
                  smooth_mm: float | None = None) -> np.ndarray:
    """Move each path point to the centroid of its cross-section, then re-fit a spline.

    Sections normal to a path that is off-centre or tilted are themselves off; a
    couple of iterations bring a voxel-level minimal path onto the object's axis
    (centroids of normal sections). Points outside the object are kept as they are.

    Sections are taken every max(step_mm, 1 mm). Returns the new path (n, 3) mm at a
    uniform ``step_mm`` arc-length step.
    """
    from ctui.engine.measure.centreline import _spline_resample

    p = np.asarray(path_mm, dtype=np.float64)
    if smooth_mm is None:
        # section centroids are precise (~0.05 voxel): a loose spline would cut bends
        smooth_mm = 0.15 * float(min(field.spacing))
    for _ in range(iterations):
        rows = sections_along_path(None, p, field=field, step_mm=max(step_mm, 1.0))
        pts = np.array([r["point_mm"] for r in rows])
        cen = pts.copy()
        for i, r in enumerate(rows):
            if r.get("centroid_mm") is None:
                continue
            move = r["centroid_mm"] - r["point_mm"]
            lim = 0.25 * r["eq_diameter_mm"]  # half the equivalent radius per iteration
            n = float(np.linalg.norm(move))
            cen[i] = r["point_mm"] + (move if n <= lim else move * (lim / n))
        # the end sections are caps: move the ends with their neighbours
        if len(cen) > 3:
            cen[0] = pts[0] + (cen[1] - pts[1])
            cen[-1] = pts[-1] + (cen[-2] - pts[-2])
        p = _spline_resample(cen, step_mm, smooth_mm=smooth_mm)
    return p


# ------------------------------------------------------------------ steps
def find_steps(s_mm: np.ndarray, values: np.ndarray, *, min_rel_jump: float = 0.1, window_mm: float = 2.0,
               margin_mm: float | None = None) -> list[dict[str, float]]:
    """Positions where a section quantity steps (e.g. a rod whose radius changes).

    A step at s is a change between the medians of ``values`` over
    [s - window, s) and (s, s + window] larger than ``min_rel_jump`` times the larger
    of the two; the position is refined to the largest local change. Changes within
    ``margin_mm`` (default 2 windows) of the first/last valid section (the object's
    end caps) are not reported.

    Returns a list of ``{"s_mm", "before", "after"}``, ordered by s.
    """
    s = np.asarray(s_mm, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(y)
    s, y = s[ok], y[ok]
    if len(s) < 5:
        return []
    step = float(np.median(np.diff(s)))
    w = max(int(round(window_mm / step)), 2)
    margin = 2.0 * window_mm if margin_mm is None else float(margin_mm)
    jumps = np.zeros(len(s))
    for i in range(w, len(s) - w):
        a = np.median(y[i - w : i])
        b = np.median(y[i + 1 : i + 1 + w])
        jumps[i] = (b - a) / max(abs(a), abs(b), 1e-12)
    from scipy.signal import find_peaks

    out = []
    for sign in (1, -1):
        peaks, _ = find_peaks(sign * jumps, height=min_rel_jump, distance=w)
        for p in peaks:
            if s[p] - s[0] < margin or s[-1] - s[p] < margin:
                continue
            out.append({
                "s_mm": float(s[p]),
                "before": float(np.median(y[max(p - w, 0) : p])),
                "after": float(np.median(y[p + 1 : p + 1 + w])),
            })
    return sorted(out, key=lambda d: d["s_mm"])


# ------------------------------------------------------------------ output
def _clean(v: Any) -> Any:
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return None if not math.isfinite(v) else round(v, 4)
    if isinstance(v, np.ndarray):
        return [_clean(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, (np.integer,)):
        return int(v)
    return v


def sections_table(rows: Iterable[dict[str, Any]], *, keys: Sequence[str] = SECTION_KEYS) -> list[dict[str, Any]]:
    """JSON-ready rows (only ``keys``; NaN -> None; floats rounded to 1e-4)."""
    return [{k: _clean(r.get(k)) for k in keys} for r in rows]


def write_sections_csv(path, rows: Iterable[dict[str, Any]], *, keys: Sequence[str] = SECTION_KEYS) -> None:
    """Write the section table as CSV (atomic)."""
    from ctui.engine.core.atomic import write_text

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(keys)
    for r in sections_table(rows, keys=keys):
        w.writerow(["" if r[k] is None else r[k] for k in keys])
    write_text(path, buf.getvalue())


def write_sections_json(path, rows: Iterable[dict[str, Any]], **extra: Any) -> None:
    """Write ``{"sections": [...], **extra}`` as JSON (atomic)."""
    from ctui.engine.core.atomic import write_text

    doc = {**{k: _clean(v) for k, v in extra.items()}, "sections": sections_table(rows)}
    write_text(path, json.dumps(doc, indent=1) + "\n")


def _sections_figure(rows, *, quantity, references, band, title, size, dpi):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    s = np.array([r["s_mm"] for r in rows], dtype=np.float64)
    y = np.array([r.get(quantity, np.nan) for r in rows], dtype=np.float64)
    fig = Figure(figsize=size, dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(s, y, "-", color="#1f77b4", lw=1.2, label=quantity)
    for ref in references or ():
        ax.axhline(ref, color="#d62728", ls="--", lw=0.8)
        if band:
            ax.axhspan(ref * (1 - band), ref * (1 + band), color="#d62728", alpha=0.12, lw=0)
    ax.set_xlabel("arc length (mm)")
    unit = "mm²" if quantity.endswith("mm2") else "mm"
    ax.set_ylabel(f"{quantity.rsplit('_', 1)[0].replace('_', ' ')} ({unit})")
    if title:
        ax.set_title(title)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def plot_sections(
    path,
    rows: Sequence[dict[str, Any]],
    *,
    quantity: str = "area_mm2",
    references: Sequence[float] | None = None,
    band: float | None = 0.02,
    title: str | None = None,
    size=(8.0, 4.0),
    dpi: int = 100,
) -> None:
    """PNG plot of a section quantity against arc length (matplotlib Agg, atomic).

    ``quantity``: any numeric row key ("area_mm2", "eq_diameter_mm",
    "min_diameter_mm", ...). ``references``: horizontal reference values (same unit),
    drawn as dashed lines with a +-``band`` relative band, like the thesis's figure 7.11.
    """
    from ctui.engine.core.atomic import atomic_path

    fig = _sections_figure(rows, quantity=quantity, references=references, band=band, title=title, size=size, dpi=dpi)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png")


def sections_plot_image(
    rows: Sequence[dict[str, Any]],
    *,
    quantity: str = "area_mm2",
    references: Sequence[float] | None = None,
    band: float | None = 0.02,
    title: str | None = None,
    size_px: tuple[int, int] = (800, 400),
) -> np.ndarray:
    """The same plot as :func:`plot_sections`, as an RGB image (h, w, 3) uint8 (for the TUI)."""
    dpi = 100
    fig = _sections_figure(rows, quantity=quantity, references=references, band=band, title=title,
                           size=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


# ------------------------------------------------------------------ volume between planes
def _isosurface(data: np.ndarray, *, spacing, origin, direction):
    """Mesh the 0 level of ``data`` (positive inside) with MESH's isosurface."""
    try:
        from ctui.engine.mesh.surface import isosurface
    except ImportError:  # MESH's module not landed yet: scikit-image's marching cubes
        from skimage.measure import marching_cubes

        from ctui.engine.core.meshdata import Mesh

        verts, faces, _, _ = marching_cubes(data, 0.0, spacing=tuple(spacing))
        m = index_matrix((1.0, 1.0, 1.0), direction)
        xyz = verts @ m.T + np.asarray(origin)
        # skimage orients faces so normals point to decreasing values (outwards here)
        return Mesh(vertices=xyz, faces=faces.astype(np.int64), meta={"method": "skimage.marching_cubes"})
    return isosurface(data, 0.0, spacing=tuple(spacing), origin=tuple(origin), direction=direction)


def volume_between(
    mask: np.ndarray | None,
    path_mm: np.ndarray,
    s1: float,
    s2: float,
    *,
    spacing=(1.0, 1.0, 1.0),
    origin=(0.0, 0.0, 0.0),
    direction=None,
    field: ObjectField | None = None,
    return_mesh: bool = False,
) -> dict[str, Any]:
    """Volume of the object between the planes normal to a path at arc lengths s1, s2.

    Parameters
    ----------
    mask : ndarray (z, y, x) or None
        The object (ignored when ``field`` is given).
    path_mm : ndarray (n, 3)
        The path, patient mm (x, y, z).
    s1, s2 : float
        Arc lengths (mm) of the two planes (any order).
    return_mesh : bool
        Add the region's surface (:class:`~ctui.engine.core.meshdata.Mesh`) as ``"mesh"``.

    Returns
    -------
    dict with ``volume_mm3``, ``volume_ml`` (Gauss theorem on the region's surface),
    ``volume_pv_mm3`` (cross-check: partial-volume integral of the smoothed mask over
    the region, weighted by the planes), ``area1_mm2``, ``area2_mm2`` (sections at
    the planes), ``s1_mm``, ``s2_mm``, ``voxels`` (region voxel count),
    ``closed`` (mesh closed), ``warnings``.
    """
    from scipy import ndimage as ndi

    from ctui.engine.measure.stats import mesh_stats

    if field is None:
        if mask is None:
            raise CtuiError("volume_between needs a mask or a field")
        field = object_field(mask, spacing=spacing, origin=origin, direction=direction)
    spl, total = _path_spline(path_mm)
    s1, s2 = sorted((float(s1), float(s2)))
    if s1 < -1e-6 or s2 > total + 1e-6:
        raise CtuiError(f"plane positions must lie on the path (0 to {total:.1f} mm), got {s1:g}, {s2:g}")
    if s2 - s1 <= 0:
        raise CtuiError("the two planes must be at different positions along the path")
    (p1, p2), (n1, n2) = path_points(path_mm, [s1, s2])
    shape = field.sdf.shape
    mfwd = index_matrix(field.spacing, field.direction)
    o = field.crop_origin
    zz, yy, xx = (np.arange(n, dtype=np.float32) for n in shape)

    def plane_dist(p, nrm, sign):
        # signed distance (mm) of voxel centres to the plane, negative on the kept side
        a = sign * (mfwd.T @ nrm)  # per-index-axis slope
        b = sign * float((o - p) @ nrm)
        return (b + a[0] * zz[:, None, None] + a[1] * yy[None, :, None] + a[2] * xx[None, None, :]).astype(np.float32)

    psi1 = plane_dist(p1, n1, -1.0)  # kept: beyond p1 along the path
    psi2 = plane_dist(p2, n2, 1.0)  # kept: before p2
    obj = field.mask | (field.sdf < 0)
    cand = obj & (psi1 <= 0) & (psi2 <= 0)
    ss = np.linspace(s1, s2, max(int((s2 - s1) / (0.25 * min(field.spacing))) + 2, 2))
    seeds = np.rint(field.to_index(spl(ss))).astype(int)
    inb = np.all((seeds >= 0) & (seeds < np.array(shape)), axis=1)
    seeds = seeds[inb]
    seeds = seeds[cand[seeds[:, 0], seeds[:, 1], seeds[:, 2]]] if len(seeds) else seeds
    if len(seeds) == 0:
        raise CtuiError("the path does not run inside the object between the two planes")
    lab, _ = ndi.label(cand, structure=np.ones((3, 3, 3)))
    keep = np.unique(lab[seeds[:, 0], seeds[:, 1], seeds[:, 2]])
    keep = keep[keep > 0]
    region = np.isin(lab, keep)
    near = ndi.binary_dilation(region, structure=np.ones((3, 3, 3)))
    F = np.maximum(np.maximum(field.sdf, psi1), psi2)
    pos = float(max(field.spacing))
    F = np.where(near, F, np.maximum(F, pos))
    # crop to the region for meshing
    idx = np.nonzero(near)
    lo = np.array([max(int(i.min()) - 1, 0) for i in idx])
    hi = np.array([min(int(i.max()) + 2, n) for i, n in zip(idx, shape)])
    sub = F[tuple(slice(a, b) for a, b in zip(lo, hi))]
    sub = np.pad(sub, 1, constant_values=pos)  # closed surface even at the crop edge
    sub_origin = o + mfwd @ (lo.astype(np.float64) - 1.0)
    mesh = _isosurface(-sub, spacing=field.spacing, origin=sub_origin, direction=field.direction)
    st = mesh_stats(mesh)
    # cross-check: partial-volume integral of the smoothed indicator over the region's
    # blur footprint (voxels nearer the region than any excluded structure), weighted
    # by each voxel's fraction on the kept side of both planes
    others = obj & ~region
    tail = int(math.ceil(3.3 * field.sigma_vox)) + 1
    foot = ndi.binary_dilation(region, structure=np.ones((3, 3, 3)), iterations=tail)
    if others.any():
        d_reg = ndi.distance_transform_edt(~region, sampling=field.spacing)
        d_oth = ndi.distance_transform_edt(~others, sampling=field.spacing)
        foot &= d_reg < d_oth
    sp_xyz = np.asarray(field.spacing)[::-1]
    ext = [float(np.abs(field.direction.T @ nn) @ sp_xyz) for nn in (n1, n2)]  # voxel extent along each normal
    w = np.clip(0.5 - psi1 / ext[0], 0, 1) * np.clip(0.5 - psi2 / ext[1], 0, 1)
    vol_pv = float((field.indicator * w)[foot].sum()) * float(np.prod(field.spacing))
    areas = sections_along_path(None, path_mm, field=field, at_s=[s1, s2])
    out = {
        "volume_mm3": st["volume_mm3"],
        "volume_ml": st["volume_mm3"] / 1000.0,
        "volume_pv_mm3": vol_pv,
        "area1_mm2": areas[0]["area_mm2"],
        "area2_mm2": areas[1]["area_mm2"],
        "s1_mm": s1,
        "s2_mm": s2,
        "voxels": int(region.sum()),
        "closed": st["closed"],
        "warnings": st["warnings"],
    }
    if return_mesh:
        out["mesh"] = mesh
    return out
