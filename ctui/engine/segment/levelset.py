"""A threshold level set with a curvature term, on a narrow band (numba).

The same equation as SimpleITK's ``ThresholdSegmentationLevelSetImageFilter``, with
phi positive inside (mm):

    d phi / dt = P(I) |grad phi| + c * div(grad phi / |grad phi|) |grad phi|

``P`` is the threshold speed: ``(I - low) / h`` below the range's middle and
``(high - I) / h`` above it (``h`` half the range's width), clipped to [-1, 1], so the
front expands into in-range values and retreats from the rest; the curvature term
(weight ``c``) shrinks thin protrusions and keeps the front from entering a neck
narrower than its radius of curvature. The propagation term is upwinded (Osher-Sethian),
the curvature term uses central differences; the anisotropic spacing is honoured.
Only voxels within ``band`` mm of the front are updated, and phi is re-initialised to
a signed distance (SimpleITK's Maurer map) every ``reinit`` iterations.

benchmarks/segment_methods.py compares it with SimpleITK's filter (same start, same
iterations) on a 100 x 200 x 200 region.
"""

from __future__ import annotations

import numpy as np

_KERNEL: list = []


def _step_py(phi, image, low, high, out, dz, dy, dx, c, dt, band):  # pragma: no cover - compiled by numba
    nz, ny, nx = phi.shape
    for z in range(nz):
        z0 = z - 1 if z > 0 else 0
        z1 = z + 1 if z < nz - 1 else nz - 1
        for y in range(ny):
            y0 = y - 1 if y > 0 else 0
            y1 = y + 1 if y < ny - 1 else ny - 1
            for x in range(nx):
                p = phi[z, y, x]
                if p > band or p < -band:
                    out[z, y, x] = p
                    continue
                x0 = x - 1 if x > 0 else 0
                x1 = x + 1 if x < nx - 1 else nx - 1
                # one-sided differences
                mxm = (p - phi[z, y, x0]) / dx
                mxp = (phi[z, y, x1] - p) / dx
                mym = (p - phi[z, y0, x]) / dy
                myp = (phi[z, y1, x] - p) / dy
                mzm = (p - phi[z0, y, x]) / dz
                mzp = (phi[z1, y, x] - p) / dz
                v = image[z, y, x]
                f = min(v - low, high - v) / (0.5 * (high - low))  # the threshold speed, +1 mid-range
                if f > 1.0:
                    f = 1.0
                elif f < -1.0:
                    f = -1.0
                if f > 0:  # the front moves outwards: phi grows
                    g = (min(mxm, 0.0) ** 2 + max(mxp, 0.0) ** 2 + min(mym, 0.0) ** 2 + max(myp, 0.0) ** 2
                         + min(mzm, 0.0) ** 2 + max(mzp, 0.0) ** 2)
                else:
                    g = (max(mxm, 0.0) ** 2 + min(mxp, 0.0) ** 2 + max(mym, 0.0) ** 2 + min(myp, 0.0) ** 2
                         + max(mzm, 0.0) ** 2 + min(mzp, 0.0) ** 2)
                prop = f * np.sqrt(g)
                curv = 0.0
                if c != 0.0:  # in-plane curvature: thick slices make a staircase along z
                    px = 0.5 * (mxm + mxp)
                    py = 0.5 * (mym + myp)
                    pxx = (mxp - mxm) / dx
                    pyy = (myp - mym) / dy
                    pxy = (phi[z, y1, x1] - phi[z, y1, x0] - phi[z, y0, x1] + phi[z, y0, x0]) / (4.0 * dx * dy)
                    g2 = px * px + py * py
                    if g2 > 1e-12:
                        curv = c * (px * px * pyy + py * py * pxx - 2.0 * px * py * pxy) / g2
                out[z, y, x] = p + dt * (prop + curv)


def _kernel():
    if not _KERNEL:
        try:
            from numba import njit

            _KERNEL.append(njit(cache=True, nogil=True)(_step_py))
        except ImportError:  # pragma: no cover - numba is a declared dependency
            _KERNEL.append(_step_py)
    return _KERNEL[0]


def _side_distance(mask: np.ndarray, spacing: tuple[float, float, float], cap: float) -> np.ndarray:
    """Distance (mm, capped at ``cap``) from each voxel of ``mask`` to the nearest voxel outside it
    (0 outside): exact in-plane distances per slice (OpenCV), then the lower envelope along z over
    the slices within ``cap``. Square pixels (dy == dx)."""
    import cv2

    dz, _, dx = spacing
    m = mask.view(np.uint8) if mask.dtype == bool and mask.flags.c_contiguous else mask.astype(np.uint8)
    sq = np.empty(m.shape, np.float32)
    for z in range(m.shape[0]):
        sq[z] = cv2.distanceTransform(m[z], cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    sq *= np.float32(dx)
    np.minimum(sq, np.float32(cap), out=sq)
    sq *= sq  # squared, in place
    out = sq.copy()
    for k in range(1, int(np.ceil(cap / dz)) + 1):
        step = np.float32((k * dz) ** 2)
        for z in range(m.shape[0]):  # slice by slice: no volume-sized temporaries
            if z + k < m.shape[0]:
                np.minimum(out[z + k], sq[z] + step, out=out[z + k])
                np.minimum(out[z], sq[z + k] + step, out=out[z])
    del sq
    return np.sqrt(out, out=out)


def _signed_distance(inside: np.ndarray, spacing: tuple[float, float, float], cap: float = 1e9) -> np.ndarray:
    """Signed distance (positive inside) with the zero level half-way between the boundary
    voxels inside and outside. Square pixels with a ``cap``: OpenCV per slice + a banded pass
    along z, halved (0.8 s for 100 x 200 x 200 on this loaded machine); otherwise SimpleITK's
    Maurer maps of the mask and of its complement, averaged, in mm (2.6 s)."""
    if abs(spacing[1] - spacing[2]) < 1e-6 * spacing[2] and cap < 1e8:
        # half the distance: the zero level lies half-way between the boundary voxels; the level-set
        # equation moves the zero level the same whatever positive factor phi carries
        phi = _side_distance(inside, spacing, cap)
        phi -= _side_distance(~inside, spacing, cap)
        phi *= np.float32(0.5)
        return phi
    import SimpleITK as sitk  # heavy import, only here

    out = None
    for m, sign in ((inside, 0.5), (~inside, -0.5)):
        img = sitk.GetImageFromArray(m.astype(np.uint8))
        img.SetSpacing((float(spacing[2]), float(spacing[1]), float(spacing[0])))
        d = sitk.GetArrayFromImage(sitk.SignedMaurerDistanceMap(img, insideIsPositive=True, squaredDistance=False,
                                                                useImageSpacing=True)).astype(np.float32)
        out = d * np.float32(sign) if out is None else out + d * np.float32(sign)
    return out  # type: ignore[return-value]


def threshold_speed(image: np.ndarray, low: float, high: float) -> np.ndarray:
    """The threshold speed P (float32, same shape): +1 at the range's middle, 0 at its ends, -1 far outside."""
    h = max((float(high) - float(low)) / 2.0, 1e-6)
    img = np.asarray(image, np.float32)
    sp = img - np.float32(low)  # below the middle the distance to low is the smaller one
    np.minimum(sp, np.float32(high) - img, out=sp)
    sp *= np.float32(1.0 / h)
    return np.clip(sp, -1.0, 1.0, out=sp)


def evolve(image: np.ndarray, initial: np.ndarray, *, low: float, high: float, spacing: tuple[float, float, float],
           curvature: float = 1.0, iterations: int = 20, reinit: int = 10) -> np.ndarray:
    """Evolve the surface of ``initial`` (bool (nz, ny, nx)) over ``image`` (any numeric dtype, read as
    is: no float copy); returns bool, the inside. Memory: two float32 arrays of the image's shape
    (phi and the next phi), three while phi is re-initialised.

    ``curvature``: weight c of the curvature term; the time step keeps both terms stable
    (at most half the finest voxel side a step for the propagation term).
    """
    dz, dy, dx = (float(s) for s in spacing)
    h = min(dz, dy, dx)
    dt = 0.5 * h
    if curvature > 0:
        dt = min(dt, 0.9 * min(dy, dx) ** 2 / (2.0 * 2.0 * curvature))
    band = 1.5 * max(dz, dy, dx)  # phi units: the front moves < 1.5 mm between re-initialisations
    cap = 2.0 * band + max(dz, dy, dx)  # distances beyond the band only need to be "far"
    phi = _signed_distance(initial, spacing, cap)
    out = np.empty_like(phi)
    step = _kernel()
    for i in range(int(iterations)):
        step(phi, image, float(low), float(high), out, dz, dy, dx, float(curvature), dt, band)
        phi, out = out, phi
        if reinit and (i + 1) % reinit == 0 and i + 1 < iterations:
            del out
            inside = phi > 0
            del phi
            phi = _signed_distance(inside, spacing, cap)
            del inside
            out = np.empty_like(phi)
    return phi > 0
