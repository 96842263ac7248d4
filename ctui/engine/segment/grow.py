"""Seeds inside and outside: competitive region growing (``grow``) and a threshold level set (``levelset``).

``grow`` (3D Slicer's "Grow from seeds", restricted to an HU range): the in-range
voxels reached from the foreground seeds are shared between the foreground and the
background seeds by a marker watershed on the in-range region's distance map (in mm,
so anisotropic voxels are handled). Both fronts rise from the deep inside of their
regions and meet at the narrowest place between them: a background seed in the bowel
cuts the kidney off at the bridge between the two, wherever the bridge is.
SimpleITK does the work (``SignedMaurerDistanceMap`` + ``MorphologicalWatershedFromMarkers``,
multi-threaded C++); benchmarks/segment_methods.py compares it with scikit-image's
``watershed`` on the same landscape.

``levelset``: a threshold level set with a curvature term (the equation of SimpleITK's
``ThresholdSegmentationLevelSetImageFilter``, on a narrow band in numba:
:mod:`ctui.engine.segment.levelset`), started from an initial object (the ``segment``
action uses the neck-cut fill) and moving at most ``margin_mm`` from it: it smooths
and completes the boundary; a front does not enter a neck narrower than about twice
the curvature weight. With background seeds the result is further limited to the
foreground's share of the ``grow`` competition.

Both work on a bounding box (the candidate region's, or the initial object's plus a margin),
and return ``(offset (z, y, x), bool mask)``. Seeds are (z, y, x) voxel indices.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage

from ctui.engine.core.limits import check_allocation
from ctui.engine.core.progress import Progress, report
from ctui.engine.segment.fill3d import fill3d_seeds
from ctui.engine.segment.levelset import evolve


def _sitk():
    import SimpleITK as sitk  # heavy import, only when a method needs it

    return sitk


def _image(arr: np.ndarray, spacing: tuple[float, float, float]):
    sitk = _sitk()
    img = sitk.GetImageFromArray(arr)
    img.SetSpacing((float(spacing[2]), float(spacing[1]), float(spacing[0])))
    return img


def _box(mask: np.ndarray, margin: tuple[int, int, int]) -> tuple[slice, slice, slice] | None:
    zs = np.flatnonzero(mask.any(axis=(1, 2)))
    if zs.size == 0:
        return None
    ys = np.flatnonzero(mask.any(axis=(0, 2)))
    xs = np.flatnonzero(mask.any(axis=(0, 1)))
    out = []
    for lo, hi, m, n in ((zs[0], zs[-1], margin[0], mask.shape[0]), (ys[0], ys[-1], margin[1], mask.shape[1]),
                         (xs[0], xs[-1], margin[2], mask.shape[2])):
        out.append(slice(max(int(lo) - m, 0), min(int(hi) + 1 + m, n)))
    return tuple(out)  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


def compete(region: np.ndarray, foreground: np.ndarray, background: np.ndarray, *,
            spacing: tuple[float, float, float], connectivity: int = 8) -> np.ndarray:
    """Share ``region`` (bool (nz, ny, nx)) between foreground and background seeds (int (n, 3) z, y, x):
    the marker watershed on minus the region's distance map (:func:`compete_watershed`), so the
    boundary runs through the narrowest neck between the seeds. Returns bool, the foreground's
    share, connected to the foreground seeds. (A faster bisection on the distance map used to
    stand in for the watershed; it disagreed with it on 2 of the 5 real cases of benchmarks/organs.py
    (agreement Dice 0.50 and 0.88) and was removed.)"""
    fg = np.asarray(foreground, np.int64).reshape(-1, 3)
    bg = np.asarray(background, np.int64).reshape(-1, 3)
    reg = region.view(np.uint8) if region.dtype == bool and region.flags.c_contiguous else \
        np.ascontiguousarray(region, dtype=np.uint8)
    mine = fill3d_seeds(reg.view(bool), fg, connectivity=connectivity)
    if not len(bg) or not mine[tuple(bg.T)].any():
        return mine  # the background is not reached: nothing to share
    return compete_watershed(region, fg, bg[mine[tuple(bg.T)]], spacing=spacing, connectivity=connectivity)


def smooth_gradient(image: np.ndarray, spacing: tuple[float, float, float], *, sigma_mm: float = 1.5) -> np.ndarray:
    """float32 (nz, ny, nx): the gradient magnitude of ``image`` after a Gaussian of ``sigma_mm`` (at least
    0.6 voxel along each axis), in value units per voxel."""
    sigma = [max(0.6, sigma_mm / float(s)) for s in spacing]
    return ndimage.gaussian_gradient_magnitude(np.asarray(image, np.float32), sigma=sigma)


def compete_edges(image: np.ndarray, region: np.ndarray, foreground: np.ndarray, background: np.ndarray, *,
                  spacing: tuple[float, float, float]) -> np.ndarray:
    """Share ``region`` between the seeds along the intensity edges: a marker watershed (SimpleITK) on the
    smoothed gradient magnitude of ``image`` (values, (nz, ny, nx), same shape), flooding only ``region``.
    The fronts meet on the strongest edge between the seeds, wherever it lies. Seeds: int (n, 3) z, y, x.
    Returns bool, the foreground's share, connected to the foreground seeds."""
    sitk = _sitk()
    fg = np.asarray(foreground, np.int64).reshape(-1, 3)
    bg = np.asarray(background, np.int64).reshape(-1, 3)
    reg = np.ascontiguousarray(region, dtype=bool)
    check_allocation(reg.size * 10, what="the edge competition (gradient, markers)")
    grad = smooth_gradient(image, spacing)
    top = float(grad.max()) + 1.0
    grad[~reg] = top  # outside the region: flooded last, dropped below
    markers = np.zeros(reg.shape, np.uint8)
    markers[tuple(bg.T)] = 2
    markers[tuple(fg.T)] = 1
    ws = sitk.MorphologicalWatershedFromMarkers(_image(grad, spacing), _image(markers, spacing),
                                                markWatershedLine=False, fullyConnected=True)
    del grad, markers
    share = sitk.GetArrayViewFromImage(ws) == 1
    share &= reg
    return fill3d_seeds(share, fg, connectivity=8)


def compete_watershed(region: np.ndarray, foreground: np.ndarray, background: np.ndarray, *,
            spacing: tuple[float, float, float], connectivity: int = 8) -> np.ndarray:
    """:func:`compete` by a marker watershed (SimpleITK), the reference and the fallback.

    Marker watershed on minus the region's distance map (mm): the boundary between the
    two shares runs through the narrowest part between them. Outside the region the
    landscape is the (positive) distance to it, so those voxels flood last and are
    dropped. Memory: about 10 bytes a voxel of ``region`` (float32 distance map, uint8
    markers and labels), checked before allocating. Returns bool, the foreground's
    share, connected to the foreground seeds.
    """
    sitk = _sitk()
    fg = np.asarray(foreground, np.int64).reshape(-1, 3)
    bg = np.asarray(background, np.int64).reshape(-1, 3)
    reg = region.view(np.uint8) if region.dtype == bool and region.flags.c_contiguous else \
        np.ascontiguousarray(region, dtype=np.uint8)
    if not len(bg):
        return fill3d_seeds(reg.view(bool), fg, connectivity=connectivity)
    check_allocation(reg.size * 10, what="the seed competition (distance map, markers)")
    land = sitk.SignedMaurerDistanceMap(_image(reg, spacing), insideIsPositive=True, squaredDistance=False,
                                        useImageSpacing=True)
    land *= -1.0  # in place: deepest inside = lowest
    markers = np.zeros(reg.shape, np.uint8)
    markers[tuple(bg.T)] = 2
    markers[tuple(fg.T)] = 1
    mk = _image(markers, spacing)
    del markers
    ws = sitk.MorphologicalWatershedFromMarkers(land, mk, markWatershedLine=False, fullyConnected=connectivity == 8)
    del land, mk
    share = sitk.GetArrayViewFromImage(ws) == 1
    share &= reg.view(bool)
    del ws
    return fill3d_seeds(share, fg, connectivity=connectivity)


def candidate(inrange: np.ndarray, seeds: np.ndarray, spacing: tuple[float, float, float],
              connectivity: int) -> tuple[tuple[slice, slice, slice], np.ndarray] | None:
    """The in-range voxels connected to any seed, cropped to their box plus a margin."""
    comp = fill3d_seeds(inrange, seeds, connectivity=connectivity)
    box = _box(comp, (1, 2, 2))
    if box is None:
        return None
    return box, np.ascontiguousarray(comp[box])  # a copy: the full-size component is freed


def grow(inrange: np.ndarray, foreground: np.ndarray, background: np.ndarray, *,
         spacing: tuple[float, float, float], connectivity: int = 8,
         progress: Progress | None = None) -> tuple[tuple[int, int, int], np.ndarray]:
    """Competitive region growing inside ``inrange`` (bool (nz, ny, nx)) from foreground and background seeds.

    Seeds: int (n, 3) (z, y, x). Returns ((z0, y0, x0), bool mask of the foreground's
    box); an empty (0, 0, 0) mask when no foreground seed is in range.
    """
    fg = np.asarray(foreground, np.int64).reshape(-1, 3)
    bg = np.asarray(background, np.int64).reshape(-1, 3)
    report(progress, 0, 3, "in-range region")
    got = candidate(inrange, np.concatenate([fg, bg]), spacing, connectivity)
    if got is None:
        return (0, 0, 0), np.zeros((0, 0, 0), bool)
    box, region = got
    off = np.array([b.start for b in box])
    report(progress, 1, 3, "competition")
    share = compete(region, fg - off, inside_seeds(bg - off, region.shape), spacing=spacing, connectivity=connectivity)
    report(progress, 3, 3, "")
    return tight(tuple(int(v) for v in off), share)  # type: ignore[arg-type]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


def inside_seeds(seeds: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    ok = np.all((seeds >= 0) & (seeds < np.array(shape)), axis=1)
    return seeds[ok]


def tight(offset: tuple[int, int, int], mask: np.ndarray) -> tuple[tuple[int, int, int], np.ndarray]:
    box = _box(mask, (0, 0, 0))
    if box is None:
        return (0, 0, 0), np.zeros((0, 0, 0), bool)
    return (offset[0] + box[0].start, offset[1] + box[1].start, offset[2] + box[2].start), mask[box].copy()


def levelset(image: np.ndarray, initial: np.ndarray, *, low: float, high: float,
             spacing: tuple[float, float, float], background: np.ndarray | None = None, curvature: float = 1.0,
             iterations: int = 20, margin_mm: float = 4.0, inrange: np.ndarray | None = None,
             connectivity: int = 8, progress: Progress | None = None) -> tuple[tuple[int, int, int], np.ndarray]:
    """Threshold level set (:func:`ctui.engine.segment.levelset.evolve`) from ``initial``, with a curvature term.

    Parameters
    ----------
    image : (nz, ny, nx) values in the range's units (HU)
    initial : bool (nz, ny, nx), inside of the starting surface. The ``segment`` action
        starts from the neck-cut fill of the seed, so the level set smooths and
        completes the boundary rather than travelling from a point (a stable front
        moves about a tenth of a millimetre an iteration with the curvature term on:
        SimpleITK's filter needed 300 iterations and a minute to half-fill a kidney from
        its seed slice in benchmarks/segment_methods.py).
    low, high : the in-range interval the front expands into
    spacing : (dz, dy, dx) mm
    background : int (n, 3) background seeds (z, y, x): the result is cut to the
        foreground's share of :func:`compete` between them
    curvature : weight c (mm) of the in-plane curvature term: at full speed the front
        does not enter a neck narrower than about 2 c, and smooths corners sharper than c
    iterations : upper bound of level-set iterations
    margin_mm : the front may move this far beyond the initial box
    inrange : optional bool mask of ``low <= image <= high`` (computed on the box when missing)

    Returns ((z0, y0, x0), bool mask).
    """
    report(progress, 0, 4, "level set")
    margin = tuple(max(1, int(np.ceil(margin_mm / float(s)))) for s in spacing)
    box = _box(np.asarray(initial, bool), margin)  # type: ignore[arg-type]  # margin: tuple() of a generator: mypy sees any length, the length is fixed by construction
    if box is None:
        return (0, 0, 0), np.zeros((0, 0, 0), bool)
    off = np.array([b.start for b in box])
    sub = image[box]  # as it is (int16 series values need no float copy)
    init = np.ascontiguousarray(initial[box], dtype=bool)
    check_allocation(sub.size * 14, what="the level set (distance maps)")
    grown = evolve(sub, init, low=low, high=high, spacing=spacing, curvature=curvature, iterations=iterations)
    report(progress, 3, 4, "level set")
    region = inrange[box] if inrange is not None else (sub >= low) & (sub <= high)
    inside = grown & (region | init)
    del grown
    inside = fill3d_seeds(inside, run_starts(init & inside), connectivity=connectivity)
    if background is not None and len(background):
        bg = inside_seeds(np.asarray(background, np.int64).reshape(-1, 3) - off, region.shape)
        inside &= compete(region | inside, np.argwhere(init), bg, spacing=spacing, connectivity=connectivity)
    report(progress, 4, 4, "")
    return tight(tuple(int(v) for v in off), inside)  # type: ignore[arg-type]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


def run_starts(mask: np.ndarray) -> np.ndarray:
    """int (n, 3) z, y, x: the first voxel of every run of ``mask`` (bool (nz, ny, nx)) along x. As
    seeds of a fill they reach what all of ``mask``'s voxels reach, from a few percent of the voxels
    (np.argwhere of a 1.2-million-voxel object is 28 MB)."""
    starts = mask.copy()
    starts[..., 1:] &= ~mask[..., :-1]
    return np.argwhere(starts)


def describe() -> dict[str, Any]:
    """The methods and what they need, for help texts."""
    return {"fill": "threshold fill + propagation with the neck-cutting leak guard",
            "grow": "competitive growing from --seed and --background inside the range (watershed on distance)",
            "levelset": "threshold level set with a curvature term from the seed slice's object"}
