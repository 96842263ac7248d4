"""Vectorised (numpy) marching cubes giving the *same* mesh as the compiled kernels.

Used while the numba kernels of :mod:`ctui.engine.mesh.mc_kernels` are not compiled yet
(a fresh install: compiling them takes 10-60 s, this path needs no compilation). The
output is identical to the compiled one: the same vertices in the same order (per
voxel row (z, y): the crossed x-edges by x, then the y-edges, then the z-edges), the
same faces in the same order (cells in raster order, the case table's triangles in
order), the same interpolation and gradient normals.

The volume is processed in slabs of z planes, so the extra memory is a few bytes per
voxel of one slab plus the output (and 24 bytes per triangle for the edge keys).
"""

from __future__ import annotations

import numpy as np

from ctui.engine.core.limits import check_allocation
from ctui.engine.core.progress import Progress, report
from ctui.engine.mesh.mc_tables import NTRI, TRI_TABLE

# edge e of a cell -> (axis, dz, dy, dx) of the voxel the edge starts at (see mc_tables)
_EDGE_START = np.array(
    [(0, 0, 0, 0), (0, 0, 1, 0), (0, 1, 0, 0), (0, 1, 1, 0),
     (1, 0, 0, 0), (1, 0, 0, 1), (1, 1, 0, 0), (1, 1, 0, 1),
     (2, 0, 0, 0), (2, 0, 0, 1), (2, 0, 1, 0), (2, 0, 1, 1)], dtype=np.int64)
_SLAB_VOXELS = 1 << 21  # about 2 M voxels per slab
_CHUNK = 1 << 18  # edges or cells per vectorised step (a few hundred bytes each in temporaries)


def _cases(ins: np.ndarray) -> np.ndarray:
    """Case (uint8) of every cell between the planes of ``ins`` (s + 1, ny, nx) bool."""
    u = ins.view(np.uint8)
    # bit = dy + 2 dz + 4 dx of the corner: the x pairs first (bits 0 and 4), then the four
    # (dy, dz) rows of pairs, each shifted by dy + 2 dz (half the passes of one per corner)
    pair = u[:, :, 1:] << np.uint8(4)
    pair |= u[:, :, :-1]
    case = pair[:-1, :-1].copy()
    tmp = np.empty_like(case)
    for shift, (dz, dy) in ((1, (0, 1)), (2, (1, 0)), (3, (1, 1))):
        np.left_shift(pair[dz: pair.shape[0] - 1 + dz, dy: pair.shape[1] - 1 + dy], np.uint8(shift), out=tmp)
        case |= tmp
    return case


def _nonzero3(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``np.nonzero`` of a C-contiguous 3D array: flat indices split by divmod (10x faster
    than numpy's multi-index nonzero on sparse slabs)."""
    _, ny, nx = a.shape
    i = np.flatnonzero(a)
    z, r = np.divmod(i, ny * nx)
    y, x = np.divmod(r, nx)
    return z, y, x


def _slab_edges(ins: np.ndarray, z0: int, n_planes: int, shape: tuple[int, int, int], kept_bytes: int
                ) -> tuple[np.ndarray, ...]:
    """Crossed edges starting in planes z0 .. z0 + n_planes - 1: (key, axis, z, y, x), sorted by key.

    Checks first that this slab's working memory, its output and the final copy of
    everything kept so far (``kept_bytes``) fit, so a huge surface stops with a message."""
    nz, ny, nx = shape
    keys, axes, zs, ys, xs = [], [], [], [], []
    p = ins[:n_planes]
    crossings = [p[:, :, :-1] != p[:, :, 1:], p[:, :-1, :] != p[:, 1:, :]]
    mz = min(n_planes, ins.shape[0] - 1)  # z-edges: not from the volume's last plane
    crossings.append(ins[:mz] != ins[1: mz + 1])
    n = sum(int(np.count_nonzero(c)) for c in crossings)
    # per edge: ~120 bytes of temporaries here and in the vertex step; out: position, normal,
    # key (32 bytes) and about two triangles' keys and ids (2 x 36 bytes); all kept to
    # the end, where they are concatenated once more
    out = n * (32 + 72)
    check_allocation(n * 120 + out + (kept_bytes + out), what=f"a surface of over {2 * n:,} triangles",
                     hint="raise the iso value or crop the series")
    for axis, cross in enumerate(crossings):
        z, y, x = _nonzero3(cross)
        z += z0
        keys.append(((z * ny + y) * 3 + axis) * nx + x)
        axes.append(np.full(len(z), axis, np.int8))
        zs.append(z)
        ys.append(y)
        xs.append(x)
    key = np.concatenate(keys)
    order = np.argsort(key, kind="stable")
    return tuple(np.concatenate(a)[order] for a in (keys, axes, zs, ys, xs))


def _grad_axis(data: np.ndarray, z, y, x, axis: int) -> np.ndarray:
    """Central-difference derivative along ``axis`` (0 x, 1 y, 2 z) at voxels (z, y, x), float64,
    one-sided at the border (as the compiled kernel's ``_grad``)."""
    n = data.shape[2 - axis]
    i = (x, y, z)[axis]
    hi = np.minimum(i + 1, n - 1)
    lo = np.maximum(i - 1, 0)
    idx_hi = [z, y, x]
    idx_lo = [z, y, x]
    idx_hi[2 - axis] = hi
    idx_lo[2 - axis] = lo
    d = data[tuple(idx_hi)].astype(np.float64) - data[tuple(idx_lo)].astype(np.float64)
    interior = (i > 0) & (i < n - 1)
    return np.where(interior, 0.5 * d, d)


def _vertices(data, level, axis, z, y, x, m, org, ginv, with_normals):
    """Positions (mm, float32) and normals of the vertices on the given edges."""
    nz, ny, nx = data.shape
    zb = z + (axis == 2)
    yb = y + (axis == 1)
    xb = x + (axis == 0)
    a = data[z, y, x].astype(np.float64)
    d = data[zb, yb, xb].astype(np.float64) - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d != 0.0, (level - a) / np.where(d != 0.0, d, 1.0), 0.5)
    t = np.clip(t, 1e-3, 0.999)
    idx = np.stack([x, y, z], axis=1).astype(np.float64)
    idx[:, axis] += t
    fidx = idx.astype(np.float32).astype(np.float64)  # the kernel stores index space in float32 first
    norms = None
    if with_normals:
        tt = fidx[:, axis] - (x, y, z)[axis]
        g = []
        for ga in range(3):
            g0 = _grad_axis(data, z, y, x, ga)
            g1 = _grad_axis(data, zb, yb, xb, ga)
            g.append(g0 + tt * (g1 - g0))
        p = [ginv[r, 0] * g[0] + ginv[r, 1] * g[1] + ginv[r, 2] * g[2] for r in range(3)]
        nrm = np.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
        scale = np.where(nrm > 0.0, -1.0 / np.where(nrm > 0.0, nrm, 1.0), nrm)
        norms = np.stack([p[r] * scale for r in range(3)], axis=1).astype(np.float32)
    pos = np.empty((len(t), 3), np.float32)
    for r in range(3):
        pos[:, r] = org[r] + m[r, 0] * fidx[:, 0] + m[r, 1] * fidx[:, 1] + m[r, 2] * fidx[:, 2]
    return pos, norms


def _cells_faces(c: np.ndarray, cz: np.ndarray, cy: np.ndarray, cx: np.ndarray, ny: int, nx: int) -> np.ndarray:
    """Edge keys (k, 3) of the triangles of cells (cz, cy, cx) with cases ``c``, in order.

    A key ``((z * ny + y) * 3 + axis) * nx + x`` splits into the cell's part (its corner
    voxel's, axis 0) plus the edge's offset from it, so each triangle corner is one lookup
    in a (case, triangle) table of offsets and one addition (a third of the temporaries
    of gathering each corner's (axis, dz, dy, dx) and building the key from them)."""
    st = _EDGE_START
    edge_off = ((st[:, 1] * ny + st[:, 2]) * 3 + st[:, 0]) * nx + st[:, 3]  # (12,) key offset of each cell edge
    off = edge_off[TRI_TABLE].reshape(-1, 3)  # (256 * 5, 3): row case * 5 + triangle
    nt = NTRI[c]
    cell = np.repeat(np.arange(len(c)), nt)
    k = np.arange(len(cell)) - np.repeat(np.cumsum(nt) - nt, nt)
    base = (cz * ny + cy) * (3 * nx) + cx  # the cell corner's key, axis 0
    key = off[c[cell].astype(np.int64) * 5 + k]
    key += base[cell][:, None]
    return key


def _slab_faces(case: np.ndarray, z0: int, shape: tuple[int, int, int]) -> np.ndarray:
    """Edge keys (k, 3) of the triangles of the slab's cells, in raster and table order
    (in chunks of cells, so the temporaries stay small on noisy data)."""
    _, ny, nx = shape
    flat = np.flatnonzero((case - np.uint8(1)) < np.uint8(254))  # cases 1..254 have triangles (0, 255 none)
    out = []
    for i in range(0, len(flat), _CHUNK):
        f = flat[i: i + _CHUNK]
        cz, cy, cx = np.unravel_index(f, case.shape)
        out.append(_cells_faces(case.ravel()[f], cz + z0, cy, cx, ny, nx))
    return np.concatenate(out) if out else np.zeros((0, 3), np.int64)


def marching_cubes_numpy(data: np.ndarray, thr, level: float, m: np.ndarray, org: np.ndarray, ginv: np.ndarray,
                         normals: bool, *, progress: Progress | None = None
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Same contract and output as the compiled path of ``marching_cubes`` (inputs already
    prepared there: kernel dtype, C-contiguous, ``thr`` in the data's dtype)."""
    shape = data.shape
    nz, ny, nx = shape
    step = max(1, _SLAB_VOXELS // max(ny * nx, 1))
    keys, poss, nrms, fkeys = [], [], [], []
    kept = 0
    for z0 in range(0, nz - 1, step):
        z1 = min(z0 + step, nz - 1)  # cells between planes z0 .. z1
        ins = data[z0: z1 + 1] > thr
        last = z1 == nz - 1
        n_planes = (z1 - z0) + (1 if last else 0)
        key, axis, z, y, x = _slab_edges(ins, z0, n_planes, shape, kept)
        pos = np.empty((len(key), 3), np.float32)
        nrm = np.empty((len(key), 3), np.float32) if normals else None
        for ax in range(3):
            sel_all = np.flatnonzero(axis == ax)
            for i in range(0, len(sel_all), _CHUNK):
                sel = sel_all[i: i + _CHUNK]
                p, n = _vertices(data, level, ax, z[sel], y[sel], x[sel], m, org, ginv, normals)
                pos[sel] = p
                if normals:
                    nrm[sel] = n
        keys.append(key)
        poss.append(pos)
        if normals:
            nrms.append(nrm)
        fkeys.append(_slab_faces(_cases(ins), z0, shape))
        kept += key.nbytes + pos.nbytes + (nrm.nbytes if normals else 0) + fkeys[-1].nbytes
        report(progress, z1, nz - 1, "marching cubes")
    all_keys = np.concatenate(keys) if keys else np.zeros(0, np.int64)
    verts = np.concatenate(poss) if poss else np.zeros((0, 3), np.float32)
    faces = np.empty((sum(len(k) for k in fkeys), 3), np.int32)
    # a slab's cells use edges starting in its planes or the next slab's first plane: each
    # slab's face keys are looked up among those two slabs' keys only (cache-sized searches,
    # 2-3x faster than one search of all the keys)
    starts = np.concatenate([[0], np.cumsum([len(k) for k in keys])])
    row = 0
    for i, fk in enumerate(fkeys):
        lo, hi = int(starts[i]), int(starts[min(i + 2, len(keys))])
        faces[row: row + len(fk)] = np.searchsorted(all_keys[lo:hi], fk) + lo
        row += len(fk)
    norms = (np.concatenate(nrms) if nrms else np.zeros((0, 3), np.float32)) if normals else None
    return verts, faces, norms
