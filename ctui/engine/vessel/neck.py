"""A section's lumen where a neighbour touches it: the in-plane neck between two bright lumens.

In one plane the vessel's in-range region may run on into a neighbour that touches it (a
chamber, the pulmonary artery, a perfused false lumen, a branch's origin). Two lumens that touch
are parted by a valley of lower values (their walls, a dissection's flap, blurred by partial
volume); one lumen that is merely not round (a crescent true lumen, the sinuses of Valsalva)
has none. So the range's floor is raised step by step from ``lo`` towards the lumen's value
(up to ``MAX_SHARE`` of the way): the first level at which a part of at least ``DETACH_SHARE`` of
the region (and ``DETACH_MM2``) comes off it is the neck, and the section is the region at that
level grown back to ``lo`` by ``REGROW_PX`` pixels away from the part that came off. Without a
neck the section is the whole region within the hard reach ``HARD_FACTOR`` times the
inscribed radius (and ``HARD_MARGIN_MM`` beyond it).
"""

from __future__ import annotations

import numpy as np

LEVELS = 5  # floors tried between lo and MAX_SHARE of the way to the lumen's value
MAX_SHARE = 0.6  # the highest floor: this share of the way from lo to the lumen's median value
DETACH_SHARE = 0.12  # a part coming off: at least this share of the region's area ...
DETACH_MM2 = 12.0  # ... and this many mm2
REGROW_PX = 2  # grid pixels the section grows back towards lo from the level of its neck
HALF_MAX_MM = 3.0  # the half-maximum's background: the lowest value this near a pixel
HARD_FACTOR = 1.7  # without a neck: the section's reach / inscribed radius
HARD_MARGIN_MM = 6.0  # ... and at least this much beyond it
_CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)


def component(mask: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """The 4-connected components of ``mask`` holding a ``seeds`` pixel."""
    from scipy import ndimage as ndi

    lab, n = ndi.label(mask, structure=_CROSS)
    if n == 0:
        return np.zeros_like(mask)
    keep = np.zeros(n + 1, bool)
    keep[lab[seeds]] = True
    keep[0] = False
    return keep[lab]


def half_max(region: np.ndarray, val: np.ndarray, seeds: np.ndarray, lo: float, h: float) -> np.ndarray:
    """``region`` peeled to the full width at half maximum: a pixel stays where its value
    (smoothed over a pixel) is at least half-way between the lumen's median value and the lowest
    value within ``HALF_MAX_MM`` around it (the wall, the fat, a flap or a false lumen beside
    it), and never above ``lo``'s floor; what stays connected to ``seeds``, holes filled."""
    from scipy import ndimage as ndi

    if not region.any():
        return region
    sm = ndi.gaussian_filter(val, 1.0)
    mu = float(np.median(sm[region]))
    k = max(1, round(HALF_MAX_MM / h))
    low = ndi.minimum_filter(sm, size=2 * k + 1)
    keep = region & (sm >= np.maximum(lo, 0.5 * (mu + low)))
    out = component(keep, seeds)
    return ndi.binary_fill_holes(out) if out.any() else region


def split(val: np.ndarray, seeds: np.ndarray, lo: float, hi: float, within: np.ndarray, h: float) -> np.ndarray | None:
    """The section's lumen (bool, the plane's grid) in the range (lo, hi) of the plane's values
    ``val``, connected to ``seeds``, inside ``within`` (the hard reach), parted from a touching
    neighbour at its neck (module docstring); None when the seeds hold no in-range pixel."""
    from scipy import ndimage as ndi

    inr = (val <= hi) & within
    base = component(inr & (val >= lo), seeds)
    if not base.any():
        return None
    mu = float(np.median(val[base]))
    if mu <= lo:
        return base
    prev = base
    for t in lo + (mu - lo) * MAX_SHARE * np.arange(1, LEVELS + 1) / LEVELS:
        above = inr & (val >= t) & prev
        comp = component(above, seeds)
        if not comp.any():
            return base
        off = above & ~comp
        lab, n = ndi.label(off, structure=_CROSS)
        if n:
            sizes = np.bincount(lab.ravel())[1:]
            big = np.nonzero((sizes >= DETACH_SHARE * comp.sum()) & (sizes * h * h >= DETACH_MM2))[0] + 1
            if big.size:  # the neck: grow the part kept back towards lo, away from the part that came off
                away = ndi.binary_dilation(np.isin(lab, big), iterations=REGROW_PX)
                grown = ndi.binary_dilation(comp, iterations=REGROW_PX) & base & ~(away & ~comp)
                return component(grown | comp, seeds)
        prev = comp
    return base
