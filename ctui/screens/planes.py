"""Orthogonal planes of the slice workspace: axial, sagittal and coronal reformats of
the volume with the objects (filled and outlined), the pending propagation proposal
(hatched, outlined in yellow) and orientation letters from the direction cosines.

A plane image is a 2D array with rows and columns in index order of the volume, except
that the rows of the sagittal and coronal planes run from the slice axis' superior end
(or its high end when the series has no S/I axis) at the top, as radiologists read them.
Pixel spacing goes with the image, so anisotropic voxels show at their true aspect
(:func:`ctui.screens.cells.fit_view` resamples by spacing).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ctui.engine.core.colors import MAX_OBJECTS, object_color
from ctui.engine.core.geometry import Geometry

PLANES = ("axial", "sagittal", "coronal")
PROPOSAL_EDGE = (255, 230, 0)  # yellow outline of a pending proposal


@dataclass(frozen=True)
class PlaneView:
    """How one plane maps the volume to a 2D image.

    ``rows``/``cols``: the volume axes (0 z, 1 y, 2 x) along the image rows and columns;
    ``flip_rows``: rows run from the high index down; ``letters``: (left, right, top,
    bottom) patient letters; ``spacing_yx``: (row, column) mm per pixel.
    """

    plane: str
    rows: int
    cols: int
    flip_rows: bool
    letters: tuple[str, str, str, str]
    spacing_yx: tuple[float, float]

    @property
    def normal(self) -> int:
        """The volume axis across the plane (the one PageUp/PageDown moves along)."""
        return 3 - self.rows - self.cols


def plane_view(volume, plane: str) -> PlaneView:
    """The :class:`PlaneView` of ``plane`` ("axial", "sagittal", "coronal") for a volume."""
    if plane not in PLANES:
        raise ValueError(f"plane must be one of {', '.join(PLANES)}, got {plane!r}")
    geo = Geometry.of(volume)
    lab = geo.orientation_labels()
    sp = geo.spacing
    if plane == "axial":
        return PlaneView(plane, 1, 2, False, (lab["x"][0], lab["x"][1], lab["y"][0], lab["y"][1]), (sp[1], sp[2]))
    zlo, zhi = lab["z"]
    flip = zlo != "S"  # superior at the top (the high end unless the index runs from S down)
    top, bottom = (zhi, zlo) if flip else (zlo, zhi)
    if plane == "sagittal":
        return PlaneView(plane, 0, 1, flip, (lab["y"][0], lab["y"][1], top, bottom), (sp[0], sp[1]))
    return PlaneView(plane, 0, 2, flip, (lab["x"][0], lab["x"][1], top, bottom), (sp[0], sp[2]))


def take(array: np.ndarray, pv: PlaneView, index: int) -> np.ndarray:
    """The 2D plane ``index`` (along ``pv.normal``) of a (z, y, x) array, rows flipped as the view says."""
    img = np.take(array, int(index), axis=pv.normal)  # the other two axes stay in order: rows < cols
    return img[::-1] if pv.flip_rows else img


def cursor_in(pv: PlaneView, zyx: tuple[int, int, int], shape: tuple[int, int, int]) -> tuple[int, int]:
    """(column, row) image pixel of voxel ``zyx`` in the plane image."""
    r = zyx[pv.rows]
    if pv.flip_rows:
        r = shape[pv.rows] - 1 - r
    return int(zyx[pv.cols]), int(r)


def voxel_of(pv: PlaneView, col: float, row: float, zyx: tuple[int, int, int],
             shape: tuple[int, int, int]) -> tuple[int, int, int]:
    """The voxel (z, y, x) under image pixel (col, row); the normal axis keeps ``zyx``'s index."""
    out = list(zyx)
    r = int(round(row))
    if pv.flip_rows:
        r = shape[pv.rows] - 1 - r
    out[pv.rows] = min(max(r, 0), shape[pv.rows] - 1)
    out[pv.cols] = min(max(int(round(col)), 0), shape[pv.cols] - 1)
    return out[0], out[1], out[2]


_LUT = np.array([(0, 0, 0)] + [object_color((i - 1) % MAX_OBJECTS + 1) for i in range(1, 256)], np.float32)


def outline(labels2d: np.ndarray) -> np.ndarray:
    """bool mask of the object pixels with a 4-neighbour of another label (the outlines)."""
    lab = labels2d
    edge = np.zeros(lab.shape, bool)
    edge[1:] |= lab[1:] != lab[:-1]
    edge[:-1] |= lab[:-1] != lab[1:]
    edge[:, 1:] |= lab[:, 1:] != lab[:, :-1]
    edge[:, :-1] |= lab[:, :-1] != lab[:, 1:]
    return edge & (lab > 0)


def compose(gray8: np.ndarray, labels2d: np.ndarray | None, proposal2d: np.ndarray | None = None, *,
            proposal_id: int = 0, alpha: float = 0.4) -> np.ndarray:
    """RGB uint8 (h, w, 3): objects filled at ``alpha`` with solid outlines; a proposal
    (bool) hatched in its object's colour with a yellow outline, so it never looks accepted."""
    rgb = np.repeat(gray8[:, :, None], 3, axis=2)
    if labels2d is not None and labels2d.any():
        m = labels2d > 0
        col = _LUT[labels2d[m]]
        rgb[m] = (rgb[m].astype(np.float32) * (1.0 - alpha) + col * alpha + 0.5).astype(np.uint8)
        e = outline(labels2d)
        rgb[e] = _LUT[labels2d[e]].astype(np.uint8)
    if proposal2d is not None and proposal2d.any():
        h, w = proposal2d.shape
        yy, xx = np.ogrid[:h, :w]
        hatch = proposal2d & (((yy + xx) % 4) < 2)
        col = _LUT[max(int(proposal_id), 1)]
        rgb[hatch] = (rgb[hatch].astype(np.float32) * 0.3 + col * 0.7 + 0.5).astype(np.uint8)
        e = outline(proposal2d.astype(np.uint8))
        rgb[e] = PROPOSAL_EDGE
    return rgb
