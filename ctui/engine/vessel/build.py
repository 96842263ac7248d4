"""One vessel from the user's points: range, path, core, growth, report rows (the engine's
whole ``ctui vessel`` run on an array; :mod:`ctui.engine.actions.vessel` wraps it)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.core.progress import Progress, report, scaled
from ctui.engine.measure.paths import arc_length, spline_resample
from ctui.engine.vessel import grow, path

LUMENS = {"contrast": "the bright lumen only (the range at the points)",
          "wall": "the lumen and what lies inside the vessel's wall, up to the fat around it (a dissection's false "
                  "lumen, thrombus)"}
SECTION_STEP_MM = 1.0  # distance between growth planes
SMOOTH_MM = 1.5  # the Gaussian (sd, mm) the vessel's voxels are smoothed with
ROUTE_SMOOTH_MM = 1.0  # spline smoothing of the voxel route


@dataclass
class Vessel:
    """The vessel in the volume's grid: ``mask`` (z, y, x) bool; ``route`` (n, 3) voxel (z, y, x)
    float indices of the smoothed path (every 0.5 mm); ``core`` voxels of the colliding fronts;
    ``range``/``band`` the values taken; ``rows`` one dict per section (s_mm, area_mm2,
    eq_diameter_mm, min_diameter_mm, max_diameter_mm, inscribed_diameter_mm, clipped);
    ``outside`` the route's stretches out of range (see :func:`path.outside_runs`); ``lengths``
    the path length (mm) of each branch (the first: start to the first end)."""

    mask: np.ndarray
    route: np.ndarray
    core_voxels: int
    range: tuple
    band: tuple | None
    rows: list = field(default_factory=list)
    outside: list = field(default_factory=list)
    lengths: list = field(default_factory=list)


def _check_points(points, shape) -> list:
    out = []
    for p in points:
        p = tuple(int(v) for v in p)
        if len(p) != 3 or any(c < 0 or c >= n for c, n in zip(p, shape)):
            raise CtuiError(f"point (slice, row, column) {p} lies outside the volume {tuple(shape)}", option="start")
        out.append(p)
    return out


def _floor(lo: float, image: np.ndarray, pts, spacing) -> float:
    """The wall's floor when the image is not CT: as far below the surroundings (``bg`` of
    :func:`path.auto_range`) as the lumen's ``lo`` is above them."""
    auto_lo, auto_hi = path.auto_range(image, pts, spacing)
    mu = auto_lo + (auto_hi - auto_lo) / 4.0
    bg = 2.0 * auto_lo - mu
    return bg - (lo - bg)


def extract(image: np.ndarray, spacing, *, start, ends, vias=(), value_range=None, lumen: str = "contrast",
            floor: float | None = None, step_mm: float = SECTION_STEP_MM, progress: Progress | None = None) -> Vessel:
    """Extract a vessel from ``image`` (z, y, x), spacing (dz, dy, dx) mm; points voxel (z, y, x).

    ``value_range``: (lo, hi) of the lumen, None = from the points (:func:`path.auto_range`);
    ``lumen``: a key of :data:`LUMENS`; ``floor``: with "wall", the value under which the
    surroundings (fat, lung) lie (None: from the points; CT: :data:`wall.CT_FLOOR`).
    Returns a :class:`Vessel`."""
    if lumen not in LUMENS:
        raise CtuiError(f"unknown lumen {lumen!r}: one of {', '.join(LUMENS)}", option="lumen")
    sp = np.asarray(spacing, dtype=float)
    start, *rest = _check_points([start, *ends, *vias], image.shape)
    ends_, vias_ = rest[:len(ends)], rest[len(ends):]
    if not ends_:
        raise CtuiError("a vessel needs at least one end", option="ends")
    box = path.crop_box(image.shape, [start, *ends_, *vias_], sp)
    off = np.array([s.start for s in box])
    img = np.asarray(image[box], dtype=np.float32)
    lo, hi = value_range if value_range is not None else path.auto_range(img, [np.subtract(p, off) for p in
                                                                                [start, *ends_, *vias_]], sp)
    if lumen == "wall" and floor is None:
        floor = _floor(lo, img, [np.subtract(p, off) for p in [start, *ends_, *vias_]], sp)
    floor = floor if lumen == "wall" else None
    report(progress, 0.02, 1, "speed map")
    dist, inr = path.lumen_distance(img, lo, hi, sp)
    legs = path.order_legs(np.subtract(start, off), [np.subtract(v, off) for v in vias_],
                           [np.subtract(e, off) for e in ends_])
    routes, leg_routes = path.minimal_path(dist, legs, sp, progress=scaled(progress, 0.05, 0.35))
    outside = [r for route in routes for r in path.outside_runs(route, inr, sp)]
    for r in outside:
        for k in ("from", "to", "middle"):
            r[k] = (np.asarray(r[k]) + off).tolist()
    report(progress, 0.35, 1, "colliding fronts")
    core = path.colliding_fronts(dist, legs, inr, sp, leg_routes)
    mask = np.zeros(img.shape, bool)
    rows: list = []
    ranges = [(lo, hi)]
    smooth, lengths = [], []
    for b, route in enumerate(routes):
        rq = _between_ends(spline_resample(route * sp, 0.5, smooth_mm=ROUTE_SMOOTH_MM), route * sp)
        if b:  # a branch: from where it leaves the trunk's vessel
            rq = _leaving(rq, mask, sp)
        sec = grow.planes(rq, step_mm=step_mm, h=0.5 * float(sp.min()))
        sec = grow.grow_sections(sec, img, sp, ranges, core, dist, floor=floor,
                                 progress=scaled(progress, 0.45 + 0.45 * b / len(routes),
                                                 0.45 + 0.45 * (b + 1) / len(routes)))
        mask |= grow.rasterise(sec, img.shape, sp)
        rows += _rows(sec, branch=b)
        smooth.append(rq / sp + off)
        lengths.append(float(arc_length(rq)[-1]))
    full = np.zeros(image.shape, bool)
    full[box] = _attached(_smoothed(mask, sp))
    report(progress, 1, 1, "done")
    return Vessel(full, np.concatenate(smooth), int(core.sum()), (float(lo), float(hi)),
                  None if floor is None else (float(floor), float(lo)), rows, outside, lengths)


def _between_ends(rq: np.ndarray, route_q: np.ndarray) -> np.ndarray:
    """The smoothed path from its point nearest the route's start to the one nearest its end,
    with the user's points as its ends (a smoothing spline overshoots and moves its ends)."""
    i = int(np.argmin(np.linalg.norm(rq - route_q[0], axis=1)))
    j = int(np.argmin(np.linalg.norm(rq - route_q[-1], axis=1)))
    if j - i < 3:
        return rq
    return np.concatenate([route_q[:1], rq[i + 1 : j], route_q[-1:]])


def _leaving(rq: np.ndarray, mask: np.ndarray, sp: np.ndarray) -> np.ndarray:
    """A branch's path from its last point inside the trunk's vessel on."""
    k = np.clip(np.rint(rq / sp).astype(int), 0, np.asarray(mask.shape) - 1)
    inside = mask[k[:, 0], k[:, 1], k[:, 2]]
    if not inside.any() or inside.all():
        return rq
    last = len(inside) - 1 - int(np.argmax(inside[::-1]))
    return rq[last:] if len(rq) - last >= 4 else rq


def _smoothed(mask: np.ndarray, sp: np.ndarray) -> np.ndarray:
    """The sections' voxels smoothed in 3D (the planes are grown one by one, their rims differ by
    a voxel from plane to plane): the mask blurred by a Gaussian of ``SMOOTH_MM``, cut at the
    level that keeps its volume (a plain half level would shrink a thin vessel)."""
    from scipy import ndimage as ndi

    n = int(mask.sum())
    if SMOOTH_MM <= 0 or n == 0:
        return mask
    g = ndi.gaussian_filter(mask.astype(np.float32), SMOOTH_MM / sp)
    flat = g.ravel()
    level = float(np.partition(flat, flat.size - n)[flat.size - n])
    return g >= max(level, 1e-3)


def _attached(mask: np.ndarray) -> np.ndarray:
    """The mask's largest 26-connected part (islands a section left beside the vessel go)."""
    from scipy import ndimage as ndi

    lab, n = ndi.label(mask, structure=np.ones((3, 3, 3)))
    if n <= 1:
        return mask
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    return lab == int(np.argmax(sizes))


def _rows(sec: grow.Sections, *, branch: int) -> list:
    """One report row per plane: area, equivalent diameter, min and max diameter through the
    section's centroid (36 directions), inscribed diameter; NaN where the plane holds nothing."""
    a = np.arange(-sec.half, sec.half + 1e-9, sec.h)
    ang = np.linspace(0.0, np.pi, 36, endpoint=False)
    d = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    rows = []
    for i, reg in enumerate(sec.regions):
        row = {"branch": branch, "s_mm": float(sec.s[i]), "clipped": bool(sec.clipped[i]), "status": "ok"}
        iu, iv = np.nonzero(reg)
        if iu.size == 0:
            rows.append(row | {"status": "outside"} | {k: float("nan") for k in ("area_mm2", "eq_diameter_mm", "min_diameter_mm",
                                                          "max_diameter_mm", "inscribed_diameter_mm")})
            continue
        xy = np.stack([a[iu], a[iv]], axis=1)
        xy = xy - xy.mean(axis=0)
        along, perp = xy @ d.T, xy @ np.stack([-d[:, 1], d[:, 0]], axis=1).T
        strip = np.abs(perp) <= 0.5 * sec.h
        span = np.array([(along[strip[:, j], j].max() - along[strip[:, j], j].min() + sec.h) if strip[:, j].any()
                         else np.nan for j in range(len(ang))])
        area = float(iu.size) * sec.h * sec.h
        rows.append(row | {"area_mm2": area, "eq_diameter_mm": 2.0 * float(np.sqrt(area / np.pi)),
                           "min_diameter_mm": float(np.nanmin(span)), "max_diameter_mm": float(np.nanmax(span)),
                           "inscribed_diameter_mm": float(sec.inscribed[i])})
    return rows


def segment_maxima(rows: list, *, every_mm: float = 50.0) -> list:
    """The largest max diameter in each ``every_mm`` of path, and where: {branch, from_mm, to_mm,
    max_diameter_mm, at_mm}."""
    out = []
    for b in sorted({r["branch"] for r in rows}):
        rs = [r for r in rows if r["branch"] == b and np.isfinite(r["max_diameter_mm"])]
        if not rs:
            continue
        s = np.array([r["s_mm"] for r in rs])
        for a0 in np.arange(0.0, float(s.max()) + 1e-9, every_mm):
            k = np.nonzero((s >= a0) & (s < a0 + every_mm))[0]
            if k.size:
                j = k[int(np.argmax([rs[i]["max_diameter_mm"] for i in k]))]
                out.append({"branch": b, "from_mm": float(a0), "to_mm": float(min(a0 + every_mm, s.max())),
                            "max_diameter_mm": rs[j]["max_diameter_mm"], "at_mm": rs[j]["s_mm"]})
    return out


def route_length(route: np.ndarray, spacing) -> float:
    """Length (mm) of a voxel route (n, 3)."""
    return float(arc_length(np.asarray(route) * np.asarray(spacing, dtype=float))[-1])
