"""The compiled (numba) flying-edges passes of :func:`ctui.engine.mesh.marching.marching_cubes`.

Compiled for int16 (CT) and float32 (distance fields, MR) data only; cached on disk
(``cache=True``; see :mod:`ctui.engine.mesh.jit` for the cache folder). While they are
not compiled yet, :mod:`ctui.engine.mesh.mc_numpy` gives the same mesh.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ctui.engine.mesh import jit

jit.configure_cache()  # the numba cache folder, before the kernels are defined


@njit(cache=True, parallel=True)
def _pass_rows(data, thr, xl, xr, sl, sr, cx):
    """Per voxel row: first/last crossed x-edge, signs at both ends, crossed x-edges."""
    nz, ny, nx = data.shape
    for z in prange(nz):
        for y in range(ny):
            row = data[z, y]
            mn = row[0]
            mx = row[0]
            for x in range(1, nx):
                v = row[x]
                mn = min(mn, v)
                mx = max(mx, v)
            if mx <= thr or mn > thr:
                s = 1 if mn > thr else 0
                xl[z, y] = nx
                xr[z, y] = -1
                sl[z, y] = s
                sr[z, y] = s
                cx[z, y] = 0
                continue
            prev = row[0] > thr
            sl[z, y] = 1 if prev else 0
            first = nx
            last = -1
            cnt = 0
            for x in range(1, nx):
                s2 = row[x] > thr
                if s2 != prev:
                    if first == nx:
                        first = x - 1
                    last = x - 1
                    cnt += 1
                prev = s2
            sr[z, y] = 1 if prev else 0
            xl[z, y] = first
            xr[z, y] = last
            cx[z, y] = cnt


@njit(cache=True, inline="always")
def _trim2(xl, xr, sl, sr, z0, y0, z1, y1, nx):
    a = min(xl[z0, y0], xl[z1, y1])
    b = max(xr[z0, y0], xr[z1, y1])
    if sl[z0, y0] != sl[z1, y1]:
        a = 0
    if sr[z0, y0] != sr[z1, y1]:
        b = nx - 2
    if a > b:
        return 1, 0
    return a, b


@njit(cache=True, inline="always")
def _trim4(xl, xr, sl, sr, z, y, nx):
    a = min(min(xl[z, y], xl[z, y + 1]), min(xl[z + 1, y], xl[z + 1, y + 1]))
    b = max(max(xr[z, y], xr[z, y + 1]), max(xr[z + 1, y], xr[z + 1, y + 1]))
    s = sl[z, y]
    if sl[z, y + 1] != s or sl[z + 1, y] != s or sl[z + 1, y + 1] != s:
        a = 0
    s = sr[z, y]
    if sr[z, y + 1] != s or sr[z + 1, y] != s or sr[z + 1, y + 1] != s:
        b = nx - 2
    if a > b:
        return 1, 0
    return a, b


@njit(cache=True, parallel=True)
def _pass_trims(xl, xr, sl, sr, ta, tb, tlen, nx):
    """Per cell row: x range of cells [ta, tb] that can hold a surface (empty: ta > tb)."""
    nz, ny = xl.shape
    for z in prange(nz - 1):
        for y in range(ny - 1):
            a, b = _trim4(xl, xr, sl, sr, z, y, nx)
            ta[z, y] = a
            tb[z, y] = b
            tlen[z, y] = b - a + 2 if a <= b else 0


@njit(cache=True, parallel=True)
def _pass_count(data, thr, xl, xr, sl, sr, ta, tb, noff, nib, cy, cz, tcount, ntri):
    """Per cell row: nibbles of the voxel columns, triangles; per voxel row: crossed y-, z-edges."""
    nz, ny, nx = data.shape
    for z in prange(nz):
        for y in range(ny):
            cy[z, y] = 0
            cz[z, y] = 0
            tcount[z, y] = 0
        if z == nz - 1:
            # last plane: only y-edges
            for y in range(ny - 1):
                a, b = _trim2(xl, xr, sl, sr, z, y, z, y + 1, nx)
                c = 0
                if a <= b:
                    r0 = data[z, y]
                    r1 = data[z, y + 1]
                    for x in range(a, b + 2):
                        if (r0[x] > thr) != (r1[x] > thr):
                            c += 1
                cy[z, y] = c
            continue
        # last row of the plane: only z-edges
        a, b = _trim2(xl, xr, sl, sr, z, ny - 1, z + 1, ny - 1, nx)
        c = 0
        if a <= b:
            r0 = data[z, ny - 1]
            r1 = data[z + 1, ny - 1]
            for x in range(a, b + 2):
                if (r0[x] > thr) != (r1[x] > thr):
                    c += 1
        cz[z, ny - 1] = c
        for y in range(ny - 1):
            a = ta[z, y]
            b = tb[z, y]
            if a > b:
                continue
            r00 = data[z, y]
            r10 = data[z, y + 1]
            r01 = data[z + 1, y]
            r11 = data[z + 1, y + 1]
            o = noff[z, y] - a
            ccy = 0
            ccz = 0
            nt = 0
            prev = 0
            for x in range(a, b + 2):
                b0 = 1 if r00[x] > thr else 0
                b1 = 1 if r10[x] > thr else 0
                b2 = 1 if r01[x] > thr else 0
                b3 = 1 if r11[x] > thr else 0
                ccy += b0 ^ b1
                ccz += b0 ^ b2
                cur = b0 | (b1 << 1) | (b2 << 2) | (b3 << 3)
                nib[o + x] = cur
                if x > a:
                    nt += ntri[prev | (cur << 4)]
                prev = cur
            cy[z, y] = ccy
            cz[z, y] = ccz
            tcount[z, y] = nt


@njit(cache=True)
def _grad(data, z, y, x, nz, ny, nx):
    """Central-difference gradient (d/dx, d/dy, d/dz) in index units."""
    if x == 0:
        gx = float(data[z, y, 1]) - float(data[z, y, 0]) if nx > 1 else 0.0
    elif x == nx - 1:
        gx = float(data[z, y, x]) - float(data[z, y, x - 1])
    else:
        gx = 0.5 * (float(data[z, y, x + 1]) - float(data[z, y, x - 1]))
    if y == 0:
        gy = float(data[z, 1, x]) - float(data[z, 0, x]) if ny > 1 else 0.0
    elif y == ny - 1:
        gy = float(data[z, y, x]) - float(data[z, y - 1, x])
    else:
        gy = 0.5 * (float(data[z, y + 1, x]) - float(data[z, y - 1, x]))
    if z == 0:
        gz = float(data[1, y, x]) - float(data[0, y, x]) if nz > 1 else 0.0
    elif z == nz - 1:
        gz = float(data[z, y, x]) - float(data[z - 1, y, x])
    else:
        gz = 0.5 * (float(data[z + 1, y, x]) - float(data[z - 1, y, x]))
    return gx, gy, gz


@njit(cache=True, inline="always")
def _put_index(verts, vid, va, vb, level, x, y, z, axis):
    """Vertex ``vid`` on the edge from voxel (x, y, z) along ``axis`` (0 x, 1 y, 2 z), index units."""
    a = float(va)
    d = float(vb) - a
    t = (level - a) / d if d != 0.0 else 0.5
    # a voxel exactly at the level would put the vertices of all its crossed edges on
    # the same point (degenerate triangles; STL readers weld them into non-manifold
    # junk): keep every vertex at least 1/1000 voxel inside its edge
    if t < 1e-3:
        t = 1e-3
    elif t > 0.999:
        t = 0.999
    verts[vid, 0] = x + t if axis == 0 else x
    verts[vid, 1] = y + t if axis == 1 else y
    verts[vid, 2] = z + t if axis == 2 else z


@njit(cache=True, inline="always")
def _put(verts, norms, vid, va, vb, level, x, y, z, axis, data, m, org, ginv, with_normals):
    """Vertex ``vid`` on its edge, finished at once (its normal, then mm): the volume's rows
    around it are still in cache (a separate pass over the vertices re-read them: ~10% of
    the whole isosurface); the same float32 index values and arithmetic as that pass."""
    _put_index(verts, vid, va, vb, level, x, y, z, axis)
    _finish_vertex(data, verts, norms, vid, m, org, ginv, with_normals)


@njit(cache=True, inline="always")
def _finish_vertex(data, verts, norms, i, m, org, ginv, with_normals):
    """Vertex ``i``: index space -> mm, and its gradient normal (interpolated along its edge)."""
    nz, ny, nx = data.shape
    fi = float(verts[i, 0])
    fj = float(verts[i, 1])
    fk = float(verts[i, 2])
    if with_normals:
        x0 = min(int(fi), nx - 1)
        y0 = min(int(fj), ny - 1)
        z0 = min(int(fk), nz - 1)
        tx = fi - x0
        ty = fj - y0
        tz = fk - z0
        x1 = x0
        y1 = y0
        z1 = z0
        t = 0.0
        if tx > 0.0 and x0 + 1 < nx:
            x1 = x0 + 1
            t = tx
        elif ty > 0.0 and y0 + 1 < ny:
            y1 = y0 + 1
            t = ty
        elif tz > 0.0 and z0 + 1 < nz:
            z1 = z0 + 1
            t = tz
        g0x, g0y, g0z = _grad(data, z0, y0, x0, nz, ny, nx)
        g1x, g1y, g1z = _grad(data, z1, y1, x1, nz, ny, nx)
        gx = g0x + t * (g1x - g0x)
        gy = g0y + t * (g1y - g0y)
        gz = g0z + t * (g1z - g0z)
        px = ginv[0, 0] * gx + ginv[0, 1] * gy + ginv[0, 2] * gz
        py = ginv[1, 0] * gx + ginv[1, 1] * gy + ginv[1, 2] * gz
        pz = ginv[2, 0] * gx + ginv[2, 1] * gy + ginv[2, 2] * gz
        nrm = math.sqrt(px * px + py * py + pz * pz)
        if nrm > 0.0:
            nrm = -1.0 / nrm  # outward = down the gradient
        norms[i, 0] = px * nrm
        norms[i, 1] = py * nrm
        norms[i, 2] = pz * nrm
    for r in range(3):
        verts[i, r] = org[r] + m[r, 0] * fi + m[r, 1] * fj + m[r, 2] * fk




@njit(cache=True)
def _edge_row_vertices(data, thr, level, xl, xr, sl, sr, z, y, vid, do_x, do_y, do_z, verts, norms, m, org, ginv,
                       with_normals):
    """Vertices of voxel row (z, y) outside any cell row (last row / last plane)."""
    nz, ny, nx = data.shape
    row = data[z, y]
    if do_x and xl[z, y] <= xr[z, y]:
        for x in range(xl[z, y], xr[z, y] + 1):
            if (row[x] > thr) != (row[x + 1] > thr):
                _put(verts, norms, vid, row[x], row[x + 1], level, x, y, z, 0, data, m, org, ginv, with_normals)
                vid += 1
    if do_y:
        a, b = _trim2(xl, xr, sl, sr, z, y, z, y + 1, nx)
        if a <= b:
            r1 = data[z, y + 1]
            for x in range(a, b + 2):
                if (row[x] > thr) != (r1[x] > thr):
                    _put(verts, norms, vid, row[x], r1[x], level, x, y, z, 1, data, m, org, ginv, with_normals)
                    vid += 1
    if do_z:
        a, b = _trim2(xl, xr, sl, sr, z, y, z + 1, y, nx)
        if a <= b:
            r1 = data[z + 1, y]
            for x in range(a, b + 2):
                if (row[x] > thr) != (r1[x] > thr):
                    _put(verts, norms, vid, row[x], r1[x], level, x, y, z, 2, data, m, org, ginv, with_normals)
                    vid += 1
    return vid


@njit(cache=True, parallel=True)
def _pass_generate(data, thr, level, xl, xr, sl, sr, ta, tb, noff, nib, cx, cy, vbase, tbase, ntri, table,
                   verts, faces, norms, m, org, ginv, with_normals):
    """Every vertex (in mm, with its normal) and every triangle, plane by plane."""
    nz, ny, nx = data.shape
    for z in prange(nz):
        ids = np.empty(12, dtype=np.int64)
        if z == nz - 1:
            # last plane: x- and y-edges of every row, no cells
            for y in range(ny):
                _edge_row_vertices(data, thr, level, xl, xr, sl, sr, z, y, vbase[z, y], True, y < ny - 1, False, verts,
                                   norms, m, org, ginv, with_normals)
            continue
        # last row of the plane: x- and z-edges
        _edge_row_vertices(data, thr, level, xl, xr, sl, sr, z, ny - 1, vbase[z, ny - 1], True, False, True, verts,
                           norms, m, org, ginv, with_normals)
        # cell rows between planes z and z+1: vertices of row (z, y) and the triangles
        for y in range(ny - 1):
            a = ta[z, y]
            b = tb[z, y]
            if a > b:
                continue
            o = noff[z, y] - a
            r00 = data[z, y]
            r10 = data[z, y + 1]
            r01 = data[z + 1, y]
            bx00 = vbase[z, y]
            bx10 = vbase[z, y + 1]
            bx01 = vbase[z + 1, y]
            bx11 = vbase[z + 1, y + 1]
            by00 = bx00 + cx[z, y]
            by01 = bx01 + cx[z + 1, y]
            bz00 = by00 + cy[z, y]
            bz10 = bx10 + cx[z, y + 1] + cy[z, y + 1]
            tid = tbase[z, y]
            prev = nib[o + a]
            for x in range(a, b + 1):
                cur = nib[o + x + 1]
                if cur == prev and (cur == 0 or cur == 15):
                    continue  # empty or full cell, no crossing at column x: nothing to do
                case = prev | (cur << 4)
                xc00 = (prev ^ cur) & 1
                ly00 = (prev ^ (prev >> 1)) & 1
                ly01 = ((prev >> 2) ^ (prev >> 3)) & 1
                lz00 = (prev ^ (prev >> 2)) & 1
                lz10 = ((prev >> 1) ^ (prev >> 3)) & 1
                # this row's own vertices: x-edge at x, y- and z-edges at column x
                if xc00:
                    _put(verts, norms, bx00, r00[x], r00[x + 1], level, x, y, z, 0, data, m, org, ginv, with_normals)
                if ly00:
                    _put(verts, norms, by00, r00[x], r10[x], level, x, y, z, 1, data, m, org, ginv, with_normals)
                if lz00:
                    _put(verts, norms, bz00, r00[x], r01[x], level, x, y, z, 2, data, m, org, ginv, with_normals)
                nt = ntri[case]
                if nt > 0:
                    ids[0] = bx00
                    ids[1] = bx10
                    ids[2] = bx01
                    ids[3] = bx11
                    ids[4] = by00
                    ids[5] = by00 + ly00
                    ids[6] = by01
                    ids[7] = by01 + ly01
                    ids[8] = bz00
                    ids[9] = bz00 + lz00
                    ids[10] = bz10
                    ids[11] = bz10 + lz10
                    for k in range(nt):
                        faces[tid, 0] = ids[table[case, k, 0]]
                        faces[tid, 1] = ids[table[case, k, 1]]
                        faces[tid, 2] = ids[table[case, k, 2]]
                        tid += 1
                # advance the running edge counters past column x
                d = prev ^ cur
                bx00 += xc00
                bx10 += (d >> 1) & 1
                bx01 += (d >> 2) & 1
                bx11 += (d >> 3) & 1
                by00 += ly00
                by01 += ly01
                bz00 += lz00
                bz10 += lz10
                prev = cur
            # the last column's y- and z-edges of this row
            if (prev ^ (prev >> 1)) & 1:
                _put(verts, norms, by00, r00[b + 1], r10[b + 1], level, b + 1, y, z, 1, data, m, org, ginv, with_normals)
            if (prev ^ (prev >> 2)) & 1:
                _put(verts, norms, bz00, r00[b + 1], r01[b + 1], level, b + 1, y, z, 2, data, m, org, ginv, with_normals)
