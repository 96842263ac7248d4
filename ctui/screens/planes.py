"""Orthogonal planes of the slice workspace: axial, sagittal and coronal reformats of
the volume with the objects (filled and outlined), the pending propagation proposal
(hatched, outlined in yellow) and orientation letters from the direction cosines.

Every plane is shown in the patient's frame, as radiologists read it, whatever the
file's axis order and signs (RAS or LPS NIfTI, NRRD, DICOM head-first or feet-first, a
sagittal acquisition): axial with the patient's right on screen left and anterior up,
coronal right on the left and superior up, sagittal anterior on the left and superior
up. Each index axis is matched to its nearest patient axis (an oblique stack is shown
to the nearest axes, with a note); the display only transposes and mirrors the file's
voxels, so labels, seeds, measurements and exports stay on the file's grid.

Every conversion between display pixels and voxels lives here (one place, exact both
ways): :func:`take` / :func:`orient` (voxels -> image), :func:`cursor_in` (voxel ->
pixel), :func:`voxel_of` (pixel -> voxel) and :func:`moved` (arrow keys on screen ->
voxel step). Pixel spacing goes with the image, so anisotropic voxels show at their
true aspect (:func:`ctui.screens.cells.fit_view` resamples by spacing).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ctui.engine.core.colors import MAX_OBJECTS, object_color
from ctui.engine.core.geometry import Geometry

PLANES = ("axial", "sagittal", "coronal")
PROPOSAL_EDGE = (255, 230, 0)  # yellow outline of a pending proposal
OBLIQUE_DEG = 1.0  # index axes further than this from their patient axis get a note

# plane -> (patient axis across the plane, (patient axis, sign) to the screen's right,
# (patient axis, sign) down the screen); patient axes in LPS: 0 x (+L), 1 y (+P), 2 z (+S)
_FRAME = {
    "axial": (2, (0, 1), (1, 1)),  # right on the left (L to the right), A up (P down)
    "coronal": (1, (0, 1), (2, -1)),  # R on the left, S up (I down)
    "sagittal": (0, (1, 1), (2, -1)),  # A on the left (P to the right), S up
}


@dataclass(frozen=True)
class PlaneView:
    """How one plane maps the volume to a 2D display image.

    ``rows``/``cols``: the volume axes (0 z, 1 y, 2 x) along the image rows (down) and
    columns (right); ``flip_rows``/``flip_cols``: that axis' index runs from its high
    end at the top / left; ``letters``: (left, right, top, bottom) patient letters;
    ``spacing_yx``: (row, column) mm per pixel; ``note``: "" or why the picture is only
    near the patient's axes (an oblique stack).
    """

    plane: str
    rows: int
    cols: int
    flip_rows: bool
    letters: tuple[str, str, str, str]
    spacing_yx: tuple[float, float]
    flip_cols: bool = False
    note: str = ""

    @property
    def normal(self) -> int:
        """The volume axis across the plane (the one PageUp/PageDown moves along)."""
        return 3 - self.rows - self.cols


def patient_axes(direction: np.ndarray) -> tuple[tuple[int, int, int], tuple[int, int, int], float]:
    """Nearest patient axis and sign of each volume axis, and the worst angle.

    ``direction``: 3x3, columns the LPS unit vectors of the x, y, z index axes. Returns
    (patient axis of volume axes 0 z, 1 y, 2 x), (+1/-1: does the index run towards
    the L/P/S end), and the largest angle (degrees) between an index axis and its
    patient axis. The pairing is the permutation with the largest total alignment, so
    two index axes never share a patient axis.
    """
    d = np.asarray(direction, np.float64).reshape(3, 3)
    cols = [d[:, 2 - i] for i in range(3)]  # unit vector of volume axis i (0 z, 1 y, 2 x)
    best = max(itertools.permutations(range(3)), key=lambda p: sum(abs(cols[i][p[i]]) for i in range(3)))
    signs = tuple(1 if cols[i][best[i]] >= 0 else -1 for i in range(3))
    cosines = [min(1.0, abs(cols[i][best[i]]) / max(np.linalg.norm(cols[i]), 1e-12)) for i in range(3)]
    worst = float(np.degrees(np.arccos(min(cosines))))
    return tuple(best), signs, worst  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


def plane_view(volume, plane: str) -> PlaneView:
    """The :class:`PlaneView` of ``plane`` ("axial", "sagittal", "coronal") for a volume
    (anything with shape, spacing, origin and direction)."""
    if plane not in PLANES:
        raise ValueError(f"plane must be one of {', '.join(PLANES)}, got {plane!r}")
    geo = Geometry.of(volume)
    lab = geo.orientation_labels()
    sp = geo.spacing
    axis_of, signs, worst = patient_axes(geo.direction)
    _normal, (p_right, s_right), (p_down, s_down) = _FRAME[plane]
    cols = axis_of.index(p_right)
    rows = axis_of.index(p_down)
    flip_cols = signs[cols] != s_right
    flip_rows = signs[rows] != s_down
    lc, hc = lab["zyx"[cols]]
    lr, hr = lab["zyx"[rows]]
    left, right = (hc, lc) if flip_cols else (lc, hc)
    top, bottom = (hr, lr) if flip_rows else (lr, hr)
    note = f"oblique stack (up to {worst:.0f}°): shown to the nearest patient axes" if worst > OBLIQUE_DEG else ""
    return PlaneView(plane, rows, cols, flip_rows, (left, right, top, bottom), (sp[rows], sp[cols]),
                     flip_cols=flip_cols, note=note)


def slice_plane(volume) -> str:
    """The plane whose images are the file's slices (normal along volume axis 0): the
    plane the pipeline, the Enter fill and propagation work on ("axial" for an axial
    acquisition, "sagittal" for a sagittal one)."""
    for p in PLANES:
        if plane_view(volume, p).normal == 0:
            return p
    return "axial"  # unreachable: the three planes' normals are the three axes


def orient(img2d: np.ndarray, pv: PlaneView) -> np.ndarray:
    """A plane's 2D array with its axes in volume order (the lower volume axis first,
    e.g. a z slice as (y, x)) -> the display image (rows down, columns right). A view
    (no copy); trailing axes (RGB) are kept."""
    img = np.swapaxes(img2d, 0, 1) if pv.rows > pv.cols else img2d
    if pv.flip_rows:
        img = img[::-1]
    if pv.flip_cols:
        img = img[:, ::-1]
    return img


def take(array: np.ndarray, pv: PlaneView, index: int) -> np.ndarray:
    """The display image of plane ``index`` (along ``pv.normal``) of a (z, y, x) array."""
    return orient(np.take(array, int(index), axis=pv.normal), pv)


def cursor_in(pv: PlaneView, zyx: tuple[int, int, int], shape: tuple[int, int, int]) -> tuple[int, int]:
    """(column, row) display pixel of voxel ``zyx`` in the plane image."""
    c, r = int(zyx[pv.cols]), int(zyx[pv.rows])
    if pv.flip_cols:
        c = shape[pv.cols] - 1 - c
    if pv.flip_rows:
        r = shape[pv.rows] - 1 - r
    return c, r


def voxel_of(pv: PlaneView, col: float, row: float, zyx: tuple[int, int, int],
             shape: tuple[int, int, int]) -> tuple[int, int, int]:
    """The voxel (z, y, x) under display pixel (col, row) (rounded, clamped into the
    volume); the normal axis keeps ``zyx``'s index. Inverse of :func:`cursor_in`."""
    out = list(zyx)
    r = min(max(int(round(row)), 0), shape[pv.rows] - 1)
    c = min(max(int(round(col)), 0), shape[pv.cols] - 1)
    out[pv.rows] = shape[pv.rows] - 1 - r if pv.flip_rows else r
    out[pv.cols] = shape[pv.cols] - 1 - c if pv.flip_cols else c
    return out[0], out[1], out[2]


def moved(pv: PlaneView, zyx: tuple[int, int, int], dx: int, dy: int) -> tuple[int, int, int]:
    """``zyx`` moved ``dx`` display pixels right and ``dy`` down (not clamped): the
    arrow keys move on screen in the arrow's direction whatever the flips."""
    out = list(zyx)
    out[pv.cols] += -dx if pv.flip_cols else dx
    out[pv.rows] += -dy if pv.flip_rows else dy
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


def _label_box(labels2d: np.ndarray) -> tuple[slice, slice] | None:
    """(rows, cols) slices of the labelled pixels' bounding box grown by one pixel (the outline
    compares each pixel with its 4 neighbours), clipped to the image; None when nothing is labelled."""
    rows = np.flatnonzero(labels2d.any(axis=1))
    if not len(rows):
        return None
    cols = np.flatnonzero(labels2d[rows[0]:rows[-1] + 1].any(axis=0))
    h, w = labels2d.shape
    return (slice(max(int(rows[0]) - 1, 0), min(int(rows[-1]) + 2, h)),
            slice(max(int(cols[0]) - 1, 0), min(int(cols[-1]) + 2, w)))


def compose(gray8: np.ndarray, labels2d: np.ndarray | None, proposal2d: np.ndarray | None = None, *,
            proposal_id: int = 0, alpha: float = 0.4) -> np.ndarray:
    """RGB uint8 (h, w, 3): objects filled at ``alpha`` with solid outlines; a proposal
    (bool) hatched in its object's colour with a yellow outline, so it never looks accepted."""
    rgb = np.repeat(gray8[:, :, None], 3, axis=2)
    box = _label_box(labels2d) if labels2d is not None else None
    if labels2d is not None and box is not None:  # blended and outlined within the objects' box (and a pixel round it): the same pixels
        lab, sub = labels2d[box], rgb[box]
        m = lab > 0
        col = _LUT[lab[m]]
        sub[m] = (sub[m].astype(np.float32) * (1.0 - alpha) + col * alpha + 0.5).astype(np.uint8)
        e = outline(lab)
        sub[e] = _LUT[lab[e]].astype(np.uint8)
    if proposal2d is not None and proposal2d.any():
        h, w = proposal2d.shape
        yy, xx = np.ogrid[:h, :w]
        hatch = proposal2d & (((yy + xx) % 4) < 2)
        col = _LUT[max(int(proposal_id), 1)]
        rgb[hatch] = (rgb[hatch].astype(np.float32) * 0.3 + col * 0.7 + 0.5).astype(np.uint8)
        e = outline(proposal2d.astype(np.uint8))
        rgb[e] = PROPOSAL_EDGE
    return rgb
