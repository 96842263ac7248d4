"""Marching squares and marching cubes kernels.

Marching cubes
--------------
:func:`marching_cubes` is an edge-based, multi-pass kernel in the style of VTK's
*flying edges* (Schroeder, Maynard, Geveci 2015), compiled with numba:

1. per x-row of voxels: does the row cross the level anywhere (min/max reduction),
   first/last crossing x-edge ("trims"), number of crossed x-edges, sign at both ends;
2. per row of cells (4 voxel rows): case of every cell inside the trims -> triangle
   count; number of crossed y- and z-edges of the row;
3. prefix sums give every row its vertex and triangle offsets;
4. per row: one vertex per crossed edge (interpolated, in mm, with a normal from the
   volume gradient by central differences), then the triangles of each cell, whose
   vertex ids come from running edge counters, so vertices are shared between cells
   (welded) with no hash table and no duplicate removal.

The data is read in its own dtype (int16 CT is never copied to float); the rows and
regions with no crossing are skipped by the trims.

Case table
----------
The 256-case table is *generated* (:func:`_build_case_table`) from one face rule
applied to every face: on an ambiguous face (two diagonal corners inside, two outside)
the inside corners are separated (the outside corners are joined across the face).
Because the decision depends only on the four values of the face, the two cells
sharing a face always agree, so the surface is crack-free and closed wherever the
object does not touch the volume border (this is the consistent-table approach of
VTK's marching cubes / flying edges; Lewiner's tables add the asymptotic decider for
a more faithful topology, at the price of a larger table). Each cell's edge segments
are chained into loops on the cube surface and fan-triangulated, oriented so that
faces are counter-clockwise seen from *outside* (outside = values <= level), i.e.
normals point down the gradient, away from the high values.

Corner numbering used throughout: ``c = dy + 2*dz + 4*dx`` so that a cell's case is
``left_nibble | right_nibble << 4``, each nibble holding the four voxel rows
(dy, dz) = (0,0), (1,0), (0,1), (1,1) at x and x+1.

Marching squares
----------------
:func:`marching_squares` returns the level lines of a 2D array as (x, y) point arrays.
It delegates to scikit-image's compiled ``find_contours`` (a well-kept library with
the same linear interpolation ``t = (c - c1) / (c2 - c1)``), converted from (row,
col) to (x, y).
"""

from __future__ import annotations

import math

import numpy as np

from ctui.engine.core.limits import check_allocation
from ctui.engine.core.progress import Progress, report
from ctui.engine.mesh import jit
from ctui.engine.mesh.mc_numpy import marching_cubes_numpy
from ctui.engine.mesh.mc_tables import _CORNER_OFFSETS, _EDGES, NTRI, TRI_TABLE

__all__ = ["NTRI", "TRI_TABLE", "_CORNER_OFFSETS", "_EDGES", "kernels_ready", "marching_cubes", "marching_squares"]


def _kernels():
    """The compiled passes (:mod:`ctui.engine.mesh.mc_kernels`), imported on first use: that
    module imports numba (0.2-0.4 s a process), which the numpy path does not need."""
    from ctui.engine.mesh import mc_kernels as k

    return k


def _kernel_list() -> tuple:
    """The dispatchers jit.use_compiled checks (looked up only when needed)."""
    k = _kernels()
    return (k._pass_rows, k._pass_count, k._pass_generate)


_KERNEL_DTYPES = (np.dtype(np.int16), np.dtype(np.float32))
_KERNEL_NAMES = ("_pass_rows", "_pass_count", "_pass_generate")  # as _kernel_list


def _threshold(data: np.ndarray, level: float):
    """Comparison threshold in the data's own dtype: inside <=> value > thr."""
    if np.issubdtype(data.dtype, np.integer):
        info = np.iinfo(data.dtype)
        t = math.floor(level)
        t = min(max(t, int(info.min) - 1), int(info.max))
        if t < info.min:  # every value is inside; compare in a wider type
            return np.int64(t)
        return data.dtype.type(t)
    if data.dtype == np.bool_:
        raise TypeError("boolean data: convert to uint8 first")
    return data.dtype.type(level)


def marching_cubes(
    data: np.ndarray,
    level: float,
    *,
    affine: np.ndarray | None = None,
    normals: bool = True,
    progress: Progress | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Isosurface of a 3D array by edge-based marching cubes.

    Parameters
    ----------
    data : ndarray, shape (nz, ny, nx)
        Any integer or float dtype (int16 and float32 are read in place; bool, int8 and
        uint8 are converted to int16, other types to float32). Voxels with value >
        ``level`` are inside.
    level : float
        Iso value in the data's units.
    affine : ndarray (4, 4), optional
        Maps homogeneous (x, y, z, 1) *indices* to output coordinates (mm); identity
        when omitted (vertices in index units, x first).
    normals : bool
        Compute vertex normals from the volume gradient (central differences),
        outward (towards lower values), unit length.
    progress : callback ``(done, total, message)``, optional (may cancel).

    Returns
    -------
    vertices : ndarray float32 (n, 3), (x, y, z)
    faces : ndarray int32 (m, 3), counter-clockwise seen from outside
    normals : ndarray float32 (n, 3) or None

    The compiled kernels run when they are compiled (in this process or in numba's
    disk cache); before that, the vectorised :func:`~ctui.engine.mesh.mc_numpy.marching_cubes_numpy`
    gives the same mesh without compiling (see :mod:`ctui.engine.mesh.jit`).
    """
    data = np.asarray(data)
    if data.ndim != 3:
        raise ValueError(f"marching_cubes needs a 3D array, got shape {data.shape}")
    if data.dtype == np.bool_:
        data = data.view(np.uint8)
    if data.dtype not in _KERNEL_DTYPES:
        # each dtype is a separate numba compilation (tens of seconds cold): the kernel
        # is compiled for int16 (CT) and float32 (distance fields, MR...); other types
        # are converted (int8/uint8/bool -> int16 exactly, the rest -> float32).
        small_int = data.dtype in (np.dtype(np.int8), np.dtype(np.uint8))
        new = np.int16 if small_int else np.float32
        check_allocation(data.size * np.dtype(new).itemsize, what="a converted copy of the volume for meshing")
        data = data.astype(new)
    if not data.flags.c_contiguous:
        check_allocation(data.nbytes, what="a contiguous copy of the volume for meshing")
        data = np.ascontiguousarray(data)
    nz, ny, nx = data.shape
    aff = np.eye(4) if affine is None else np.asarray(affine, dtype=np.float64)
    m = np.ascontiguousarray(aff[:3, :3])
    org = np.ascontiguousarray(aff[:3, 3])
    empty = (np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros((0, 3), np.float32) if normals else None)
    if min(nz, ny, nx) < 2:
        return empty
    ginv = np.ascontiguousarray(np.linalg.inv(m).T)
    thr = _threshold(data, float(level))
    if isinstance(thr, np.int64) and data.dtype != np.int64:
        # level below the dtype's range: everything inside, no surface
        return empty
    if not jit.use_compiled(_kernel_list, data.dtype, work=int(data.size), cached_in=("mc_kernels", _KERNEL_NAMES)):
        if data.size >= jit.SMALL_WORK:
            jit.compile_in_background()
        return marching_cubes_numpy(data, thr, float(level), m, org, ginv, bool(normals), progress=progress)
    return _marching_cubes_compiled(data, thr, float(level), m, org, ginv, bool(normals), progress) or empty


def _marching_cubes_compiled(data, thr, level, m, org, ginv, normals, progress):
    """The flying-edges passes (:mod:`ctui.engine.mesh.mc_kernels`); None when there is no surface."""
    nz, ny, nx = data.shape
    shape2 = (nz, ny)
    xl = np.empty(shape2, np.int64)
    xr = np.empty(shape2, np.int64)
    sl = np.empty(shape2, np.uint8)
    sr = np.empty(shape2, np.uint8)
    cx = np.empty(shape2, np.int64)
    cy = np.empty(shape2, np.int64)
    cz = np.empty(shape2, np.int64)
    tc = np.empty(shape2, np.int64)
    ta = np.ones(shape2, np.int64)
    tb = np.zeros(shape2, np.int64)
    tlen = np.zeros(shape2, np.int64)
    k = _kernels()
    report(progress, 0, 4, "marching cubes")
    k._pass_rows(data, thr, xl, xr, sl, sr, cx)
    k._pass_trims(xl, xr, sl, sr, ta, tb, tlen, nx)
    noff = np.zeros(nz * ny, np.int64)
    np.cumsum(tlen.ravel()[:-1], out=noff[1:])
    n_nib = int(noff[-1] + tlen.ravel()[-1])
    check_allocation(n_nib, what="marching cubes' cell cases")
    nib = np.empty(n_nib, np.uint8)
    noff = noff.reshape(shape2)
    report(progress, 1, 4, "marching cubes")
    k._pass_count(data, thr, xl, xr, sl, sr, ta, tb, noff, nib, cy, cz, tc, NTRI)
    nv_row = (cx + cy + cz).ravel()
    vbase = np.zeros(nz * ny, np.int64)
    np.cumsum(nv_row[:-1], out=vbase[1:])
    tbase = np.zeros(nz * ny, np.int64)
    np.cumsum(tc.ravel()[:-1], out=tbase[1:])
    nv = int(vbase[-1] + nv_row[-1])
    nt = int(tbase[-1] + tc.ravel()[-1])
    if nt == 0 and nv == 0:
        return None
    check_allocation(nv * 12 * (2 if normals else 1) + nt * 12,
                     what=f"a surface of {nt:,} triangles", hint="raise the iso value or crop the series")
    verts = np.empty((nv, 3), np.float32)
    norms = np.empty((nv, 3) if normals else (1, 3), np.float32)
    faces = np.empty((nt, 3), np.int32)
    report(progress, 2, 4, "marching cubes")
    k._pass_generate(data, thr, level, xl, xr, sl, sr, ta, tb, noff, nib, cx, cy, vbase.reshape(shape2),
                     tbase.reshape(shape2), NTRI, TRI_TABLE, verts, faces, norms, m, org, ginv, normals)
    report(progress, 4, 4, "marching cubes")
    return verts, faces, (norms if normals else None)


def kernels_ready(dtype=np.int16) -> bool:
    """Whether marching cubes' compiled kernels for ``dtype`` data are ready (compiled in
    this process or cached on disk)."""
    return all(jit.is_compiled(k, np.dtype(dtype)) for k in _kernel_list())


# --------------------------------------------------------------------------- squares


def marching_squares(grid2d: np.ndarray, level: float) -> list[np.ndarray]:
    """Level lines of a 2D array.

    Parameters
    ----------
    grid2d : ndarray, shape (ny, nx)
        Values, indexed ``grid2d[y, x]``.
    level : float
        Contour value.

    Returns
    -------
    list of ndarray float64 (n, 2)
        Each contour's points as (x, y) pixel coordinates, one point per crossed grid
        edge, linearly interpolated (``t = (level - c1) / (c2 - c1)``). Closed contours
        repeat their first point at the end (scikit-image's convention).
    """
    from skimage.measure import find_contours

    g = np.asarray(grid2d, dtype=np.float64)
    if g.ndim != 2:
        raise ValueError(f"marching_squares needs a 2D array, got shape {g.shape}")
    return [np.ascontiguousarray(c[:, ::-1]) for c in find_contours(g, level)]
