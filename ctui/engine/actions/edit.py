"""Editing actions of the slice workspace (the TUI's Enter, brush, eraser, islands, fill
between slices), one engine function each, calling the engine's editing
tools (:mod:`ctui.engine.segment.edit`, methods of ``Segmentation``; one undo step each):
brush and eraser dabs on any plane limited to a slice range and a value (HU) range,
fill in three modes (add, replace, subtract), keep the largest island, remove islands
under N voxels, fill between slices.

Modes as the TUI shows them: *add* joins the object (other objects kept); *replace*:
a fill becomes the object on its slice, a brush claims other objects' voxels;
*subtract* removes from the object.
"""

from __future__ import annotations

from dataclasses import dataclass

from ctui.engine.core.errors import CtuiError
from ctui.engine.segment.edit import MODES
from ctui.engine.segment.necks import DEFAULT_NECK_MM
from ctui.engine.segment.selection import Segmentation, fill_range, neck_fill

__all__ = ["MODES", "EditLimits", "dab", "fill_slice", "parse_limits"]


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


def dab(seg: Segmentation, volume, zyx: tuple[int, int, int], *, axis: int, object_id: int, radius: int,
        mode: str, limits: EditLimits) -> int:
    """One brush dab (``mode`` "subtract": the eraser) at voxel ``zyx`` in the plane across
    volume ``axis`` (0 axial, 1 coronal, 2 sagittal); returns voxels changed. Off the image:
    CtuiError, nothing changed."""
    z, y, x = zyx
    brush_mode = "subtract" if mode == "subtract" else "add"
    return seg.paint_brush(x, y, z, object_id, radius=radius, axis=axis, mode=brush_mode, slices=limits.slices,
                           values=volume.data if limits.values is not None else None, hu=limits.values,
                           spacing=volume.spacing, overwrite=(mode == "replace"))


def fill_slice(seg: Segmentation, image, x: int, y: int, z: int, *, object_id: int, mode: str,
               low: float | None = None, high: float | None = None, tolerance: float | None = None,
               connectivity: int = 8, min_area: int = 5, limits: EditLimits | None = None,
               data=None, neck_mm: float = DEFAULT_NECK_MM,
               spacing_yx: tuple[float, float] = (1.0, 1.0)) -> tuple[int, str, tuple[float, float]]:
    """Threshold fill at (x, y) on slice z, cut at necks narrower than ``neck_mm`` (the
    same seed-slice fill as ``ctui segment``: :func:`neck_fill`; pixel size
    ``spacing_yx`` (dy, dx) mm), applied in ``mode`` (one undo step); the HU limit masks
    it as it does the brush. Returns (pixels changed, the reason when nothing changed,
    (low, high))."""
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
