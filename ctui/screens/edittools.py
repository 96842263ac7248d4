"""Editing tools of the slice workspace on top of ``Segmentation`` (one undo step each).

Brush and eraser dabs on any plane, limited to a slice range and a value (HU) range;
fill and paint in three modes (add, replace, subtract); keep the largest island,
remove islands under N voxels, fill between slices (shape-based interpolation of the
key slices drawn by the user). Every change goes through ``Segmentation.apply_region``,
``paint`` or ``erase`` so it is undoable.

The island and interpolation helpers use scipy.ndimage (labelling, Euclidean
distance transforms) on the object's bounding box only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ctui.engine.core.errors import CtuiError
from ctui.engine.segment.selection import Segmentation, fill_range, threshold_fill
from ctui.screens.planes import PlaneView

MODES = ("add", "replace", "subtract")


@dataclass
class EditLimits:
    """Where edits may write: slices ``slices`` (first, last inclusive, 0-based) and
    voxel values ``values`` (low, high inclusive, data units such as HU); None = anywhere."""

    slices: tuple[int, int] | None = None
    values: tuple[float, float] | None = None

    def describe(self) -> str:
        parts = []
        if self.slices is not None:
            parts.append(f"slices {self.slices[0]}..{self.slices[1]}")
        if self.values is not None:
            parts.append(f"values {self.values[0]:g}..{self.values[1]:g}")
        return ", ".join(parts) or "none"

    def allows_slice(self, z: int) -> bool:
        return self.slices is None or self.slices[0] <= z <= self.slices[1]


def parse_limits(text: str, nz: int) -> EditLimits:
    """``"slices 10:40 hu 100:300"`` (either part optional, ``-`` or empty = none) -> EditLimits."""
    words = text.replace(",", " ").lower().split()
    lim = EditLimits()
    i = 0
    while i < len(words):
        key = words[i]
        if key in ("-", "none", "off"):
            i += 1
            continue
        if key not in ("slices", "slice", "hu", "values", "value") or i + 1 >= len(words):
            raise CtuiError("limits: write e.g. 'slices 10:40 hu 100:300' (either part may be left out)")
        lo_s, _, hi_s = words[i + 1].replace("..", ":").partition(":")
        try:
            lo, hi = float(lo_s), float(hi_s)
        except ValueError:
            raise CtuiError(f"limits: {words[i + 1]!r} is not LOW:HIGH") from None
        lo, hi = min(lo, hi), max(lo, hi)
        if key.startswith("slice"):
            a, b = int(lo), int(hi)
            if a < 0 or b > nz - 1:
                raise CtuiError(f"limits: slices run from 0 to {nz - 1}, got {a}:{b}")
            lim.slices = (a, b)
        else:
            lim.values = (lo, hi)
        i += 2
    return lim


def brush_mask(pv: PlaneView, index: int, center: tuple[int, int], radius: int,
               shape: tuple[int, int, int], spacing: tuple[float, float, float]) -> tuple[np.ndarray, tuple[int, int, int]]:
    """A disk of ``radius`` in-plane pixels (of the finer axis, round in mm) at image pixel
    ``center`` (column, row in the *volume's* index order, not flipped) on plane ``index``.

    Returns (bool mask (dz, dy, dx), offset (z, y, x)) clipped to the volume; raises
    CtuiError when the centre is off the image.
    """
    col, row = center
    nr, nc = shape[pv.rows], shape[pv.cols]
    if not (0 <= col < nc and 0 <= row < nr):
        raise CtuiError(f"the brush is off the image ({col}, {row} outside {nc}x{nr})")
    sr, sc = spacing[pv.rows], spacing[pv.cols]
    unit = min(sr, sc)
    rr = max(int(np.floor(radius * unit / sr)), 0)
    rc = max(int(np.floor(radius * unit / sc)), 0)
    r0, r1 = max(row - rr, 0), min(row + rr, nr - 1)
    c0, c1 = max(col - rc, 0), min(col + rc, nc - 1)
    yy, xx = np.mgrid[r0:r1 + 1, c0:c1 + 1]
    disk = ((yy - row) * sr) ** 2 + ((xx - col) * sc) ** 2 <= (radius * unit + 1e-6) ** 2 + 1e-9
    disk[row - r0, col - c0] = True
    size = [1, 1, 1]
    off = [0, 0, 0]
    size[pv.rows], size[pv.cols] = disk.shape
    off[pv.rows], off[pv.cols], off[pv.normal] = r0, c0, int(index)
    return disk.reshape(size), (off[0], off[1], off[2])


def limit_mask(mask: np.ndarray, offset: tuple[int, int, int], data: np.ndarray, limits: EditLimits) -> np.ndarray:
    """``mask`` (placed at ``offset`` in ``data``) with voxels outside the limits removed."""
    z0, y0, x0 = offset
    dz, dy, dx = mask.shape
    out = mask.copy()
    if limits.slices is not None:
        a, b = limits.slices
        zs = np.arange(z0, z0 + dz)
        out[(zs < a) | (zs > b)] = False
    if limits.values is not None:
        lo, hi = limits.values
        box = data[z0:z0 + dz, y0:y0 + dy, x0:x0 + dx]
        out &= (box >= lo) & (box <= hi)
    return out


def apply_mask(seg: Segmentation, mask: np.ndarray, offset: tuple[int, int, int], object_id: int, mode: str,
               *, label: str) -> int:
    """Paint (add: keep other objects; replace: claim them) or subtract ``mask``; returns voxels changed."""
    if mode == "subtract":
        return seg.erase(mask, offset=offset, object_id=object_id)
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    return seg.paint(mask, object_id, offset=offset, overwrite=(mode == "replace"), label=label)


def fill_slice(seg: Segmentation, image: np.ndarray, x: int, y: int, z: int, *, object_id: int, mode: str,
               low: float | None = None, high: float | None = None, tolerance: float | None = None,
               connectivity: int = 8, min_area: int = 5, limits: EditLimits | None = None,
               data: np.ndarray | None = None) -> tuple[int, str, tuple[float, float]]:
    """Threshold fill at (x, y) on slice z in ``mode`` as one undo step.

    add: the fill joins the object (other objects kept); replace: the fill becomes the
    object on this slice (its other pixels there are cleared; other objects' pixels are
    claimed); subtract: the fill is removed from the object. Returns (pixels changed,
    reason when nothing changed, (low, high)).
    """
    nz, ny, nx = seg.shape
    if not (0 <= x < nx and 0 <= y < ny and 0 <= z < nz):
        raise CtuiError(f"seed ({x}, {y}, {z}) outside the volume")
    lim = limits or EditLimits()
    if not lim.allows_slice(z):
        raise CtuiError(f"slice {z} is outside the edit limits ({lim.describe()})")
    lo, hi = fill_range(float(image[y, x]), tolerance=tolerance, low=low, high=high)
    mask = threshold_fill(image, x, y, low=lo, high=hi, connectivity=connectivity)
    if data is not None and lim.values is not None:
        mask = limit_mask(mask[None], (z, 0, 0), data, lim)[0]
    area = int(mask.sum())
    if area == 0:
        return 0, f"seed value {float(image[y, x]):g} is outside the range [{lo:g}, {hi:g}]", (lo, hi)
    if area < min_area and mode != "subtract":
        return 0, f"fill of {area} px is smaller than the minimum area {min_area} px", (lo, hi)
    if mode == "subtract":
        return seg.erase(mask[None], offset=(z, 0, 0), object_id=object_id), "", (lo, hi)
    seg.add_object(object_id=object_id)
    info = seg.objects[object_id]
    info.seeds.append((int(x), int(y), int(z)))
    info.settings.update({"low": lo, "high": hi, "connectivity": connectivity})
    if mode == "add":
        n = seg.paint(mask[None], object_id, offset=(z, 0, 0), label=f"fill object {object_id} at ({x}, {y}, {z})")
        return n, "", (lo, hi)
    region = seg.labels[z:z + 1]
    new = np.where(region == object_id, np.uint8(0), region)
    new[0][mask] = object_id
    n = int(np.count_nonzero(new != region))
    seg.apply_region((slice(z, z + 1), slice(0, ny), slice(0, nx)), new,
                     label=f"replace object {object_id} on slice {z}")
    return n, "", (lo, hi)


def _object_box(seg: Segmentation, object_id: int):
    box = seg.object_bbox(object_id)
    if box is None:
        raise CtuiError(f"object {object_id} is empty")
    return box


def keep_largest_island(seg: Segmentation, object_id: int) -> int:
    """Keep only the object's largest 26-connected piece; returns voxels removed (one undo step)."""
    box = _object_box(seg, object_id)
    region = seg.labels[box]
    m = region == object_id
    lab, n = ndimage.label(m, structure=np.ones((3, 3, 3), bool))
    if n <= 1:
        return 0
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    drop = m & (lab != int(np.argmax(sizes)))
    seg.apply_region(box, np.where(drop, np.uint8(0), region), label=f"keep largest island of object {object_id}")
    return int(drop.sum())


def remove_small_islands(seg: Segmentation, object_id: int, min_voxels: int) -> int:
    """Remove the object's 26-connected pieces under ``min_voxels``; returns voxels removed."""
    box = _object_box(seg, object_id)
    region = seg.labels[box]
    m = region == object_id
    lab, n = ndimage.label(m, structure=np.ones((3, 3, 3), bool))
    sizes = np.bincount(lab.ravel())
    small = sizes < int(min_voxels)
    small[0] = False
    drop = small[lab]
    if not drop.any():
        return 0
    seg.apply_region(box, np.where(drop, np.uint8(0), region),
                     label=f"remove islands under {min_voxels} voxels of object {object_id}")
    return int(drop.sum())


def _signed_distance(m: np.ndarray) -> np.ndarray:
    """Signed in-plane distance (px): > 0 inside, < 0 outside (shape-based interpolation)."""
    if not m.any():
        return np.full(m.shape, -1e6, np.float32)
    inside = ndimage.distance_transform_edt(m)
    outside = ndimage.distance_transform_edt(~m)
    return (inside - outside).astype(np.float32)


def fill_between_slices(seg: Segmentation, object_id: int, *, limits: EditLimits | None = None) -> int:
    """Interpolate the object on the empty slices between the slices drawn (shape-based:
    linear blend of signed distance maps of the two key slices, as ITK-SNAP/Slicer do).
    Writes only unlabelled voxels; one undo step; returns voxels added."""
    box = _object_box(seg, object_id)
    zs, ys, xs = box
    pad = 2
    ys = slice(max(ys.start - pad, 0), min(ys.stop + pad, seg.shape[1]))
    xs = slice(max(xs.start - pad, 0), min(xs.stop + pad, seg.shape[2]))
    box = (zs, ys, xs)
    region = seg.labels[box]
    m = region == object_id
    keys = np.flatnonzero(m.any(axis=(1, 2)))
    new = region.copy()
    lim = limits or EditLimits()
    for a, b in zip(keys[:-1], keys[1:]):
        if b - a < 2:
            continue
        da, db = _signed_distance(m[a]), _signed_distance(m[b])
        for k in range(a + 1, b):
            if not lim.allows_slice(zs.start + k):
                continue
            t = (k - a) / (b - a)
            inside = (1 - t) * da + t * db > 0
            new[k][inside & (region[k] == 0)] = object_id
    added = int(np.count_nonzero(new != region))
    if added:
        seg.apply_region(box, new, label=f"fill between slices of object {object_id}")
    return added
