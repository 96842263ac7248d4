"""What one seed tells before anything is filled: the value range of its neighbourhood and the leak guard's width.

* :func:`seed_range`: the range from the seed's neighbourhood (a ball of ``RANGE_BALL_MM``,
  at least two voxels across): median +- ``RANGE_K`` robust standard deviations, the
  deviation being the larger of the ball's MAD (x 1.4826) and the image noise (the MAD of
  neighbour differences / sqrt 2), so one flat patch does not give a range narrower than
  the noise. With k = 2 this spans about the 2.5-97.5th percentiles of a uniform organ
  (InVesalius' "confidence" growing uses the same idea). A small histogram of the ball
  goes with it, for the TUI.
* :func:`auto_width`: the in-range region joined to the seed inside a box around it, and
  :func:`ctui.engine.segment.autoneck.choose_width` on it.
* :func:`seed_depth`: the half-thickness of the in-range region at the seed (what the sweep
  calls the local depth), for the size check when the width is given.
* :func:`seed_voxels`: the seed and its in-range neighbours (one voxel around it): a seed
  on a noise voxel still starts the object.
* :func:`denoised`: on a noisy series a tissue whose values lie within the noise of a bound
  of the range (the liver at ~80 HU beside a range from 120 HU, noise ~36 HU) shows as in-range
  specks, and specks bridge the organ into it one voxel at a time (at a 13% density they
  percolate in 3D). When more than ``SPECKLE`` of the in-range pixels within ``SPECKLE_MM``
  of the seed on its slice are specks of under 4 pixels, the fill runs on a 3 x 3 median of
  each slice. Measured on the contrast CT of ``totalseg_example`` (1.5 mm), seeds in the right
  kidney's upper pole with ``--range 120:400``: specks 0.03-0.07 of the in-range pixels, 653 mL
  over all 164 slices (slice mode) without the median, 8.4 mL over slices 0-9 (the pole that
  field of view holds) with it. The unenhanced abdomen's organs (benchmarks/organs.py seeds,
  their 5-95th percentile or automatic ranges): specks 0-0.01, filled unchanged. A range
  narrower than +- ``RANGE_K`` noise sd (the right kidney's 5-95th percentile) never takes the
  median: its specks are its own tissue's noise (see ``NARROW``).

Values are in the pipeline's domain (HU by default). Seeds are (x, y, z) = (column, row,
slice), as on the command line; internal arrays are (z, y, x).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from scipy import ndimage

from ctui.engine.core.limits import check_allocation
from ctui.engine.segment.autorange import OUTLIER, plateau_range
from ctui.engine.segment.autoneck import NeckChoice, choose_width, coarse, local_depth, resample_factors, sweep_box
from ctui.engine.segment.fill3d import fill3d_seeds
from ctui.engine.segment.necks import fill_holes_2d
from ctui.engine.segment.pipeline import Pipeline, Step
from ctui.engine.segment.selection import in_range

RANGE_BALL_MM = 10.0
RANGE_K = 2.0
# a neighbourhood whose spread is more than this many times the image noise mixes tissues (real CT: the unenhanced
# kidneys, spleen and liver 1.0-1.2x; a contrast kidney's cortex and medulla 1.8x, the aorta beside its thrombus
# 3.8x): its median +- 2 sd spans them, so the range is widened from the seed's own value instead (autorange)
MIXED = 1.5
HIST_BINS = 16
SPECKLE = 0.025  # share of the in-range pixels near the seed in specks above which the fill runs on a median
SPECKLE_MM = 20.0
# ... unless the range spans less than this share of 2 x RANGE_K noise sd (the automatic range's least width): the
# unenhanced right kidney's 5-95th percentile range, -21:36 HU, is 3.0-3.9 noise sd wide at its random seeds; four of
# ten saw specks on their slice (0.03-0.07), took the median and leaked into the liver (Dice 0.43-0.79, 1.4-3.5x;
# 0.88-0.89 without it). The contrast CT's 120:400 is 7.3 sd wide, a brainstem's automatic range 4.0.
NARROW = 0.99


@dataclass
class RangeChoice:
    """A range suggested by the seed's neighbourhood: ``low``..``high`` (inclusive), the median and robust sd,
    and a histogram (``hist`` counts over ``edges``, HIST_BINS bins over median +- 4 sd)."""

    low: float
    high: float
    median: float
    sd: float
    voxels: int
    hist: list[int] = field(default_factory=list)
    edges: list[float] = field(default_factory=list)
    noise: float = 0.0  # the image noise sd near the seed (neighbour differences), same units
    rule: str = "ball"  # "plateau": widened from the seed's value until the joined volume jumps; "ball": median +- k sd
    why: str = ""  # one line: how the range was chosen
    steps: Any = None  # autorange.RangeSteps when rule == "plateau"

    def to_dict(self) -> dict[str, Any]:
        return {"low": round(self.low, 3), "high": round(self.high, 3), "median": round(self.median, 3),
                "sd": round(self.sd, 3), "noise": round(self.noise, 3), "voxels": self.voxels, "hist": list(self.hist),
                "edges": [round(e, 3) for e in self.edges], "rule": self.rule, "why": self.why,
                "steps": None if self.steps is None else self.steps.to_dict()}


def _ball_values(volume: Any, pipe: Any, seed: tuple[int, int, int]) -> tuple[np.ndarray, float]:
    """The pipeline's values in a ball around the seed (x, y, z), and the noise sd from neighbour differences."""
    x, y, z = seed
    nz, ny, nx = volume.data.shape
    sp = tuple(float(s) for s in volume.spacing)
    r = [max(1, int(math.ceil(RANGE_BALL_MM / s))) for s in sp]
    r = [max(v, 2) if s <= RANGE_BALL_MM / 2 else v for v, s in zip(r, sp)]
    z0, z1 = max(z - r[0], 0), min(z + r[0] + 1, nz)
    y0, y1 = max(y - r[1], 0), min(y + r[1] + 1, ny)
    x0, x1 = max(x - r[2], 0), min(x + r[2] + 1, nx)
    window = pipe.window_for(volume)
    sub = np.stack([np.asarray(pipe.final_region(volume, zz, y0, y1, x0, x1, window=window), np.float32)
                    for zz in range(z0, z1)])
    zz, yy, xx = np.mgrid[z0:z1, y0:y1, x0:x1]
    ball = ((zz - z) * sp[0]) ** 2 + ((yy - y) * sp[1]) ** 2 + ((xx - x) * sp[2]) ** 2 <= max(RANGE_BALL_MM, max(sp)) ** 2
    diffs = np.diff(sub, axis=2).ravel() if sub.shape[2] > 1 else np.zeros(1, np.float32)
    noise = 1.4826 * float(np.median(np.abs(diffs - np.median(diffs)))) / math.sqrt(2.0)
    return sub[ball], min(noise, _slice_noise(volume, pipe, seed, window))


NOISE_MM = 40.0  # the noise is also measured on the seed's slice this far around it ...


def _slice_noise(volume: Any, pipe: Any, seed: tuple[int, int, int], window: Any) -> float:
    """The noise sd from neighbour differences (rows and columns) on the seed's slice within NOISE_MM: on a coarse
    grid (3.9 mm pixels of a head-and-neck CT) the ball's few differences are mostly edges (143 HU for a spinal
    cord's ball; 20-40 HU here)."""
    x, y, z = seed
    _dz, dy, dx = (float(v) for v in volume.spacing)
    ny, nx = volume.data.shape[1:]
    ry, rx = max(2, int(NOISE_MM / dy)), max(2, int(NOISE_MM / dx))
    img = np.asarray(pipe.final_region(volume, z, max(y - ry, 0), min(y + ry + 1, ny), max(x - rx, 0),
                                       min(x + rx + 1, nx), window=window), np.float32)
    d = np.concatenate([np.diff(img, axis=1).ravel(), np.diff(img, axis=0).ravel()])
    if not d.size:
        return float("inf")
    return 1.4826 * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(2.0)


def seed_range(volume: Any, pipe: Any, seed: tuple[int, int, int], *, k: float = RANGE_K,
               rule: str = "plateau") -> RangeChoice:
    """The automatic range for a seed (x, y, z): ``rule="plateau"`` (default) widened from the seed's own value
    until the joined volume jumps (:mod:`ctui.engine.segment.autorange`); ``"ball"`` the neighbourhood's
    median +- k sd (see the module docstring). Holds the seed's own value unless it is an outlier
    (further than ``autorange.OUTLIER`` noise sd from its 3 x 3 x 3 median: the fill then starts beside it)."""
    vals, noise = _ball_values(volume, pipe, seed)
    med = float(np.median(vals))
    mad = 1.4826 * float(np.median(np.abs(vals - med)))
    sd = max(mad, noise, 1e-6)
    lo, hi = med - k * sd, med + k * sd
    x, y, z = seed
    window = pipe.window_for(volume)
    own = float(pipe.final_region(volume, z, y, y + 1, x, x + 1, window=window)[0, 0])
    steps, why, centre = None, f"the seed's {RANGE_BALL_MM:g} mm neighbourhood: median {med:.0f} +- {k:g} x {sd:.0f}", own
    if rule == "plateau":  # the ball's range, but never past a value where a neighbour joins
        centre = _own_value(volume, pipe, seed, window)
        _a, _b, steps = plateau_range(volume, pipe, seed, max(noise, 1e-6), centre, own)
        cut = []
        if "low" in steps.stops and steps.stops["low"] > lo:
            cut.append(f"low {lo:.0f} -> {steps.stops['low']:.0f} ({steps.closed['low']})")
            lo = steps.stops["low"]
        if "high" in steps.stops and steps.stops["high"] < hi:
            cut.append(f"high {hi:.0f} -> {steps.stops['high']:.0f} ({steps.closed['high']})")
            hi = steps.stops["high"]
        why += "; " + ("narrowed where a neighbour joins the seed's region: " + ", ".join(cut) if cut
                       else "no neighbour joins within it")
    if rule != "plateau" or abs(own - centre) <= OUTLIER * max(noise, 1e-6):
        lo, hi = min(lo, own), max(hi, own)  # an outlier seed voxel is left out: the fill starts beside it
    edges = np.linspace(min(med - 4 * sd, lo), max(med + 4 * sd, hi), HIST_BINS + 1)
    hist = np.histogram(np.clip(vals, edges[0], edges[-1]), bins=edges)[0]
    return RangeChoice(low=lo, high=hi, median=med, sd=sd, voxels=int(vals.size), hist=[int(h) for h in hist],
                       edges=[float(e) for e in edges], noise=float(noise), rule=rule, why=why, steps=steps)


def _own_value(volume: Any, pipe: Any, seed: tuple[int, int, int], window: Any) -> float:
    """The median of the seed's 3 x 3 x 3 neighbourhood: its own tissue, not the 10 mm ball's mix."""
    x, y, z = seed
    nz, ny, nx = volume.data.shape
    y0, y1, x0, x1 = max(y - 1, 0), min(y + 2, ny), max(x - 1, 0), min(x + 2, nx)
    vals = [np.asarray(pipe.final_region(volume, zz, y0, y1, x0, x1, window=window), np.float32)
            for zz in range(max(z - 1, 0), min(z + 2, nz))]
    return float(np.median(np.concatenate([v.ravel() for v in vals])))


def denoised(volume: Any, pipe: Any, seed: tuple[int, int, int], low: float, high: float) -> Any | None:
    """A copy of ``pipe`` with a 3 x 3 median of each slice when the range speckles around the seed (x, y, z):
    more than SPECKLE of the in-range pixels within SPECKLE_MM on the seed's slice are specks of under 4
    pixels (noise straddling a bound); None otherwise, always when the pipeline has filters of its own
    (the user's filters decide), and when the range is narrower than the automatic one's least (+- RANGE_K
    noise sd): its specks are then the seed's own tissue's noise, and the range was read from unfiltered values."""
    if pipe.active_steps() or high - low < NARROW * 2 * RANGE_K * _ball_values(volume, pipe, seed)[1]:
        return None
    x, y, z = seed
    _dz, dy, dx = (float(v) for v in volume.spacing)
    ry, rx = max(2, int(SPECKLE_MM / dy)), max(2, int(SPECKLE_MM / dx))
    y0, x0 = max(y - ry, 0), max(x - rx, 0)
    img = pipe.final_region(volume, z, y0, y + ry + 1, x0, x + rx + 1, window=pipe.window_for(volume))
    inr = in_range(img, low, high)
    n, _lab, stats, _c = cv2.connectedComponentsWithStats(inr.view(np.uint8), connectivity=8)
    specks = int(stats[1:, cv2.CC_STAT_AREA][stats[1:, cv2.CC_STAT_AREA] < 4].sum()) if n > 1 else 0
    if specks <= SPECKLE * max(int(np.count_nonzero(inr)), 1):
        return None
    return Pipeline([Step(name="median", params={"size": 3})], domain=pipe.domain, window=pipe.window)


def seed_voxels(inrange: np.ndarray, seed_zyx: tuple[int, int, int]) -> np.ndarray:
    """int (n, 3) z, y, x: the seed and its in-range 26-neighbours in ``inrange`` (bool (nz, ny, nx))."""
    z, y, x = seed_zyx
    nz, ny, nx = inrange.shape
    box = (slice(max(z - 1, 0), z + 2), slice(max(y - 1, 0), y + 2), slice(max(x - 1, 0), x + 2))
    pts = np.argwhere(inrange[box]) + np.array([b.start for b in box])
    seed = np.array([[z, y, x]])
    return np.unique(np.concatenate([seed, pts]), axis=0) if len(pts) else seed


def box_inrange(volume: Any, pipe: Any, low: float, high: float, box: tuple[slice, slice, slice], *,
                labels: np.ndarray | None = None, object_id: int = 0) -> np.ndarray:
    """bool (box shape): the pipeline's final view in [low, high] inside ``box``; other objects' voxels False."""
    shape = tuple(b.stop - b.start for b in box)
    check_allocation(int(np.prod(shape)), what="the in-range box around the seed")
    out = np.zeros(shape, bool)
    window = pipe.window_for(volume)
    for k, z in enumerate(range(box[0].start, box[0].stop)):
        img = pipe.final_region(volume, z, box[1].start, box[1].stop, box[2].start, box[2].stop, window=window)
        out[k] = in_range(img, low, high).view(bool)
        if labels is not None:
            lab = labels[z, box[1], box[2]]
            if lab.any():
                out[k] &= (lab == 0) | (lab == object_id)
    return out


def auto_width(volume: Any, pipe: Any, seed: tuple[int, int, int], low: float, high: float, *,
               labels: np.ndarray | None = None, object_id: int = 0,
               limit: tuple[slice, slice, slice] | None = None) -> NeckChoice:
    """The leak guard's width for a seed (x, y, z) and range: the sweep on a box of about 2 x 90 mm around it
    (clipped to ``limit``, a (z, y, x) box of slices, when given)."""
    x, y, z = seed
    sp = tuple(float(s) for s in volume.spacing)
    box = sweep_box(tuple(volume.data.shape), (z, y, x), sp)  # type: ignore[arg-type]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
    if limit is not None:
        box = tuple(slice(max(b.start, lb.start), min(b.stop, lb.stop)) for b, lb in zip(box, limit))  # type: ignore[assignment]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
    inr = box_inrange(volume, pipe, low, high, box, labels=labels, object_id=object_id)
    org = np.array([b.start for b in box])
    local = (z - org[0], y - org[1], x - org[2])
    if not inr[local]:
        return NeckChoice(0.0, reason="the seed is outside the range")
    seeds = seed_voxels(inr, local)
    cand = fill3d_seeds(inr, seeds, connectivity=8)
    del inr
    choice = choose_width(cand, seeds, sp)  # type: ignore[arg-type]  # sp: tuple() of a generator: mypy sees any length, the length is fixed by construction
    if choice.region is not None:
        choice.region.origin = tuple(int(v) for v in org)  # type: ignore[assignment]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
    return choice


DEPTH_BOX_MM = 45.0  # seed_depth looks this far around the seed (deeper organs are reported as this deep)


def seed_depth(volume: Any, pipe: Any, seed: tuple[int, int, int], low: float, high: float, *,
               labels: np.ndarray | None = None, object_id: int = 0) -> float:
    """The local depth (mm) at a seed (x, y, z): the largest distance to the range's edge within
    ``autoneck.DEPTH_REACH_MM`` of the seed (``autoneck.local_depth``), holes filled slice by slice, on a
    box of ``DEPTH_BOX_MM`` around it; 0 when the seed is outside the range. The sweep measures the same on
    its coarse grid; this is for a width the user gave (``--neck MM``, ``--neck 0``), where no sweep runs."""
    x, y, z = seed
    sp = tuple(float(s) for s in volume.spacing)
    box = tuple(slice(max(c - h, 0), min(c + h + 1, n)) for c, n, h in
                zip((z, y, x), volume.data.shape, (max(2, int(math.ceil(DEPTH_BOX_MM / s))) for s in sp)))
    inr = box_inrange(volume, pipe, low, high, box, labels=labels, object_id=object_id)
    local = tuple(c - b.start for c, b in zip((z, y, x), box))
    if not inr[local]:
        return 0.0
    f = resample_factors(sp)  # on the sweep's coarse grid, as the sweep measures it (0.06 -> 0.01 s, 0.8 mm pixels)
    inr = fill_holes_2d(coarse(inr, f))
    sp = tuple(s * k for s, k in zip(sp, f))
    local = tuple(c // k for c, k in zip(local, f))
    dt = ndimage.distance_transform_edt(np.pad(inr, 1), sampling=sp)[1:-1, 1:-1, 1:-1]
    return local_depth(dt, np.array([local]), sp)  # type: ignore[arg-type]  # local: tuple() of a generator: mypy sees any length, the length is fixed by construction
