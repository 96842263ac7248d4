"""Editing tools of a :class:`ctui.engine.segment.selection.Segmentation` (a mixin), all undoable.

Every method ends in one ``apply_region`` call, so each edit is one undo step storing
only its bounding box. The TUI binds keys to these; the CLI has twins where they make
sense (``ctui segment --keep-largest --min-island N --interpolate``):

==========================  ===========================================================
``brush(...)``              the brush footprint: a disc of ``radius`` px in the plane of
                            ``axis`` (0 axial, 1 coronal, 2 sagittal) through a voxel
``paint_brush(...)``        paint (``mode="add"``/``"replace"``) or erase (``"subtract"``)
                            a brush dab, limited to ``slices`` and an HU range
                            (``values`` + ``hu``: Slicer's "masking")
``apply_mask(...)``         any mask (a fill, a proposal) with mode add / replace / subtract
``keep_largest_island``     drop every 3D island of the object but the largest
``remove_islands``          drop the islands under ``min_voxels``
``fill_between_slices``     interpolate the object across the empty slices between the
                            key slices drawn (signed-distance interpolation along z, as
                            Slicer's "Fill between slices" and ITK-SNAP do)
==========================  ===========================================================

Modes: ``add`` sets the object where the mask is (other objects kept unless
``overwrite``); ``replace`` makes the object equal the mask on the planes the mask
touches (along ``axis``); ``subtract`` clears the object where the mask is.
Coordinates: voxel indices x (column), y (row), z (slice, numbered from 0).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from ctui.engine.core.errors import CtuiError

MODES = ("add", "replace", "subtract")
Box = tuple[slice, slice, slice]


def _bbox(mask: np.ndarray) -> Box | None:
    zs = np.flatnonzero(mask.any(axis=(1, 2)))
    if zs.size == 0:
        return None
    ys = np.flatnonzero(mask.any(axis=(0, 2)))
    xs = np.flatnonzero(mask.any(axis=(0, 1)))
    return (slice(int(zs[0]), int(zs[-1]) + 1), slice(int(ys[0]), int(ys[-1]) + 1), slice(int(xs[0]), int(xs[-1]) + 1))


def brush(shape: tuple[int, int, int], x: int, y: int, z: int, *, radius: float, axis: int = 0,
          spacing: tuple[float, float, float] | None = None) -> tuple[tuple[int, int, int], np.ndarray]:
    """The brush footprint: ((z0, y0, x0), bool 3D mask, one voxel thick along ``axis``).

    A disc of ``radius`` pixels in the plane of ``axis`` (0: the axial slice z, 1: the
    coronal plane y, 2: the sagittal plane x) centred on voxel (x, y, z), clipped to the
    volume. With ``spacing`` (dz, dy, dx) the disc is round in mm (``radius`` counts
    pixels of the finer of the plane's two axes). Raises CtuiError when (x, y, z) is off
    the image.
    """
    nz, ny, nx = shape
    if not (0 <= x < nx and 0 <= y < ny and 0 <= z < nz):
        raise CtuiError(f"brush at x {x}, y {y}, slice {z} is off the image (x 0..{nx - 1}, y 0..{ny - 1}, "
                        f"slices 0..{nz - 1}); nothing painted")
    if axis not in (0, 1, 2):
        raise CtuiError(f"brush axis must be 0 (axial), 1 (coronal) or 2 (sagittal), got {axis}")
    if radius < 0:
        raise CtuiError("brush radius must be >= 0")
    centre = (z, y, x)
    plane = [a for a in range(3) if a != axis]
    sp = (1.0, 1.0, 1.0) if spacing is None else tuple(float(v) for v in spacing)
    fine = min(sp[plane[0]], sp[plane[1]])
    semi = [radius * fine / sp[a] for a in plane]
    lo = [max(centre[a] - int(np.floor(s)), 0) for a, s in zip(plane, semi)]
    hi = [min(centre[a] + int(np.floor(s)) + 1, shape[a]) for a, s in zip(plane, semi)]
    u = np.arange(lo[0], hi[0])[:, None] - centre[plane[0]]
    v = np.arange(lo[1], hi[1])[None, :] - centre[plane[1]]
    disc = (u / max(semi[0], 0.5)) ** 2 + (v / max(semi[1], 0.5)) ** 2 <= 1.0 + 1e-9
    disc = np.expand_dims(disc, axis)
    offset = [0, 0, 0]
    offset[axis] = centre[axis]
    offset[plane[0]], offset[plane[1]] = lo
    return (offset[0], offset[1], offset[2]), disc


def _sdf(mask: np.ndarray, spacing_yx: tuple[float, float]) -> np.ndarray:
    """Signed distance (positive inside) of a 2D mask, in mm (OpenCV's exact L2 transform per side)."""
    m = mask.astype(np.uint8)
    scale = float(np.sqrt(spacing_yx[0] * spacing_yx[1]))
    inside = cv2.distanceTransform(m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    outside = cv2.distanceTransform(1 - m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return (inside - outside + np.where(m > 0, -0.5, 0.5).astype(np.float32)) * scale


class EditMixin:
    """Editing methods for :class:`~ctui.engine.segment.selection.Segmentation` (uses its
    ``labels``, ``apply_region`` and ``add_object``)."""

    labels: np.ndarray

    if TYPE_CHECKING:  # provided by Segmentation, the one class that mixes this in
        def apply_region(self, box: Box, new_values: np.ndarray, *, label: str = "edit") -> None: ...

        def add_object(self, name: str | None = None, **kw: Any) -> int: ...

    # ------------------------------------------------------------ masks
    def apply_mask(self, mask: np.ndarray, object_id: int, *, offset: tuple[int, int, int] = (0, 0, 0),
                   mode: str = "add", axis: int = 0, overwrite: bool = False, label: str | None = None) -> int:
        """Apply ``mask`` (bool 3D placed at ``offset`` (z, y, x), or 2D on slice ``offset[0]``) to the object.

        ``mode``: "add", "replace" (the object equals the mask on the planes along
        ``axis`` that the mask touches) or "subtract". One undo step; returns voxels changed.
        """
        if mode not in MODES:
            raise CtuiError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
        m = mask[None] if mask.ndim == 2 else mask
        bb = _bbox(m)
        if bb is None:
            return 0
        oz, oy, ox = offset
        box = (slice(oz + bb[0].start, oz + bb[0].stop), slice(oy + bb[1].start, oy + bb[1].stop),
               slice(ox + bb[2].start, ox + bb[2].stop))
        if mode == "replace":  # widen the box to the object's extent on the planes the mask touches
            ob = self.object_bbox(object_id)  # type: ignore[attr-defined]
            if ob is not None:
                box = tuple(box[a] if a == axis else slice(min(box[a].start, ob[a].start), max(box[a].stop, ob[a].stop))
                            for a in range(3))  # type: ignore[assignment]
        full = np.zeros(tuple(b.stop - b.start for b in box), bool)
        rel = tuple(slice(o + b.start - bx.start, o + b.stop - bx.start) for o, b, bx in zip(offset, bb, box))
        full[rel] = m[bb]
        region = self.labels[box]
        mine = region == object_id
        free = np.ones(region.shape, bool) if overwrite else (region == 0) | mine
        if mode == "subtract":
            new = np.where(full & mine, np.uint8(0), region)
        elif mode == "add":
            new = np.where(full & free, np.uint8(object_id), region)
        else:
            new = np.where(mine & ~full, np.uint8(0), region)
            new = np.where(full & (free | mine), np.uint8(object_id), new)
        changed = int(np.count_nonzero(new != region))
        if mode != "subtract":
            self.add_object(object_id=object_id)
        self.apply_region(box, new, label=label or f"{mode} object {object_id}")
        return changed

    def paint_brush(self, x: int, y: int, z: int, object_id: int, *, radius: float, axis: int = 0,
                    mode: str = "add", slices: tuple[int, int] | None = None, values: np.ndarray | None = None,
                    hu: tuple[float, float] | None = None, spacing: tuple[float, float, float] | None = None,
                    overwrite: bool = False) -> int:
        """One brush dab (``mode="subtract"``: the eraser) at voxel (x, y, z); returns voxels changed.

        ``slices``: only slices A..B (inclusive) are painted; ``values`` (the series data,
        (nz, ny, nx)) with ``hu`` (low, high): only voxels whose value is in range are
        painted (masking). A dab off the image raises CtuiError and changes nothing.
        """
        off, m = brush(self.labels.shape, x, y, z, radius=radius, axis=axis, spacing=spacing)
        m = self._masked(off, m, slices=slices, values=values, hu=hu)
        verb = {"add": "paint", "replace": "paint (replace)", "subtract": "erase"}.get(mode, mode)
        return self.apply_mask(m, object_id, offset=off, mode=mode, axis=axis, overwrite=overwrite,
                               label=f"{verb} object {object_id} at ({x}, {y}, {z})")

    def _masked(self, off: tuple[int, int, int], m: np.ndarray, *, slices: tuple[int, int] | None,
                values: np.ndarray | None, hu: tuple[float, float] | None) -> np.ndarray:
        m = m.copy()
        if slices is not None:
            zs = np.arange(off[0], off[0] + m.shape[0])
            m[(zs < slices[0]) | (zs > slices[1])] = False
        if hu is not None:
            if values is None:
                raise CtuiError("painting limited to a value range needs the series values")
            box = tuple(slice(o, o + n) for o, n in zip(off, m.shape))
            v = values[box]
            m &= (v >= hu[0]) & (v <= hu[1])
        return m

    # ------------------------------------------------------------ islands
    def _islands(self, object_id: int, connectivity: int) -> tuple[Box, np.ndarray, np.ndarray] | None:
        from scipy import ndimage  # scipy is heavy; only edits need it

        box = self.object_bbox(object_id)  # type: ignore[attr-defined]
        if box is None:
            return None
        region = self.labels[box]
        st = ndimage.generate_binary_structure(3, 1 if connectivity == 6 else (2 if connectivity == 18 else 3))
        lab, n = ndimage.label(region == object_id, structure=st)
        sizes = np.bincount(lab.ravel(), minlength=n + 1)
        sizes[0] = 0
        return box, lab, sizes

    def keep_largest_island(self, object_id: int, *, connectivity: int = 6) -> int:
        """Keep only the object's largest 3D island (6-, 18- or 26-connected). One undo step; voxels removed."""
        got = self._islands(object_id, connectivity)
        if got is None:
            return 0
        box, lab, sizes = got
        keep = np.zeros(sizes.size, bool)
        keep[int(np.argmax(sizes))] = True
        return self._drop(box, lab, keep, f"keep the largest island of object {object_id}")

    def remove_islands(self, object_id: int, min_voxels: int, *, connectivity: int = 6) -> int:
        """Remove the object's islands smaller than ``min_voxels``. One undo step; voxels removed."""
        got = self._islands(object_id, connectivity)
        if got is None:
            return 0
        box, lab, sizes = got
        return self._drop(box, lab, sizes >= int(min_voxels), f"remove islands under {min_voxels} voxels of object {object_id}")

    def _drop(self, box: Box, lab: np.ndarray, keep: np.ndarray, label: str) -> int:
        keep[0] = False
        region = self.labels[box]
        gone = (lab > 0) & ~keep[lab]
        n = int(np.count_nonzero(gone))
        if n:
            self.apply_region(box, np.where(gone, np.uint8(0), region), label=label)
        return n

    # ------------------------------------------------------------ interpolation
    def fill_between_slices(self, object_id: int, *, slices: tuple[int, int] | None = None,
                            spacing: tuple[float, float, float] | None = None, overwrite: bool = False) -> int:
        """Fill the object on the empty slices between its key slices (the slices it is drawn on).

        Between two key slices a < b, slice z gets ``(1 - t) d_a + t d_b > 0`` with
        ``t = (z - a) / (b - a)`` and ``d`` the signed distance (mm, positive inside) of
        the object on a key slice. ``slices`` limits the key slices used (A..B
        inclusive). One undo step; returns voxels added.
        """
        box = self.object_bbox(object_id)  # type: ignore[attr-defined]
        if box is None:
            return 0
        sp = (1.0, 1.0, 1.0) if spacing is None else spacing
        ny, nx = self.labels.shape[1:]
        margin = 2
        yb = slice(max(box[1].start - margin, 0), min(box[1].stop + margin, ny))
        xb = slice(max(box[2].start - margin, 0), min(box[2].stop + margin, nx))
        zb = box[0]
        region = self.labels[zb, yb, xb]
        mine = region == object_id
        keys = [int(k) for k in np.flatnonzero(mine.any(axis=(1, 2)))]
        if slices is not None:
            keys = [k for k in keys if slices[0] <= k + zb.start <= slices[1]]
        new = region.copy()
        for a, b in zip(keys, keys[1:]):
            if b - a < 2:
                continue
            da, db = _sdf(mine[a], sp[1:]), _sdf(mine[b], sp[1:])  # type: ignore[index]
            for k in range(a + 1, b):
                t = (k - a) / (b - a)
                fill = ((1.0 - t) * da + t * db) > 0
                free = np.ones(fill.shape, bool) if overwrite else (new[k] == 0)
                new[k][fill & free] = object_id
        added = int(np.count_nonzero(new != region))
        if added:
            self.apply_region((zb, yb, xb), new, label=f"fill between slices of object {object_id}")
        return added
