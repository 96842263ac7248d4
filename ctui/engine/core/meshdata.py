"""The triangle mesh type shared by meshing, rendering, measurement and export."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Mesh:
    """A triangle mesh.

    Attributes
    ----------
    vertices : ndarray float32 or float64, shape (n, 3)
        Positions (x, y, z) in mm (patient coordinates unless stated).
    faces : ndarray int32/int64, shape (m, 3)
        Vertex indices; counter-clockwise seen from outside (outward normals by the
        right-hand rule).
    normals : ndarray float32, shape (n, 3) or None
        Unit vertex normals pointing outwards, if known.
    object_id : int
        The segmented object this surface belongs to (0 when none).
    meta : dict
        Free-form information (method, iso value...), never patient identifiers.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    object_id: int = 0
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def n_vertices(self) -> int:
        return int(len(self.vertices))

    @property
    def n_faces(self) -> int:
        return int(len(self.faces))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min_xyz, max_xyz) in mm."""
        if self.n_vertices == 0:
            z = np.zeros(3)
            return z, z
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def centre(self) -> np.ndarray:
        lo, hi = self.bounds()
        return (lo + hi) / 2.0

    def volume_mm3(self) -> float:
        """Enclosed volume by the Gauss theorem (meaningful for closed meshes)."""
        return signed_volume_mm3(self.vertices, self.faces)

    def area_mm2(self) -> float:
        """Surface area in mm^2."""
        return float(face_areas(self.vertices, self.faces).sum())


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area (mm^2) of each triangle, shape (m,)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return np.zeros(0)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def signed_volume_mm3(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Enclosed volume (mm^3) by the divergence (Gauss) theorem.

    V = 1/3 * sum_f (centroid_f . n_f) * area_f, which for triangles equals
    1/6 * sum_f a . (b x c). Positive for outward-oriented closed surfaces. The origin
    is moved to the vertices' mean first, which keeps the sum well conditioned far from
    the patient origin.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return 0.0
    v = v - v.mean(axis=0)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def face_cross(vt: np.ndarray, fc: np.ndarray) -> tuple[np.ndarray, ...]:
    """(ax, ay, az, nx, ny, nz) of faces ``fc`` (m, 3) on vertex coordinate rows ``vt`` (3, n): each face's
    first vertex and the cross product of its two edges from it (|n| = twice the area), by components:
    contiguous gathers, about 3x faster than np.cross on (m, 3) rows."""
    ax, ay, az = (vt[k][fc[:, 0]] for k in range(3))
    ux, uy, uz = (vt[k][fc[:, 1]] - c for k, c in zip(range(3), (ax, ay, az)))
    wx, wy, wz = (vt[k][fc[:, 2]] - c for k, c in zip(range(3), (ax, ay, az)))
    return ax, ay, az, uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
