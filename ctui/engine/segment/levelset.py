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
phi is re-initialised to a signed distance every ``reinit`` iterations.

How the work is kept small (the update rule is unchanged):

* the box: only the initial object's bounding box plus the farthest the front can
  travel (one band width per re-initialisation period) is worked on;
* the band: the voxels the front can reach before the next re-initialisation (reinit x dt
  x (1 + c / pixel) + one voxel step) are listed once per re-initialisation as runs along
  x, and each iteration visits only them, writing the new values into a list and then
  into phi (no second volume);
* the signed distance: in-plane distances (OpenCV's 5 x 5 chamfer, inside and outside
  in one array, slices without inside voxels skipped) and a lower envelope along z over
  the slices within the cap, in one numba pass a row at a time;
* a convergence stop: when no voxel changes side for as long as a front at half speed
  needs to cross a voxel.

benchmarks/segment_methods.py compares it with SimpleITK's filter (same start, same
iterations) on a 100 x 200 x 200 region (``--only levelset``, on the loaded 2-core machine):
0.69 s wall, 0.34 s CPU, against SimpleITK's 9.3 s wall, 2.3 s CPU, with the same result as the
full-volume sweep this replaced (2.8 s wall, 0.94 s CPU): 0.994 x truth, Dice 0.997
(SimpleITK 0.984 x, Dice 0.992).
"""

from __future__ import annotations

import numpy as np

_KERNELS: dict = {}


def _step_py(phi, image, runs, new, low, high, dz, dy, dx, c, dt):  # pragma: no cover - compiled by numba
    """One explicit step on the band, given as runs (z, y, x0, x1) along x; new values into ``new``
    (in the runs' order)."""
    nz, ny, nx = phi.shape
    k = 0
    ix = 1.0 / dx  # multiplications, not divisions: the step 25% faster
    iy = 1.0 / dy
    iz = 1.0 / dz
    ixy = 1.0 / (4.0 * dx * dy)
    inv_h = 1.0 / (0.5 * (high - low))
    for r in range(runs.shape[0]):
        z = runs[r, 0]
        y = runs[r, 1]
        z0 = z - 1 if z > 0 else 0
        z1 = z + 1 if z < nz - 1 else nz - 1
        y0 = y - 1 if y > 0 else 0
        y1 = y + 1 if y < ny - 1 else ny - 1
        for x in range(runs[r, 2], runs[r, 3]):
            x0 = x - 1 if x > 0 else 0
            x1 = x + 1 if x < nx - 1 else nx - 1
            p = phi[z, y, x]
            # one-sided differences
            mxm = (p - phi[z, y, x0]) * ix
            mxp = (phi[z, y, x1] - p) * ix
            mym = (p - phi[z, y0, x]) * iy
            myp = (phi[z, y1, x] - p) * iy
            mzm = (p - phi[z0, y, x]) * iz
            mzp = (phi[z1, y, x] - p) * iz
            v = float(image[z, y, x])
            f = min(v - low, high - v) * inv_h  # the threshold speed, +1 mid-range
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
                pxx = (mxp - mxm) * ix
                pyy = (myp - mym) * iy
                pxy = (phi[z, y1, x1] - phi[z, y1, x0] - phi[z, y0, x1] + phi[z, y0, x0]) * ixy
                g2 = px * px + py * py
                if g2 > 1e-12:
                    curv = c * (px * px * pyy + py * py * pxx - 2.0 * px * py * pxy) / g2
            new[k] = p + dt * (prop + curv)
            k += 1


def _commit_py(phi, runs, new):  # pragma: no cover - compiled by numba
    """Write the band's new values into phi; returns (voxels that went inside, voxels that went outside)."""
    k = 0
    grew = 0
    shrank = 0
    for r in range(runs.shape[0]):
        z = runs[r, 0]
        y = runs[r, 1]
        for x in range(runs[r, 2], runs[r, 3]):
            was = phi[z, y, x] > 0
            now = new[k] > 0
            if now and not was:
                grew += 1
            elif was and not now:
                shrank += 1
            phi[z, y, x] = new[k]
            k += 1
    return grew, shrank


def _band_py(phi, band):  # pragma: no cover - compiled by numba
    """The voxels with |phi| <= band as runs along x: int32 (n, 4) z, y, x0, x1 (x1 excluded)."""
    nz, ny, nx = phi.shape
    n = 0
    for z in range(nz):
        for y in range(ny):
            inside = False
            for x in range(nx):
                b = -band <= phi[z, y, x] <= band
                if b and not inside:
                    n += 1
                inside = b
    runs = np.empty((n, 4), np.int32)
    n = 0
    for z in range(nz):
        for y in range(ny):
            inside = False
            for x in range(nx):
                b = -band <= phi[z, y, x] <= band
                if b and not inside:
                    runs[n, 0] = z
                    runs[n, 1] = y
                    runs[n, 2] = x
                    n += 1
                elif inside and not b:
                    runs[n - 1, 3] = x
                inside = b
            if inside:
                runs[n - 1, 3] = nx
    return runs


def _envelope_py(pix, inside, phi, dz, dx, cap):  # pragma: no cover - compiled by numba
    """phi = +-0.5 x the distance (mm, capped) to the other side: ``pix`` holds the in-plane distance
    (pixels; overwritten with squared mm) of every voxel to the nearest voxel of the other side in
    its slice; the lower envelope over the slices within ``cap`` adds the through-plane part. Whole
    rows at a time (SIMD): 8 ms against 29 ms voxel by voxel with an early stop, 2.3 M voxels."""
    nz, ny, nx = pix.shape
    kmax = int(np.ceil(cap / dz))
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                v = min(pix[z, y, x] * dx, cap)
                pix[z, y, x] = v * v
    best = np.empty((ny, nx), np.float32)
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                best[y, x] = pix[z, y, x]
        for k in range(1, kmax + 1):
            step = np.float32((k * dz) * (k * dz))
            for zz in (z - k, z + k):
                if zz < 0 or zz >= nz:
                    continue
                for y in range(ny):
                    for x in range(nx):
                        o = step + (pix[zz, y, x] if inside[zz, y, x] == inside[z, y, x] else np.float32(0))
                        best[y, x] = min(best[y, x], o)
        for y in range(ny):
            for x in range(nx):
                d = np.float32(0.5) * np.sqrt(best[y, x])
                phi[z, y, x] = d if inside[z, y, x] else -d


def _kernel(name: str):
    """The numba-compiled kernel (cached on disk), or the Python one without numba."""
    if name not in _KERNELS:
        fn = {"step": _step_py, "commit": _commit_py, "band": _band_py, "envelope": _envelope_py}[name]
        try:
            from numba import njit

            _KERNELS[name] = njit(cache=True, nogil=True, boundscheck=False)(fn)
        except ImportError:  # pragma: no cover - numba is a declared dependency
            _KERNELS[name] = fn
    return _KERNELS[name]


def _signed_distance(inside: np.ndarray, spacing: tuple[float, float, float], cap: float = 1e9,
                     out: np.ndarray | None = None) -> np.ndarray:
    """Signed distance (float32, positive inside) with the zero level half-way between the boundary
    voxels inside and outside, in half millimetres (the level-set equation moves the zero level the
    same whatever positive factor phi carries). Square pixels with a ``cap``: OpenCV per slice (both
    sides in one array; the 5 x 5 chamfer mask: 1 and 1.4 pixels exact, within 0.4 pixel of the exact
    distance up to 20 pixels, 2.5 times faster) + a numba pass along z (``out`` reused when given);
    otherwise SimpleITK's Maurer maps of the mask and of its complement, averaged."""
    if abs(spacing[1] - spacing[2]) < 1e-6 * spacing[2] and cap < 1e8:
        import cv2

        dz, _, dx = (float(s) for s in spacing)
        m = inside.view(np.uint8) if inside.dtype == bool and inside.flags.c_contiguous else \
            np.ascontiguousarray(inside, dtype=np.uint8)
        sq = np.empty(m.shape, np.float32)  # in-plane distances in pixels, squared mm in the kernel
        inv = np.empty(m.shape[1:], np.uint8)
        far = np.float32(cap / dx + 1.0)
        for z in range(m.shape[0]):
            if not m[z].any():  # no inside voxel in the slice: every voxel is far in-plane
                sq[z] = far
                continue
            np.subtract(1, m[z], out=inv)
            cv2.distanceTransform(m[z], cv2.DIST_L2, cv2.DIST_MASK_5, dst=sq[z])
            sq[z] += cv2.distanceTransform(inv, cv2.DIST_L2, cv2.DIST_MASK_5)  # one side is 0 a pixel
        phi = out if out is not None else np.empty(m.shape, np.float32)
        _kernel("envelope")(sq, m, phi, dz, dx, float(cap))
        return phi
    import SimpleITK as sitk  # heavy import, only here

    acc = None
    for mk, sign in ((inside, 0.5), (~inside, -0.5)):
        img = sitk.GetImageFromArray(mk.astype(np.uint8))
        img.SetSpacing((float(spacing[2]), float(spacing[1]), float(spacing[0])))
        d = sitk.GetArrayFromImage(sitk.SignedMaurerDistanceMap(img, insideIsPositive=True, squaredDistance=False,
                                                                useImageSpacing=True)).astype(np.float32)
        acc = d * np.float32(sign) if acc is None else acc + d * np.float32(sign)
    return acc  # type: ignore[return-value]  # acc is set on the loop's first pass (never None here)


def threshold_speed(image: np.ndarray, low: float, high: float) -> np.ndarray:
    """The threshold speed P (float32, same shape): +1 at the range's middle, 0 at its ends, -1 far outside."""
    h = max((float(high) - float(low)) / 2.0, 1e-6)
    img = np.asarray(image, np.float32)
    sp = img - np.float32(low)  # below the middle the distance to low is the smaller one
    np.minimum(sp, np.float32(high) - img, out=sp)
    sp *= np.float32(1.0 / h)
    return np.clip(sp, -1.0, 1.0, out=sp)


def _reach_box(initial: np.ndarray, margin_mm: float,
               spacing: tuple[float, float, float]) -> tuple[slice, slice, slice] | None:
    """``initial``'s bounding box grown by ``margin_mm`` (clipped to the array); None when empty."""
    out = []
    for axis in range(3):
        others = tuple(a for a in range(3) if a != axis)
        idx = np.flatnonzero(initial.any(axis=others))
        if idx.size == 0:
            return None
        m = int(np.ceil(margin_mm / float(spacing[axis]))) + 1
        out.append(slice(max(int(idx[0]) - m, 0), min(int(idx[-1]) + 1 + m, initial.shape[axis])))
    return tuple(out)  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


def evolve(image: np.ndarray, initial: np.ndarray, *, low: float, high: float, spacing: tuple[float, float, float],
           curvature: float = 1.0, iterations: int = 20, reinit: int = 10,
           patience: int | None = None) -> np.ndarray:
    """Evolve the surface of ``initial`` (bool (nz, ny, nx)) over ``image`` (any numeric dtype, read as
    is: no float copy); returns bool, the inside, the shape of ``image``.

    ``curvature``: weight c of the curvature term; the time step keeps both terms stable
    (at most half the finest voxel side a step for the propagation term).
    ``iterations``: the most iterations; the evolution stops earlier when no voxel has changed
    side for ``patience`` iterations in a row (0: never; None: the iterations a front at half
    the full speed needs to cross the finest voxel side, so only a front slower than that
    everywhere, or at rest, is taken as converged).
    Memory: two float32 arrays of the initial object's box grown by the reach (phi, and the
    squared distances while phi is re-initialised), a uint8 mask of it and the band's lists.
    """
    dz, dy, dx = (float(s) for s in spacing)
    h = min(dz, dy, dx)
    dt = 0.5 * h
    if curvature > 0:
        dt = min(dt, 0.9 * min(dy, dx) ** 2 / (2.0 * 2.0 * curvature))
    # the band (phi units: half millimetres) holds every voxel the front can reach before the next
    # re-initialisation: at most dt a step for the propagation term, dt * c / min(dy, dx) more for the
    # curvature term (curvatures up to one over a pixel), plus one voxel step; never more than the
    # 1.5 voxel steps of the former fixed band
    travel = (reinit or max(int(iterations), 1)) * dt * (1.0 + float(curvature) / min(dy, dx))
    band = min(1.5 * max(dz, dy, dx), 0.5 * (travel + max(dz, dy, dx)))
    cap = 2.0 * band + max(dz, dy, dx)  # distances beyond the band only need to be "far"
    iterations = int(iterations)
    periods = max(1, -(-iterations // reinit)) if reinit else 1
    # a voxel changes only while in the band (2 x band mm of the front, phi being half a distance)
    # of one re-initialisation: the front never gets farther than this from the initial one
    box = _reach_box(initial, periods * 2.0 * band + max(dz, dy, dx), spacing)
    result = np.zeros(initial.shape, bool)
    if box is None:
        return result
    sub = image[box]
    phi = _signed_distance(np.ascontiguousarray(initial[box], dtype=bool), spacing, cap)
    step, commit, listing = _kernel("step"), _kernel("commit"), _kernel("band")
    runs = listing(phi, np.float32(band))
    new = np.empty(int((runs[:, 3] - runs[:, 2]).sum()), np.float32)
    if patience is None:
        patience = int(np.ceil(h / (0.5 * dt)))
    quiet = 0
    for i in range(iterations):
        step(phi, sub, runs, new, float(low), float(high), dz, dy, dx, float(curvature), dt)
        grew, shrank = commit(phi, runs, new)
        quiet = quiet + 1 if grew + shrank == 0 else 0
        if patience and quiet >= patience:
            break
        if reinit and (i + 1) % reinit == 0 and i + 1 < iterations:
            inside = phi > 0
            phi = _signed_distance(inside, spacing, cap, out=phi)
            del inside
            runs = listing(phi, np.float32(band))
            new = np.empty(int((runs[:, 3] - runs[:, 2]).sum()), np.float32)
    np.greater(phi, 0, out=result[box])
    return result
