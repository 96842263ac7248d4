"""The leak guard's width, found from the data: a sweep of neck widths and the jump where the organ ends.

Nobody knows in advance how wide the bridge from an organ into its neighbours is (a
renal vein is 10 mm, a partial-volume contact with bowel 3-6 mm), and a fixed width
fails both ways: too narrow cuts nothing, too wide cuts the organ itself. The in-range
region grown from the seed is therefore opened with balls of increasing radius r (the
"opening by reconstruction restricted to one radius" of :mod:`ctui.engine.segment.necks`),
and the volume V(r) of what stays joined to the seed is recorded. While r is smaller
than the bridges, V(r) is the organ plus its leaks; at the radius where the widest
bridge stops carrying the front, V(r) drops by a large factor (the leak goes); above
it, V(r) shrinks only slowly as the organ's own thin parts go, until r nears the
organ's half-thickness. The chosen radius is the one just after the last drop that is a
leak going: a drop by at least ``JUMP`` and by at least the square root of the largest drop
of the sweep, that removes at least ``LEAK_BALLS`` balls of the local depth (a rim or a cap
rounded off by the opening is smaller), among radii up to ``MAX_FRACTION`` of the local
depth (the half-thickness of the in-range region near the seed): the widest result before
the volume jumps, as airway-tree segmentation detects explosions. A seed near the organ's edge
sees a thinner organ than one at its middle, so the sweep then goes on to ``MAX_FRACTION`` of the
organ's depth (:func:`organ_depth`) when that keeps the organ's deep point, the seed's own and a
width the object at the seed holds (abdomen, spleen: a seed 14.7 mm deep reached its 18 mm neck,
Dice 0.82 -> 0.89; benchmarks/organs.py --seeds prints the Dice between seeds). The opened region at that
radius also bounds where propagation may go (:class:`Region`); :func:`cut_3d`/:func:`cut_2d`
cut at the chosen width by the same rule at full resolution.

Holes (noise pixels out of range inside an organ, the renal sinus, vessels in the
liver) are filled slice by slice before the opening, so they do not eat the organ from
inside; the result keeps holes up to ``HOLE_MM2`` a slice when asked (``fill_holes``).

Measured on ``../shared/data/totalseg_example/ct_abdomen_3mm.nii.gz`` (one seed at each
organ's deepest point, 3D): a fixed 5 mm neck with each organ's own 5-95th percentile range
gave Dice 0.08-0.64; this choice with no range given: kidney right 0.900, kidney left 0.939,
spleen 0.898, liver 0.896, volumes 0.96-1.10x the reference (benchmarks/organs.py prints the
full table, slice mode and the peers included).

The sweep runs on a box around the seed resampled to about ``SWEEP_MM`` voxels (the
chosen width is a physical size; coarse voxels find it as well and keep the cost of a
slice-mode kidney on a 300 x 512 x 512 series small). Shapes: masks (nz, ny, nx) bool;
spacing (dz, dy, dx) mm; seeds (n, 3) int z, y, x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from scipy import ndimage

from ctui.engine.segment.fill3d import fill3d_seeds
from ctui.engine.segment.necks import disc, fill_holes_2d, grow_back, morph_ball, seeded_components

JUMP = 1.1  # a drop of V(r) by more than this factor from one radius to the next is a leak going
MAX_FRACTION = 0.55  # radii up to this fraction of the local depth (larger ones cut the organ itself)
DEPTH_REACH_MM = 10.0  # the local depth is the deepest in-range point within this distance of the seed
SWEEP_MM = 2.0  # the sweep's voxel size (mm; the series' own when coarser)
BOX_MM = 150.0  # half-size of the sweep's box around the seed (mm)
MAX_RADII = 14
LEVEL = 0.8  # organ_depth joins through voxels deeper than this fraction of the local depth (0.55: a kidney seed
# joined a deeper neighbour through its contact and was cut)
LEAK_BALLS = 0.5  # the smallest piece a leak takes, in balls of the local depth
SPLIT_BALLS = 0.5  # the least core a leak leaves behind as it goes, in balls of the sweep's radius,
SPLIT_MM3 = 2000.0  # and in mm^3
HOLE_MM2 = 200.0  # largest hole filled (mm^2 a slice): noise and vessels, not the renal sinus (Dice best on the kidneys)


@dataclass
class NeckChoice:
    """What the automatic leak guard chose.

    ``width_mm``: the neck width (2 r) to cut at, 0 when no leak was found (nothing to cut);
    ``radii_mm``/``volumes``: the sweep (volume in sweep voxels joined to the seed at each
    radius; None where it was not needed: away from the radii where a thick part split off);
    ``splits``: the core voxels cut off at each radius; ``depth_mm``: the local half-thickness at
    the seed; ``reason``: one line.
    """

    width_mm: float
    depth_mm: float = 0.0
    radii_mm: list[float] = field(default_factory=list)
    volumes: list[int | None] = field(default_factory=list)
    reason: str = ""
    leak_ratio: float = 1.0  # V before / V after the chosen drop
    splits: list[int] = field(default_factory=list)  # core voxels cut off from the seed's core at each radius
    region: "Region | None" = None  # the opened region at the chosen width (coarse), for slice-mode propagation

    def to_dict(self) -> dict[str, Any]:
        return {"width_mm": round(self.width_mm, 3), "depth_mm": round(self.depth_mm, 3),
                "radii_mm": [round(r, 3) for r in self.radii_mm], "volumes": list(self.volumes),
                "reason": self.reason, "leak_ratio": round(self.leak_ratio, 3), "splits": list(self.splits)}


SWEEP_VOXELS = 1_000_000  # the sweep's grid is made coarser until the box holds at most this many voxels


def resample_factors(spacing: tuple[float, float, float], shape: tuple[int, ...] | None = None) -> tuple[int, int, int]:
    """Integer factors that bring the voxels to about SWEEP_MM (never finer than the series), coarser
    when the box would hold more than SWEEP_VOXELS voxels."""
    target = SWEEP_MM
    while True:
        f = tuple(max(1, int(round(target / s))) if s < target else 1 for s in spacing)
        if shape is None or np.prod([-(-n // k) for n, k in zip(shape, f)]) <= SWEEP_VOXELS or target > 8:
            return f  # type: ignore[return-value]  # f: tuple() of a generator: mypy sees any length, the length is fixed by construction
        target *= 1.25


def coarse(mask: np.ndarray, factors: tuple[int, int, int]) -> np.ndarray:
    """bool mask downsampled by integer ``factors`` (a coarse voxel is in when at least half its voxels are)."""
    fz, fy, fx = factors
    if (fz, fy, fx) == (1, 1, 1):
        return np.asarray(mask, bool)
    nz, ny, nx = mask.shape
    cz, cy, cx = -(-nz // fz), -(-ny // fy), -(-nx // fx)
    pad = np.zeros((cz * fz, cy * fy, cx * fx), np.uint8)
    pad[:nz, :ny, :nx] = mask
    s = pad.reshape(cz, fz, cy, fy, cx, fx).sum(axis=(1, 3, 5), dtype=np.int32)
    return s * 2 >= fz * fy * fx


def choose_width(candidate: np.ndarray, seeds_zyx: np.ndarray, spacing: tuple[float, float, float], *,
                 jump: float = JUMP, max_fraction: float = MAX_FRACTION) -> NeckChoice:
    """Choose the neck width for ``candidate`` (bool (nz, ny, nx), the in-range region joined to the seeds).

    The candidate is resampled to about ``SWEEP_MM`` voxels, its holes filled slice by
    slice, and opened by reconstruction with balls of increasing radius (distance map
    thresholds); see the module docstring for the rule. Returns :class:`NeckChoice`.
    """
    seeds = np.asarray(seeds_zyx, np.int64).reshape(-1, 3)
    f = resample_factors(spacing, candidate.shape)
    sp = tuple(float(s) * k for s, k in zip(spacing, f))
    if not candidate.any():
        return NeckChoice(0.0, reason="the seed's region is too small to sweep")
    # only the candidate's box is resampled (its start on the coarse grid, so the coarse voxels are the same)
    fb = _bbox3(candidate)
    start = [(b.start // k) * k for b, k in zip(fb, f)]
    off = np.array(start) // np.array(f)
    cand = fill_holes_2d(coarse(candidate[tuple(slice(a, b.stop) for a, b in zip(start, fb))], f))
    cs = seeds // np.array(f) - off
    cs = cs[np.all((cs >= 0) & (cs < np.array(cand.shape)), axis=1)]
    cs = cs[cand[tuple(cs.T)]] if len(cs) else cs
    if not len(cs):
        return NeckChoice(0.0, reason="the seed's region is too small to sweep")
    cand = fill3d_seeds(cand, cs, connectivity=8)
    box = _bbox3(cand)
    cand = np.ascontiguousarray(cand[box])  # the sweep works on the region's own box
    cs = cs - np.array([b.start for b in box])
    dt = ndimage.distance_transform_edt(cand, sampling=sp)
    depth = local_depth(dt, cs, sp)
    organ, top, near = organ_depth(dt, cs, sp)
    geo = (cand, box, off, f, sp, candidate.shape)
    radii = _radii(dt, cand, depth * max_fraction, min(sp))
    own = radii[-1]  # the widest radius the seed's own sweep takes
    if organ > depth:  # the seed's own sweep, then wider radii up to the organ's (the seed's sampled as before)
        radii += [r for r in _radii(dt, cand, organ * max_fraction, min(sp))[1:] if r > radii[-1]]
    choice, kept = _pick(dt, cs, depth, radii, jump, geo)
    if organ > depth and choice.width_mm > 2.0 * own + 1e-6 and not (
            kept[top] and kept[near] and choice.width_mm <= 2.0 * float(dt[tuple(cs[0])])):
        # the organ's depth came from a neighbour the sweep then cut off, or the cut left the seed's own deep part,
        # or the width is wider than the object at the seed, whose own part a cut at full resolution would lose
        # (the right kidney's seed 6.7 mm deep, a 19 mm neck: 0.08x): the seed's own sweep, as before
        choice, kept = _pick(dt, cs, depth, radii[:radii.index(own) + 1], jump, geo)
    return choice


def _pick(dt: np.ndarray, cs: np.ndarray, depth: float, radii: list[float], jump: float,
          geo: tuple[Any, ...]) -> tuple[NeckChoice, np.ndarray]:
    """The sweep over ``radii`` (mm) on the region ``geo[0]`` (its distance map ``dt``, seeds ``cs``, local depth
    ``depth``; ``geo``: region, box, offset, factors, spacing, candidate's shape): the choice, and the coarse
    region it keeps."""
    cand, box, off, f, sp, shape = geo
    used, split = _sweep_cores(cand, dt, cs, radii, sp)
    if len(used) < 2:
        return NeckChoice(0.0, depth_mm=depth, reason="the region is thinner than the narrowest width swept"), cand
    # a leak going takes a piece of at least LEAK_BALLS balls of the local depth (a rim or a cap rounded off
    # by the opening is smaller), drops the volume by at least ``bar``, and leaves a thick part behind: the
    # seed's core (voxels deeper than r) loses a part that is still core (a neighbour beyond the neck), of
    # at least half a ball of radius r and SPLIT_MM3. Shaving a pole or a rim only thins the core; an
    # organ's own waist splits off a small piece of core (contrast kidney, nephrographic, at 12 mm: 0.8 mL).
    # The abdomen's leaks leave 3-900 mL (the liver's last one on a 1 x 1 x 3 mm grid, at 18 mm: 3.2 mL,
    # 0.97 balls; with noise 4 mL, 1.2 balls).
    vox = float(np.prod(sp))
    ball = 4.0 / 3.0 * math.pi * depth ** 3 / vox
    splits_at = [i for i in range(1, len(used))
                 if split[i] * vox >= max(SPLIT_BALLS * 4.0 / 3.0 * math.pi * used[i] ** 3, SPLIT_MM3)]
    # the opened volumes are needed only around those radii (a reconstruction each: most of the sweep's cost)
    vols: list[int | None] = [None] * len(used)
    vols[0] = int(np.count_nonzero(cand))  # the unopened region: on a noisy series the first opening cuts bridges
    opened: dict[int, np.ndarray] = {}
    for i in sorted({k for j in splits_at for k in (j - 1, j)} - {0}):
        got = _opened(cand, dt, cs, used[i], sp)
        opened[i] = got
        vols[i] = int(np.count_nonzero(got))
    drops = {i: vols[i - 1] / max(vols[i], 1) for i in splits_at}
    big = [i for i in splits_at if vols[i - 1] - vols[i] >= LEAK_BALLS * ball]
    bar = max(jump, math.sqrt(max([drops[i] for i in big], default=1.0)))
    j, ratio = 0, 1.0
    for i in big:
        if drops[i] >= bar:
            j, ratio = i, drops[i]
    if j == 0:
        # no neck to cut, but slice mode still goes no further than the region joined to the seed in 3D: its
        # seeding from the previous slice grown by a few pixels crossed gaps that the 3D fill does not
        # (contrast kidney, 120:400: 296 mL through the left renal vein's gap, 97.5 mL in 3D)
        return NeckChoice(0.0, depth_mm=depth, radii_mm=used, volumes=vols, splits=split,
                          region=_region(cand, box, off, f, sp, shape),
                          reason="no leak: the volume does not drop as the neck width grows"), cand
    r = used[j]
    return NeckChoice(2.0 * r, depth_mm=depth, radii_mm=used, volumes=vols, leak_ratio=ratio, splits=split,
                      region=_region(opened[j], box, off, f, sp, shape),
                      reason=f"the volume drops {ratio:.1f}x between necks of {2 * used[j - 1]:.1f} and {2 * r:.1f} mm"), opened[j]


def _sweep_cores(cand: np.ndarray, dt: np.ndarray, seeds: np.ndarray, radii: list[float],
                 sp: tuple[float, float, float]) -> tuple[list[float], list[int]]:
    """The radii the seeds' core reaches (with 0: the unopened region first) and, at each, the core voxels
    (distance > r) cut off from the seeds' core since the previous radius (0 at the first two)."""
    used, split = [0.0], [0]
    prev = None
    for r in radii:
        core = dt > r
        hit = _core_seeds(core, dt, seeds, r, sp)
        if not len(hit):
            break
        kept = fill3d_seeds(core, hit, connectivity=8)
        split.append(0 if prev is None else int(np.count_nonzero(prev & core)) - int(np.count_nonzero(kept)))
        prev = kept
        used.append(r)
    return used, split


def _region(kept: np.ndarray, box: tuple[slice, ...], off: np.ndarray, f: tuple[int, int, int],
            sp: tuple[float, ...], shape: tuple[int, ...]) -> "Region":
    """The sweep's ``kept`` (coarse, on the region's box) as a :class:`Region` over the candidate's grid."""
    full = np.zeros(tuple(-(-n // k) for n, k in zip(shape, f)), bool)
    full[tuple(slice(b.start + o, b.stop + o) for b, o in zip(box, off))] = kept
    # on a coarser grid than the series the region's edge is uncertain by one coarse voxel: grow it by
    # that much; on the series' own grid it is exact (growing it there added a one-voxel rim of
    # partial-volume voxels: right kidney slice mode volume 1.23x -> 1.12x the reference)
    return Region(factors=f, mask=morph_ball(full, max(sp), sp, erode=False) if max(f) > 1 else full)


def _bbox3(m: np.ndarray) -> tuple[slice, slice, slice]:
    zs = np.flatnonzero(m.any(axis=(1, 2)))
    sub = m[zs[0]:zs[-1] + 1]
    rows = sub.any(axis=2)  # (z, y): one pass over the occupied slices gives rows and columns
    ys = np.flatnonzero(rows.any(axis=0))
    xs = np.flatnonzero(sub[:, ys[0]:ys[-1] + 1].any(axis=(0, 1)))
    return slice(zs[0], zs[-1] + 1), slice(ys[0], ys[-1] + 1), slice(xs[0], xs[-1] + 1)


@dataclass
class Region:
    """Where a slice-by-slice propagation may go: the sweep's opened region at the chosen width, grown by one
    coarse voxel (``mask`` bool on the coarse grid of integer ``factors``, ``origin`` (z, y, x) of its box)."""

    factors: tuple[int, int, int]
    mask: np.ndarray
    origin: tuple[int, int, int] = (0, 0, 0)

    def crop(self, z: int, y0: int, y1: int, x0: int, x1: int) -> np.ndarray:
        """bool (y1 - y0, x1 - x0): the allowed pixels of slice ``z`` in that crop. Beyond the sweep's box
        along the slices everything is allowed, so an organ longer than the box (a tube of 420 mm from a
        seed in its middle) goes on instead of ending at it; beside the box in-plane nothing is (the
        liver's region reaches the box's side through the stomach: allowing beyond it, Dice 0.90 -> 0.84)."""
        fz, fy, fx = self.factors
        cz = (z - self.origin[0]) // fz
        if not 0 <= cz < self.mask.shape[0]:
            return np.ones((y1 - y0, x1 - x0), bool)
        out = np.zeros((y1 - y0, x1 - x0), bool)
        oy, ox = self.origin[1], self.origin[2]
        ya, yb = max(y0, oy), min(y1, oy + self.mask.shape[1] * fy)  # the crop's rows and columns in the box
        xa, xb = max(x0, ox), min(x1, ox + self.mask.shape[2] * fx)
        if ya >= yb or xa >= xb:
            return out
        cy, cx = (ya - oy) // fy, (xa - ox) // fx
        sub = self.mask[cz, cy:(yb - 1 - oy) // fy + 1, cx:(xb - 1 - ox) // fx + 1]
        if fy > 1 or fx > 1:  # slices and repeats, not fancy indexing: 16 -> 2 ms a kidney (300 slices)
            sub = np.repeat(np.repeat(sub, fy, axis=0), fx, axis=1)
        ry, rx = ya - oy - cy * fy, xa - ox - cx * fx
        out[ya - y0:yb - y0, xa - x0:xb - x0] = sub[ry:ry + yb - ya, rx:rx + xb - xa]
        return out


def local_depth(dt: np.ndarray, seeds: np.ndarray, sp: tuple[float, float, float]) -> float:
    reach = [max(1, int(math.ceil(DEPTH_REACH_MM / s))) for s in sp]
    best = 0.0
    for z, y, x in seeds[:64]:
        sub = dt[max(z - reach[0], 0):z + reach[0] + 1, max(y - reach[1], 0):y + reach[1] + 1,
                 max(x - reach[2], 0):x + reach[2] + 1]
        best = max(best, float(sub.max()))
    return best


def organ_depth(dt: np.ndarray, seeds: np.ndarray,
                sp: tuple[float, float, float]) -> tuple[float, tuple[int, int, int], tuple[int, int, int]]:
    """The depth (mm) of the organ a seed lies in, the same from any seed in it: from the deepest point within
    ``DEPTH_REACH_MM`` of the seeds (depth d, :func:`local_depth`), the deepest point of ``dt`` joined to it
    through voxels at least d deep. A seed near the organ's edge sees only its local half-thickness; the
    climb reaches the organ's middle without crossing a neck narrower than d (a neighbour behind a bridge
    the sweep can cut, which is at most ``MAX_FRACTION`` of d wide)."""
    reach = [max(1, int(math.ceil(DEPTH_REACH_MM / s))) for s in sp]
    tops = []
    for z, y, x in seeds[:64]:
        box = (slice(max(z - reach[0], 0), z + reach[0] + 1), slice(max(y - reach[1], 0), y + reach[1] + 1),
               slice(max(x - reach[2], 0), x + reach[2] + 1))
        sub = dt[box]
        k = np.unravel_index(int(np.argmax(sub)), sub.shape)
        tops.append((float(sub[k]), tuple(int(i) + b.start for i, b in zip(k, box))))
    d, top = max(tops)
    if d <= 0:
        return 0.0, top, top
    joined = fill3d_seeds(dt > LEVEL * d, np.array([top]), connectivity=8)
    deep = np.where(joined, dt, 0.0)
    k = np.unravel_index(int(np.argmax(deep)), deep.shape)
    return float(deep[k]), tuple(int(i) for i in k), top  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


def _radii(dt: np.ndarray, cand: np.ndarray, rmax: float, step: float) -> list[float]:
    """Radii to sweep: the distinct distance values below ``rmax`` (each opens a different ball), thinned
    to at most MAX_RADII, starting one voxel in."""
    vals = np.unique(np.round(dt[cand], 3))
    vals = vals[(vals >= step * 0.999) & (vals <= rmax)]
    if len(vals) > 1:
        vals = vals[:-1]
    if len(vals) > MAX_RADII:  # every small radius (where leaks go), the larger ones thinned
        head = vals[:MAX_RADII // 2]
        tail = vals[MAX_RADII // 2:]
        vals = np.concatenate([head, tail[np.unique(np.linspace(0, len(tail) - 1, MAX_RADII - len(head)).round().astype(int))]])
    return [0.5 * step] + [float(v) for v in vals]  # the first keeps every voxel: the region before any cut


def _opened(cand: np.ndarray, dt: np.ndarray, seeds: np.ndarray, r: float,
            sp: tuple[float, float, float]) -> np.ndarray:
    """Voxels of ``cand`` within r of the part of {dt > r} that the seeds reach (r at most a radius that
    :func:`_sweep_cores` found the seeds' core at)."""
    core = dt > r
    hit = _core_seeds(core, dt, seeds, r, sp)
    kept = fill3d_seeds(core, hit, connectivity=8)
    box = _grown_box(kept, r, sp)  # the reconstruction stays within r of the kept core: work on its box
    back = morph_ball(np.ascontiguousarray(kept[box]), r, sp, erode=False)
    back &= cand[box]
    got = np.zeros(cand.shape, bool)
    got[box] = fill3d_seeds(back, hit - np.array([b.start for b in box]), connectivity=8)
    return got


def _grown_box(m: np.ndarray, r: float, sp: tuple[float, float, float]) -> tuple[slice, slice, slice]:
    b = _bbox3(m)
    k = [int(math.ceil(r / s)) + 1 for s in sp]
    return tuple(slice(max(x.start - kk, 0), min(x.stop + kk, n)) for x, kk, n in zip(b, k, m.shape))  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


def _core_seeds(core: np.ndarray, dt: np.ndarray, seeds: np.ndarray, r: float,
                sp: tuple[float, float, float]) -> np.ndarray:
    """Seeds in the core, or else the core voxel nearest to the first seed (within r plus one voxel)."""
    inside = seeds[core[tuple(seeds.T)]]
    if len(inside):
        return inside
    c = [int(v) for v in seeds[0]]
    k = [1 + int(math.ceil(r / s)) for s in sp]
    box = tuple(slice(max(c[i] - k[i], 0), c[i] + k[i] + 1) for i in range(3))
    pts = np.argwhere(core[box])
    if not len(pts):
        return np.zeros((0, 3), np.int64)
    pts += np.array([b.start for b in box])
    d2 = (((pts - np.array(c)) * np.array(sp)) ** 2).sum(axis=1)
    i = int(np.argmin(d2))
    if d2[i] > (r + max(sp)) ** 2:
        return np.zeros((0, 3), np.int64)
    return pts[i:i + 1]


def sweep_box(shape: tuple[int, int, int], seed_zyx: tuple[int, int, int],
              spacing: tuple[float, float, float]) -> tuple[slice, slice, slice]:
    """The box (slices z, y, x) of half-size ``BOX_MM`` around the seed, clipped to ``shape``."""
    out = []
    for c, n, s in zip(seed_zyx, shape, spacing):
        h = max(2, int(math.ceil(BOX_MM / float(s))))
        out.append(slice(max(int(c) - h, 0), min(int(c) + h + 1, int(n))))
    return tuple(out)  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


def cut_3d(candidate: np.ndarray, seeds_zyx: np.ndarray, *, width_mm: float, spacing: tuple[float, float, float],
           fill_holes: bool = False, connectivity: int = 8) -> tuple[np.ndarray, str]:
    """The part of ``candidate`` (bool (nz, ny, nx)) joined to the seeds through necks at least ``width_mm`` wide,
    by the sweep's rule: the seeds' component of the erosion by a ball of radius width/2 (holes
    filled slice by slice), grown back by the radius inside the filled candidate. ``fill_holes``:
    whether the result keeps the filled holes. Returns (mask, status "ok" | "cut" | "thin" | "lost")."""
    cand = np.asarray(candidate, bool)
    seeds = np.asarray(seeds_zyx, np.int64).reshape(-1, 3)
    if width_mm <= 0 or not cand.any():
        return (fill_holes_2d(cand) if fill_holes else cand.copy()), "ok"
    r = width_mm / 2.0
    box = _bbox3(cand)
    raw = np.ascontiguousarray(cand[box])
    filled = fill_holes_2d(raw)
    org = np.array([b.start for b in box])
    sub_seeds = seeds - org
    sub_seeds = sub_seeds[np.all((sub_seeds >= 0) & (sub_seeds < np.array(raw.shape)), axis=1)]
    core = morph_ball(filled, r, spacing, erode=True)
    hit = _core_seeds(core, core.astype(np.float32), sub_seeds, r, spacing) if len(sub_seeds) else sub_seeds
    out = np.zeros(cand.shape, bool)
    if not len(hit):
        out[box] = filled if fill_holes else raw
        return out, "thin"
    kept = fill3d_seeds(core, hit, connectivity=connectivity)
    del core
    got = grow_back(kept, hit, filled, r, spacing, connectivity=connectivity)
    status = "cut" if np.count_nonzero(got & raw) < np.count_nonzero(raw) else "ok"
    got &= raw if not fill_holes else _small_holes(raw, spacing[1:])
    out[box] = got
    return out, status


def _small_holes(raw: np.ndarray, spacing_yx: tuple[float, ...]) -> np.ndarray:
    """``raw`` with its holes up to ``HOLE_MM2`` per slice filled (noise, vessels), larger ones (the renal
    sinus) left open: bool, same shape (2D or 3D)."""
    if raw.ndim == 3:
        return np.stack([_small_holes(m, spacing_yx) for m in raw]) if len(raw) else raw.copy()
    holes = fill_holes_2d(raw) & ~raw
    if not holes.any():
        return raw.copy()
    n, lab, stats, _c = cv2.connectedComponentsWithStats(holes.view(np.uint8), connectivity=4)
    small = stats[:, cv2.CC_STAT_AREA] * float(spacing_yx[0]) * float(spacing_yx[1]) <= HOLE_MM2
    small[0] = False
    return raw | small[lab]


def cut_2d(candidate: np.ndarray, reference: np.ndarray, *, width_mm: float, spacing_yx: tuple[float, float],
           fill_holes: bool = False, connectivity: int = 8) -> tuple[np.ndarray, str]:
    """:func:`cut_3d` on one slice: the part of ``candidate`` (bool (ny, nx)) joined to ``reference`` (the
    previous slice's object) through necks at least ``width_mm`` wide. Returns (mask, status)."""
    raw = np.asarray(candidate, bool)
    if width_mm <= 0 or not raw.any():
        return (fill_holes_2d(raw) if fill_holes else raw.copy()), "ok"
    r = width_mm / 2.0
    filled = fill_holes_2d(raw)
    kern = disc(r / spacing_yx[0], r / spacing_yx[1])
    core = cv2.erode(filled.view(np.uint8), kern, borderType=cv2.BORDER_REPLICATE)
    ref = np.asarray(reference, bool)
    kept = seeded_components(core, ref & (core > 0), connectivity=connectivity)
    if not kept.any():
        near = cv2.dilate(ref.view(np.uint8), kern).astype(bool)
        kept = seeded_components(core, near & (core > 0), connectivity=connectivity)
        if not kept.any():
            return (fill_holes_2d(raw) if fill_holes else raw.copy()), ("thin" if not core.any() else "lost")
    back = (cv2.dilate(kept.view(np.uint8), kern) & filled.view(np.uint8)).view(bool)
    got = seeded_components(back, kept, connectivity=connectivity)
    status = "cut" if np.count_nonzero(got & raw) < np.count_nonzero(raw) else "ok"
    return got & (_small_holes(raw, spacing_yx) if fill_holes else raw), status


def cut_faces(removed: np.ndarray, kept: np.ndarray, *, at_most: int = 4) -> list[tuple[float, float, int]]:
    """Where a cut went through, on one slice: the centroids (y, x) and pixel counts of the pieces of
    ``removed`` (bool (ny, nx)) that touch ``kept`` (bool (ny, nx)), largest first."""
    if not removed.any() or not np.any(kept):
        return []
    touch = removed & cv2.dilate(np.asarray(kept, np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    if not touch.any():
        return []
    n, lab, stats, cent = cv2.connectedComponentsWithStats(touch.view(np.uint8), connectivity=8)
    order = np.argsort(-stats[1:, cv2.CC_STAT_AREA])[:at_most] + 1
    return [(round(float(cent[i][1]), 1), round(float(cent[i][0]), 1), int(stats[i, cv2.CC_STAT_AREA])) for i in order]
