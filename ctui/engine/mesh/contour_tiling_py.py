"""The tiling kernels of :mod:`ctui.engine.mesh.contour_tiling` in plain Python, for use
before numba has compiled them (a fresh install's first contour mesh).

Same algorithm, same floating-point operations in the same order (IEEE doubles, no
fused multiply-add: numba compiles without ``fastmath``), same tie-breaking, so the
triangles are identical to the compiled kernels' (``tests/engine/mesh/test_cold_start.py`` checks a
real kidney meshed with a cold and a warm numba cache). About 1-2 us per table cell.
"""

from __future__ import annotations

import math

import numpy as np

INF = 1e300


def _closest_start(p0: tuple, q: list) -> int:
    best = 1e300
    bj = 0
    for j, (x, y, z) in enumerate(q):
        dx, dy, dz = x - p0[0], y - p0[1], z - p0[2]
        d = dx * dx + dy * dy + dz * dz
        if d < best:
            best = d
            bj = j
    return bj


def _tri_area(a: tuple, b: tuple, c: tuple) -> float:
    ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    cx = uy * vz - uz * vy
    cy = uz * vx - ux * vz
    cz = ux * vy - uy * vx
    return 0.5 * math.sqrt(cx * cx + cy * cy + cz * cz)


def _band_lows(n: int, m: int, band: int, w: int, full: bool) -> list[int]:
    if full:
        return [0] * (n + 1)
    lo = []
    for i in range(n + 1):
        jl = max(0, int(i * m / n) - band)
        lo.append(min(jl, m + 1 - w))
    return lo


def _tile_dp_band(p: list, q: list, pid: list, qid: list, band: int) -> tuple[list | None, bool]:
    """One band of the minimum-area DP (``contour_tiling._tile_dp_band``)."""
    n, m = len(p), len(q)
    s = _closest_start(p[0], q)
    p2 = [p[i % n] for i in range(n + 1)]
    q2 = [q[(j + s) % m] for j in range(m + 1)]
    full = band <= 0 or 2 * band + 2 >= m + 1
    w = m + 1 if full else 2 * band + 2
    lo = _band_lows(n, m, band, w, full)
    cost = [[INF] * w for _ in range(n + 1)]
    choice = [bytearray(w) for _ in range(n + 1)]
    cost[0][0 - lo[0]] = 0.0
    for i in range(n + 1):
        li = lo[i]
        ln = lo[i + 1] if i < n else 0
        ci, chi = cost[i], choice[i]
        pi = p2[i]
        pn = p2[i + 1] if i < n else None
        cn, chn = (cost[i + 1], choice[i + 1]) if i < n else (None, None)
        for k in range(w):
            c = ci[k]
            if c >= INF:
                continue
            j = li + k
            if i < n:
                kk = j - ln
                if 0 <= kk < w:
                    a = c + _tri_area(pi, pn, q2[j])
                    if a < cn[kk]:
                        cn[kk] = a
                        chn[kk] = 1
            if j < m and k + 1 < w:
                a = c + _tri_area(pi, q2[j + 1], q2[j])
                if a < ci[k + 1]:
                    ci[k + 1] = a
                    chi[k + 1] = 2
    kend = m - lo[n]
    if kend < 0 or kend >= w or cost[n][kend] >= INF:
        return None, True
    return _trace(choice, lo, w, full, n, m, s, pid, qid)


def _trace(choice, lo, w, full, n, m, s, pid, qid) -> tuple[list | None, bool]:
    rows: list = [None] * (n + m)
    i, j, t = n, m, n + m - 1
    touched = False
    while i > 0 or j > 0:
        kk = j - lo[i]
        if not full and ((kk == 0 and lo[i] > 0) or (kk == w - 1 and lo[i] + w - 1 < m)):
            touched = True
        ch = choice[i][kk]
        if ch == 1:
            i -= 1
            rows[t] = (pid[i % n], pid[(i + 1) % n], qid[(j + s) % m])
        elif ch == 2:
            j -= 1
            rows[t] = (pid[i % n], qid[(j + 1 + s) % m], qid[(j + s) % m])
        else:
            return None, True
        t -= 1
    return rows, touched


def tile_dp_py(p: list, q: list, pid: list, qid: list, band: int) -> list | None:
    """``contour_tiling.tile_dp`` (band doubled while the path touches its edge)."""
    b = band
    while True:
        t, touched = _tile_dp_band(p, q, pid, qid, b)
        if b <= 0 or (t is not None and not touched):
            return t
        b = 2 * b
        if 2 * b + 2 >= len(q) + 1:
            b = 0


def tile_greedy_py(p: list, q: list, pid: list, qid: list) -> list:
    """``contour_tiling.tile_greedy``: shortest-diagonal advance."""
    n, m = len(p), len(q)
    s = _closest_start(p[0], q)
    rows = []
    i = j = 0
    while i < n or j < m:
        pi, pn = i % n, (i + 1) % n
        qj, qn = (j + s) % m, (j + 1 + s) % m
        if j >= m:
            adv_p = True
        elif i < n:
            a, b, c, d = p[pn], q[qj], p[pi], q[qn]
            d1 = (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2])
            d2 = (c[0] - d[0]) * (c[0] - d[0]) + (c[1] - d[1]) * (c[1] - d[1]) + (c[2] - d[2]) * (c[2] - d[2])
            adv_p = d1 <= d2
        else:
            adv_p = False
        if adv_p:
            rows.append((pid[pi], pid[pn], qid[qj]))
            i += 1
        else:
            rows.append((pid[pi], qid[qn], qid[qj]))
            j += 1
    return rows


def tile_range_py(P, poff, pid, Q, qoff, qid, bands, use_dp, toff, out, ok) -> None:
    """``contour_tiling._tile_range`` over every pair, in plain Python."""
    pl = [tuple(r) for r in np.asarray(P, np.float64).tolist()]
    ql = [tuple(r) for r in np.asarray(Q, np.float64).tolist()]
    pidl, qidl = pid.tolist(), qid.tolist()
    for k in range(len(poff) - 1):
        a0, a1, b0, b1 = int(poff[k]), int(poff[k + 1]), int(qoff[k]), int(qoff[k + 1])
        args = (pl[a0:a1], ql[b0:b1], pidl[a0:a1], qidl[b0:b1])
        if use_dp:
            t = tile_dp_py(*args, int(bands[k]))
            if t is None:
                t = tile_dp_py(*args, 0)
        else:
            t = tile_greedy_py(*args)
        if t is None or len(t) != toff[k + 1] - toff[k]:
            ok[k] = 0
            continue
        out[toff[k]:toff[k + 1]] = t
