"""Vessel path: lumen range, speed map, minimal path through the user's points, colliding fronts.

Points are voxel indices (z, y, x) of the volume; paths are patient mm (x, y, z) like every
path of :mod:`ctui.engine.measure.paths`. The cost of one mm of travel is
``1 / (eps + d**2)`` with ``d`` (mm) the distance to the border of the in-range region (the
lumen), so the route keeps to the lumen's middle and crossing out-of-range voxels costs
``1 / eps`` per mm (a stenosis or an artefact is crossed, lung or fat is not); the route is
found by Dijkstra on the 26-connected voxel graph with mm steps
(:func:`ctui.engine.measure.centreline.minimal_route`, the solver of ``ctui measure --path auto``'s
centreline too).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.core.progress import Progress, report
from ctui.engine.measure.centreline import minimal_route

COST_POWER = 2.0  # cost per mm 1 / (eps + d**COST_POWER)
COST_EPS = 0.01  # 1 / COST_EPS: the cost of one mm outside the lumen's range
CORE_MARGIN_MM = 20.0  # the colliding fronts' box around each leg's route
MARGIN_MM = 50.0  # the work box: the points' box grown by this much (a route may bend out of it)


@dataclass
class Legs:
    """The route as chains of voxel points (z, y, x): one chain per end, from the start through
    its waypoints to that end (the first chain is the trunk; the others branch from it)."""

    chains: list

    @property
    def pairs(self) -> list:
        """Every leg (a, b): consecutive points of a chain."""
        return [(c[i], c[i + 1]) for c in self.chains for i in range(len(c) - 1)]


def crop_box(shape, points, spacing, margin_mm: float = MARGIN_MM) -> tuple[slice, slice, slice]:
    """The work box: the points' bounding box grown by ``margin_mm``, clipped to the volume."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    m = np.ceil(margin_mm / np.asarray(spacing, dtype=float)).astype(int)
    lo = np.maximum(np.floor(p.min(axis=0)).astype(int) - m, 0)
    hi = np.minimum(np.ceil(p.max(axis=0)).astype(int) + m + 1, np.asarray(shape))
    return tuple(slice(int(a), int(b)) for a, b in zip(lo, hi))


def auto_range(image: np.ndarray, points, spacing) -> tuple[float, float]:
    """The lumen's range (lo, hi) from the values at the user's points.

    ``mu``: the median of the 3 x 3 x 3 medians at the points (the lumen); ``bg``: the median
    of the values below ``mu`` in a box of +-15 mm around them (the wall and what surrounds
    it); ``lo`` halfway between, ``hi`` as far above ``mu`` as ``lo`` is below it, three times
    (contrast is uneven, calcium brighter)."""
    img = np.asarray(image)
    meds, around = [], []
    r = np.maximum(np.round(15.0 / np.asarray(spacing, dtype=float)).astype(int), 2)
    for p in np.asarray(points, dtype=int).reshape(-1, 3):
        sl = tuple(slice(max(int(c) - 1, 0), int(c) + 2) for c in p)
        meds.append(float(np.median(img[sl])))
        big = tuple(slice(max(int(c) - k, 0), int(c) + k + 1) for c, k in zip(p, r))
        around.append(img[big].ravel())
    mu = float(np.median(meds))
    vals = np.concatenate(around).astype(np.float64)
    below = vals[vals < mu - 0.1 * abs(mu)]
    bg = float(np.median(below)) if below.size else mu - abs(mu)
    lo = 0.5 * (mu + bg)
    return lo, mu + 3.0 * (mu - lo)


def lumen_distance(image: np.ndarray, lo: float, hi: float, spacing) -> tuple[np.ndarray, np.ndarray]:
    """(d, in-range mask) of a (cropped) image: d (mm) the distance to the border of the
    in-range voxels (0 outside them)."""
    from scipy import ndimage as ndi

    img = np.asarray(image)
    inr = (img >= lo) & (img <= hi)
    return ndi.distance_transform_edt(inr, sampling=tuple(float(s) for s in spacing)), inr


def leg_cost(dist: np.ndarray, a, b, spacing, box=None) -> np.ndarray:
    """Cost per mm of one leg (from ``a`` to ``b``; ``box``: the part of ``dist`` it runs in):
    ``1 / (eps + d**2)``, d the distance to the lumen's border (mm)."""
    d = dist if box is None else dist[box]
    return 1.0 / (COST_EPS + d ** COST_POWER)


def order_legs(start, vias, ends) -> Legs:
    """Chains from ``start`` through the waypoints to each end. One end: the waypoints in the
    order given. Several ends (a tree): each waypoint belongs to the end it lies nearest, in
    order of distance from the start."""
    start = tuple(int(v) for v in start)
    ends = [tuple(int(v) for v in e) for e in ends]
    if not ends:
        raise CtuiError("a vessel needs at least one end", option="ends")
    by_end: list[list] = [[] for _ in ends]
    for v in vias:
        v = tuple(int(c) for c in v)
        k = int(np.argmin([np.linalg.norm(np.subtract(v, e)) for e in ends])) if len(ends) > 1 else 0
        by_end[k].append(v)
    if len(ends) > 1:
        by_end = [sorted(b, key=lambda q: float(np.linalg.norm(np.subtract(q, start)))) for b in by_end]
    return Legs([[start, *by_end[k], e] for k, e in enumerate(ends)])


def _spur(before: np.ndarray, after: np.ndarray, within: float = 1.5) -> int:
    """Points the route runs out to a waypoint and back along the same voxels: how many of the
    last points of ``before`` lie within ``within`` voxels of the first points of ``after``."""
    k = 0
    n = min(len(before), len(after)) - 2
    while k < n and np.linalg.norm(before[-2 - k] - after[k + 1]) <= within:
        k += 1
    return k


def minimal_path(dist: np.ndarray, legs: Legs, spacing, *, progress: Progress | None = None
                 ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(chain routes, leg routes) on the cost of :func:`leg_cost` from ``dist`` (the lumen's
    distance map, :func:`lumen_distance`): voxel routes (k, 3), (z, y, x) float indices, one
    per chain, from the start through its waypoints to its end; and one per leg (``legs.pairs``)."""
    routes, leg_routes = [], []
    n = len(legs.pairs)
    for chain in legs.chains:
        parts = []
        for a, b in zip(chain[:-1], chain[1:]):
            report(progress, len(leg_routes), n, "minimal path")
            r = minimal_route(leg_cost(dist, a, b, spacing), a, b, spacing)
            leg_routes.append(r)
            if parts:  # a waypoint off the lumen's middle: the route goes out to it and back; cut the spur
                k = _spur(parts[-1], r)
                parts[-1] = parts[-1][: len(parts[-1]) - k]
                r = r[k:]
            parts.append(r if not parts else r[1:])
        routes.append(np.concatenate(parts))
    return routes, leg_routes


def outside_runs(route: np.ndarray, inr: np.ndarray, spacing, min_mm: float = 5.0) -> list[dict]:
    """Stretches of a voxel route through out-of-range voxels longer than ``min_mm``: each
    {from, to (voxel z, y, x), length_mm, middle (voxel z, y, x: where a waypoint would help)}."""
    k = np.rint(route).astype(int)
    out = ~inr[k[:, 0], k[:, 1], k[:, 2]]
    step = np.linalg.norm(np.diff(route, axis=0) * np.asarray(spacing, dtype=float), axis=1)
    runs, i = [], 0
    while i < len(out):
        if not out[i]:
            i += 1
            continue
        j = i
        while j + 1 < len(out) and out[j + 1]:
            j += 1
        length = float(step[max(i - 1, 0):j].sum())
        if length >= min_mm:
            runs.append({"from": k[i].tolist(), "to": k[j].tolist(), "length_mm": length,
                         "middle": k[(i + j) // 2].tolist()})
        i = j + 1
    return runs


def colliding_fronts(dist: np.ndarray, legs: Legs, inr: np.ndarray, spacing=(1.0, 1.0, 1.0), routes=None
                     ) -> np.ndarray:
    """The core: SimpleITK's colliding fronts (the region where the fronts from a leg's two
    ends meet, negative output) on the speed ``1 / cost``, for each leg, in range, joined.
    The fronts start at the leg's ends, so the core does not pass behind the start or an end.
    ``routes``: each leg's voxel route; the fronts run in its box grown by ``CORE_MARGIN_MM``."""
    import SimpleITK as sitk

    core = np.zeros(dist.shape, bool)
    for k, (a, b) in enumerate(legs.pairs):
        r = routes[k] if routes is not None else np.array([a, b], dtype=float)
        box = crop_box(dist.shape, r, spacing, margin_mm=CORE_MARGIN_MM)
        lo = np.array([s.start for s in box])
        speed = sitk.GetImageFromArray((1.0 / leg_cost(dist, a, b, spacing, box)).astype(np.float32))
        f = sitk.CollidingFrontsImageFilter()
        f.SetSeedPoints1([[int(c) for c in np.subtract(a, lo)[::-1]]])
        f.SetSeedPoints2([[int(c) for c in np.subtract(b, lo)[::-1]]])
        f.ApplyConnectivityOn()
        f.StopOnTargetsOn()
        core[box] |= sitk.GetArrayFromImage(f.Execute(speed)) < 0
    return core & inr
