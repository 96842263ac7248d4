"""The vessel's wall in each plane (``--lumen wall``): the lumen and what lies inside the wall.

A dissection's false lumen or a mural thrombus is as grey as the tissue around the vessel, so no
range tells it apart; the fat (CT: below ``floor`` HU, -30 by default) or lung around the vessel
does. From the lumen's centroid, rays every 5 degrees run out until the first value under the
floor, or, where the vessel touches another bright lumen (a chamber, a neighbouring vessel), to
the darkest point between the two. The rays that found such an end fit a circle (the outline is
round; rays that ran on along an organ, the oesophagus, the spine, are cut at it, half a voxel
inside the ray ends); each ray is capped at ``SPREAD`` times their median and smoothed over
neighbouring rays, and the rays are re-cast from their polygon's centroid (``ITERATIONS``: the
lumen is often off-centre in a dissection). The rays and centres are then smoothed along the path
over ``ALONG`` planes, and each plane's wall region is its polygon joined with the lumen where the
band between them is thick enough (an opening by a disc of ``BAND_MM``, or ``BAND_SHARE`` of the
lumen's radius if less): a thin ring is the vessel's own wall and the tissue on it, not a false
lumen or a thrombus.
"""

from __future__ import annotations

import numpy as np

N_RAYS = 72
SPREAD = 1.3  # a ray may run this many times the median ray's length
REACH = 3.0  # rays run at most this many times the lumen's reach from its centroid (and 12 mm),
EXTRA_MM = 15.0  # ... and at most this much beyond it
ITERATIONS = 3  # rays cast from the lumen's centroid, then from their polygon's
MIN_FOUND = 12  # rays that met fat or another lumen needed to fit the outline
ALONG = 13  # planes (mm at the default step) the wall's rays are smoothed over along the path
BAND_MM = 6.0  # the wall's band joins the lumen where it is at least this thick (an opening by this disc) ...
BAND_SHARE = 0.5  # ... or this share of the lumen's equivalent radius, if less (a small vessel's thrombus)
CT_FLOOR = -30.0  # HU: fat and lung lie below it, a thrombosed false lumen above


def _rays(val: np.ndarray, lumen: np.ndarray, c: np.ndarray, h: float, half: float, rmax: float, floor: float,
          lo: float, bright: float) -> tuple[np.ndarray, np.ndarray]:
    """(lengths (N_RAYS,) mm, found (N_RAYS,) bool) of the rays from c (mm, grid frame): to the
    first value under ``floor`` (fat, lung); where a ray leaves the vessel's lumen (the region
    ``lumen``) and meets another bright lumen (``bright`` or more, not ``lumen``: a chamber, a
    neighbouring vessel) first, to the darkest point between them; ``rmax`` where it meets
    neither (not found)."""
    from scipy import ndimage as ndi

    ang = np.linspace(0.0, 2 * np.pi, N_RAYS, endpoint=False)
    t = np.arange(0.0, rmax + 1e-9, 0.5 * h)
    pts = c[None, None, :] + t[None, :, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)[:, None, :]
    idx = (pts + half) / h
    at = [idx[..., 0].ravel(), idx[..., 1].ravel()]
    v = ndi.map_coordinates(val, at, order=1, mode="constant", cval=-1e4).reshape(len(ang), len(t))
    own = ndi.map_coordinates(lumen.astype(np.float32), at, order=0, mode="constant").reshape(v.shape) > 0.5
    out_lumen = np.maximum.accumulate(~own & (v < lo), axis=1)
    edge = np.where(out_lumen.any(axis=1), np.argmax(out_lumen, axis=1), len(t) - 1)
    below = v < floor
    again = out_lumen & ~own & (v >= bright)  # another lumen: the vessel's own (seen from its wall's centre) is not
    n = len(t)
    first_floor = np.where(below.any(axis=1), np.argmax(below, axis=1), n)
    first_again = np.where(again.any(axis=1), np.argmax(again, axis=1), n)
    use_floor = (first_floor < n) & (first_floor <= first_again)
    use_again = ~use_floor & (first_again < n)
    # the darkest point between leaving the lumen and meeting the other one
    between = (np.arange(n)[None, :] >= edge[:, None]) & (np.arange(n)[None, :] <= first_again[:, None])
    darkest = np.argmin(np.where(between, v, np.inf), axis=1)
    rho = np.full(len(ang), rmax)
    rho[use_floor] = t[first_floor[use_floor]]
    rho[use_again] = t[darkest[use_again]]
    found = use_floor | use_again
    return rho, found


def _circle_clip(rho: np.ndarray, found: np.ndarray, c: np.ndarray, inset: float) -> np.ndarray:
    """Rays cut at the circle fitted (least squares, twice, the second time without the points
    more than 2 mm outside the first) to the ends of the rays that met fat or another lumen: the
    vessel's outline is round, the rays that ran on (along an organ, the spine) are not."""
    if found.sum() < MIN_FOUND:
        return rho
    ang = np.linspace(0.0, 2 * np.pi, N_RAYS, endpoint=False)
    d = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    keep = found.copy()
    for _ in range(2):
        x = rho[keep, None] * d[keep]
        a = np.column_stack([x, np.ones(len(x))])
        sol, *_ = np.linalg.lstsq(a, (x ** 2).sum(axis=1), rcond=None)
        m = 0.5 * sol[:2]
        r = float(np.sqrt(max(sol[2] + m @ m, 0.0)))
        keep = found & (np.linalg.norm(rho[:, None] * d - m, axis=1) <= r + 2.0)
        if keep.sum() < MIN_FOUND:
            break
    # distance along each ray from c (the origin) to the circle (m, r)
    b = d @ m
    disc = b * b - (m @ m - r * r)
    reach = np.where(disc >= 0, b + np.sqrt(np.maximum(disc, 0.0)), rho)
    return np.minimum(rho, reach - inset)


def _smoothed(rho: np.ndarray) -> np.ndarray:
    from scipy import ndimage as ndi

    rho = np.minimum(rho, SPREAD * float(np.median(rho)))
    return ndi.median_filter(rho, size=5, mode="wrap")


def _polygon(rho: np.ndarray, c: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Grid pixels inside the star-shaped polygon of ray lengths ``rho`` around c."""
    du, dv = a[:, None] - c[0], a[None, :] - c[1]
    theta = np.mod(np.arctan2(dv, du), 2 * np.pi)
    ang = np.linspace(0.0, 2 * np.pi, N_RAYS + 1)
    r = np.interp(theta, ang, np.append(rho, rho[0]))
    return np.hypot(du, dv) <= r


def wall_rays(lumen: np.ndarray, val: np.ndarray, *, h: float, half: float, floor: float, lo: float,
              bright: float, inset: float = 0.0) -> tuple[np.ndarray, np.ndarray] | None:
    """(centre (2,) mm in the plane's grid frame, ray lengths (N_RAYS,) mm) of the wall around
    the lumen region ``lumen`` of one plane (module docstring); None without a lumen. ``val``:
    the plane's values; ``inset`` (mm): the fitted outline is drawn this much inside the ray
    ends (a ray ends at its first sample in the fat, about half a voxel beyond the border)."""
    if not lumen.any():
        return None
    a = np.arange(-half, half + 1e-9, h)
    iu, iv = np.nonzero(lumen)
    c = np.array([a[iu].mean(), a[iv].mean()])
    reach = float(np.hypot(a[iu] - c[0], a[iv] - c[1]).max())
    rmax = min(max(REACH * reach, 12.0), reach + EXTRA_MM, half)
    for it in range(ITERATIONS):
        rho, found = _rays(val, lumen, c, h, half, rmax, floor, lo, bright)
        rho = _smoothed(_circle_clip(rho, found, c, inset) if it else rho)
        if it < ITERATIONS - 1:
            c = c + _centroid(rho)
    return c, rho


def wall_regions(lumens: np.ndarray, walls: list, *, h: float, half: float) -> np.ndarray:
    """Each plane's wall region (n, g, g) bool: its lumen and the polygon of its rays, the rays'
    lengths and the centres first smoothed along the path (running median over ``ALONG`` planes:
    the wall does not jump from one plane to the next)."""
    from scipy import ndimage as ndi

    a = np.arange(-half, half + 1e-9, h)
    ok = np.array([w is not None for w in walls])
    out = lumens.copy()
    if not ok.any():
        return out
    cs = np.array([w[0] for w in walls if w is not None])
    rhos = np.array([w[1] for w in walls if w is not None])
    cs = ndi.median_filter(cs, size=(ALONG, 1), mode="nearest")
    rhos = ndi.median_filter(rhos, size=(ALONG, 1), mode="nearest")
    band = np.zeros_like(lumens)
    for k, i in enumerate(np.nonzero(ok)[0]):
        band[i] = _polygon(rhos[k], cs[k], a) & ~lumens[i]
    width = np.minimum(BAND_MM, BAND_SHARE * np.sqrt(lumens.reshape(len(lumens), -1).sum(axis=1) / np.pi) * h)
    radius = np.floor(0.5 * width / h).astype(int)  # a band thinner than the width is the vessel's own wall
    for r in np.unique(radius[radius >= 1]):  # one opening per disc size, plane by plane
        k = np.nonzero(radius == r)[0]
        disc = np.hypot(*np.mgrid[-r:r + 1, -r:r + 1]) <= r
        band[k] = ndi.binary_opening(band[k], structure=disc[None])
    return out | band


def _centroid(rho: np.ndarray) -> np.ndarray:
    """Centroid (2,) of the star polygon of ray lengths ``rho`` about the origin (shoelace)."""
    ang = np.linspace(0.0, 2 * np.pi, N_RAYS, endpoint=False)
    x, y = rho * np.cos(ang), rho * np.sin(ang)
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum()
    if abs(area) < 1e-9:
        return np.zeros(2)
    return np.array([((x + x1) * cross).sum(), ((y + y1) * cross).sum()]) / (6.0 * area)
