"""The workspace's segmentation keys: fill, brush, eraser, modes, limits, islands,
fill between slices, objects, undo/redo (:class:`EditOwner`, composed by :class:`WorkspaceScreen`).

Every change is one undo step of the engine's ``Segmentation``; the screen only asks
and reports."""

from __future__ import annotations

from typing import Any

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.actions import defaults
from ctui.engine.actions import edit as et
from ctui.screens.dialogs import ChoiceScreen, ConfirmScreen, PromptScreen
from ctui.screens.planes import plane_view
from ctui.screens.ws_host import Owner
from ctui.screens.ws_state import mm

EDIT_ERRORS = (CtuiError, ValueError, IndexError)


class EditOwner(Owner):
    """The label edits: every change one undo step of the session's ``Segmentation``."""

    # ------------------------------------------------------------------ guards
    def busy(self) -> bool:
        """Label edits wait while a propagation reads the labels (Escape cancels it)."""
        if self.ws.jobs.segmenting:
            self.app.notify("A propagation is running: wait for it or press Escape to cancel", severity="warning", timeout=3)
            return True
        return False

    def editable(self) -> bool:
        return not self.busy()

    def edited(self, msg: str) -> None:
        self.ws.labels_changed()
        self.set_status(msg)
        self.refresh_view()

    # ------------------------------------------------------------------ fill
    def action_fill(self) -> None:
        if not self.editable():
            return
        s = self.s
        if plane_view(s.volume, s.plane).normal != 0:
            self.app.notify("Fill works on the file's slices (the axial view of an axial series: press 1)",
                            severity="warning", timeout=3)
            return
        try:
            with s._lock:
                image = s.pipeline.final_slice(s.volume, s.z)
            kw: dict[str, Any] = {"low": s.range_[0], "high": s.range_[1]} if s.range_ else {"tolerance": s.tolerance}
            n, reason, (lo, hi) = et.fill_slice(s.seg, image, s.x, s.y, s.z, object_id=s.current, mode=s.edit_mode,
                                                connectivity=s.connectivity, limits=s.limits, data=s.volume.data,
                                                spacing_yx=(s.volume.spacing[1], s.volume.spacing[2]), box=s.roi_box, **kw)
        except EDIT_ERRORS as exc:
            self.app.notify(str(exc), severity="error")
            return
        if reason:
            fv = s.filtered_value()
            used = "" if fv is None else f" (the fill uses the filtered value {fv:g}; raw {s.value():g})"
            self.app.notify(f"Fill rejected: {reason}{used}", severity="warning")
            return
        verb = {"add": "Filled", "replace": "Replaced with", "subtract": "Subtracted"}[s.edit_mode]
        self.edited(f"{verb} {n} px, object {s.current} (range {lo:g}..{hi:g}); p propagates, u undoes")

    # ------------------------------------------------------------------ brush / eraser
    def dab(self, tool: str, zyx: tuple[int, int, int] | None = None) -> int:
        """One brush (or eraser) dab at ``zyx`` (the cursor) on the current plane; returns voxels changed."""
        s = self.s
        pv = plane_view(s.volume, s.plane)
        mode = "subtract" if tool == "eraser" else s.edit_mode
        return et.dab(s.seg, s.volume, s.zyx if zyx is None else zyx, axis=pv.normal, object_id=s.current,
                      radius=0, radius_mm=s.brush, mode=mode, limits=s.limits, box=s.roi_box)

    def action_dab(self) -> None:
        if not self.editable():
            return
        tool = self.ws.edit_tools.pen or "brush"
        try:
            n = self.dab(tool)
        except EDIT_ERRORS as exc:
            self.app.notify(str(exc), severity="error")
            return
        msg = f"{'Erased' if tool == 'eraser' else 'Painted'} {n} voxels (brush {mm(self.s.brush)} mm); u undoes"
        if n:
            self.edited(msg)
        else:  # nothing changed: no new labels version (it would recount every object's volume)
            self.set_status(msg)

    def action_pen(self, tool: str) -> None:
        """b / E: put the brush (eraser) down, so moving the cursor paints (erases) from where it went down;
        again lifts it. Putting it down paints nothing (b b leaves the labels as they were; Space dabs)."""
        s = self.s
        if not self.ws.edit_tools.toggle_pen(tool):
            self.set_status(f"{tool.capitalize()} lifted")
            self.update_panel()
            return
        self.refresh_view()  # the pen's outline
        verb = "paint" if tool == "brush" else "erase"
        self.set_status(f"{tool.capitalize()} down ({mm(s.brush)} mm, {s.edit_mode}{'; ' + s.limits.describe() if s.limits.slices or s.limits.values else ''}): move or drag to {verb} "
                        f"from here (Space: a dab); {'b' if tool == 'brush' else 'E'} lifts it, ,/. size")

    def stroke(self, start: tuple[int, int, int], end: tuple[int, int, int]) -> None:
        """Dabs from ``start`` to ``end`` (a cursor move with the pen down), as undo steps of one dab each;
        the pen's first stroke since it went down paints ``start`` too (the stroke starts where it went down)."""
        steps = max(abs(a - b) for a, b in zip(start, end))
        first = 0 if not self.ws.edit_tools.pen_painted else 1
        self.ws.edit_tools.pen_painted = True
        pts = [tuple(int(round(a + (b - a) * t)) for a, b in zip(start, end))
               for t in np.linspace(0.0, 1.0, steps + 1)[first:]] if steps else []
        n = 0
        try:
            for p in dict.fromkeys(pts):
                n += self.dab(self.ws.edit_tools.pen, p)  # type: ignore[arg-type]  # the pen is down while a stroke runs (never None here)
        except EDIT_ERRORS as exc:
            self.app.notify(str(exc), severity="error")
        if n:
            self.ws.labels_changed()

    def action_brush_size(self, d: int) -> None:
        """,/. : the brush radius in mm, one in-plane pixel per step (0 mm: a single pixel)."""
        s = self.s
        step = float(min(s.volume.spacing[1:]))
        s.brush = float(min(max(round(((s.brush or 0.0) + d * step) / step) * step, 0.0), 100.0))
        self.set_status(f"Brush radius {mm(s.brush)} mm ({s.brush_px(plane_view(s.volume, s.plane).normal):.1f} px)")
        self.refresh_view()

    def action_edit_mode(self) -> None:
        s = self.s
        s.edit_mode = et.MODES[(et.MODES.index(s.edit_mode) + 1) % len(et.MODES)]
        what = {"add": "fill/paint add to the object (other objects kept)",
                "replace": "fill replaces the object on the slice, paint claims other objects",
                "subtract": "fill/paint remove from the object"}[s.edit_mode]
        self.app.notify(f"Mode {s.edit_mode}: {what}", timeout=3)
        self.update_panel()

    # ------------------------------------------------------------------ limits
    def action_limits(self) -> None:
        s = self.s
        nz = s.shape[0]

        def done(val: str | None) -> None:
            if val is None:
                return
            try:
                s.limits = et.parse_limits(val, nz)
            except CtuiError as exc:
                self.app.notify(str(exc), severity="error")
                return
            self.set_status(f"Edit and propagation limits: {s.limits.describe()}")
            self.update_panel()

        cur = " ".join(([f"slices {s.limits.slices[0]}:{s.limits.slices[1]}"] if s.limits.slices else [])
                       + ([f"hu {s.limits.values[0]:g}:{s.limits.values[1]:g}"] if s.limits.values else []))
        self.app.push_screen(PromptScreen(f"Limits: 'slices A:B' (0..{nz - 1}) and/or 'hu LO:HI' (empty: none)", cur), done)

    def action_stop_slice(self) -> None:
        """s: propagation and edits stop at this slice, on the side of the object it lies on."""
        s = self.s
        nz = s.shape[0]
        rng = s.seg.slice_range(s.current) if s.seg is not None else None
        mid = (rng[0] + rng[1]) / 2 if rng else nz / 2
        a, b = s.limits.slices or (0, nz - 1)
        if s.z >= mid:
            b = s.z
        else:
            a = s.z
        s.limits.slices = (min(a, b), max(a, b))
        self.set_status(f"Stop at slice {s.z}: edits and propagation limited to slices {s.limits.slices[0]}..{s.limits.slices[1]} (i edits)")
        self.update_panel()

    # ------------------------------------------------------------------ whole-object tools
    def _object_tool(self, fn, done_msg: str) -> None:
        if not self.editable():
            return
        try:
            n = fn(self.s.seg, self.s.current)
        except EDIT_ERRORS as exc:
            self.app.notify(str(exc), severity="error")
            return
        self.edited(done_msg.format(n=n, obj=self.s.current))

    def action_keep_largest(self) -> None:
        self._object_tool(lambda seg, oid: seg.keep_largest_island(oid),
                          "Kept the largest island of object {obj}: {n} voxels removed (u undoes)")

    def action_remove_islands(self) -> None:
        def done(val: str | None) -> None:
            if not val:
                return
            try:
                n = int(val.strip())
                if n < 1:
                    raise ValueError
            except ValueError:
                self.app.notify("Give a number of voxels (e.g. 100)", severity="error")
                return
            self._object_tool(lambda seg, oid: seg.remove_islands(oid, n),
                              "Removed {n} voxels of islands of object {obj} (u undoes)")

        self.app.push_screen(PromptScreen("Remove islands smaller than N voxels", "100"), done)

    def action_fill_between(self) -> None:
        if not self.editable():
            return
        try:
            n = self.s.seg.fill_between_slices(self.s.current, slices=self.s.limits.slices, spacing=self.s.volume.spacing)
        except EDIT_ERRORS as exc:
            self.app.notify(str(exc), severity="error")
            return
        self.edited(f"Filled between slices: {n} voxels added to object {self.s.current} (u undoes)")

    def action_tools(self) -> None:
        options = [("keep_largest", "Keep the largest island (I)"), ("remove_islands", "Remove islands under N voxels (X)"),
                   ("fill_between", "Fill between slices (F)"),
                   ("keep_island", "Keep the island under the cursor (3D)"),
                   ("keep_island_slice", "Keep the island under the cursor (this slice)"),
                   ("remove_island", "Remove the island under the cursor (3D)"),
                   ("scissors_in_slice", "Scissors: erase inside the box (or polygon), this slice"),
                   ("scissors_in_box", "Scissors: erase inside the box (or polygon), its slices"),
                   ("scissors_in_all", "Scissors: erase inside the box (or polygon), all slices"),
                   ("scissors_out_box", "Scissors: erase outside the box (or polygon), its slices"),
                   ("scissors_out_all", "Scissors: erase outside the box (or polygon), all slices"),
                   ("scissors_point", "Scissors polygon: a point at the cursor (P; the scissors then use it)"),
                   ("smooth", "Smooth: median / opening / closing, size in mm"),
                   ("box_corner", "ROI box: a corner at the cursor (y)"),
                   ("box_typed", "ROI box: type its corners X0,Y0,Z0,X1,Y1,Z1"), ("box_clear", "ROI box off (Y)"),
                   ("edit_mode", "Mode add / replace / subtract (R)"),
                   ("limits", "Limits: slice range and HU range (i)"), ("stop_slice", "Stop at this slice (s)")]

        def done(choice: str | None) -> None:
            if choice:
                self.ws.action_do(choice)

        self.app.push_screen(ChoiceScreen(f"Edit object {self.s.current}", options), done)

    # ------------------------------------------------------------------ fill settings
    def action_tolerance(self, d: int) -> None:
        s = self.s
        if s.range_ is not None:
            lo, hi = s.range_
            step = max((hi - lo) * 0.05, 1.0)
            s.range_ = (lo - d * step, hi + d * step) if hi - lo + 2 * d * step > 0 else s.range_
        else:
            step = 5.0 if s.tolerance < 50 else 10.0
            s.tolerance = max(0.0, s.tolerance + d * step)
        self.update_panel()

    def action_range_edit(self) -> None:
        def done(val: str | None) -> None:
            if val is None:
                return
            val = val.strip()
            try:
                if ":" in val or ".." in val:
                    lo, hi = [float(p) for p in val.replace("..", ":").split(":")]
                    self.s.range_ = (min(lo, hi), max(lo, hi))
                else:
                    self.s.tolerance = abs(float(val))
                    self.s.range_ = None
            except ValueError:
                self.app.notify("Give a tolerance (e.g. 60) or a range LO:HI (e.g. 150:400)", severity="error")
                return
            self.update_panel()

        cur = f"{self.s.range_[0]:g}:{self.s.range_[1]:g}" if self.s.range_ else f"{self.s.tolerance:g}"
        self.app.push_screen(PromptScreen("Tolerance (±T around the seed value) or range LO:HI", cur), done)

    def action_prop_mode(self) -> None:
        self.s.prop_mode = "3d" if self.s.prop_mode == "slice" else "slice"
        self.app.notify(f"Propagation: {'one 3D flood fill' if self.s.prop_mode == '3d' else 'slice by slice'}", timeout=2)
        self.update_panel()

    def action_connectivity(self) -> None:
        self.s.connectivity = 4 if self.s.connectivity == 8 else 8
        self.update_panel()

    # ------------------------------------------------------------------ objects
    def action_new_object(self) -> None:
        try:
            self.s.current = self.s.seg.add_object()
        except ValueError as exc:
            self.app.notify(str(exc), severity="error")
            return
        self.s.dirty = True
        self.update_panel()

    def action_rename_object(self) -> None:
        s = self.s
        s.seg.add_object(object_id=s.current)
        info = s.seg.objects[s.current]

        def done(val: str | None) -> None:
            if val and val.strip():
                info.name = val.strip()[:40]
                s.dirty = True
                self.update_panel()

        def picked(choice: str | None) -> None:
            if choice == "_type":
                self.app.push_screen(PromptScreen(f"Name of object {s.current}", info.name), done)
            elif choice:
                done(choice)

        # the common structures first (no typing); names other objects have are left out
        taken = {o.name for i, o in s.seg.objects.items() if i != s.current}
        names = [n for n in defaults.STRUCTURE_NAMES if n not in taken]
        self.app.push_screen(ChoiceScreen(f"Name of object {s.current} (now {info.name})",
                                          [("_type", "type a name ...")] + [(n, n) for n in names]), picked)

    def action_clear_object(self) -> None:
        s = self.s
        if not self.editable():
            return

        def done(ok: bool | None) -> None:
            if ok:
                n = s.seg.clear_object(s.current)
                self.edited(f"Cleared {n} voxels of object {s.current} (u undoes)")

        self.app.push_screen(ConfirmScreen(f"Erase every voxel of object {s.current}? (u undoes)", "Erase", "Keep"), done)

    def action_cycle_object(self) -> None:
        ids = sorted(self.s.seg.objects) or [1]
        self.s.current = ids[(ids.index(self.s.current) + 1) % len(ids)] if self.s.current in ids else ids[0]
        self.update_panel()

    def action_undo(self, redo: bool = False) -> None:
        if self.busy():
            return
        label = self.s.seg.redo() if redo else self.s.seg.undo()
        verb = "Redone" if redo else "Undone"
        self.app.notify(f"{verb}: {label}" if label else f"Nothing to {verb[:-2].lower()}", timeout=2)
        if label:
            self.ws.labels_changed()
            self.refresh_view()
