"""The workspace's 3D edit tools (:class:`ToolOwner`, composed by the workspace screen),
from the ``t`` menu: keep or remove the island under the cursor (3D or its slice), scissors
inside or outside the ROI box or a polygon (this slice, the box's slices, all slices),
smoothing with a size in mm. Each is one undo step of the engine's ``Segmentation``
through :mod:`ctui.engine.actions.edit`; bad input is a message and nothing changes."""

from __future__ import annotations

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.actions import edit as et
from ctui.engine.core.errors import CtuiError
from ctui.screens.dialogs import ChoiceScreen, ConfirmScreen, PromptScreen
from ctui.screens.ws_host import Owner

EDIT_ERRORS = (CtuiError, ValueError, IndexError)


class ToolOwner(Owner):
    """The 3D edit actions of the ``t`` menu (module docstring)."""

    # ------------------------------------------------------------------ 3D edit tools (t menu)
    def _tool(self, fn, msg: str, *, main_body: bool = False) -> None:
        """Run the edit ``fn`` (one undo step). When it removes more than
        ``defaults.EDIT_CONFIRM_SHARE`` of the object (or, ``main_body``, the island it
        removed was the object's main body) it is undone, the voxels it would remove are drawn
        in red and a dialog asks before doing it again (the same step, redone)."""
        if not self.ws.edit.editable():
            return
        s, oid = self.s, self.s.current
        bb = s.seg.object_bbox(oid)
        was = None if bb is None else s.seg.labels[bb] == oid
        try:
            r = fn()
        except EDIT_ERRORS as exc:
            self.app.notify(f"{exc} (nothing changed)", severity="warning")
            return
        removed, before = int(r.get("removed", 0)), int(r.get("voxels_before", 0))
        share = removed / before if before else 0.0
        body = main_body and removed > int(r.get("voxels", 0))
        if removed and was is not None and (share > defaults.EDIT_CONFIRM_SHARE or body):
            doomed = np.zeros(s.shape, bool)
            doomed[bb] = was & (s.seg.labels[bb] != oid)
            s.seg.undo()
            self._ask_destructive(r, msg, doomed, share, body)
            return
        self._tool_done(r, msg)

    def _tool_done(self, r: dict, msg: str) -> None:
        self.ws.labels_changed()
        self.set_status(msg.format(**r, obj=self.s.current))
        self.refresh_view()

    def _ask_destructive(self, r: dict, msg: str, doomed, share: float, body: bool) -> None:
        s = self.s
        ml = r["removed"] * float(np.prod(s.volume.spacing)) / 1000.0
        what = "the object's main body: " if body else ""
        self.ws.edit_tools.doomed = doomed
        self.refresh_view()

        def done(yes: bool | None) -> None:
            self.ws.edit_tools.doomed = None
            if yes:
                s.seg.redo()
                self._tool_done(r, msg)
                return
            self.set_status(f"Nothing removed from object {s.current} (the edit would take {r['removed']} voxels, "
                            f"{ml:.1f} mL)")
            self.refresh_view()

        stay = "1 voxel stays" if r["voxels"] == 1 else f"{r['voxels']} voxels stay"
        self.app.push_screen(ConfirmScreen(
            f"This removes {what}{r['removed']} voxels, {ml:.1f} mL, {share:.0%} of object {s.current} "
            f"(red on the image; {stay}). Remove them?", yes="Remove", no="Keep",
            at_bottom=True), done)

    def _island(self, keep: bool, in_slice: bool) -> None:
        s = self.s
        what = ("Kept the" if keep else "Removed the") + (" slice island" if in_slice else " island")
        self._tool(lambda: et.island(s.seg, s.zyx, object_id=s.current, keep=keep, in_slice=in_slice, box=s.roi_box),
                   what + " under the cursor of object {obj}: {removed} voxels removed, {voxels} left (u undoes)",
                   main_body=not keep and not in_slice)

    def action_keep_island(self) -> None:
        self._island(True, False)

    def action_keep_island_slice(self) -> None:
        self._island(True, True)

    def action_remove_island(self) -> None:
        self._island(False, False)

    def _scissors(self, inside: bool, where: str) -> None:
        """Erase inside/outside the polygon (3 points or more: P) or else the ROI box, on this
        slice, the box's slices (a polygon: the slice limits, else all) or all slices. A box
        drawn on one slice that spans more: asks whether to cut that slice only or all of them."""
        s = self.s
        poly = self.ws.edit_tools.polygon if len(self.ws.edit_tools.polygon) >= 3 else None
        if poly is None and s.roi_box is None:
            self.app.notify("Scissors cut with the ROI box or a polygon: set one first (y / P, or drag after y)",
                            severity="warning")
            return
        drawn = self.ws.edit_tools.box_drawn_on
        if where == "box" and poly is None and drawn is not None and s.roi_box is not None:
            (z0, z1), _, _ = s.roi_box
            self.app.push_screen(ChoiceScreen(
                "The box was drawn on one slice: cut on", [
                    ("drawn", f"slice {drawn} only (where it was drawn)"),
                    ("box", f"its slices {z0}..{z1} ({z1 - z0 + 1} slices)")]),
                lambda got: None if not got else self._cut(inside, (drawn, drawn) if got == "drawn" else (z0, z1), None,
                                                           f"slice {drawn}" if got == "drawn" else "box"))
            return
        nz = s.shape[0]
        slices = {"slice": (s.z, s.z), "box": None if poly is None else s.limits.slices, "all": (0, nz - 1)}[where]
        self._cut(inside, slices, poly, where)

    def _cut(self, inside: bool, slices, poly, where: str) -> None:
        s = self.s
        what = "polygon" if poly is not None else "box"
        self._tool(lambda: et.cut(s.seg, object_id=s.current, box=None if poly else s.roi_box, polygon=poly,
                                  inside=inside, slices=slices),
                   f"Scissors ({'inside' if inside else 'outside'} the {what}, {where}): "
                   + "{removed} voxels of object {obj} erased (u undoes)")

    def action_scissors_point(self) -> None:
        """P: a polygon point at the cursor (the file's slice plane); clicks then add points too."""
        s = self.s
        n = self.ws.edit_tools.add_point(s.x, s.y)
        self.set_status(f"Polygon: {n} point(s); click or P adds points, t then Scissors cuts "
                        "(3 points or more), Y clears")
        self.refresh_view()

    def action_scissors_in_slice(self) -> None:
        self._scissors(True, "slice")

    def action_scissors_in_box(self) -> None:
        self._scissors(True, "box")

    def action_scissors_in_all(self) -> None:
        self._scissors(True, "all")

    def action_scissors_out_box(self) -> None:
        self._scissors(False, "box")

    def action_scissors_out_all(self) -> None:
        self._scissors(False, "all")

    def action_smooth(self) -> None:
        s = self.s

        def done(val: str | None) -> None:
            if not val or not val.strip():
                return
            words = val.replace(":", " ").split()
            try:
                method, size = words[0].lower(), float(words[1]) if len(words) > 1 else 3.0
            except ValueError:
                self.app.notify("Smooth: write a method and a size in mm, e.g. 'median 3'", severity="error")
                return
            self._tool(lambda: et.smooth(s.seg, object_id=s.current, method=method, size_mm=size,
                                         spacing=s.volume.spacing, box=s.roi_box),
                       f"Smoothed ({method} {size:g} mm) object " + "{obj}: {ml_before:.1f} -> {ml:.1f} ml "
                       "(-{removed} +{added} voxels; u undoes)")

        self.app.push_screen(PromptScreen(f"Smooth object {s.current}: median|opening|closing and a size in mm", "median 3"), done)

    def action_box_typed(self) -> None:
        """The ROI box typed as two corners X0,Y0,Z0,X1,Y1,Z1 (as ``ctui segment/edit --box``)."""
        s = self.s

        def done(val: str | None) -> None:
            if not val or not val.strip():
                return
            try:
                s.roi_box = et.parse_box(val.strip(), s.shape)
                self.ws.edit_tools.box_drawn_on = None
            except CtuiError as exc:
                self.app.notify(f"{exc} (box unchanged)", severity="warning")
                return
            (z0, z1), (y0, y1), (x0, x1) = s.roi_box
            self.set_status(f"ROI box x {x0}..{x1}, y {y0}..{y1}, slices {z0}..{z1} (Y removes it)")
            self.refresh_view()

        cur = ""
        if s.roi_box is not None:
            (z0, z1), (y0, y1), (x0, x1) = s.roi_box
            cur = f"{x0},{y0},{z0},{x1},{y1},{z1}"
        self.app.push_screen(PromptScreen("ROI box: two corners X0,Y0,Z0,X1,Y1,Z1 (X0,Y0,X1,Y1: every slice)", cur), done)
