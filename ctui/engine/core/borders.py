"""Object borders as ordered polygons (outer boundaries and holes), per slice.

Coordinates and orientation convention
--------------------------------------
``Border.points`` is a float array (n, 2) of (x, y) **pixel** coordinates: x = column
(increasing to the right), y = row (increasing downwards, as the image is stored and
shown with row 0 at the top). Points are the centres of the object's boundary pixels
(8-connected chain from ``cv2.findContours``), not repeated at the end.

Orientation is defined by the shoelace signed area computed on these numbers,
``A = 1/2 * sum(x[i] * y[i+1] - x[i+1] * y[i])``:

* outer boundaries have ``A > 0`` (counter-clockwise in the usual mathematical x-right,
  y-up sense applied to the (x, y) values; since rows grow downwards on screen this
  looks clockwise when the slice is displayed with row 0 at the top);
* holes have ``A < 0``.

The same holds for (x_mm, y_mm) along the volume's x and y index axes; for patient
coordinates use :func:`border_mm`, which maps through the volume's geometry.

Several parts per slice are separate outer borders; each hole follows the outer
border that contains it. Single-pixel parts give a one-point border (area 0), and
one-pixel-wide lines give a degenerate polygon (area 0); both are kept (``hole``
False) so no part of the object is lost.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np


@dataclass
class Border:
    """One closed polygon: ``points`` float (n, 2) (x, y) pixels; ``hole`` True for inner borders."""

    points: np.ndarray
    hole: bool = False

    @property
    def signed_area(self) -> float:
        """Shoelace area in pixel^2 (> 0 outer, < 0 hole; see module docstring)."""
        return signed_area(self.points)

    def __len__(self) -> int:
        return len(self.points)


def signed_area(points: np.ndarray) -> float:
    """Shoelace signed area of a closed polygon (n, 2) in its own units."""
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 3:
        return 0.0
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def slice_borders(mask2d: np.ndarray, *, simplify: bool = False) -> list[Border]:
    """Borders of a 2D mask (bool/uint8 (ny, nx), nonzero = object).

    Outer borders have positive shoelace area, holes negative (module docstring). Each
    outer border is followed by its holes. ``simplify`` keeps only the corners of
    straight runs (``CHAIN_APPROX_SIMPLE``).
    """
    m = np.ascontiguousarray(mask2d != 0, dtype=np.uint8)
    if not m.any():
        return []
    method = cv2.CHAIN_APPROX_SIMPLE if simplify else cv2.CHAIN_APPROX_NONE
    contours, hierarchy = cv2.findContours(m, cv2.RETR_CCOMP, method)
    if hierarchy is None:
        return []
    hier = hierarchy[0]
    out: list[Border] = []

    def _make(i: int, hole: bool) -> Border:
        pts = contours[i].reshape(-1, 2).astype(np.float64)
        a = signed_area(pts)
        if (not hole and a < 0) or (hole and a > 0):
            pts = pts[::-1].copy()
        return Border(points=pts, hole=hole)

    for i in range(len(contours)):
        if hier[i][3] >= 0:  # a hole, emitted after its parent
            continue
        out.append(_make(i, False))
        child = hier[i][2]
        while child >= 0:
            out.append(_make(child, True))
            child = hier[child][0]
    return out


def object_borders(labels: np.ndarray, object_id: int, *, simplify: bool = False) -> list[list[Border]]:
    """Borders of object ``object_id`` on every slice of ``labels`` (uint8 (nz, ny, nx)).

    Returns a list of length nz; slices without the object give an empty list.
    Only the object's bounding box is traced (fast on large volumes).
    """
    nz = labels.shape[0]
    out: list[list[Border]] = [[] for _ in range(nz)]
    m = labels == object_id
    zs = np.flatnonzero(m.any(axis=(1, 2)))
    if zs.size == 0:
        return out
    ys = np.flatnonzero(m.any(axis=(0, 2)))
    xs = np.flatnonzero(m.any(axis=(0, 1)))
    y0, y1, x0, x1 = ys[0], ys[-1] + 1, xs[0], xs[-1] + 1
    # pad by one pixel so borders on the crop edge are traced like on the full slice
    for z in zs:
        crop = np.zeros((y1 - y0 + 2, x1 - x0 + 2), np.uint8)
        crop[1:-1, 1:-1] = m[z, y0:y1, x0:x1]
        bs = slice_borders(crop, simplify=simplify)
        for b in bs:
            b.points = b.points + np.array([x0 - 1, y0 - 1], dtype=np.float64)
        out[int(z)] = bs
    return out


def border_mm(border: Border | np.ndarray, volume: Any, z: int) -> np.ndarray:
    """Border points of slice ``z`` in patient mm (n, 3) (x, y, z), through the volume's geometry."""
    pts = border.points if isinstance(border, Border) else np.asarray(border, dtype=np.float64)
    zyx = np.column_stack([np.full(len(pts), float(z)), pts[:, 1], pts[:, 0]])
    return volume.index_to_mm(zyx)


def border_mm_inplane(border: Border | np.ndarray, spacing: tuple[float, float, float]) -> np.ndarray:
    """Border points scaled to in-plane mm (n, 2): (x * dx, y * dy) along the index axes."""
    pts = border.points if isinstance(border, Border) else np.asarray(border, dtype=np.float64)
    return pts * np.array([spacing[2], spacing[1]], dtype=np.float64)


def borders_for_mric(labels: np.ndarray, object_ids: list[int] | None = None) -> list[list[list[np.ndarray]]]:
    """Borders in the layout ``ctui.engine.io.mric.write_mric`` takes.

    Returns per slice, per object (ascending id), per border an int array (n, 2) of
    (x, y) pixels.
    """
    if object_ids is None:
        object_ids = [int(i) for i in np.unique(labels) if i != 0]
    per_obj = {oid: object_borders(labels, oid) for oid in object_ids}
    out: list[list[list[np.ndarray]]] = []
    for z in range(labels.shape[0]):
        sl = []
        for oid in object_ids:
            bs = per_obj[oid][z]
            if bs:
                sl.append([np.rint(b.points).astype(np.int32) for b in bs])
        out.append(sl)
    return out
