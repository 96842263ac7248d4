"""The one geometry type: a voxel grid placed in patient space.

Conventions (see :mod:`ctui.engine.core.volume`): shape and spacing in (z, y, x) order,
spacing in mm; origin is the LPS patient position (x, y, z) in mm of voxel (0, 0, 0)'s
centre; ``direction`` is 3x3 with *columns* the unit vectors of the x, y and z index axes.
Every voxel <-> mm conversion in ctui goes through :class:`Geometry`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.core.limits import MIN_SPACING_MM


#: largest coordinate or voxel size accepted (mm): 1000 km, far beyond any scanner
MAX_MM = 1e9


def _vec3(value: Any, name: str, *, positive: bool = False) -> tuple[float, float, float]:
    try:
        vals = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise CtuiError(f"{name}: expected three numbers, got {value!r}") from None
    if len(vals) != 3:
        raise CtuiError(f"{name}: expected three numbers, got {len(vals)}")
    if not all(math.isfinite(v) for v in vals):
        raise CtuiError(f"{name}: not a finite number in {list(vals)}")
    if positive and min(vals) < MIN_SPACING_MM:  # 1e-300 mm passes "> 0" and divides by zero later
        raise CtuiError(f"{name}: every value must be at least {MIN_SPACING_MM:g} mm, got {list(vals)}")
    if max(abs(v) for v in vals) > MAX_MM:  # 1e308 mm is finite but overflows every product (fuzz finding)
        raise CtuiError(f"{name}: values beyond {MAX_MM:g} mm in {list(vals)}")
    return vals[0], vals[1], vals[2]


def _direction(value: Any, *, orthonormal: bool = False) -> np.ndarray:
    """3x3 float matrix; finite and invertible (``orthonormal``: unit columns at right angles,
    as every file ctui writes has; a loaded volume may carry a slight shear)."""
    if value is None:
        return np.eye(3)
    try:
        d = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise CtuiError("direction: expected a 3x3 matrix of numbers") from None
    if d.size != 9 or not np.all(np.isfinite(d)):
        raise CtuiError("direction: expected a 3x3 matrix of finite numbers")
    d = d.reshape(3, 3)
    det = abs(np.linalg.det(d))
    if det < 1e-6:
        raise CtuiError("direction: the matrix is singular")
    if orthonormal and (abs(det - 1.0) > 1e-3 or not np.allclose(d.T @ d, np.eye(3), atol=1e-3)):
        raise CtuiError("direction: the columns are not unit vectors at right angles")
    return d


@dataclass(frozen=True)
class Geometry:
    """Shape (nz, ny, nx), spacing (dz, dy, dx) mm, origin (x, y, z) mm, direction 3x3."""

    shape: tuple[int, int, int]
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        try:
            shape = tuple(int(s) for s in self.shape)
        except (TypeError, ValueError):
            raise CtuiError(f"shape: expected three integers, got {self.shape!r}") from None
        if len(shape) != 3 or min(shape) < 1:
            raise CtuiError(f"shape: expected three integers >= 1, got {list(shape)}")
        object.__setattr__(self, "shape", shape)
        object.__setattr__(self, "spacing", _vec3(self.spacing, "spacing", positive=True))
        object.__setattr__(self, "origin", _vec3(self.origin, "origin"))
        object.__setattr__(self, "direction", _direction(self.direction))

    # ---------------------------------------------------------------- constructors
    @classmethod
    def of(cls, obj: Any) -> "Geometry":
        """The geometry of a Volume (or anything with shape/spacing/origin/direction)."""
        if isinstance(obj, Geometry):
            return obj
        shape = getattr(obj, "shape", None)
        if shape is None:
            shape = obj.data.shape
        return cls(tuple(shape), obj.spacing, obj.origin, obj.direction)

    @classmethod
    def from_dict(cls, d: dict) -> "Geometry":
        """Inverse of :meth:`to_dict`; raises CtuiError naming the field that is wrong."""
        if not isinstance(d, dict):
            raise CtuiError("geometry: expected an object")
        direction = _direction(d.get("direction"), orthonormal=True)  # files: strict
        return cls(d.get("shape_zyx"), d.get("spacing_zyx_mm", (1.0, 1.0, 1.0)),  # type: ignore[arg-type]  # a file's fields: __post_init__ checks each one and raises CtuiError
                   d.get("origin_xyz_mm", (0.0, 0.0, 0.0)), direction)

    def to_dict(self) -> dict:
        return {
            "shape_zyx": list(self.shape),
            "spacing_zyx_mm": [float(s) for s in self.spacing],
            "origin_xyz_mm": [float(o) for o in self.origin],
            "direction": [[float(v) for v in row] for row in self.direction.tolist()],
        }

    # ---------------------------------------------------------------- derived
    @property
    def spacing_xyz(self) -> np.ndarray:
        """(dx, dy, dz) in mm."""
        return np.array(self.spacing[::-1], dtype=np.float64)

    @property
    def affine(self) -> np.ndarray:
        """4x4 matrix mapping homogeneous (x, y, z, 1) indices to LPS mm."""
        a = np.eye(4)
        a[:3, :3] = self.direction * self.spacing_xyz[None, :]
        a[:3, 3] = self.origin
        return a

    @property
    def voxel_volume_mm3(self) -> float:
        return float(np.prod(self.spacing))

    @property
    def slice_normal(self) -> np.ndarray:
        return self.direction[:, 2].copy()

    def index_to_mm(self, zyx: Any) -> np.ndarray:
        """Voxel indices (..., 3) in (z, y, x) order -> patient mm (..., 3) in (x, y, z)."""
        idx = np.asarray(zyx, dtype=np.float64)[..., ::-1]
        return idx @ (self.direction * self.spacing_xyz[None, :]).T + np.asarray(self.origin)

    def mm_to_index(self, xyz: Any) -> np.ndarray:
        """Patient mm (..., 3) in (x, y, z) -> fractional voxel indices (..., 3) in (z, y, x)."""
        p = np.asarray(xyz, dtype=np.float64) - np.asarray(self.origin)
        m = self.direction * self.spacing_xyz[None, :]
        return (p @ np.linalg.inv(m).T)[..., ::-1]

    def contains(self, zyx: Sequence[int]) -> bool:
        return all(0 <= int(i) < n for i, n in zip(zyx, self.shape))

    def same_grid(self, other: "Geometry", *, tol_mm: float = 1e-3) -> bool:
        """True when both grids put every voxel at the same place (within tol_mm)."""
        o = Geometry.of(other)
        if self.shape != o.shape:
            return False
        corners = np.array([[0, 0, 0], [n - 1 for n in self.shape]], dtype=float)
        return bool(np.allclose(self.index_to_mm(corners), o.index_to_mm(corners), atol=tol_mm)
                    and np.allclose(self.direction, o.direction, atol=1e-4))

    def orientation_labels(self) -> dict[str, tuple[str, str]]:
        """For each index axis 'x', 'y', 'z': the patient letters at its low and high end.

        LPS: +x is L, +y is P, +z is S; the dominant component of each axis picks the letter.
        """
        pos = ("L", "P", "S")
        neg = ("R", "A", "I")
        out = {}
        for k, name in enumerate("xyz"):
            v = self.direction[:, k]
            a = int(np.argmax(np.abs(v)))
            hi = pos[a] if v[a] > 0 else neg[a]
            lo = neg[a] if v[a] > 0 else pos[a]
            out[name] = (lo, hi)
        return out
