"""Leak guard by neck cutting: keep what joins the object through a neck wider than N mm.

A flood fill leaks when the object touches a neighbour of the same values through a
bridge (partial volume between a kidney and bowel, liver or a vessel). Counting area
misses slow leaks; cutting necks does not. The candidate region is opened with a ball
of diameter ``neck_mm`` in physical units (so anisotropic voxels are handled: a 5 mm
ball is 7 px across on 0.7 mm pixels and one slice thick on 3 mm slices): every part
narrower than the ball disappears, bridges included. Of the opened region only the
parts touching the reference (the previous slice's object, or the seed) are kept, and
the rim the opening shaved off is given back where it lies within the ball's radius of
the kept part (``candidate & dilate(kept)``), so the object keeps its corners and a
neck costs at most a stub one radius long. This is "opening by reconstruction"
restricted to one radius, which is what stops the reconstruction from flowing back
through the neck.

Balls are decomposed into discs per slice offset (a ball of radius r over slices
dz apart is, at slice offset k, a disc of radius sqrt(r^2 - (k dz)^2)), so a 3D
erosion is an AND of OpenCV 2D erosions: about 20 ms for a 100 x 200 x 200 crop
against 0.9 s for ``scipy.ndimage.binary_erosion`` with the same 3D structuring
element (measured on this machine, 2 loaded cores).

Shapes: 2D masks (ny, nx), 3D masks (nz, ny, nx), bool. Spacing (dy, dx) or
(dz, dy, dx) in mm.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ctui.engine.segment.fill3d import fill3d_seeds

DEFAULT_NECK_MM = 5.0

_KERNELS: dict[tuple[int, int], np.ndarray] = {}


def disc(ry: float, rx: float) -> np.ndarray:
    """uint8 elliptic kernel of semi-axes ``ry``, ``rx`` pixels (pixels whose centres lie inside; at least 1x1)."""
    key = (round(max(float(ry), 0.0), 4), round(max(float(rx), 0.0), 4))
    k = _KERNELS.get(key)
    if k is None:
        a, b = int(math.floor(key[0] + 1e-6)), int(math.floor(key[1] + 1e-6))
        yy, xx = np.mgrid[-a:a + 1, -b:b + 1]
        k = (((yy / max(key[0], 0.5)) ** 2 + (xx / max(key[1], 0.5)) ** 2) <= 1.0 + 1e-6).astype(np.uint8)
        _KERNELS[key] = k
    return k


def ball_sections(radius_mm: float, spacing: tuple[float, float, float]) -> list[tuple[int, np.ndarray]]:
    """A ball of ``radius_mm`` as [(slice offset k, 2D kernel)], k = -K..K."""
    dz, dy, dx = (float(s) for s in spacing)
    kz = int(math.floor(radius_mm / dz + 1e-9))
    out = []
    for k in range(-kz, kz + 1):
        r = math.sqrt(max(radius_mm**2 - (k * dz) ** 2, 0.0))
        out.append((k, disc(r / dy, r / dx)))
    return out


def _morph2d(m: np.ndarray, kernel: np.ndarray, erode: bool) -> np.ndarray:
    if kernel.size == 1:
        return m.copy()  # never hand back (and later modify) the caller's array
    op = cv2.erode if erode else cv2.dilate
    return op(m, kernel, borderType=cv2.BORDER_REPLICATE if erode else cv2.BORDER_CONSTANT, borderValue=0)


def morph_ball(mask: np.ndarray, radius_mm: float, spacing: tuple[float, float, float], *, erode: bool) -> np.ndarray:
    """Erosion or dilation of a bool 3D mask by a ball of ``radius_mm`` (outside the array: replicate for erosion).

    Slice by slice: each input slice is eroded (dilated) once per distinct section of the
    ball (the sections at offsets +k and -k are the same disc) and kept while an output
    slice within reach needs it, so the only full-size allocation is the result.
    """
    m = mask.view(np.uint8) if mask.dtype == bool and mask.flags.c_contiguous else np.ascontiguousarray(mask, dtype=np.uint8)
    nz = m.shape[0]
    sections = ball_sections(radius_mm, spacing)
    kz = len(sections) // 2
    kernels = [kern for k, kern in sections if k >= 0]  # kernels[|k|]
    out = np.empty(m.shape, np.uint8)
    cache: dict[tuple[int, int], np.ndarray] = {}

    def get(zz: int, j: int) -> np.ndarray:
        key = (zz, j)
        r = cache.get(key)
        if r is None:
            r = _morph2d(m[zz], kernels[j], erode)
            cache[key] = r
        return r

    for z in range(nz):
        acc = None
        for k in range(-kz, kz + 1):
            zz = min(max(z + k, 0), nz - 1) if erode else z + k
            if not 0 <= zz < nz:
                continue
            r = get(zz, abs(k))
            if acc is None:
                acc = r.copy()
            elif erode:
                np.minimum(acc, r, out=acc)
            else:
                np.maximum(acc, r, out=acc)
        out[z] = acc if acc is not None else 0
        for key in [key for key in cache if key[0] < z + 1 - kz]:
            del cache[key]  # no later output slice reaches back that far
    return out.view(bool)


def fill_holes_2d(mask: np.ndarray) -> np.ndarray:
    """bool (nz, ny, nx) (or (ny, nx)): ``mask`` with the holes of every slice filled (4-connected background)."""
    m = np.asarray(mask, bool)
    if m.ndim == 2:
        return _fill2d(m)
    out = np.empty(m.shape, bool)
    for z in range(m.shape[0]):
        out[z] = _fill2d(m[z]) if m[z].any() else False
    return out


def _fill2d(m: np.ndarray) -> np.ndarray:
    """Holes of one slice filled: the background reachable from the border stays background.
    OpenCV's flood fill from a one-pixel frame (about 10x scipy's binary_fill_holes on 512x512)."""
    h, w = m.shape
    pad = np.zeros((h + 2, w + 2), np.uint8)
    pad[1:-1, 1:-1] = m
    mask = np.zeros((h + 4, w + 4), np.uint8)
    cv2.floodFill(pad, mask, (0, 0), 2, flags=4)
    return pad[1:-1, 1:-1] != 2


def seeded_components(inrange: np.ndarray, seeds: np.ndarray, *, connectivity: int = 8) -> np.ndarray:
    """Connected components of ``inrange`` (2D) holding any ``seeds`` pixel; bool, same shape."""
    m = np.ascontiguousarray(inrange, dtype=np.uint8)
    n, lab = cv2.connectedComponents(m, connectivity=connectivity, ltype=cv2.CV_32S)
    if n <= 1:
        return np.zeros(m.shape, bool)
    keep = np.zeros(n, bool)
    keep[lab[np.asarray(seeds, bool) & (m > 0)]] = True
    keep[0] = False
    return keep[lab]


def cut_necks_2d(candidate: np.ndarray, reference: np.ndarray, *, neck_mm: float, spacing_yx: tuple[float, float],
                 connectivity: int = 8) -> tuple[np.ndarray, str]:
    """The part of ``candidate`` joined to ``reference`` through necks at least ``neck_mm`` wide.

    Parameters
    ----------
    candidate : bool (ny, nx), e.g. the in-range regions touching the previous object
    reference : bool (ny, nx), the previous slice's object (or the seed's fill)
    neck_mm : the narrowest neck followed (mm); 0 disables the cut
    spacing_yx : pixel size (dy, dx) mm

    Returns
    -------
    (bool (ny, nx), status): status "ok" (nothing cut), "cut" (something was cut off),
    "thin" (the whole candidate is thinner than the neck: returned unchanged, the caller
    decides), or "lost" (no wide part touches the reference: empty mask).
    """
    cand = np.ascontiguousarray(candidate, dtype=np.uint8)
    if neck_mm <= 0 or not cand.any():
        return cand.astype(bool), "ok"
    r = neck_mm / 2.0
    kern = disc(r / spacing_yx[0], r / spacing_yx[1])
    core = cv2.dilate(cv2.erode(cand, kern, borderType=cv2.BORDER_REPLICATE), kern)
    core &= cand
    if not core.any():
        return cand.astype(bool), "thin"
    ref = np.asarray(reference, bool)
    kept = seeded_components(core, ref & (core > 0), connectivity=connectivity)
    if not kept.any():
        near = cv2.dilate(ref.astype(np.uint8), kern).astype(bool)
        kept = seeded_components(core, near & (core > 0), connectivity=connectivity)
        if not kept.any():
            return np.zeros(cand.shape, bool), "lost"
    out = (cv2.dilate(kept.view(np.uint8), kern) & cand).view(bool)  # every piece lies within r of ``kept``
    return out, ("cut" if np.count_nonzero(out) < np.count_nonzero(cand) else "ok")


def cut_necks_3d(candidate: np.ndarray, seeds_zyx: np.ndarray, *, neck_mm: float,
                 spacing: tuple[float, float, float], connectivity: int = 8,
                 inplace: bool = False) -> tuple[np.ndarray, str]:
    """The part of ``candidate`` (bool (nz, ny, nx)) joined to the seeds through necks >= ``neck_mm``.

    ``seeds_zyx``: int (n, 3) voxels of the object known to be right (the seed, or the
    seed slice's object). Works on the candidate's bounding box only, with at most three
    box-sized uint8 arrays alive at once; ``inplace=True`` writes the result into
    ``candidate`` (no full-size copy). Returns (bool mask of the candidate's shape,
    status as in :func:`cut_necks_2d`).
    """
    cand = np.asarray(candidate, bool)
    if neck_mm <= 0 or not cand.any():
        return cand, "ok"
    r = neck_mm / 2.0
    zs = np.flatnonzero(cand.any(axis=(1, 2)))
    ys = np.flatnonzero(cand.any(axis=(0, 2)))
    xs = np.flatnonzero(cand.any(axis=(0, 1)))
    box = (slice(zs[0], zs[-1] + 1), slice(ys[0], ys[-1] + 1), slice(xs[0], xs[-1] + 1))
    sub = np.ascontiguousarray(cand[box])
    seeds = np.asarray(seeds_zyx, np.int64).reshape(-1, 3) - np.array([zs[0], ys[0], xs[0]])
    seeds = seeds[np.all((seeds >= 0) & (seeds < np.array(sub.shape)), axis=1)]
    er = morph_ball(sub, r, spacing, erode=True)
    core = morph_ball(er, r, spacing, erode=False)
    del er
    core &= sub
    hit = seeds[core[tuple(seeds.T)]] if len(seeds) else seeds
    if not len(hit):
        return cand, "thin"
    kept = fill3d_seeds(core, hit, connectivity=connectivity)
    del core
    got = grow_back(kept, hit, sub, r, spacing, connectivity=connectivity)
    status = "cut" if np.count_nonzero(got) < np.count_nonzero(sub) else "ok"
    out = cand if inplace else np.zeros(cand.shape, bool)
    out[box] = got
    return out, status


def grow_back(kept: np.ndarray, seeds: np.ndarray, region: np.ndarray, radius_mm: float,
              spacing: tuple[float, float, float], *, connectivity: int = 8) -> np.ndarray:
    """The part of ``region`` within ``radius_mm`` of ``kept`` that the seeds reach: an opening's core
    given back its rim (bool, the shape of ``region``; ``kept`` is consumed)."""
    back = morph_ball(kept, radius_mm, spacing, erode=False)
    del kept
    back &= region
    return fill3d_seeds(back, seeds, connectivity=connectivity)
