"""The volume model shared by every part of ctui.

Conventions (all of ctui):

* voxels are a numpy array in (z, y, x) order; ``spacing`` is (dz, dy, dx) in mm;
* patient coordinates are DICOM's LPS, in mm, written (x, y, z);
* ``origin`` is the patient position (x, y, z) of voxel index (0, 0, 0)'s centre;
* ``direction`` is a 3x3 matrix whose *columns* are the unit vectors, in patient
  coordinates, of the x (column), y (row) and z (slice) index axes (ITK's convention);
  so ``p = origin + direction @ (spacing_xyz * (i, j, k))`` with (i, j, k) = (x, y, z)
  indices;
* CT values are Hounsfield units (after RescaleSlope/RescaleIntercept);
* slice 0 is the lowest slice along the slice normal.

Meshes are in patient mm (x, y, z) unless a function says otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.core.errors import CtuiError

from ctui.engine.core.geometry import Geometry


@dataclass
class Volume:
    """A 3D image with geometry.

    Attributes
    ----------
    data : ndarray, shape (nz, ny, nx)
        Voxel values (HU for CT). Any numeric dtype; loaders give int16 for CT
        when the rescaled values fit, else float32.
    spacing : tuple (dz, dy, dx)
        Voxel size in mm.
    origin : tuple (x, y, z)
        Patient position in mm of the centre of voxel (0, 0, 0).
    direction : ndarray, shape (3, 3)
        Columns: patient-space unit vectors of the x, y and z index axes.
    modality : str
        "CT", "MR", "OT" (other / plain images)...
    window : tuple (centre, width)
        Default display window in the data's units.
    source : str
        Description of where the data came from (path, format, series
        description). Never holds patient identifiers.
    series : list of dict
        The series found at the source (for DICOM); each a dict with at least
        ``uid``, ``description``, ``modality``, ``files``, ``shape_zyx``.
    skipped : list of dict
        ``{"file": str, "reason": str}`` for every file that was not loaded.
    warnings : list of str
        Geometry and loading warnings (uneven spacing, tilt, default spacing...).
    slice_positions : ndarray (nz,) or None
        Position of each slice along the slice normal in mm, as found in the
        source (before any resampling), for reporting.
    meta : dict
        Free-form extra information without patient identifiers.
    """

    data: np.ndarray
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: np.ndarray = field(default_factory=lambda: np.eye(3))
    modality: str = "OT"
    window: tuple[float, float] | None = None
    source: str = ""
    series: list[dict[str, Any]] = field(default_factory=list)
    skipped: list[dict[str, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    slice_positions: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.data.ndim != 3:
            raise ValueError(f"Volume data must be 3D (z, y, x), got shape {self.data.shape}")
        self.spacing = tuple(float(s) for s in self.spacing)  # type: ignore[assignment]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
        self.origin = tuple(float(o) for o in self.origin)  # type: ignore[assignment]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
        self.direction = np.asarray(self.direction, dtype=np.float64).reshape(3, 3)
        for s in self.spacing:
            if not (np.isfinite(s) and s > 0):  # a loader's bug or a header it let through: never NaN in JSON
                raise CtuiError(f"voxel size must be positive and finite, got {self.spacing} (dz, dy, dx) mm")
        if self.window is None:
            from ctui.engine.core.windows import auto_window  # local: windows imports nothing heavy

            self.window = auto_window(self.data, modality=self.modality)

    # ------------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int, int]:
        """(nz, ny, nx)."""
        nz, ny, nx = self.data.shape
        return int(nz), int(ny), int(nx)

    @property
    def spacing_xyz(self) -> np.ndarray:
        """(dx, dy, dz) in mm."""
        return np.array(self.spacing[::-1], dtype=np.float64)

    @property
    def geometry(self) -> Geometry:
        """The grid as a :class:`~ctui.engine.core.geometry.Geometry` (the one voxel <-> mm type)."""
        return Geometry(self.shape, self.spacing, self.origin, self.direction)

    @property
    def affine(self) -> np.ndarray:
        """4x4 matrix mapping homogeneous (i, j, k, 1) = (x, y, z) indices to LPS mm."""
        return self.geometry.affine

    @property
    def slice_normal(self) -> np.ndarray:
        """Unit vector (x, y, z) of increasing slice index in patient space."""
        return self.direction[:, 2].copy()

    def index_to_mm(self, zyx: np.ndarray | tuple[float, float, float]) -> np.ndarray:
        """Voxel indices (..., 3) in (z, y, x) order -> patient mm (..., 3) in (x, y, z)."""
        return self.geometry.index_to_mm(zyx)

    def mm_to_index(self, xyz: np.ndarray | tuple[float, float, float]) -> np.ndarray:
        """Patient mm (..., 3) in (x, y, z) -> fractional voxel indices (..., 3) in (z, y, x)."""
        return self.geometry.mm_to_index(xyz)

    @property
    def assumptions(self) -> list:
        """What the loader assumed in place of the file (typed
        :class:`~ctui.engine.core.assumptions.Assumption` items of ``warnings``)."""
        from ctui.engine.core.assumptions import assumptions  # local: a small module, kept off the import graph

        return assumptions(self.warnings)

    def voxel_volume_mm3(self) -> float:
        """Volume of one voxel in mm^3."""
        return float(np.prod(self.spacing))

    def extent_mm(self) -> tuple[float, float, float]:
        """Physical size (z, y, x) of the voxel grid in mm (n * spacing)."""
        return tuple(n * s for n, s in zip(self.shape, self.spacing))  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction

    def value_range(self) -> tuple[float, float]:
        """(min, max) of the voxel values (``meta["value_range"]`` for a headers-only
        Volume, whose ``data`` is a placeholder: see ``ctui.engine.io.series.inspect``)."""
        if self.meta.get("headers_only"):  # never computed on the placeholder; NaN: no slice sampled
            lo, hi = self.meta.get("value_range") or (float("nan"), float("nan"))
            return float(lo), float(hi)
        return float(self.data.min()), float(self.data.max())

    def describe(self) -> dict[str, Any]:
        """A JSON-ready summary (no patient identifiers)."""
        lo, hi = self.value_range()
        return {
            "shape_zyx": list(self.shape),
            "spacing_zyx_mm": [round(s, 6) for s in self.spacing],
            "origin_xyz_mm": [round(o, 4) for o in self.origin],
            "direction": [[round(v, 6) for v in row] for row in self.direction.tolist()],
            "modality": self.modality,
            "dtype": str(self.data.dtype),
            "value_range": [lo, hi],
            "window": list(self.window) if self.window else None,
            "source": self.source,
            "series": self.series,
            "skipped": self.skipped,
            "warnings": self.warnings,
            "assumptions": [a.to_dict() for a in self.assumptions],
        }
