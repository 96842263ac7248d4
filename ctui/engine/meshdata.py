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
