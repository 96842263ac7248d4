"""Marching cubes case table, generated from one face rule (see :mod:`ctui.engine.mesh.marching`).

Corner numbering: ``c = dy + 2*dz + 4*dx``; edges 0-3 along x, 4-7 along y, 8-11
along z. :data:`NTRI` (256,) triangles per case, :data:`TRI_TABLE` (256, maxT, 3) their
edge indices, counter-clockwise seen from outside (outside = values <= level).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

# corner c -> offsets (dx, dy, dz)
_CORNER_OFFSETS = np.array([[(c >> 2) & 1, c & 1, (c >> 1) & 1] for c in range(8)], dtype=np.int64)


def _corner(dx: int, dy: int, dz: int) -> int:
    return dy + 2 * dz + 4 * dx


# edges: 0-3 along x, 4-7 along y, 8-11 along z (see module docstring)
_EDGES = np.array(
    [
        (_corner(0, 0, 0), _corner(1, 0, 0)),
        (_corner(0, 1, 0), _corner(1, 1, 0)),
        (_corner(0, 0, 1), _corner(1, 0, 1)),
        (_corner(0, 1, 1), _corner(1, 1, 1)),
        (_corner(0, 0, 0), _corner(0, 1, 0)),
        (_corner(1, 0, 0), _corner(1, 1, 0)),
        (_corner(0, 0, 1), _corner(0, 1, 1)),
        (_corner(1, 0, 1), _corner(1, 1, 1)),
        (_corner(0, 0, 0), _corner(0, 0, 1)),
        (_corner(1, 0, 0), _corner(1, 0, 1)),
        (_corner(0, 1, 0), _corner(0, 1, 1)),
        (_corner(1, 1, 0), _corner(1, 1, 1)),
    ],
    dtype=np.int64,
)


def _faces_ccw() -> list[list[int]]:
    """The cube's six faces as corner cycles, counter-clockwise seen from outside."""
    faces = []
    for axis in range(3):
        for side in (0, 1):
            corners = [c for c in range(8) if _CORNER_OFFSETS[c][axis] == side]
            pts = _CORNER_OFFSETS[corners].astype(float)
            centre = pts.mean(axis=0)
            normal = np.zeros(3)
            normal[axis] = 1.0 if side else -1.0
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            v = np.cross(normal, u)
            ang = [math.atan2((p - centre) @ v, (p - centre) @ u) for p in pts]
            faces.append([corners[i] for i in np.argsort(ang)])
    return faces


def _edge_faces() -> list[set[int]]:
    """For each cube edge, the two cube faces (axis, side) it lies on, as ints."""
    out = []
    for a, b in _EDGES:
        ca, cb = _CORNER_OFFSETS[a], _CORNER_OFFSETS[b]
        out.append({ax * 2 + int(ca[ax]) for ax in range(3) if ca[ax] == cb[ax]})
    return out


_EDGE_FACES = _edge_faces()
_EDGE_MID = np.array([(_CORNER_OFFSETS[a] + _CORNER_OFFSETS[b]) / 2.0 for a, b in _EDGES])


def _triangulate_loop(loop: list[int]) -> list[tuple[int, int, int]]:
    """Triangulate one edge loop without a diagonal between two vertices on the same
    cube face (such a diagonal would lie in the face and be shared with the
    neighbouring cell: a non-manifold edge). Among the valid triangulations the one
    with the shortest diagonals (at the edge midpoints) is kept."""
    n = len(loop)
    if n == 3:
        return [tuple(loop)]

    def ok(i: int, j: int) -> bool:
        if (j - i) % n in (1, n - 1):
            return True
        return not (_EDGE_FACES[loop[i]] & _EDGE_FACES[loop[j]])

    def dist(i: int, j: int) -> float:
        return float(np.linalg.norm(_EDGE_MID[loop[i]] - _EDGE_MID[loop[j]]))

    @lru_cache(maxsize=None)
    def best(i: int, j: int):
        """Best triangulation of the sub-polygon i..j (i < j), diagonal (i, j) given."""
        if j - i < 2:
            return 0.0, ()
        res = None
        for k in range(i + 1, j):
            if not (ok(i, k) and ok(k, j)):
                continue
            c1, t1 = best(i, k)
            c2, t2 = best(k, j)
            if c1 == math.inf or c2 == math.inf:
                continue
            c = c1 + c2 + (dist(i, k) if k - i > 1 else 0.0) + (dist(k, j) if j - k > 1 else 0.0)
            if res is None or c < res[0]:
                res = (c, t1 + t2 + ((i, k, j),))
        return res if res is not None else (math.inf, ())

    cost, tris = best(0, n - 1)
    if cost == math.inf:
        raise RuntimeError(f"no valid triangulation for edge loop {loop}")
    return [(loop[a], loop[b], loop[c]) for a, b, c in tris]


def _build_case_table() -> tuple[np.ndarray, np.ndarray]:
    """Generate (ntri (256,), tris (256, maxT, 3)) edge-index triangle table."""
    edge_of = {}
    for e, (a, b) in enumerate(_EDGES):
        edge_of[(int(a), int(b))] = e
        edge_of[(int(b), int(a))] = e
    faces = _faces_ccw()
    all_tris: list[list[tuple[int, int, int]]] = []
    for case in range(256):
        inside = [(case >> c) & 1 for c in range(8)]
        nxt: dict[int, int] = {}
        for f in faces:
            n = len(f)
            for i in range(n):
                a, b = f[i], f[(i + 1) % n]
                if not inside[a] and inside[b]:  # out -> in crossing starts a segment
                    for j in range(1, n):
                        c, d = f[(i + j) % n], f[(i + j + 1) % n]
                        if inside[c] and not inside[d]:  # next in -> out crossing ends it
                            nxt[edge_of[(a, b)]] = edge_of[(c, d)]
                            break
        tris: list[tuple[int, int, int]] = []
        seen: set[int] = set()
        for start in sorted(nxt):
            if start in seen:
                continue
            loop = [start]
            seen.add(start)
            e = nxt[start]
            while e != start:
                loop.append(e)
                seen.add(e)
                e = nxt[e]
            tris.extend(_triangulate_loop(loop))
        all_tris.append(tris)
    # orientation: corner 0 alone inside -> outward normal must point to (+,+,+)
    mid = np.array([(_CORNER_OFFSETS[a] + _CORNER_OFFSETS[b]) / 2.0 for a, b in _EDGES])
    t = all_tris[1][0]
    nrm = np.cross(mid[t[1]] - mid[t[0]], mid[t[2]] - mid[t[0]])
    flip = nrm.sum() < 0
    maxt = max(len(t) for t in all_tris)
    ntri = np.zeros(256, dtype=np.int64)
    table = np.zeros((256, maxt, 3), dtype=np.int64)
    for case, tris in enumerate(all_tris):
        ntri[case] = len(tris)
        for k, (a, b, c) in enumerate(tris):
            table[case, k] = (a, c, b) if flip else (a, b, c)
    return ntri, table


NTRI, TRI_TABLE = _build_case_table()
