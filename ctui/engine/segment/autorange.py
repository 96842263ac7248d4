"""The automatic range: widened outward from the seed's own values until the joined region's volume jumps.

A range from the seed's neighbourhood statistics (median +- 2 sd of a 10 mm ball) fails on
organs with internal structure: a contrast kidney's ball holds cortex, medulla and sinus, so
its spread reaches the liver and muscle around it (9.4 L from a kidney seed); a mandible's
ball holds marrow, cortical bone and soft tissue; a thin structure's ball (a lateral
ventricle, the spinal cord) is mostly its neighbours. The seed's own tissue is what a range
has to start from, and what stops it is the neighbours, which only connectivity tells.

:func:`plateau_range` therefore starts from the seed's own values (the median of its
3 x 3 x 3 neighbourhood +- ``START_K`` times the image noise) and widens the range one step
at a time on a coarse copy of a box around the seed (about ``BOX_MM`` each side, sampled
every ``autoneck.SWEEP_MM``, the neck sweep's grid): at each step it tries the lower and the
upper bound one step further (steps grow geometrically, in units of the noise) and keeps the
side whose joined region grows less. A side whose step makes the joined region grow more than
``JUMP`` times (plus the voxels it already had) is closed: a neighbour joined. The range is the
widest before both sides closed: the plateau of the joined volume, as the neck width's sweep
keeps the widest neck before the volume jumps. The steps and volumes are reported (``why``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.segment.autoneck import resample_factors
from ctui.engine.segment.fill3d import fill3d_seeds

BOX_MM = 60.0  # half-size of the box the range is measured on
START_K = 2.0  # the first range: the seed's value +- this many noise sd
LADDER = (2.0, 2.5, 3.2, 4.0, 5.0, 6.3, 8.0, 10.0, 12.5, 16.0, 20.0, 25.0, 32.0, 40.0, 50.0)  # noise sd
JUMP = 4.0  # a step that multiplies the joined volume by more than this closes its side ...
OUTLIER = 4.0  # a seed voxel further than this many noise sd from its 3 x 3 x 3 median is an outlier (calcium,
# a vessel's speck: a right kidney's random seed on a 153 HU voxel took -33:153 and the body, 18x the kidney)
MIN_ML = 0.5  # ... once the joined region holds this much (smaller, it is still the seed's own tissue filling in)


@dataclass
class RangeSteps:
    """How :func:`plateau_range` chose: the centre, the noise unit, the accepted (low, high, volume) steps
    (volume in mL of the joined region in the box) and the closing step of each side."""

    centre: float
    unit: float
    steps: list[tuple[float, float, float]] = field(default_factory=list)
    closed: dict[str, str] = field(default_factory=dict)  # "low"/"high": why it stopped
    stops: dict[str, float] = field(default_factory=dict)  # "low"/"high": the bound before a jump (sides that jumped)

    def to_dict(self) -> dict[str, Any]:
        return {"centre": round(self.centre, 3), "unit": round(self.unit, 3),
                "steps": [[round(a, 1), round(b, 1), round(v, 2)] for a, b, v in self.steps],
                "closed": dict(self.closed), "stops": {k: round(v, 3) for k, v in self.stops.items()}}

    def why(self) -> str:
        lo, hi, v = self.steps[-1]
        parts = [f"{side} bound: {why}" for side, why in self.closed.items()]
        return (f"widened from the seed's value {self.centre:.0f} to {lo:.0f}:{hi:.0f} ({v:.0f} mL joined near the "
                f"seed); " + "; ".join(parts))


def _box_values(volume: Any, pipe: Any, seed: tuple[int, int, int]) -> tuple[np.ndarray, tuple[int, int, int], float]:
    """float32 (nz, ny, nx): the pipeline's values on the coarse grid of a box around the seed (x, y, z);
    the seed's index in it; the volume (mL) of one coarse voxel."""
    x, y, z = seed
    sp = tuple(float(s) for s in volume.spacing)
    f = resample_factors(sp)  # type: ignore[arg-type]  # sp: tuple() of a generator: mypy sees any length, the length is fixed by construction
    shape = volume.data.shape
    half = [max(2, int(math.ceil(BOX_MM / s))) for s in sp]
    lo = [max(c - h, 0) for c, h in zip((z, y, x), half)]
    lo = [c - ((c - a) // k) * k for c, a, k in zip((z, y, x), lo, f)]  # the seed lies on the coarse grid
    hi = [min(c + h + 1, n) for c, h, n in zip((z, y, x), half, shape)]
    if not pipe.active_steps() and getattr(pipe, "domain", "hu") == "hu":
        vals = np.asarray(volume.data[lo[0]:hi[0]:f[0], lo[1]:hi[1]:f[1], lo[2]:hi[2]:f[2]], np.float32)
    else:
        window = pipe.window_for(volume)
        vals = np.stack([np.asarray(pipe.final_region(volume, zz, lo[1], hi[1], lo[2], hi[2], window=window),
                                    np.float32)[::f[1], ::f[2]] for zz in range(lo[0], hi[0], f[0])])
    local = tuple((c - a) // k for c, a, k in zip((z, y, x), lo, f))
    return vals, local, float(np.prod([s * k for s, k in zip(sp, f)])) / 1000.0  # type: ignore[return-value]  # sp, f: tuple() of a generator: mypy sees any length, the length is fixed by construction


def _joined(vals: np.ndarray, seed: np.ndarray, lo: float, hi: float) -> int:
    """Voxels of the in-range region joined to the seed, or to its in-range 26-neighbours when the seed voxel
    itself is out of range (a noise voxel, a speck of calcium: the fill starts beside it, see ``snap``)."""
    inr = (vals >= lo) & (vals <= hi)
    z, y, x = (int(v) for v in seed[0])
    if not inr[z, y, x]:
        box = (slice(max(z - 1, 0), z + 2), slice(max(y - 1, 0), y + 2), slice(max(x - 1, 0), x + 2))
        pts = np.argwhere(inr[box])
        if not len(pts):
            return 0
        seed = pts + np.array([b.start for b in box])
    return int(np.count_nonzero(fill3d_seeds(inr, seed, connectivity=8)))


def plateau_range(volume: Any, pipe: Any, seed: tuple[int, int, int], noise: float,
                  centre: float, own: float) -> tuple[float, float, RangeSteps]:
    """(low, high, steps): the widest range around ``centre`` (the seed's own value) before the region joined
    to the seed (x, y, z) in a box around it jumps in volume; ``noise`` the image noise sd (the step unit);
    ``own`` the seed voxel's value (always in the range)."""
    vals, local, vox_ml = _box_values(volume, pipe, seed)
    unit = max(float(noise), 1e-3 * max(float(np.ptp(vals)), 1e-6))
    s = np.array([local])
    ia = ib = 0
    lo, hi = min(centre - LADDER[0] * unit, own), max(centre + LADDER[0] * unit, own)
    v = _joined(vals, s, lo, hi)
    least = MIN_ML / vox_ml
    steps = RangeSteps(centre=centre, unit=unit, steps=[(lo, hi, v * vox_ml)])
    open_ = {"low": True, "high": True}
    while any(open_.values()):
        tries = {}
        if open_["low"]:
            if ia + 1 < len(LADDER):
                nlo = min(centre - LADDER[ia + 1] * unit, lo)
                tries["low"] = (nlo, hi, _joined(vals, s, nlo, hi))
            else:
                open_["low"] = False
                steps.closed["low"] = "the widest step tried"
        if open_["high"]:
            if ib + 1 < len(LADDER):
                nhi = max(centre + LADDER[ib + 1] * unit, hi)
                tries["high"] = (lo, nhi, _joined(vals, s, lo, nhi))
            else:
                open_["high"] = False
                steps.closed["high"] = "the widest step tried"
        for side, (a, b, nv) in list(tries.items()):
            if nv > JUMP * max(v, 1) and v >= least:
                open_[side] = False
                edge = a if side == "low" else b
                steps.closed[side] = f"at {edge:.0f} the joined volume jumps {nv / max(v, 1):.1f}x"
                steps.stops[side] = lo if side == "low" else hi
                del tries[side]
        if not tries:
            break
        side = min(tries, key=lambda k: tries[k][2])
        lo, hi, v = tries[side]
        if side == "low":
            ia += 1
        else:
            ib += 1
        steps.steps.append((lo, hi, v * vox_ml))
    return lo, hi, steps
