"""3D flood fill of an in-range mask from a seed slice (a numba scanline fill).

:func:`fill3d` keeps the voxels of a boolean volume connected to a start mask on one
slice; :func:`fill3d_seeds` the voxels connected to any of a list of seed voxels.
Until a process has loaded the numba kernel, a large mask with few x-runs (an organ's
range in its box) is filled by joining its runs (:func:`_runs`, scipy's connected
components of the run graph), which does not load numba (:data:`RUN_FILL_RUNS`). Every path
gives the same voxels (tests/engine/segment/test_propagate.py, tests/engine/segment/test_segment_memory.py).
"""

from __future__ import annotations

import numpy as np


def fill3d(inrange: np.ndarray, z: int, start_mask: np.ndarray, *, connectivity: int = 8) -> np.ndarray:
    """Voxels of ``inrange`` (bool (nz, ny, nx)) connected to ``start_mask`` (bool (ny, nx)) on slice ``z``.

    Connectivity in 3D: 6 for ``connectivity=4``; in-plane 8 plus the voxel above and
    below for ``connectivity=8``. A numba scanline flood fill (runs along x, so memory
    is read in order) visits only the component: on 300x512x512 it took 0.15 s on a
    70%-noisy block and a few ms on solid objects, against about 0.4 s for
    ``scipy.ndimage.label`` of the whole mask (equal results: tests/engine/segment/test_propagate.py).
    A plain voxel-by-voxel depth-first numba fill was slower than scipy (cache misses)
    and was dropped. scipy labels instead when numba is missing, and for small volumes while numba
    is not loaded yet (:data:`SMALL_FILL`); large masks with few runs are filled by their runs then.
    """
    inr = np.ascontiguousarray(inrange, dtype=bool)
    start = start_mask.astype(bool) & inr[z]
    yx = np.argwhere(start)
    seeds = np.column_stack([np.full(len(yx), z), yx]).astype(np.int32)
    return _fill(inr, seeds, connectivity)


def _scanline_fill_py(inr, seeds, out, eight):  # pragma: no cover - compiled by numba
    nz, ny, nx = inr.shape
    cap = max(seeds.shape[0] * 2, 4096)
    stack = np.empty((cap, 3), np.int32)
    top = 0
    for i in range(seeds.shape[0]):
        stack[top, 0] = seeds[i, 0]
        stack[top, 1] = seeds[i, 1]
        stack[top, 2] = seeds[i, 2]
        top += 1
    e = 1 if eight else 0
    while top > 0:
        top -= 1
        z = stack[top, 0]
        y = stack[top, 1]
        x = stack[top, 2]
        if inr[z, y, x] == 0 or out[z, y, x] != 0:
            continue
        xl = x
        while xl > 0 and inr[z, y, xl - 1] != 0 and out[z, y, xl - 1] == 0:
            xl -= 1
        xr = x
        while xr < nx - 1 and inr[z, y, xr + 1] != 0 and out[z, y, xr + 1] == 0:
            xr += 1
        for xx in range(xl, xr + 1):
            out[z, y, xx] = 1
        for k in range(4):
            if k == 0:
                zz = z
                yy = y - 1
                a = xl - e
                b = xr + e
            elif k == 1:
                zz = z
                yy = y + 1
                a = xl - e
                b = xr + e
            elif k == 2:
                zz = z - 1
                yy = y
                a = xl
                b = xr
            else:
                zz = z + 1
                yy = y
                a = xl
                b = xr
            if zz < 0 or zz >= nz or yy < 0 or yy >= ny:
                continue
            a = max(a, 0)
            b = min(b, nx - 1)
            inseg = False
            for xx in range(a, b + 1):
                if inr[zz, yy, xx] != 0 and out[zz, yy, xx] == 0:
                    if not inseg:
                        if top >= stack.shape[0]:
                            bigger = np.empty((stack.shape[0] * 2, 3), np.int32)
                            bigger[:top] = stack[:top]
                            stack = bigger
                        stack[top, 0] = zz
                        stack[top, 1] = yy
                        stack[top, 2] = xx
                        top += 1
                        inseg = True
                else:
                    inseg = False


_SCAN: list = []


def _scanline_kernel():
    """The numba-compiled scanline fill (compiled once, cached on disk), or None."""
    if not _SCAN:
        try:
            from numba import njit

            _SCAN.append(njit(cache=True, nogil=True)(_scanline_fill_py))
        except ImportError:  # pragma: no cover
            _SCAN.append(None)
    return _SCAN[0]


def _label_fill(inr: np.ndarray, seeds: np.ndarray, connectivity: int) -> np.ndarray:
    """:func:`fill3d_seeds` by scipy's labelling (the same connectivity as the scanline fill)."""
    from scipy import ndimage  # scipy is loaded by the engine anyway; kept next to its one use here

    if not len(seeds):
        return np.zeros(inr.shape, bool)
    lab, n = ndimage.label(inr, structure=_structure(connectivity))
    keep = np.zeros(n + 1, bool)
    keep[lab[tuple(seeds.T)]] = True
    keep[0] = False
    return keep[lab]


def _structure(connectivity: int) -> np.ndarray:
    st = np.zeros((3, 3, 3), bool)
    st[1] = True if connectivity == 8 else np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)
    st[0, 1, 1] = st[2, 1, 1] = True
    return st


#: Below this many voxels, while numba is not loaded yet, scipy's labelling fills instead: importing numba
#: and loading the cached kernel costs 0.5-0.7 s a process, scipy.ndimage.label 10-30 ms per million voxels
#: (a kidney from one seed on a small series: 1.2 -> 0.4 s CPU for the whole command).
SMALL_FILL = 2_000_000


def fill3d_seeds(inrange: np.ndarray, seeds_zyx: np.ndarray, *, connectivity: int = 8) -> np.ndarray:
    """Voxels of ``inrange`` (bool (nz, ny, nx)) connected to any seed (int (n, 3) z, y, x). bool, same shape."""
    inr = np.ascontiguousarray(inrange, dtype=bool)
    seeds = np.asarray(seeds_zyx, dtype=np.int32).reshape(-1, 3)
    return _fill(inr, seeds, connectivity)


def _fill(inr: np.ndarray, seeds: np.ndarray, connectivity: int) -> np.ndarray:
    """The fill by the numba kernel once it is loaded; before, by scipy's labelling (small volumes) or by runs
    (:func:`run_fill`, while the mask has few runs); else the kernel is loaded. All give the same voxels."""
    kernel = _SCAN[0] if _SCAN else None
    if kernel is None and inr.size > SMALL_FILL:
        runs = _runs(inr, limit=RUN_FILL_RUNS)
        if runs is not None:
            return _paint_runs(inr.shape, runs, _run_components(runs, inr.shape, seeds, connectivity))
        kernel = _scanline_kernel()
    if kernel is None:
        return _label_fill(inr, seeds, connectivity)
    out = np.zeros(inr.shape, np.uint8)
    if len(seeds):
        kernel(inr.view(np.uint8), np.ascontiguousarray(seeds), out, connectivity == 8)
    return out.view(bool)


#: A mask over SMALL_FILL voxels is filled by its x-runs while it has at most this many: about 200 bytes a run
#: at the peak (80 MB at the limit) against the ~110 MB (llvmlite's library and the JIT) that loading numba's
#: kernel adds to a process, and 1-1.5 s less for a process's first fill (a kidney's sweep box on a
#: 134 x 512 x 512 CT, 134 x 391 x 344 voxels, 82k runs: 0.2 s). A noisy mask has more runs: the kernel fills it.
RUN_FILL_RUNS = 400_000
_SLAB = 16  # slices per step when finding and painting runs (temporaries of 16 slices)


def _runs(inr: np.ndarray, *, limit: int) -> tuple[np.ndarray, ...] | None:
    """The x-runs of a bool (nz, ny, nx) mask: (row = z * ny + y, x0, x1 inclusive) int64 arrays in row-major
    order; None when there are more than ``limit``."""
    nz, ny, nx = inr.shape
    rows, x0s, x1s, n = [], [], [], 0
    for z0 in range(0, nz, _SLAB):
        a = inr[z0:z0 + _SLAB].view(np.int8)
        d = np.diff(a, axis=2, prepend=np.int8(0), append=np.int8(0))  # (s, ny, nx + 1): +1 starts, -1 ends
        st = np.flatnonzero(d == 1)
        n += len(st)
        if n > limit:
            return None
        en = np.flatnonzero(d == -1)
        rows.append(st // (nx + 1) + z0 * ny)
        x0s.append(st % (nx + 1))
        x1s.append(en % (nx + 1) - 1)
    return np.concatenate(rows), np.concatenate(x0s), np.concatenate(x1s)


def _run_components(runs: tuple[np.ndarray, ...], shape: tuple[int, ...], seeds: np.ndarray,
                    connectivity: int) -> np.ndarray:
    """bool per run: joined to a seed voxel (z, y, x) through runs that touch, with the kernel's connectivity
    (rows y +- 1 of a slice overlapping, widened by one voxel for 8; the same row of slices z +- 1 overlapping)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    row, x0, x1 = runs
    n = len(row)
    if not n:
        return np.zeros(0, bool)
    nz, ny, nx = shape
    w = nx + 2  # row * w + x orders runs; x - 1 and x + 1 stay within their row's span
    c0, c1 = row * w + x0, row * w + x1
    src, dst = [], []
    for step, ext, ok in ((1, 1 if connectivity == 8 else 0, row % ny < ny - 1), (ny, 0, row < (nz - 1) * ny)):
        i = np.flatnonzero(ok)
        lo = np.searchsorted(c1, (row[i] + step) * w + x0[i] - ext, side="left")
        hi = np.searchsorted(c0, (row[i] + step) * w + x1[i] + ext, side="right")
        cnt = np.maximum(hi - lo, 0)
        total = int(cnt.sum())
        src.append(np.repeat(i, cnt))
        dst.append(np.repeat(lo - (np.cumsum(cnt) - cnt), cnt) + np.arange(total))
    a, b = np.concatenate(src), np.concatenate(dst)
    _, comp = connected_components(coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(n, n)), directed=False)
    keep = np.zeros(int(comp.max(initial=-1)) + 1, bool)
    if len(seeds):
        s = np.asarray(seeds, np.int64)
        pos = (s[:, 0] * ny + s[:, 1]) * w + s[:, 2]
        k = np.searchsorted(c0, pos, side="right") - 1
        hit = (k >= 0) & (c1[np.maximum(k, 0)] >= pos)
        keep[comp[k[hit]]] = True
    return keep[comp]


def _paint_runs(shape: tuple[int, ...], runs: tuple[np.ndarray, ...], chosen: np.ndarray) -> np.ndarray:
    """bool (nz, ny, nx): the chosen runs' voxels (set by flat index, ``_PAINT`` voxels at a time)."""
    nx = shape[2]
    row, x0, x1 = (r[chosen] for r in runs)
    first, length = row * nx + x0, x1 - x0 + 1
    ends = np.cumsum(length)
    out = np.zeros(shape, bool)
    flat = out.reshape(-1)
    a = 0
    while a < len(row):
        b = max(int(np.searchsorted(ends, (ends[a - 1] if a else 0) + _PAINT, side="right")), a + 1)
        n = length[a:b]
        flat[np.repeat(first[a:b] - (np.cumsum(n) - n), n) + np.arange(int(n.sum()))] = True
        a = b
    return out


_PAINT = 1_000_000  # voxels a step (24 bytes each while painting)
