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
``island_at``               keep (or remove) the island under a voxel, in its slice or in 3D
``scissors``                erase the object inside or outside a box or a polygon, on a
                            slice range (all slices by default)
``smooth``                  median, opening or closing of the object with a ball of a
                            size in mm
==========================  ===========================================================

A box (``roi``) is ((z0, z1), (y0, y1), (x0, x1)), inclusive voxel ranges, as the TUI's
ROI box: painting (``paint_brush(box=...)``) and these tools write only inside it.

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
SMOOTHING = ("median", "opening", "closing")
Box = tuple[slice, slice, slice]
Roi = tuple[tuple[int, int], tuple[int, int], tuple[int, int]]


def roi_slices(roi: Roi, shape: tuple[int, int, int]) -> Box:
    """The slices of an inclusive voxel box ((z0, z1), (y0, y1), (x0, x1)) clipped to ``shape``.

    Corners may come in any order. Raises CtuiError for a box of zero width or height
    in the slice (two corners on one row or column) or one wholly off the volume."""
    out = []
    for a, (lo, hi) in enumerate(roi):
        lo, hi = sorted((int(lo), int(hi)))
        if a > 0 and lo == hi:
            raise CtuiError(f"the box has zero {'height' if a == 1 else 'width'} ({'y' if a == 1 else 'x'} {lo}..{hi}): "
                            "give two corners apart")
        lo, hi = max(lo, 0), min(hi, shape[a] - 1)
        if lo > hi:
            raise CtuiError(f"the box {roi} lies outside the volume (shape z, y, x {tuple(shape)})")
        out.append(slice(lo, hi + 1))
    return out[0], out[1], out[2]


def polygon_mask(points, shape_yx: tuple[int, int]) -> np.ndarray:
    """bool (ny, nx): the polygon through (x, y) pixel ``points`` filled (its edges included).

    Needs at least 3 points that do not lie on one line (CtuiError otherwise)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) < 3:
        raise CtuiError(f"a polygon needs at least 3 points, got {len(pts)}")
    mask = np.zeros(shape_yx, np.uint8)
    cv2.fillPoly(mask, [np.round(pts).astype(np.int32)], 1)
    if not mask.any():
        raise CtuiError("the polygon lies outside the slice")
    return mask.astype(bool)


def ball(size_mm: float, spacing: tuple[float, float, float]) -> np.ndarray:
    """bool ball of diameter ``size_mm`` on a grid of ``spacing`` (dz, dy, dx) mm (at least
    one voxel across; an axis whose voxels are wider than the ball gets one voxel)."""
    r = [int(np.floor(size_mm / 2.0 / float(sp) + 1e-9)) for sp in spacing]
    if max(r) == 0:
        raise CtuiError(f"smoothing size {size_mm:g} mm is under two voxels ({', '.join(f'{v:g}' for v in spacing)} mm): "
                        "give a larger size")
    zz, yy, xx = np.ogrid[-r[0]:r[0] + 1, -r[1]:r[1] + 1, -r[2]:r[2] + 1]
    d = sum((g * float(sp)) ** 2 for g, sp in zip((zz, yy, xx), spacing))
    return d <= (size_mm / 2.0) ** 2 + 1e-6


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


def in_roi(offset: tuple[int, int, int], shape: tuple[int, int, int], roi: Roi) -> np.ndarray:
    """bool array of ``shape`` placed at ``offset`` (z, y, x): True inside the inclusive box ``roi``."""
    axes = []
    for o, n, (lo, hi) in zip(offset, shape, roi):
        idx = np.arange(o, o + n)
        axes.append((idx >= min(lo, hi)) & (idx <= max(lo, hi)))
    return axes[0][:, None, None] & axes[1][None, :, None] & axes[2][None, None, :]


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
            ob = self.object_bbox(object_id)  # type: ignore[attr-defined]  # EditMixin: Segmentation, which it is mixed into, defines object_bbox
            if ob is not None:
                box = tuple(box[a] if a == axis else slice(min(box[a].start, ob[a].start), max(box[a].stop, ob[a].stop))
                            for a in range(3))  # type: ignore[assignment]  # box: tuple() of a generator: mypy sees any length, the length is fixed by construction
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
                    overwrite: bool = False, box: Roi | None = None) -> int:
        """One brush dab (``mode="subtract"``: the eraser) at voxel (x, y, z); returns voxels changed.

        ``slices``: only slices A..B (inclusive) are painted; ``values`` (the series data,
        (nz, ny, nx)) with ``hu`` (low, high): only voxels whose value is in range are
        painted (masking); ``box``: only voxels inside the ROI box. A dab off the image
        raises CtuiError and changes nothing.
        """
        off, m = brush(self.labels.shape, x, y, z, radius=radius, axis=axis, spacing=spacing)
        m = self._masked(off, m, slices=slices, values=values, hu=hu)
        if box is not None:
            m &= in_roi(off, m.shape, box)
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

        box = self.object_bbox(object_id)  # type: ignore[attr-defined]  # EditMixin: Segmentation, which it is mixed into, defines object_bbox
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
        box = self.object_bbox(object_id)  # type: ignore[attr-defined]  # EditMixin: Segmentation, which it is mixed into, defines object_bbox
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
            da, db = _sdf(mine[a], sp[1:]), _sdf(mine[b], sp[1:])
            for k in range(a + 1, b):
                t = (k - a) / (b - a)
                fill = ((1.0 - t) * da + t * db) > 0
                free = np.ones(fill.shape, bool) if overwrite else (new[k] == 0)
                new[k][fill & free] = object_id
        added = int(np.count_nonzero(new != region))
        if added:
            self.apply_region((zb, yb, xb), new, label=f"fill between slices of object {object_id}")
        return added

    # ------------------------------------------------------------ 3D edits at a point, scissors, smoothing
    def island_at(self, object_id: int, x: int, y: int, z: int, *, keep: bool = True, in_slice: bool = False,
                  connectivity: int = 6, box: Roi | None = None) -> int:
        """Keep (``keep``) or remove the object's island through voxel (x, y, z).

        ``in_slice``: the islands of slice z only (4-connected; the other slices stay);
        else 3D islands (6-, 18- or 26-connected). ``box``: only voxels inside the ROI
        box are removed. One undo step; returns voxels removed. CtuiError when the voxel
        is off the image or not on the object (nothing changed)."""
        from scipy import ndimage

        nz, ny, nx = self.labels.shape
        if not (0 <= x < nx and 0 <= y < ny and 0 <= z < nz):
            raise CtuiError(f"({x}, {y}, {z}) is off the image (x 0..{nx - 1}, y 0..{ny - 1}, slices 0..{nz - 1})")
        if self.labels[z, y, x] != object_id:
            raise CtuiError(f"voxel ({x}, {y}, {z}) is not on object {object_id}: put the cursor on the island")
        if in_slice:
            bb: Box = (slice(z, z + 1), slice(0, ny), slice(0, nx))
            lab, _n = ndimage.label(self.labels[z] == object_id)
            lab = lab[None]
        else:
            bb = self.object_bbox(object_id)  # type: ignore[attr-defined]  # EditMixin: Segmentation, which it is mixed into, defines object_bbox
            st = ndimage.generate_binary_structure(3, 1 if connectivity == 6 else (2 if connectivity == 18 else 3))
            lab, _n = ndimage.label(self.labels[bb] == object_id, structure=st)
        this = lab == lab[z - bb[0].start, y - bb[1].start, x - bb[2].start]
        gone = (lab > 0) & (~this if keep else this)
        if box is not None:
            gone &= in_roi((bb[0].start, bb[1].start, bb[2].start), gone.shape, box)
        n = int(np.count_nonzero(gone))
        if n:
            what = ("keep" if keep else "remove") + (" the slice island" if in_slice else " the island")
            self.apply_region(bb, np.where(gone, np.uint8(0), self.labels[bb]),
                              label=f"{what} of object {object_id} at ({x}, {y}, {z})")
        return n

    def scissors(self, object_id: int, *, roi: Roi | None = None, polygon=None, inside: bool = True,
                 slices: tuple[int, int] | None = None) -> int:
        """Erase the object inside (``inside``) or outside a region on a slice range.

        The region is the box ``roi`` ((z0, z1), (y0, y1), (x0, x1) inclusive: its y, x
        extent; its z range unless ``slices`` is given) or ``polygon`` ((x, y) pixel
        points, filled) on every slice of ``slices`` (first, last inclusive; default all).
        One undo step; returns voxels erased (0: none of the object was there)."""
        nz, ny, nx = self.labels.shape
        if (roi is None) == (polygon is None):
            raise CtuiError("scissors need a box or a polygon (one of them)")
        if roi is not None:
            bz, by, bx = roi_slices(roi, self.labels.shape)
            region = np.zeros((ny, nx), bool)
            region[by, bx] = True
            zr = (bz.start, bz.stop - 1) if slices is None else slices
        else:
            region = polygon_mask(polygon, (ny, nx))
            zr = (0, nz - 1) if slices is None else slices
        z0, z1 = sorted((int(zr[0]), int(zr[1])))
        z0, z1 = max(z0, 0), min(z1, nz - 1)
        if z0 > z1:
            raise CtuiError(f"slices {zr[0]}..{zr[1]} lie outside the volume (slices 0..{nz - 1})")
        cut = region if inside else ~region
        ob = self.object_bbox(object_id)  # type: ignore[attr-defined]  # EditMixin: Segmentation, which it is mixed into, defines object_bbox
        if ob is None or z1 < ob[0].start or z0 >= ob[0].stop:
            return 0
        # the undo step stores only the object's box on these slices
        bb: Box = (slice(max(z0, ob[0].start), min(z1 + 1, ob[0].stop)), ob[1], ob[2])
        cur = self.labels[bb]
        gone = (cur == object_id) & cut[ob[1], ob[2]][None]
        n = int(np.count_nonzero(gone))
        if n:
            self.apply_region(bb, np.where(gone, np.uint8(0), cur),
                              label=f"scissors {'inside' if inside else 'outside'} on object {object_id}, slices {z0}..{z1}")
        return n

    def smooth(self, object_id: int, *, method: str = "median", size_mm: float = 3.0,
               spacing: tuple[float, float, float] = (1.0, 1.0, 1.0), box: Roi | None = None) -> tuple[int, int]:
        """Smooth the object with a ball of diameter ``size_mm`` (on ``spacing`` (dz, dy, dx) mm):
        ``median`` (majority vote in the ball), ``opening`` (removes spurs and thin
        bridges), ``closing`` (fills notches and small holes). Voxels of other objects
        are never taken; ``box`` limits the change to the ROI box. One undo step;
        returns (voxels removed, voxels added). CtuiError for an empty object, an unknown
        method or a size under two voxels (nothing changed)."""
        from scipy import ndimage

        if method not in SMOOTHING:
            raise CtuiError(f"smoothing method must be one of {', '.join(SMOOTHING)}, got {method!r}")
        ob = self.object_bbox(object_id)  # type: ignore[attr-defined]  # EditMixin: Segmentation, which it is mixed into, defines object_bbox
        if ob is None:
            raise CtuiError(f"object {object_id} is empty: nothing to smooth")
        k = ball(float(size_mm), spacing)
        pad = [n // 2 + 1 for n in k.shape]
        shape = self.labels.shape
        bb: Box = tuple(slice(max(o.start - p, 0), min(o.stop + p, n)) for o, p, n in zip(ob, pad, shape))  # type: ignore[assignment]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
        region = self.labels[bb]
        mine = region == object_id
        if method == "median":
            votes = ndimage.convolve(mine.astype(np.int16), k.astype(np.int16), mode="constant")
            new_mask = votes * 2 > int(k.sum())
        elif method == "opening":
            new_mask = ndimage.binary_opening(mine, structure=k)
        else:
            padded = np.pad(mine, [(p, p) for p in pad])
            new_mask = ndimage.binary_closing(padded, structure=k)[tuple(slice(p, -p) for p in pad)]
        new_mask &= (region == 0) | mine
        if box is not None:
            inside = in_roi((bb[0].start, bb[1].start, bb[2].start), region.shape, box)
            new_mask = np.where(inside, new_mask, mine)
        removed = int(np.count_nonzero(mine & ~new_mask))
        added = int(np.count_nonzero(new_mask & ~mine))
        if removed or added:
            new = np.where(mine & ~new_mask, np.uint8(0), region)
            new = np.where(new_mask & ~mine, np.uint8(object_id), new)
            self.apply_region(bb, new, label=f"smooth ({method} {size_mm:g} mm) object {object_id}")
        return removed, added
