"""A pending segmentation result (the label volume untouched until it is accepted).

The TUI shows a :class:`Proposal` hatched on every plane; the review strip reads its
per-slice areas; accepting it is one undo step of the :class:`Segmentation`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.segment.selection import Segmentation
from ctui.engine.segment.selection import _bbox2d as _bbox  # noqa: F401 - one 2D box function


@dataclass
class Proposal:
    """A pending propagation result (labels untouched until :meth:`accept`).

    ``masks``: {z: (y0, x0, bool (h, w))} per slice; ``areas``: {z: pixels};
    ``stops``: {"forward"/"backward": reason}; ``leaks``: list of
    {slice, area, previous_area, direction, action}; ``timings``: seconds per phase.
    """

    object_id: int
    start_slice: int
    shape: tuple[int, int, int]
    masks: dict[int, tuple[int, int, np.ndarray]] = field(default_factory=dict)
    areas: dict[int, int] = field(default_factory=dict)
    stops: dict[str, str] = field(default_factory=dict)
    leaks: list[dict[str, Any]] = field(default_factory=list)
    cancelled: bool = False
    settings: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    accepted: bool = False
    necks: list[int] = field(default_factory=list)  # slices where the neck cut removed something
    replace: bool = False  # accept() makes the object exactly this (a whole segmentation), not adds to it
    cuts: list[dict[str, Any]] = field(default_factory=list)  # where: {"slice", "y", "x", "voxels"} (the cut faces)
    # where leaks enter (segment.leaks: {"slice", "voxel", "ml", ...}): the review strip's L marks
    leak_entries: list[dict[str, Any]] = field(default_factory=list)

    @property
    def voxels(self) -> int:
        return int(sum(self.areas.values()))

    @property
    def slices(self) -> tuple[int, int] | None:
        zs = [z for z, a in self.areas.items() if a > 0]
        return (min(zs), max(zs)) if zs else None

    def warnings(self) -> list[str]:
        out = []
        for lk in self.leaks:
            out.append(f"leak guard at slice {lk['slice']} ({lk['direction']}): area {lk['area']} px after {lk['previous_area']} px, {lk['action']}")
        if self.cancelled:
            out.append("propagation cancelled; result is partial")
        return out

    def bbox(self) -> tuple[tuple[int, int], tuple[int, int], tuple[int, int]] | None:
        if not self.masks:
            return None
        zs = sorted(self.masks)
        y0 = min(m[0] for m in self.masks.values())
        x0 = min(m[1] for m in self.masks.values())
        y1 = max(m[0] + m[2].shape[0] for m in self.masks.values())
        x1 = max(m[1] + m[2].shape[1] for m in self.masks.values())
        return (zs[0], zs[-1] + 1), (y0, y1), (x0, x1)

    def mask3d(self) -> tuple[tuple[int, int, int], np.ndarray] | None:
        """(offset (z, y, x), bool array of the bounding box), or None if empty."""
        bb = self.bbox()
        if bb is None:
            return None
        (z0, z1), (y0, y1), (x0, x1) = bb
        out = np.zeros((z1 - z0, y1 - y0, x1 - x0), bool)
        for z, (my, mx, m) in self.masks.items():
            out[z - z0, my - y0:my - y0 + m.shape[0], mx - x0:mx - x0 + m.shape[1]] |= m
        return (z0, y0, x0), out

    def slice_mask(self, z: int) -> np.ndarray:
        """bool (ny, nx) of the proposal on slice ``z`` (for preview)."""
        out = np.zeros(self.shape[1:], bool)
        if z in self.masks:
            y0, x0, m = self.masks[z]
            out[y0:y0 + m.shape[0], x0:x0 + m.shape[1]] = m
        return out

    def accept(self, segmentation: Segmentation) -> int:
        """Write the proposal into the label volume as one undo step; returns voxels changed."""
        got = self.mask3d()
        self.accepted = True
        if got is None:
            return 0
        offset, m = got
        if self.replace:
            return _replace_object(segmentation, self.object_id, offset, m, bool(self.settings.get("overwrite")))
        return segmentation.paint(m, self.object_id, offset=offset, overwrite=bool(self.settings.get("overwrite")),
                                  label=f"propagate object {self.object_id}")

    @classmethod
    def of_mask(cls, object_id: int, start_slice: int, mask: np.ndarray, **kw: Any) -> Proposal:
        """A proposal holding the whole object ``mask`` (bool (nz, ny, nx)); accepting it replaces the object."""
        prop = cls(object_id=object_id, start_slice=int(start_slice), shape=tuple(mask.shape), replace=True, **kw)
        for z in np.flatnonzero(mask.any(axis=(1, 2))):
            bb = _bbox(mask[z])
            assert bb is not None
            prop.masks[int(z)] = (bb[0], bb[2], mask[z, bb[0]:bb[1], bb[2]:bb[3]].copy())
            prop.areas[int(z)] = int(np.count_nonzero(prop.masks[int(z)][2]))
        return prop


    def summary(self) -> dict[str, Any]:
        rng = self.slices
        return {"object_id": self.object_id, "start_slice": self.start_slice, "voxels": self.voxels,
                "slices": None if rng is None else list(rng), "stops": dict(self.stops),
                "leaks": list(self.leaks), "cancelled": self.cancelled, "warnings": self.warnings(),
                "areas": {int(z): int(a) for z, a in sorted(self.areas.items())}}


def _replace_object(seg: Segmentation, oid: int, offset: tuple[int, int, int], m: np.ndarray, overwrite: bool) -> int:
    """One undo step: the object's voxels become exactly ``m`` (at ``offset``); returns voxels changed."""
    old = seg.object_bbox(oid)
    new = tuple(slice(o, o + n) for o, n in zip(offset, m.shape))
    box = new if old is None else tuple(slice(min(a.start, b.start), max(a.stop, b.stop)) for a, b in zip(old, new))
    cur = seg.labels[box]
    vals = cur.copy()
    vals[vals == oid] = 0
    full = np.zeros(vals.shape, bool)
    full[tuple(slice(n.start - b.start, n.stop - b.start) for n, b in zip(new, box))] = m
    vals[full & ((vals == 0) | overwrite)] = oid
    changed = int(np.count_nonzero(vals != cur))
    seg.apply_region(box, vals, label=f"segment object {oid}")  # type: ignore[arg-type]  # box: tuple() of a generator: mypy sees any length, the length is fixed by construction
    return changed
