"""One section: the region of a sampled plane around the path point, and 2D figures.

A plane normal to the path is sampled from the object's smooth indicator
(:class:`~ctui.engine.measure.fields.ObjectField`) on a square grid centred on the
path point (:func:`sample_planes`: all planes of a batch in one trilinear
``map_coordinates`` call). :func:`section_of_plane` then extracts the 0.5 contour that
encloses the centre (marching squares, ``skimage.measure.find_contours``) and
measures:

* the partial-volume area: integral of the sampled indicator over the plane region
  that belongs to the enclosing contour (its connected blur footprint, split from
  neighbours by nearest contour). Gaussian smoothing preserves mass, so this estimate
  has no curvature bias;
* the shoelace (2D Gauss theorem) area of the enclosing contour;
* minimum and maximum Feret diameters (:func:`feret_diameters`), and the contour's
  centroid (to re-centre paths).

Imports nothing of ctui (numpy, scipy, scikit-image); no knowledge of paths.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

# ------------------------------------------------------------------ 2D geometry
_CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)  # 4-connected regions (scipy's default)


def _next(a: np.ndarray) -> np.ndarray:
    """The next vertex of each vertex of a closed polygon (``np.roll(a, -1, 0)``, cheaper)."""
    return np.concatenate((a[1:], a[:1]))


def shoelace_area(poly: np.ndarray) -> float:
    """Signed area of a closed polygon (n, 2) by the 2D Gauss theorem (CCW > 0)."""
    p = np.asarray(poly, dtype=np.float64)
    if len(p) < 3:
        return 0.0
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, _next(y)) - np.dot(y, _next(x)))


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
        e = _next(q) - q
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
    e = _next(h) - h
    el = np.linalg.norm(e, axis=1)
    ok = el > 0
    nrm = np.stack([-e[ok, 1], e[ok, 0]], axis=1) / el[ok, None]
    proj = h @ nrm.T  # (points, edges): extent of the hull across each edge
    widths = proj.max(axis=0) - proj.min(axis=0)
    return float(widths.min()), float(pdist(h).max())


def points_in_poly(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    from skimage.measure import points_in_poly

    return points_in_poly(np.asarray(points, dtype=np.float64), np.asarray(poly, dtype=np.float64))


# ------------------------------------------------------------------ one plane
def sample_planes(indicator: np.ndarray, centres: np.ndarray, u_idx: np.ndarray, v_idx: np.ndarray,
                  t: np.ndarray) -> np.ndarray:
    """Sample square planes of ``indicator`` (trilinear, 0 outside).

    ``centres`` (b, 3), ``u_idx``, ``v_idx`` (b, 3): plane centres and in-plane unit
    steps, all in fractional (z, y, x) indices of ``indicator``; ``t`` (n,): grid
    offsets along u and v (mm). Returns (b, n, n) float32, rows along u.
    """
    from scipy import ndimage as ndi

    # built axis by axis in (3, b, n, n) order: no transposed copy of the whole grid
    coords = np.empty((3, len(centres), len(t), len(t)))
    for k in range(3):
        coords[k] = (centres[:, k, None, None] + u_idx[:, k, None, None] * t[None, :, None]
                     + v_idx[:, k, None, None] * t[None, None, :])
    vals = ndi.map_coordinates(indicator, coords.reshape(3, -1), order=1, mode="constant", cval=0.0)
    return vals.reshape(len(centres), len(t), len(t))


def section_of_plane(g: np.ndarray, h: float, tail: int = 4) -> dict[str, Any]:
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
    hi_lab, nhi = ndi.label(g >= 0.5, structure=_CROSS)
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
        if points_in_poly([[c, c]], cont)[0]:
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
    xn, yn = _next(x), _next(y)
    cr = x * yn - xn * y
    a2 = cr.sum()
    cen = np.array([((x + xn) * cr).sum(), ((y + yn) * cr).sum()]) / (3.0 * a2) if a2 else pts.mean(axis=0)
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
