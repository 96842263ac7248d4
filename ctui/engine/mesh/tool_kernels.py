"""Compiled (numba) kernels of :mod:`ctui.engine.mesh.meshtools`: vertex normals and the
mesh report's topology and integrals in one pass.

Imported only when they run (numba costs 0.2-0.4 s to import and 0.4-0.6 s to start per
process): :mod:`~ctui.engine.mesh.meshtools` uses them when numba is already running in the
process (after compiled marching cubes, in the TUI after the warm-up) or on large meshes,
and its numpy code otherwise (same results).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ctui.engine.mesh import jit

jit.configure_cache()  # the numba cache folder, before the kernels are defined


@njit(cache=True)
def _vertex_normals(v, f):
    n = np.zeros((v.shape[0], 3))
    for t in range(f.shape[0]):
        a, b, c = f[t, 0], f[t, 1], f[t, 2]
        ux = v[b, 0] - v[a, 0]
        uy = v[b, 1] - v[a, 1]
        uz = v[b, 2] - v[a, 2]
        wx = v[c, 0] - v[a, 0]
        wy = v[c, 1] - v[a, 1]
        wz = v[c, 2] - v[a, 2]
        nx = uy * wz - uz * wy
        ny = uz * wx - ux * wz
        nz = ux * wy - uy * wx
        for k in (a, b, c):
            n[k, 0] += nx
            n[k, 1] += ny
            n[k, 2] += nz
    out = np.empty((v.shape[0], 3), np.float32)
    for i in range(v.shape[0]):
        ln = np.sqrt(n[i, 0] ** 2 + n[i, 1] ** 2 + n[i, 2] ** 2)
        if ln == 0.0:
            ln = 1.0
        for c in range(3):
            out[i, c] = n[i, c] / ln
    return out


@njit(cache=True, inline="always")
def _find(parent, a):
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True)
def _vertex_labels(f, nv):
    """Component (0..k-1, numbered by first vertex) of every vertex used by a face (-1 for
    unused ones), joined through shared faces: union-find with path halving."""
    parent = np.arange(nv)
    for t in range(f.shape[0]):
        for j in range(2):
            ra = _find(parent, f[t, j])
            rb = _find(parent, f[t, j + 1])
            if ra < rb:
                parent[rb] = ra
            elif rb < ra:
                parent[ra] = rb
    used = np.zeros(nv, np.bool_)
    for t in range(f.shape[0]):
        for j in range(3):
            used[f[t, j]] = True
    lab = np.full(nv, -1, np.int64)
    ncomp = 0
    for i in range(nv):
        if used[i]:
            r = _find(parent, i)
            if lab[r] < 0:
                lab[r] = ncomp
                ncomp += 1
            lab[i] = lab[r]
    return ncomp, lab


@njit(cache=True)
def _report_kernel(v, f, centre):
    """(components, closed components, edges, boundary edges, non-manifold edges, winding
    consistent, used vertices, area mm², volume mm³ of the closed components) of a mesh:
    vertices ``v`` (n, 3) mm, faces ``f`` (m, 3), volume terms about ``centre`` (3,)."""
    nv = v.shape[0]
    m = f.shape[0]
    ncomp, lab = _vertex_labels(f, nv)
    n_used = 0
    for i in range(nv):
        if lab[i] >= 0:
            n_used += 1
    # half-edges grouped by their lower vertex (counting sort): each undirected edge is
    # found among its lower vertex's few half-edges with a scratch slot per upper vertex
    start = np.zeros(nv + 1, np.int64)
    for t in range(m):
        for j in range(3):
            a, b = f[t, j], f[t, (j + 1) % 3]
            start[min(a, b) + 1] += 1
    for i in range(nv):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    upper = np.empty(3 * m, np.int64)
    fwd = np.empty(3 * m, np.bool_)
    for t in range(m):
        for j in range(3):
            a, b = f[t, j], f[t, (j + 1) % 3]
            lo = min(a, b)
            upper[fill[lo]] = max(a, b)
            fwd[fill[lo]] = a < b
            fill[lo] += 1
    slot = np.full(nv, -1, np.int64)
    maxdeg = 0
    for i in range(nv):
        maxdeg = max(maxdeg, start[i + 1] - start[i])
    cnt = np.zeros(maxdeg, np.int64)
    fw = np.zeros(maxdeg, np.int64)
    bad = np.zeros(ncomp, np.bool_)
    n_edges = boundary = nonman = 0
    consistent = True
    for lo in range(nv):
        k = 0
        for h in range(start[lo], start[lo + 1]):
            u = upper[h]
            if slot[u] < 0:
                slot[u] = k
                cnt[k] = 0
                fw[k] = 0
                k += 1
            cnt[slot[u]] += 1
            fw[slot[u]] += fwd[h]
        for h in range(start[lo], start[lo + 1]):
            slot[upper[h]] = -1
        n_edges += k
        for e in range(k):
            c = cnt[e]
            boundary += c == 1
            nonman += c > 2
            if fw[e] > 1 or c - fw[e] > 1:
                consistent = False
            if c % 2 == 1:
                bad[lab[lo]] = True
    area = 0.0
    per_comp = np.zeros(ncomp)
    for t in range(m):
        a, b, c = f[t, 0], f[t, 1], f[t, 2]
        ax = v[a, 0] - centre[0]
        ay = v[a, 1] - centre[1]
        az = v[a, 2] - centre[2]
        ux = (v[b, 0] - centre[0]) - ax
        uy = (v[b, 1] - centre[1]) - ay
        uz = (v[b, 2] - centre[2]) - az
        wx = (v[c, 0] - centre[0]) - ax
        wy = (v[c, 1] - centre[1]) - ay
        wz = (v[c, 2] - centre[2]) - az
        nx = uy * wz - uz * wy
        ny = uz * wx - ux * wz
        nz = ux * wy - uy * wx
        area += 0.5 * np.sqrt(nx * nx + ny * ny + nz * nz)
        per_comp[lab[a]] += (ax * nx + ay * ny + az * nz) / 6.0
    vol = 0.0
    closed = 0
    for c in range(ncomp):
        if not bad[c]:
            closed += 1
            vol += per_comp[c]
    return ncomp, closed, n_edges, boundary, nonman, consistent, n_used, area, vol
