"""Tiling kernels of :mod:`ctui.engine.mesh.contour_connect`: triangulate the band between
two closed loops of adjacent slices (minimum-area DP or greedy shortest diagonal),
compiled with numba (``cache=True``; see :mod:`ctui.engine.mesh.jit`).
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

from ctui.engine.mesh import jit
from ctui.engine.mesh.contour_tiling_py import tile_range_py

jit.configure_cache()  # the numba cache folder, before the kernels are defined

# --------------------------------------------------------------------------- tiling kernels


@njit(cache=True, nogil=True)
def _tri_area(a0, a1, a2, b0, b1, b2, c0, c1, c2):
    ux = b0 - a0
    uy = b1 - a1
    uz = b2 - a2
    vx = c0 - a0
    vy = c1 - a1
    vz = c2 - a2
    cx = uy * vz - uz * vy
    cy = uz * vx - ux * vz
    cz = ux * vy - uy * vx
    return 0.5 * math.sqrt(cx * cx + cy * cy + cz * cz)


@njit(cache=True, nogil=True)
def _closest_start(P, Q):
    """Index in Q of the point closest to P[0]."""
    best = 1e300
    bj = 0
    for j in range(Q.shape[0]):
        d = (Q[j, 0] - P[0, 0]) ** 2 + (Q[j, 1] - P[0, 1]) ** 2 + (Q[j, 2] - P[0, 2]) ** 2
        if d < best:
            best = d
            bj = j
    return bj


@njit(cache=True, nogil=True)
def tile_dp(P, Q, pid, qid, band):
    """Minimum-area tiling of two closed loops P (n, 3), Q (m, 3) (same orientation).

    Returns triangles (n + m, 3) of ids from ``pid`` / ``qid``, oriented so that for
    counter-clockwise loops (seen from +z) with Q above P the normals point outwards.
    The path starts at P[0] and the point of Q closest to it. ``band``: half-width
    (in points of Q) of the searched band around the arc-length diagonal ``j = i m / n``
    (<= 0: the full table); the band is doubled while the best path touches its edge,
    so the result is the full table's optimum whenever that lies inside a band.
    """
    b = band
    while True:
        t, touched = _tile_dp_band(P, Q, pid, qid, b)
        if b <= 0 or (t.shape[0] > 0 and not touched):
            return t
        b = 2 * b
        if 2 * b + 2 >= Q.shape[0] + 1:
            b = 0


@njit(cache=True, nogil=True)
def _tile_dp_band(P, Q, pid, qid, band):
    """DP within one band; returns (triangles, whether the path touches the band edge)."""
    n = P.shape[0]
    m = Q.shape[0]
    s = _closest_start(P, Q)
    # unrolled copies: P2[i] = P[i % n], Q2[j] = Q[(j + s) % m], for i <= n, j <= m
    P2 = np.empty((n + 1, 3))
    Q2 = np.empty((m + 1, 3))
    for i in range(n + 1):
        for c in range(3):
            P2[i, c] = P[i % n, c]
    for j in range(m + 1):
        for c in range(3):
            Q2[j, c] = Q[(j + s) % m, c]
    if band <= 0 or 2 * band + 2 >= m + 1:
        W = m + 1
        full = True
    else:
        W = 2 * band + 2
        full = False
    lo = np.empty(n + 1, np.int64)
    for i in range(n + 1):
        if full:
            lo[i] = 0
        else:
            jl = int(i * m / n) - band
            if jl < 0:
                jl = 0
            if jl > m + 1 - W:
                jl = m + 1 - W
            lo[i] = jl
    INF = 1e300
    cost = np.full((n + 1, W), INF)
    choice = np.zeros((n + 1, W), np.uint8)
    cost[0, 0 - lo[0]] = 0.0
    for i in range(n + 1):
        li = lo[i]
        ln = lo[i + 1] if i < n else 0
        px = P2[i, 0]
        py = P2[i, 1]
        pz = P2[i, 2]
        for k in range(W):
            c = cost[i, k]
            if c >= INF:
                continue
            j = li + k
            if i < n:
                kk = j - ln
                if 0 <= kk < W:
                    a = c + _tri_area(px, py, pz, P2[i + 1, 0], P2[i + 1, 1], P2[i + 1, 2],
                                      Q2[j, 0], Q2[j, 1], Q2[j, 2])
                    if a < cost[i + 1, kk]:
                        cost[i + 1, kk] = a
                        choice[i + 1, kk] = 1
            if j < m and k + 1 < W:
                a = c + _tri_area(px, py, pz, Q2[j + 1, 0], Q2[j + 1, 1], Q2[j + 1, 2],
                                  Q2[j, 0], Q2[j, 1], Q2[j, 2])
                if a < cost[i, k + 1]:
                    cost[i, k + 1] = a
                    choice[i, k + 1] = 2
    out = np.empty((n + m, 3), np.int64)
    kend = m - lo[n]
    if kend < 0 or kend >= W or cost[n, kend] >= INF:
        return out[:0], True
    i = n
    j = m
    t = n + m - 1
    touched = False
    while i > 0 or j > 0:
        kk = j - lo[i]
        if not full and ((kk == 0 and lo[i] > 0) or (kk == W - 1 and lo[i] + W - 1 < m)):
            touched = True
        ch = choice[i, kk]
        if ch == 1:
            i -= 1
            out[t, 0] = pid[i % n]
            out[t, 1] = pid[(i + 1) % n]
            out[t, 2] = qid[(j + s) % m]
        elif ch == 2:
            j -= 1
            out[t, 0] = pid[i % n]
            out[t, 1] = qid[(j + 1 + s) % m]
            out[t, 2] = qid[(j + s) % m]
        else:
            return out[:0], True
        t -= 1
    return out, touched


@njit(cache=True, nogil=True)
def tile_greedy(P, Q, pid, qid):
    """Shortest-diagonal tiling (Christiansen): advance on the loop whose next
    diagonal is shorter. Same conventions as :func:`tile_dp`."""
    n = P.shape[0]
    m = Q.shape[0]
    s = _closest_start(P, Q)
    out = np.empty((n + m, 3), np.int64)
    i = 0
    j = 0
    k = 0
    while i < n or j < m:
        pi = i % n
        pn = (i + 1) % n
        qj = (j + s) % m
        qn = (j + 1 + s) % m
        adv_p = False
        if j >= m:
            adv_p = True
        elif i < n:
            d1 = (P[pn, 0] - Q[qj, 0]) ** 2 + (P[pn, 1] - Q[qj, 1]) ** 2 + (P[pn, 2] - Q[qj, 2]) ** 2
            d2 = (P[pi, 0] - Q[qn, 0]) ** 2 + (P[pi, 1] - Q[qn, 1]) ** 2 + (P[pi, 2] - Q[qn, 2]) ** 2
            adv_p = d1 <= d2
        if adv_p:
            out[k, 0] = pid[pi]
            out[k, 1] = pid[pn]
            out[k, 2] = qid[qj]
            i += 1
        else:
            out[k, 0] = pid[pi]
            out[k, 1] = qid[qn]
            out[k, 2] = qid[qj]
            j += 1
        k += 1
    return out


@njit(cache=True, nogil=True)
def _tile_range(P, poff, pid, Q, qoff, qid, bands, use_dp, toff, out, ok, k0, k1):
    """Tile pairs k0 .. k1 - 1 (see :func:`tile_many`); releases the GIL."""
    for k in range(k0, k1):
        a0, a1 = poff[k], poff[k + 1]
        b0, b1 = qoff[k], qoff[k + 1]
        if use_dp:
            t = tile_dp(P[a0:a1], Q[b0:b1], pid[a0:a1], qid[b0:b1], bands[k])
            if t.shape[0] == 0:
                t = tile_dp(P[a0:a1], Q[b0:b1], pid[a0:a1], qid[b0:b1], 0)
        else:
            t = tile_greedy(P[a0:a1], Q[b0:b1], pid[a0:a1], qid[b0:b1])
        if t.shape[0] != toff[k + 1] - toff[k]:
            ok[k] = 0
            continue
        out[toff[k]:toff[k + 1]] = t


def tile_many(P, poff, pid, Q, qoff, qid, bands, use_dp, toff, out, *, threads: int | None = None):
    """Tile many loop pairs: pair k is P[poff[k]:poff[k+1]] with Q[qoff[k]:qoff[k+1]]; its
    n + m triangles go to out[toff[k]:toff[k+1]]. Returns per pair 1 (ok) or 0 (band too
    narrow: caller retries with the full table).

    Chunks of pairs (balanced by their table sizes) run in threads on a GIL-free kernel:
    the same work split as the former ``prange`` loop, without the parallel compiler's
    cost on first use (50 s -> 15 s to compile on a loaded 2-core machine).
    """
    npair = poff.shape[0] - 1
    ok = np.ones(npair, np.int64)
    if int(poff[-1] + qoff[-1]) <= PY_TILING_MAX_POINTS and not kernels_ready():
        # a fresh install: the same tiling in plain Python now (no compilation; the DP
        # kernel takes 5-60 s to compile), the kernels compiled in the background
        jit.compile_in_background()
        tile_range_py(P, poff, pid, Q, qoff, qid, bands, use_dp, toff, out, ok)
        return ok
    n = max(1, min(int(threads or os.cpu_count() or 1), npair // 4))
    if n == 1:
        _tile_range(P, poff, pid, Q, qoff, qid, bands, use_dp, toff, out, ok, 0, npair)
        return ok

    work = np.cumsum(np.diff(poff) * np.diff(qoff))
    cuts = np.searchsorted(work, work[-1] * np.arange(1, n) / n)
    bounds = np.unique(np.concatenate([[0], cuts, [npair]]))
    with ThreadPoolExecutor(len(bounds) - 1) as ex:
        list(ex.map(lambda i: _tile_range(P, poff, pid, Q, qoff, qid, bands, use_dp, toff, out, ok,
                                          int(bounds[i]), int(bounds[i + 1])), range(len(bounds) - 1)))
    return ok


#: contour points up to which a fresh install tiles in plain Python (the same minimum-area
#: tiling, :mod:`ctui.engine.mesh.contour_tiling_py`) rather than waiting for the compiler;
#: beyond it the kernel is compiled in this process (5-60 s) -- the triangles are the same
PY_TILING_MAX_POINTS = 100_000


def kernels_ready() -> bool:
    """Whether the compiled tiling kernel is ready (compiled or cached; ``CTUI_KERNELS``)."""
    return jit.use_compiled([_tile_range])
