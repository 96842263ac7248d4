"""Discrete marching cubes of a multi-label label map in one pass.

:func:`multilabel_marching_cubes` walks the cells of a label map once and emits, for
every object present at a cell's eight corners, that object's triangles (the corners
holding the object are "inside", every other label, background or another object, is
"outside"). It is the one-pass counterpart of VTK's ``vtkDiscreteFlyingEdges3D``:
one scan gives one closed surface per object, however many objects there are, instead
of one marching-cubes pass per label.

Details
-------
* Vertices sit at the midpoints of the voxel edges whose two labels differ; an edge
  between objects ``a`` and ``b`` carries two vertices at the same place, one for
  each object, so every object's surface is closed on its own (two touching objects
  each get their side of the shared wall).
* Vertices are welded as they are made: two rolling buffers hold the vertex ids of
  the x- and y-edges of the two voxel planes of the current cell layer, one buffer
  those of its z-edges (a few MB for a 512x512 plane, whatever the slice count).
* The case table is :data:`ctui.engine.mesh.marching.TRI_TABLE`, whose ambiguous-face rule
  depends only on a face's four corners, so neighbouring cells agree and surfaces
  have no cracks. Faces are counter-clockwise seen from outside the object.
* Only the bounding box of the non-zero labels (plus one voxel of background on
  every side) is scanned; voxel rows that are background in all four rows of a cell
  row are skipped whole.

The surfaces are terraced (the voxels' staircase, like any discrete marching cubes);
:func:`ctui.engine.mesh.surface.label_surfaces` uses this kernel for ``smooth=False`` and a
smoothed signed distance per object for smooth surfaces.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Sequence

import numpy as np
from numba import njit

from ctui.engine.mesh import jit
from ctui.engine.mesh.marching import _CORNER_OFFSETS, _EDGES, NTRI, TRI_TABLE

jit.configure_cache()  # the numba cache folder, before the kernels are defined

# per table edge: axis (0 x, 1 y, 2 z) and the offsets (dx, dy, dz) of its lower corner
_EDGE_AXIS = np.array([0] * 4 + [1] * 4 + [2] * 4, dtype=np.int64)
_EDGE_LOW = np.array([_CORNER_OFFSETS[a] for a, _ in _EDGES], dtype=np.int64)
_EDGE_A = np.array([a for a, _ in _EDGES], dtype=np.int64)


@njit(cache=True, nogil=True)
def _grow_f(a, n):
    b = np.empty((max(2 * a.shape[0], n), a.shape[1]), a.dtype)
    b[: a.shape[0]] = a
    return b


@njit(cache=True, nogil=True)
def _grow_i(a, n):
    b = np.empty(max(2 * a.shape[0], n), a.dtype)
    b[: a.shape[0]] = a
    return b


@njit(cache=True, nogil=True, inline="always")
def _both_empty(empty, z0, y0, z1, y1):
    """Both voxel rows are all background: no edge between them is crossed."""
    return empty[z0, y0] and empty[z1, y1]


@njit(cache=True, nogil=True)
def _reserve(verts, vlab, need):
    """Room for ``need`` vertices (grown once per plane for the plane's worst case,
    so the inner loops write without checks)."""
    if need > verts.shape[0]:
        verts = _grow_f(verts, need)
        vlab = _grow_i(vlab, need)
    return verts, vlab


@njit(cache=True, nogil=True, inline="always")
def _set_vertex(verts, vlab, nv, x, y, z, lv):
    verts[nv, 0] = x
    verts[nv, 1] = y
    verts[nv, 2] = z
    vlab[nv] = lv


@njit(cache=True, nogil=True)
def _plane_vertices(lab, empty, z, buf, verts, vlab, nv):
    """Vertices of the x- and y-edges of voxel plane z; ids into buf (ny, nx, 2, 2)
    (only the entries of crossed edges are written, and only those are read)."""
    ny, nx = lab.shape[1], lab.shape[2]
    verts, vlab = _reserve(verts, vlab, nv + 4 * ny * nx)
    for y in range(ny):
        if not empty[z, y]:  # x-edges of row y
            for x in range(nx - 1):
                la = lab[z, y, x]
                lb = lab[z, y, x + 1]
                if la == lb:
                    continue
                if la != 0:
                    _set_vertex(verts, vlab, nv, x + 0.5, y, z, la)
                    buf[y, x, 0, 0] = nv
                    nv += 1
                if lb != 0:
                    _set_vertex(verts, vlab, nv, x + 0.5, y, z, lb)
                    buf[y, x, 0, 1] = nv
                    nv += 1
        if y + 1 < ny and not _both_empty(empty, z, y, z, y + 1):  # y-edges between rows y, y+1
            for x in range(nx):
                la = lab[z, y, x]
                lb = lab[z, y + 1, x]
                if la == lb:
                    continue
                if la != 0:
                    _set_vertex(verts, vlab, nv, x, y + 0.5, z, la)
                    buf[y, x, 1, 0] = nv
                    nv += 1
                if lb != 0:
                    _set_vertex(verts, vlab, nv, x, y + 0.5, z, lb)
                    buf[y, x, 1, 1] = nv
                    nv += 1
    return verts, vlab, nv


@njit(cache=True, nogil=True)
def _z_vertices(lab, empty, z, zbuf, verts, vlab, nv):
    """Vertices of the z-edges between voxel planes z and z+1; ids into zbuf (ny, nx, 2)."""
    ny, nx = lab.shape[1], lab.shape[2]
    verts, vlab = _reserve(verts, vlab, nv + 2 * ny * nx)
    for y in range(ny):
        if _both_empty(empty, z, y, z + 1, y):
            continue
        for x in range(nx):
            la = lab[z, y, x]
            lb = lab[z + 1, y, x]
            if la == lb:
                continue
            if la != 0:
                _set_vertex(verts, vlab, nv, x, y, z + 0.5, la)
                zbuf[y, x, 0] = nv
                nv += 1
            if lb != 0:
                _set_vertex(verts, vlab, nv, x, y, z + 0.5, lb)
                zbuf[y, x, 1] = nv
                nv += 1
    return verts, vlab, nv


@njit(cache=True, nogil=True)
def _kernel(lab, empty, z_start, z_stop, ntri_t, table, edge_axis, edge_low, edge_a):
    """Cell layers z_start <= z < z_stop; vertices of voxel planes z_start..z_stop.

    Returns verts (n, 3) index (x, y, z), vertex labels, tris, triangle labels and the
    vertex id ranges of the first plane's and the last plane's x/y-edge vertices
    (the planes shared with the neighbouring chunks)."""
    nz, ny, nx = lab.shape
    cap = 4096
    verts = np.empty((cap, 3), np.float32)
    vlab = np.empty(cap, np.int32)
    tris = np.empty((cap, 3), np.int32)
    tlab = np.empty(cap, np.int32)
    nv = 0
    nt = 0
    bufs = np.empty((2, ny, nx, 2, 2), np.int32)
    zbuf = np.empty((ny, nx, 2), np.int32)
    vals = np.empty(8, lab.dtype)
    labs = np.empty(8, lab.dtype)
    verts, vlab, nv = _plane_vertices(lab, empty, z_start, bufs[z_start & 1], verts, vlab, nv)
    first_end = nv
    last_start = nv
    last_end = nv
    for z in range(z_start, z_stop):
        last_start = nv
        verts, vlab, nv = _plane_vertices(lab, empty, z + 1, bufs[(z + 1) & 1], verts, vlab, nv)
        last_end = nv
        verts, vlab, nv = _z_vertices(lab, empty, z, zbuf, verts, vlab, nv)
        for y in range(ny - 1):
            if (_both_empty(empty, z, y, z, y + 1) and _both_empty(empty, z, y, z + 1, y)
                    and _both_empty(empty, z, y, z + 1, y + 1)):
                continue
            # the cell's corners c = dy + 2*dz + 4*dx: its left face (x) is corners 0-3,
            # its right face (x + 1) corners 4-7; a face whose four voxels are equal and
            # equal to the next face's makes a uniform cell (no surface), skipped
            pa = lab[z, y, 0]
            pb = lab[z, y + 1, 0]
            pc = lab[z + 1, y, 0]
            pd = lab[z + 1, y + 1, 0]
            puni = pa == pb and pa == pc and pa == pd
            for x in range(nx - 1):
                qa = lab[z, y, x + 1]
                qb = lab[z, y + 1, x + 1]
                qc = lab[z + 1, y, x + 1]
                qd = lab[z + 1, y + 1, x + 1]
                quni = qa == qb and qa == qc and qa == qd
                if puni and quni and pa == qa:
                    continue
                vals[0] = pa
                vals[1] = pb
                vals[2] = pc
                vals[3] = pd
                vals[4] = qa
                vals[5] = qb
                vals[6] = qc
                vals[7] = qd
                pa, pb, pc, pd, puni = qa, qb, qc, qd, quni
                # the distinct non-zero labels of the cell
                nl = 0
                for c in range(8):
                    v = vals[c]
                    if v == 0:
                        continue
                    seen = False
                    for k in range(nl):
                        if labs[k] == v:
                            seen = True
                            break
                    if not seen:
                        labs[nl] = v
                        nl += 1
                for k in range(nl):
                    lv = labs[k]
                    case = 0
                    for c in range(8):
                        if vals[c] == lv:
                            case |= 1 << c
                    m = ntri_t[case]
                    if m == 0:
                        continue
                    if nt + m > tris.shape[0]:
                        tris = _grow_f(tris, nt + m)
                        tlab = _grow_i(tlab, nt + m)
                    for t in range(m):
                        for j in range(3):
                            e = table[case, t, j]
                            side = 0 if vals[edge_a[e]] == lv else 1
                            dx, dy, dz = edge_low[e, 0], edge_low[e, 1], edge_low[e, 2]
                            ax = edge_axis[e]
                            if ax == 2:
                                vid = zbuf[y + dy, x + dx, side]
                            else:
                                vid = bufs[(z + dz) & 1, y + dy, x + dx, ax, side]
                            tris[nt, j] = vid
                        tlab[nt] = lv
                        nt += 1
    return verts[:nv], vlab[:nv], tris[:nt], tlab[:nt], first_end, last_start, last_end


def _run_chunks(crop: np.ndarray, empty: np.ndarray, threads: int):
    """Run the kernel on z chunks in threads (numba releases the GIL) and weld the
    planes the chunks share: each chunk makes the vertices of its first and last voxel
    planes in the same scan order, so chunk k+1's first-plane vertices are chunk k's
    last-plane vertices, one for one."""
    nzc = crop.shape[0] - 1  # cell layers
    n = max(1, min(int(threads), nzc // 8 or 1))
    # balance the chunks by work: the rows holding objects, not the slice count
    work = np.cumsum((~empty[:-1]).sum(axis=1) + (~empty[1:]).sum(axis=1) + 1)
    bounds = np.concatenate([[0], np.searchsorted(work, work[-1] * np.arange(1, n) / n) + 1, [nzc]])
    bounds = np.unique(np.clip(bounds, 0, nzc))
    n = len(bounds) - 1
    args = (NTRI, TRI_TABLE, _EDGE_AXIS, _EDGE_LOW, _EDGE_A)
    if n == 1:
        parts = [_kernel(crop, empty, 0, nzc, *args)]
    else:
        with ThreadPoolExecutor(n) as ex:
            parts = list(ex.map(lambda k: _kernel(crop, empty, int(bounds[k]), int(bounds[k + 1]), *args),
                                range(n)))
    verts, vlabs, tris, tlabs = [], [], [], []
    base = 0
    prev_last = None  # (start, end) in global ids of the previous chunk's last plane
    for v, vl, t, tl, first_end, last_start, last_end in parts:
        # chunk ids -> global ids: its own vertices follow the ones kept so far; those of
        # its first plane (all but the first chunk's) are the previous chunk's last plane
        dup = 0 if prev_last is None else first_end
        offset = base - dup
        t2 = t + np.int32(offset)
        if dup:
            ps, pe = prev_last
            if pe - ps != dup:
                raise RuntimeError("multilabel marching cubes: chunk seam mismatch")
            seam = t < dup
            t2[seam] = t[seam] + np.int32(ps)
        verts.append(v[dup:])
        vlabs.append(vl[dup:])
        tris.append(t2)
        tlabs.append(tl)
        prev_last = (last_start + offset, last_end + offset)
        base += len(v) - dup
    return np.concatenate(verts), np.concatenate(vlabs), np.concatenate(tris), np.concatenate(tlabs)


def multilabel_marching_cubes(labels: np.ndarray, *, affine: np.ndarray | None = None,
                              objects: Sequence[int] | None = None, threads: int | None = None
                              ) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """One closed, terraced surface per object of a label map, in one pass.

    Parameters
    ----------
    labels : ndarray (nz, ny, nx) of integers (or whole-valued floats)
        0 background, other values objects (any ids: negative or large ones are
        renumbered for the kernel and reported under their own ids).
    affine : (4, 4), optional
        Maps homogeneous voxel indices (x, y, z, 1) to mm (identity: voxel units).
    objects : sequence of int, optional
        Only these ids (the scan is the same; other objects' triangles are dropped).
    threads : int, optional
        Slabs of slices meshed in parallel (default: the CPU count); the vertices of the
        planes the slabs share are welded, so the result is the same for any count.

    Returns
    -------
    dict {object id: (vertices float32 (n, 3) mm, faces int32 (m, 3))}
        Faces counter-clockwise seen from outside the object (for a right-handed
        affine); objects with no voxel are absent.
    """
    lab = np.asarray(labels)
    if lab.ndim != 3:
        raise ValueError(f"multilabel_marching_cubes needs a 3D label map, got shape {lab.shape}")
    ids_back = None
    if lab.dtype not in (np.uint8, np.uint16):
        if not np.issubdtype(lab.dtype, np.integer) and not np.issubdtype(lab.dtype, np.bool_):
            if lab.size and not np.array_equal(lab, np.round(lab)):
                raise ValueError("a label map holds whole numbers")
        if lab.size and (lab.min() < 0 or lab.max() > 65535):
            # other ids (negative, huge): numbered 1..n for the kernel, mapped back after
            ids = np.unique(lab)
            ids = ids[ids != 0]
            if len(ids) > 65535:
                raise ValueError("more than 65535 objects in a label map")
            inside = lab != 0
            compact = np.zeros(lab.shape, np.uint16)
            compact[inside] = np.searchsorted(ids, lab[inside]) + 1
            lab = compact
            ids_back = np.r_[0, ids].astype(np.int64)  # kernel id -> the caller's id
        else:
            lab = lab.astype(np.uint16)
    nz_any = lab.any(axis=2)  # (nz, ny): rows holding any object (numpy's vectorized any)
    if not nz_any.any():
        return {}
    zs = np.flatnonzero(nz_any.any(axis=1))
    ys = np.flatnonzero(nz_any.any(axis=0))
    xs = np.flatnonzero(lab[zs[0]: zs[-1] + 1, ys[0]: ys[-1] + 1].any(axis=(0, 1)))
    z0, z1, y0, y1, x0, x1 = zs[0], zs[-1] + 1, ys[0], ys[-1] + 1, xs[0], xs[-1] + 1
    crop = np.pad(lab[z0:z1, y0:y1, x0:x1], 1)  # one voxel of background on every side
    # voxel rows all background, (nz, ny) of the padded crop: the crop's x range holds
    # every object voxel of its rows, so the full rows' flags serve
    empty = ~np.pad(nz_any[z0:z1, y0:y1], 1)
    verts, vlab, tris, tlab = _run_chunks(crop, empty, threads or os.cpu_count() or 1)
    # crop index -> volume index -> mm
    shift = np.eye(4)
    shift[:3, 3] = (x0 - 1, y0 - 1, z0 - 1)
    aff = (np.eye(4) if affine is None else np.asarray(affine, dtype=np.float64)) @ shift
    xyz = verts @ aff[:3, :3].T.astype(np.float32)
    xyz += aff[:3, 3].astype(np.float32)
    if np.linalg.det(aff[:3, :3]) < 0:  # mirrored: keep the faces counter-clockwise from outside
        tris = np.ascontiguousarray(tris[:, ::-1])
    wanted = None if objects is None else {int(o) for o in objects}
    if ids_back is not None and wanted is not None:  # the caller's ids -> the kernel's
        fwd = {int(v): k for k, v in enumerate(ids_back) if k}
        wanted = {fwd[o] for o in wanted if o in fwd}
    out: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    nlab = int(max(vlab.max(initial=0), tlab.max(initial=0)))
    # every vertex belongs to exactly one object: group vertices and triangles by
    # object (counting sort, linear) and number the vertices within their object
    vorder, vlocal, vstart, vcount = _group(vlab, nlab)
    torder, _, tstart, tcount = _group(tlab, nlab)
    xyz = xyz[vorder]
    faces = vlocal[tris[torder]]
    for k in range(1, nlab + 1):
        if tcount[k] == 0 or (wanted is not None and k not in wanted):
            continue
        key = k if ids_back is None else int(ids_back[k])
        out[key] = (xyz[vstart[k]: vstart[k] + vcount[k]],
                    np.ascontiguousarray(faces[tstart[k]: tstart[k] + tcount[k]]))
    return out


@njit(cache=True)
def _group(labels, nlab):
    """Counting sort of ids 0..nlab: order, rank within its id, start and count per id."""
    n = labels.shape[0]
    count = np.zeros(nlab + 1, np.int64)
    for i in range(n):
        count[labels[i]] += 1
    start = np.zeros(nlab + 1, np.int64)
    for k in range(1, nlab + 1):
        start[k] = start[k - 1] + count[k - 1]
    pos = start.copy()
    order = np.empty(n, np.int64)
    local = np.empty(n, np.int32)
    for i in range(n):
        k = labels[i]
        order[pos[k]] = i
        local[i] = pos[k] - start[k]
        pos[k] += 1
    return order, local, start, count
