"""Editing actions of the slice workspace (the TUI's Enter, brush, eraser, islands, fill
between slices), one engine function each, calling the engine's editing
tools (:mod:`ctui.engine.segment.edit`, methods of ``Segmentation``; one undo step each):
brush and eraser dabs on any plane limited to a slice range and a value (HU) range,
fill in three modes (add, replace, subtract), keep the largest island, remove islands
under N voxels, fill between slices.

3D edits (TUI: mouse, the ``t`` menu; CLI: ``ctui edit``): keep or remove the island
under a voxel (:func:`island`), scissors inside/outside a box or polygon (:func:`cut`),
smoothing with a size in mm (:func:`smooth`); painting, fills and these tools are
confined to an ROI box when one is given (``box``: ((z0, z1), (y0, y1), (x0, x1))
inclusive voxel ranges, :func:`parse_box` reads "X0,Y0,Z0,X1,Y1,Z1" as ``ctui segment --box``).

Modes as the TUI shows them: *add* joins the object (other objects kept); *replace*:
a fill becomes the object on its slice, a brush claims other objects' voxels;
*subtract* removes from the object.
"""

from __future__ import annotations

from dataclasses import dataclass

from ctui.engine.core.errors import CtuiError
import numpy as np

from ctui.engine.segment.edit import MODES, SMOOTHING, Roi, in_roi, roi_slices
from ctui.engine.segment.necks import DEFAULT_NECK_MM
from ctui.engine.segment.selection import Segmentation, fill_range, neck_fill
from ctui.engine.segment import review  # re-exported: the review strip and marks of the workspace

__all__ = ["MODES", "SMOOTHING", "EditLimits", "Segmentation", "box_of_corners", "cut", "dab", "fill_slice", "island",
           "parse_box", "parse_limits", "review", "smooth"]


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


def brush_radius_px(radius_mm: float, spacing: tuple[float, float, float], axis: int) -> float:
    """A brush radius in mm as pixels of the finer of the two in-plane axes of the plane
    across ``axis`` (what :func:`ctui.engine.segment.edit.brush` counts)."""
    plane = [float(spacing[a]) for a in range(3) if a != axis]
    return float(radius_mm) / min(plane)


def dab(seg: Segmentation, volume, zyx: tuple[int, int, int], *, axis: int, object_id: int, radius: float,
        mode: str, limits: EditLimits, radius_mm: float | None = None, box: Roi | None = None) -> int:
    """One brush dab (``mode`` "subtract": the eraser) at voxel ``zyx`` in the plane across
    volume ``axis`` (0 axial, 1 coronal, 2 sagittal); returns voxels changed. The radius
    is ``radius_mm`` mm when given (else ``radius`` pixels of the finer in-plane spacing);
    ``box`` confines it to the ROI box. Off the image: CtuiError, nothing changed."""
    z, y, x = zyx
    if radius_mm is not None:
        radius = brush_radius_px(radius_mm, volume.spacing, axis)
    brush_mode = "subtract" if mode == "subtract" else "add"
    return seg.paint_brush(x, y, z, object_id, radius=radius, axis=axis, mode=brush_mode, slices=limits.slices,
                           values=volume.data if limits.values is not None else None, hu=limits.values,
                           spacing=volume.spacing, overwrite=(mode == "replace"), box=box)


def parse_box(text: str, shape: tuple[int, int, int]) -> Roi:
    """``"X0,Y0,Z0,X1,Y1,Z1"`` (two opposite corners, voxel indices, as ``ctui segment --box``;
    ``"X0,Y0,Z0:X1,Y1,Z1"`` too; ``"X0,Y0,X1,Y1"`` or ``"X0,Y0:X1,Y1"``: every slice) ->
    ((z0, z1), (y0, y1), (x0, x1)), checked against ``shape``."""
    try:
        v = [int(t) for t in text.replace(":", ",").split(",")]
        if len(v) not in (4, 6):
            raise ValueError
    except ValueError:
        raise CtuiError(f"box {text!r}: write two corners X0,Y0,Z0,X1,Y1,Z1 (or X0,Y0,X1,Y1 for every slice)") from None
    p, q = (v[:3], v[3:]) if len(v) == 6 else (v[:2] + [0], v[2:] + [shape[0] - 1])
    box = box_of_corners((p[2], p[1], p[0]), (q[2], q[1], q[0]))
    roi_slices(box, shape)  # raises for a zero-size box or one off the volume
    return box


def box_of_corners(a: tuple[int, int, int], b: tuple[int, int, int]) -> Roi:
    """The inclusive box ((z0, z1), (y0, y1), (x0, x1)) spanned by corner voxels ``a`` and ``b`` (z, y, x)."""
    lo = [min(int(u), int(v)) for u, v in zip(a, b)]
    hi = [max(int(u), int(v)) for u, v in zip(a, b)]
    return (lo[0], hi[0]), (lo[1], hi[1]), (lo[2], hi[2])


def island(seg: Segmentation, zyx: tuple[int, int, int], *, object_id: int, keep: bool = True,
           in_slice: bool = False, box: Roi | None = None) -> dict:
    """Keep (or remove) the object's island under voxel ``zyx`` (slice or 3D): one undo step.
    Returns {removed, voxels_before, voxels}."""
    z, y, x = zyx
    before = seg.voxels(object_id)
    n = seg.island_at(object_id, x, y, z, keep=keep, in_slice=in_slice, box=box)
    return {"removed": n, "voxels_before": before, "voxels": seg.voxels(object_id)}


def cut(seg: Segmentation, *, object_id: int, box: Roi | None = None, polygon=None, inside: bool = True,
        slices: tuple[int, int] | None = None) -> dict:
    """Scissors: erase the object inside/outside the box or polygon on ``slices`` (inclusive;
    default: the box's slices, or all for a polygon). One undo step. Returns {removed,
    voxels_before, voxels}; CtuiError when nothing of the object lies there (nothing changed)."""
    before = seg.voxels(object_id)
    n = seg.scissors(object_id, roi=box, polygon=polygon, inside=inside, slices=slices)
    if n == 0:
        where = "inside" if inside else "outside"
        raise CtuiError(f"nothing of object {object_id} lies {where} the {'box' if box is not None else 'polygon'}"
                        f"{'' if slices is None else f' on slices {slices[0]}..{slices[1]}'}: nothing cut")
    return {"removed": n, "voxels_before": before, "voxels": seg.voxels(object_id)}


def smooth(seg: Segmentation, *, object_id: int, method: str, size_mm: float,
           spacing: tuple[float, float, float], box: Roi | None = None) -> dict:
    """Smooth the object (median / opening / closing, ball of ``size_mm`` mm): one undo step.
    Returns {removed, added, voxels_before, voxels, ml_before, ml} (ml from ``spacing``)."""
    before = seg.voxels(object_id)
    removed, added = seg.smooth(object_id, method=method, size_mm=size_mm, spacing=spacing, box=box)
    vox_ml = float(np.prod(spacing)) / 1000.0
    after = seg.voxels(object_id)
    return {"removed": removed, "added": added, "voxels_before": before, "voxels": after,
            "ml_before": before * vox_ml, "ml": after * vox_ml}


def fill_slice(seg: Segmentation, image, x: int, y: int, z: int, *, object_id: int, mode: str,
               low: float | None = None, high: float | None = None, tolerance: float | None = None,
               connectivity: int = 8, min_area: int = 5, limits: EditLimits | None = None,
               data=None, neck_mm: float = DEFAULT_NECK_MM,
               spacing_yx: tuple[float, float] = (1.0, 1.0),
               box: Roi | None = None) -> tuple[int, str, tuple[float, float]]:
    """Threshold fill at (x, y) on slice z, cut at necks narrower than ``neck_mm`` (the
    same seed-slice fill as ``ctui segment``: :func:`neck_fill`; pixel size
    ``spacing_yx`` (dy, dx) mm), applied in ``mode`` (one undo step); the HU limit masks
    it as it does the brush. Returns (pixels changed, the reason when nothing changed,
    (low, high)). ``box``: the fill stays inside the ROI box."""
    nz, ny, nx = seg.shape
    if not (0 <= x < nx and 0 <= y < ny and 0 <= z < nz):
        raise CtuiError(f"seed ({x}, {y}, {z}) outside the volume")
    lim = limits or EditLimits()
    if not lim.allows_slice(z):
        raise CtuiError(f"slice {z} is outside the edit limits ({lim.describe()})")
    lo, hi = fill_range(float(image[y, x]), tolerance=tolerance, low=low, high=high)
    mask = neck_fill(image, x, y, low=lo, high=hi, connectivity=connectivity, neck_mm=neck_mm,
                     spacing_yx=spacing_yx)
    if data is not None and lim.values is not None:
        mask &= (data[z] >= lim.values[0]) & (data[z] <= lim.values[1])
    if box is not None:
        if not box[0][0] <= z <= box[0][1]:
            raise CtuiError(f"slice {z} is outside the ROI box (slices {box[0][0]}..{box[0][1]})")
        mask &= in_roi((z, 0, 0), (1, ny, nx), box)[0]
    area = int(mask.sum())
    if area == 0:
        return 0, f"seed value {float(image[y, x]):g} is outside the range [{lo:g}, {hi:g}]", (lo, hi)
    if area < min_area and mode != "subtract":
        return 0, f"fill of {area} px is smaller than the minimum area {min_area} px", (lo, hi)
    if mode != "subtract":
        seg.add_object(object_id=object_id)
        info = seg.objects[object_id]
        info.seeds.append((int(x), int(y), int(z)))
        info.settings.update({"low": lo, "high": hi, "connectivity": connectivity, "neck_mm": neck_mm})
    verb = {"add": "fill", "replace": "replace", "subtract": "subtract"}[mode]
    n = seg.apply_mask(mask, object_id, offset=(z, 0, 0), mode=mode, axis=0, overwrite=(mode == "replace"),
                       label=f"{verb} object {object_id} at ({x}, {y}, {z})")
    return n, "", (lo, hi)
