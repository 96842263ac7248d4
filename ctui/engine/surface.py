"""Surfaces of volumes and segmented objects, in patient mm.

* :func:`isosurface`: marching cubes at a value (HU...), crack-free, welded vertices,
  gradient normals (see :mod:`ctui.engine.marching`).
* :func:`mask_surface`: a binary mask's surface *without staircase*: the surface is
  the zero level of a smoothed signed-distance field (distances in mm, so anisotropic
  voxels are handled), cropped to the object's bounding box, with the level corrected
  so the enclosed volume equals the mask's voxel volume (to about 0.1 %). Thick
  slices can be refined by shape-based interpolation (signed distances interpolated
  between slices).
* :func:`label_surfaces`: every object of a label map; one scan of the label map
  (``scipy.ndimage.find_objects``) gives every object's bounding box, then each object is
  meshed inside its own box only, so the cost is the sum of the objects' boxes, not one
  pass over the whole volume per label.

Geometry follows :mod:`ctui.engine.volume`: spacing (dz, dy, dx) mm, origin (x, y, z)
of voxel (0, 0, 0)'s centre, direction columns = x, y, z index axes;
``p = origin + direction @ (spacing_xyz * (i, j, k))``.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .meshdata import Mesh


def affine_from(spacing: Sequence[float], origin: Sequence[float] = (0.0, 0.0, 0.0),
                direction: np.ndarray | None = None) -> np.ndarray:
    """4x4 matrix mapping homogeneous (x, y, z, 1) indices to patient mm.

    spacing is (dz, dy, dx) mm (ctui's convention); origin (x, y, z) mm.
    """
    sp = np.asarray(spacing, dtype=np.float64).reshape(3)[::-1]
    d = np.eye(3) if direction is None else np.asarray(direction, dtype=np.float64).reshape(3, 3)
    a = np.eye(4)
    a[:3, :3] = d * sp[None, :]
    a[:3, 3] = np.asarray(origin, dtype=np.float64).reshape(3)
    return a


def _fix_handedness(faces: np.ndarray, affine: np.ndarray) -> np.ndarray:
    # a left-handed index->mm map mirrors the mesh: swap winding to stay CCW outward
    if np.linalg.det(affine[:3, :3]) < 0:
        return np.ascontiguousarray(faces[:, ::-1])
    return faces


def isosurface(data: np.ndarray, level: float, *, spacing: Sequence[float] = (1.0, 1.0, 1.0),
               origin: Sequence[float] = (0.0, 0.0, 0.0), direction: np.ndarray | None = None,
               normals: bool = True) -> Mesh:
    """Isosurface of a volume at ``level``.

    Parameters
    ----------
    data : ndarray (nz, ny, nx), any numeric dtype (not copied)
        Voxels with value > level are inside.
    level : float
        Iso value in the data's units (HU for CT).
    spacing : (dz, dy, dx) mm; origin : (x, y, z) mm; direction : (3, 3), columns x, y, z axes.

    Returns
    -------
    Mesh
        vertices float32 (n, 3) mm, faces int32 (m, 3) counter-clockwise from outside
        (outside = values <= level), unit normals float32 (n, 3) from the gradient.
        Vertices are shared between cells (one per crossed voxel edge).
    """
    from .marching import marching_cubes

    aff = affine_from(spacing, origin, direction)
    v, f, n = marching_cubes(data, level, affine=aff, normals=normals)
    f = _fix_handedness(f, aff)
    return Mesh(vertices=v, faces=f, normals=n, meta={"method": "marching-cubes", "level": float(level)})
