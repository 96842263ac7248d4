"""Vessel growth section by section along the path.

Works in the work box's own frame: positions ``q = index * spacing`` mm in (z, y, x) order
(an orthonormal frame, so distances and angles are the patient's). The path is cut into
sections ``step`` mm apart (default 1 mm), each a plane normal to the path carried by
rotation-minimising frames. In each plane the image is sampled (trilinear, on a grid of half
the smallest voxel side), and the vessel's section is the in-range region holding the path
point or the core's pixels, parted at its neck from a neighbour touching it and peeled to the
half maximum (:mod:`ctui.engine.vessel.neck`), holes filled. Continuity: the section may not
reach further from the path than ``neck.HARD_FACTOR`` times the lumen's inscribed radius there,
or that radius plus ``neck.HARD_MARGIN_MM`` (the larger of the 3D and the in-plane distance to
the range's border, running median over ``REF_MM`` of path), nor exceed ``AREA_JUMP`` times the
running median of the areas around it (it is then cut back to 1.1 times the running median
reach). Every voxel
takes the section of its nearest path point: it is in the vessel when it lies in that
section's slab and region; voxels behind the first plane or beyond the last are never in it
(the cut planes at both ends: the aortic root stops at the start, a branch at its origin).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ctui.engine.core.progress import Progress, report
from ctui.engine.measure.paths import arc_length, path_points, rotation_minimising_frames
from ctui.engine.vessel import neck
from ctui.engine.vessel.wall import EXTRA_MM, wall_rays, wall_regions

REF_MM = 10.0  # running-median window of the inscribed radius
AREA_JUMP = 1.5  # a section's area / the median of the previous ones beyond which it is clipped
EDGE_PX = 1  # grid pixels the lumen's rim may add outside the range
EDGE_SHARE = 0.3  # ... down to lo - EDGE_SHARE * |lo|
END_CHORD_MM = 4.0  # the end planes are normal to the path's chord over this length (a spline's end bends)
AREA_WINDOW_MM = 31.0  # the area rule's running median window (path mm)
KEEP_BYTES = 64e6  # the planes' values are kept between the two passes up to this size, else sampled again


@dataclass
class Sections:
    """The planes: ``s`` (n,) arc length mm; ``p``, ``t``, ``u``, ``v`` (n, 3) point, normal and
    in-plane basis in the work frame (mm, z, y, x); ``h`` grid step mm; ``half`` the grid's half
    side mm; ``regions`` (n, g, g) bool, the vessel in each plane (row: u, column: v);
    ``inscribed`` (n,) the largest disc inside each region, diameter mm; ``clipped`` (n,) bool."""

    s: np.ndarray
    p: np.ndarray
    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    h: float
    half: float
    regions: np.ndarray | None = None
    inscribed: np.ndarray | None = None
    clipped: np.ndarray | None = None

    def grid(self, i: int) -> np.ndarray:
        """Positions (g, g, 3) mm (work frame) of plane i's grid."""
        a = np.arange(-self.half, self.half + 1e-9, self.h)
        return self.p[i] + a[:, None, None] * self.u[i] + a[None, :, None] * self.v[i]


def planes(route_q: np.ndarray, *, step_mm: float, h: float, half: float = 0.0) -> Sections:
    """Sections every ``step_mm`` along a smooth path (k, 3) mm in the work frame (``half``:
    the grid's half side; 0: set by :func:`grow_sections` from the reach allowed)."""
    total = float(arc_length(route_q)[-1])
    s = np.arange(0.0, total + 1e-9, step_mm)
    p, t = path_points(route_q, s)
    for i, j in ((0, min(END_CHORD_MM / step_mm, len(s) - 1)), (len(s) - 1, max(len(s) - 1 - END_CHORD_MM / step_mm, 0))):
        c = p[i] - p[int(j)] if i else p[int(j)] - p[0]  # the cut planes: normal to the chord over the end's mm
        if np.linalg.norm(c) > 0:
            t[i] = c / np.linalg.norm(c)
    u, v = rotation_minimising_frames(p, t)
    return Sections(s, p, t, u, v, h, half)


def _sample(vol: np.ndarray, q: np.ndarray, spacing, order: int = 1, cval: float = -1e4) -> np.ndarray:
    from scipy import ndimage as ndi

    idx = (q / np.asarray(spacing, dtype=float)).reshape(-1, 3).T
    return ndi.map_coordinates(vol, idx, order=order, mode="constant", cval=cval).reshape(q.shape[:-1])


def _nearest(vol: np.ndarray, q: np.ndarray, spacing) -> np.ndarray:
    """``vol`` (bool) at the voxels nearest positions ``q`` (..., 3) mm; False outside."""
    k = np.rint(q / np.asarray(spacing, dtype=float)).astype(int)
    ok = np.all((k >= 0) & (k < np.asarray(vol.shape)), axis=-1)
    k = np.where(ok[..., None], k, 0)
    return vol[k[..., 0], k[..., 1], k[..., 2]] & ok


def _seeded(mask: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """The 4-connected components of ``mask`` holding a ``seeds`` pixel, holes filled."""
    from scipy import ndimage as ndi

    lab, n = ndi.label(mask)
    if n == 0:
        return np.zeros_like(mask)
    keep = np.unique(lab[seeds & mask])
    keep = keep[keep > 0]
    return ndi.binary_fill_holes(np.isin(lab, keep)) if keep.size else np.zeros_like(mask)


def _radius_limit(sec: Sections, dist: np.ndarray, spacing, planar: np.ndarray | None = None) -> np.ndarray:
    """Per section: the reach allowed (mm) from the inscribed radius along the path: the 3D
    distance to the range's border at the path point, or the in-plane one (``planar``, mm) where
    larger (near a cut end the valve or a flap closes the lumen along the path, not across it),
    running median over ``REF_MM``."""
    from scipy import ndimage as ndi

    r = _sample(dist.astype(np.float32), sec.p, spacing, order=1, cval=0.0)
    if planar is not None:
        r = np.maximum(r, planar)
    step = float(sec.s[1] - sec.s[0]) if len(sec.s) > 1 else 1.0
    r = ndi.median_filter(r, size=max(3, int(round(REF_MM / step)) | 1), mode="nearest")
    return np.maximum(neck.HARD_FACTOR * r, r + neck.HARD_MARGIN_MM)


def _planar_radius(val: np.ndarray, seeds: np.ndarray, lo: float, hi: float, rr: np.ndarray) -> float:
    """The in-plane distance (mm) from the plane's centre (the path point) to the border of its
    in-range region (``rr``: each grid pixel's distance from the centre, mm)."""
    base = neck.component((val >= lo) & (val <= hi), seeds)
    g = len(val)
    if not base[g // 2, g // 2] or base.all():
        return 0.0
    return float(rr[~base].min())


def grow_sections(sec: Sections, image: np.ndarray, spacing, ranges: list, core: np.ndarray, dist: np.ndarray, *,
                  floor: float | None = None, progress: Progress | None = None) -> Sections:
    """Fill ``sec.regions``: in each plane, the pixels in the lumen's range (``ranges[0]``: (lo,
    hi)) connected to the path point or the core's pixels, parted from touching neighbours at
    their neck and peeled to the half maximum (:mod:`neck`), under the continuity rule (module
    docstring); with ``floor``, the wall region around it (:func:`wall.wall_rays`, :func:`wall.wall_regions`).
    ``dist``: distance (mm) to the border of the lumen's voxels (the inscribed radius)."""
    from scipy import ndimage as ndi

    n = len(sec.s)
    lo, hi = ranges[0]
    limit = _radius_limit(sec, dist, spacing)
    if not sec.half:
        sec.half = float(limit.max()) + (EXTRA_MM if floor is not None else 0.0) + 2.0 * sec.h
    a = np.arange(-sec.half, sec.half + 1e-9, sec.h)
    rr = np.hypot(a[:, None], a[None, :])
    g = len(a)
    centre = np.zeros((g, g), bool)
    centre[g // 2, g // 2] = True
    regions = np.zeros((n, g, g), bool)
    seeds_all = np.zeros((n, g, g), bool)
    img = np.asarray(image, dtype=np.float32)
    planar = np.zeros(n)
    vals = np.zeros((n, g, g), np.float32) if n * g * g * 4 <= KEEP_BYTES else None
    for i in range(n):  # the in-plane radii first
        if i % 32 == 0:
            report(progress, i, 2 * n, "sections")
        q = sec.grid(i)
        seeds_all[i] = centre | _nearest(core, q, spacing)
        val = _sample(img, q, spacing)
        planar[i] = _planar_radius(val, seeds_all[i], lo, hi, rr)
        if vals is not None:
            vals[i] = val
    limit = np.minimum(_radius_limit(sec, dist, spacing, planar), sec.half - 2.0 * sec.h)
    walls: list = []
    for i in range(n):
        if i % 32 == 0:
            report(progress, n + i, 2 * n, "sections")
        val, seeds = vals[i] if vals is not None else _sample(img, sec.grid(i), spacing), seeds_all[i]
        reg = neck.split(val, seeds, lo, hi, rr <= limit[i], sec.h)
        reg = np.zeros((g, g), bool) if reg is None else neck.half_max(ndi.binary_fill_holes(reg), val, seeds, lo,
                                                                         sec.h)
        if EDGE_PX and reg.any():  # the lumen's rim, blurred below the range by partial volume
            out = (val < lo) | (val > hi)
            rim = ndi.binary_dilation(reg, iterations=EDGE_PX) & (val >= lo - EDGE_SHARE * abs(lo)) & out
            reg = reg | (rim & (rr <= limit[i]))
        if floor is not None:
            walls.append(wall_rays(reg, val, h=sec.h, half=sec.half, floor=floor, lo=lo, bright=lo + 0.25 * (hi - lo),
                                   inset=0.5 * float(max(spacing))))
        regions[i] = reg
    if floor is not None:
        regions = wall_regions(regions, walls, h=sec.h, half=sec.half)
    sec.regions, sec.clipped = regions, _continuity(regions, seeds_all, rr, sec)
    sec.inscribed = _inscribed(regions, sec.h)
    return sec


def _continuity(regions: np.ndarray, seeds: np.ndarray, rr: np.ndarray, sec: Sections) -> np.ndarray:
    """The area rule: a section over ``AREA_JUMP`` times the running median of the areas (over
    ``AREA_WINDOW_MM`` of path: a branch's origin or a leak is a bump shorter than that, a real
    widening is not) is cut back to 1.1 times the running median reach. Returns the sections cut."""
    from scipy import ndimage as ndi

    area = regions.reshape(len(regions), -1).sum(axis=1).astype(float)
    reach = np.array([float(rr[r].max()) if r.any() else 0.0 for r in regions])
    step = float(sec.s[1] - sec.s[0]) if len(sec.s) > 1 else 1.0
    size = max(3, int(round(AREA_WINDOW_MM / step)) | 1)
    ref_a = ndi.median_filter(area, size=size, mode="nearest")
    ref_r = ndi.median_filter(reach, size=size, mode="nearest")
    cut = (area > AREA_JUMP * ref_a) & (ref_a > 0)
    for i in np.nonzero(cut)[0]:
        regions[i] = _seeded(regions[i] & (rr <= 1.1 * ref_r[i]), seeds[i])
    return cut


def _inscribed(regions: np.ndarray, h: float) -> np.ndarray:
    """Diameter (mm) of the largest disc inside each plane's region (one distance transform of
    the stack, the planes too far apart along it to see each other)."""
    from scipy import ndimage as ndi

    if not regions.any():
        return np.zeros(len(regions))
    (a, b), (c, d) = (np.nonzero(regions.any(axis=k))[0][[0, -1]] for k in ((0, 2), (0, 1)))
    padded = np.pad(regions[:, a:b + 1, c:d + 1], ((1, 1), (1, 1), (1, 1)))
    far = 4.0 * regions.shape[1] * h
    d = ndi.distance_transform_edt(padded, sampling=(far, h, h))[1:-1]
    return 2.0 * d.reshape(len(regions), -1).max(axis=1)


def _reach(sec: Sections, i: int) -> float:
    """How far (mm) the cut plane at section i reaches: 1.5 times its region's reach, at least 3 grid steps."""
    a = np.arange(-sec.half, sec.half + 1e-9, sec.h)
    reg = sec.regions[i]
    r = float(np.hypot(a[:, None], a[None, :])[reg].max()) if reg.any() else 0.0
    return max(1.5 * r, 3.0 * sec.h)


def rasterise(sec: Sections, shape, spacing, *, progress: Progress | None = None) -> np.ndarray:
    """The vessel's voxels (bool ``shape``): each voxel within the grid's reach of the path
    takes its nearest plane; it is in the vessel when within half a step of that plane (never
    behind the first plane or beyond the last: the cut planes) and in its region."""
    from scipy import ndimage as ndi
    from scipy.spatial import cKDTree

    sp = np.asarray(spacing, dtype=float)
    out = np.zeros(shape, bool)
    if sec.regions is None or not sec.regions.any():
        return out
    seedmask = np.zeros(shape, bool)
    k = np.clip(np.rint(sec.p / sp).astype(int), 0, np.asarray(shape) - 1)
    seedmask[k[:, 0], k[:, 1], k[:, 2]] = True
    near = ndi.distance_transform_edt(~seedmask, sampling=sp) <= sec.half
    report(progress, 0, 1, "voxels")
    vox = np.argwhere(near)
    q = vox * sp
    _, j = cKDTree(sec.p).query(q)
    d = q - sec.p[j]
    w = np.einsum("ij,ij->i", d, sec.t[j])
    step = float(sec.s[1] - sec.s[0]) if len(sec.s) > 1 else 1.0
    ok = np.abs(w) <= step + 1e-6  # interior voxels: within one step of their nearest plane
    for e, sign in ((0, -1.0), (len(sec.s) - 1, 1.0)):  # the cut planes: nothing behind an end near it
        de = q - sec.p[e]
        ok &= ~((sign * (de @ sec.t[e]) > 0) & (np.linalg.norm(de, axis=1) <= _reach(sec, e)))
    iu = np.rint((np.einsum("ij,ij->i", d, sec.u[j]) + sec.half) / sec.h).astype(int)
    iv = np.rint((np.einsum("ij,ij->i", d, sec.v[j]) + sec.half) / sec.h).astype(int)
    g = sec.regions.shape[1]
    ok &= (iu >= 0) & (iu < g) & (iv >= 0) & (iv < g)
    hit = np.zeros(len(vox), bool)
    hit[ok] = sec.regions[j[ok], iu[ok], iv[ok]]
    v = vox[hit]
    out[v[:, 0], v[:, 1], v[:, 2]] = True
    return out
