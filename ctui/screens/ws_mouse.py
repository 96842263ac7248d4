"""The workspace's mouse (:class:`MouseOwner`, composed by :class:`ctui.screens.workspace.WorkspaceScreen`),
the ROI box and background seeds.

Mouse (any terminal that reports mouse events: xterm SGR, tmux with ``mouse on``, SSH):

=============================  ==========================================================
left click                     the cursor (and the crosshair of the other planes) moves
                               there; with ``z`` (click fills) on, it fills as Enter; with
                               the brush/eraser down (b / E) it paints a dab
double click                   segment the current object from there (S at the click)
left drag                      brush/eraser down: paints (erases) along the drag; after
                               ``y`` (box): the ROI box from press to release (the
                               cursor stays); else the cursor follows
right click, Ctrl+click        place (or remove) a background seed
Shift/Alt drag, middle drag    pan (when zoomed in)
wheel / Ctrl+wheel             next/previous slice / zoom (in: on the pointer, the
                               cursor goes there)
click on the side panel        select that object
click on the review strip      go to that slice
=============================  ==========================================================

Every display <-> voxel conversion goes through :mod:`ctui.screens.planes`.
"""

from __future__ import annotations

from typing import Any

from ctui.engine.actions import edit as et
from ctui.engine.core.errors import CtuiError
from ctui.screens import planes
from ctui.screens.dialogs import PromptScreen
from ctui.screens.graphics import PIXEL_MODES, cell_pixels
from ctui.screens.imageview import ImageView
from ctui.screens.keytable import keys
from ctui.screens.strip import ReviewStrip
from ctui.screens.ws_keys import panel_text
from ctui.screens.ws_host import Owner, WorkspaceHost
from ctui.screens.ws_state import mm

EDIT_ERRORS = (CtuiError, ValueError, IndexError)
MOUSE_HELP = ("[b]Mouse[/b] (terminals that report it; tmux: set -g mouse on): click = cursor (z: click fills; "
              "brush down: a dab), double click = segment from there (S), drag = paint/erase with the brush down, the ROI box after y; right click or "
              "Ctrl+click = background seed; Shift/Alt or middle drag = pan; wheel = slices, Ctrl+wheel = zoom "
              "(in: on the pointer); "
              "click an object in the side panel to select it, the review strip to go to a slice. "
              "g takes a slice, x,y or x,y,z.\n")

MOUSE_BINDINGS = keys(via="do", table="""
z                    click_fills      Click fills on/off                                                hidden
B                    background_seed  Background seed here on/off                                       hidden
y                    box_corner       ROI box corner here (or drag)                                     hidden
Y                    box_clear        ROI box off                                                       hidden
right_curly_bracket  mark(1)          Next marked slice                                                 hidden
left_curly_bracket   mark(-1)         Previous marked slice                                             hidden
C                    cut_here         Cut the proposal at this slice                                    hidden
A                    accept_to_here   Accept from the seed to here                                      hidden
P                    scissors_point   Polygon point here (then clicks)                                  hidden
""")


def _plane_of(ws: WorkspaceHost, widget) -> str:
    wid = widget.id or ""
    if wid.startswith("o-"):
        return wid[2:]
    if wid.startswith("g-"):
        return planes.slice_plane(ws.s.volume)
    return ws.s.plane


def _corner_box(a, b, normal: int, shape, slices=None):
    """The box of corners ``a``, ``b`` (z, y, x); along the plane's normal axis a box drawn
    in one plane spans ``slices`` (the slice limits) or the whole volume."""
    box = list(et.box_of_corners(a, b))
    if a[normal] == b[normal]:
        box[normal] = tuple(slices) if (normal == 0 and slices is not None) else (0, shape[normal] - 1)
    return tuple(box)


class MouseOwner(Owner):
    """The screen's mouse events (the screen hands each on) and the box/seed/goto keys."""

    def __init__(self, ws: WorkspaceHost) -> None:
        super().__init__(ws)
        self.drag: tuple | None = None  # what a held button drags: ("pan" | "box" | "paint" | "cursor" | "strip", ...)
        self.box_end: tuple[int, int, int] | None = None  # the voxel under the mouse while a box is dragged
        self.move_pending: Any = None  # the latest mouse move not drawn yet (moves coalesce)

    # ------------------------------------------------------------------ where the mouse is
    def _voxel_at(self, widget: ImageView, event, *, inside: bool = True):
        """(plane, (z, y, x)) under the mouse, or None off the image (``inside``)."""
        region = widget.content_region
        col, row = event.screen_x - region.x, event.screen_y - region.y
        pos = widget.display_to_image(int(col), int(row))
        if pos is None or widget.rgb is None:
            return None
        h, w = widget.rgb.shape[:2]
        if inside and not (-0.5 <= pos[0] < w - 0.5 and -0.5 <= pos[1] < h - 0.5):
            return None
        plane = _plane_of(self.ws, widget)
        pv = planes.plane_view(self.s.volume, plane)
        return plane, planes.voxel_of(pv, pos[0], pos[1], self.s.zyx, self.s.shape)

    def _under(self, event):
        """The widget under the mouse (a terminal's events reach the screen without one)."""
        try:
            return self.ws.get_widget_at(int(event.screen_x), int(event.screen_y))[0]
        except Exception:  # off the screen
            return getattr(event, "widget", None)

    def _image_view(self, event) -> ImageView | None:
        """The slice view under the mouse (in sixel/kitty modes the widget there is its image child)."""
        w = self._under(event)
        while w is not None and w is not self.ws and not isinstance(w, ImageView):
            w = w.parent
        if isinstance(w, ImageView) and w.id not in (None, "o-3d"):
            return w
        return None

    # ------------------------------------------------------------------ mouse events
    def mouse_down(self, event) -> None:
        w = self._under(event)
        if isinstance(w, ReviewStrip):
            z = w.slice_at(int(event.screen_x - w.content_region.x))
            if z is not None:
                self.ws.review.go_slice(z)
                self.drag = ("strip", w, z)  # a drag along the strip picks the slice limits
                w.capture_mouse()
            return
        iv = self._image_view(event)
        if iv is None:
            return
        if event.button == 2 or (event.button == 1 and (event.shift or event.meta)):
            if self.ws.viewstate.zoom <= 1:
                self.set_status("Zoom in first (+ or Ctrl+wheel) to pan")
                return
            self.drag = ("pan", iv, event.screen_x, event.screen_y, self.ws.viewstate.pan_center or self.ws.view_center())
            iv.capture_mouse()
            return
        got = self._voxel_at(iv, event)
        if got is None:
            self.set_status("Click on the image: that click was outside it (nothing changed)")
            return
        plane, zyx = got
        if event.button == 3 or event.ctrl:
            placed = self.s.toggle_background_seed(zyx)
            z, y, x = zyx
            self.set_status(f"Background seed {'placed' if placed else 'removed'} at x {x}, y {y}, slice {z} "
                            f"({len(self.s.background_seeds)} in all)")
            self.refresh_view()
            return
        if event.button != 1:
            return
        self._click(iv, plane, zyx)

    def _click(self, iv: ImageView, plane: str, zyx) -> None:
        s, tools = self.s, self.ws.edit_tools
        s.plane = plane
        if tools.box_corner is not None:  # drawing the box: the cursor (the seed, say) stays where it is
            self.box_end = zyx
            self.drag = ("box", iv, plane, zyx, s.roi_box)
            iv.capture_mouse()
            return
        s.z, s.y, s.x = zyx
        s.clamp()
        if tools.polygon_mode and planes.plane_view(s.volume, plane).normal == 0:
            n = tools.add_point(s.x, s.y)
            self.set_status(f"Polygon: {n} point(s); t then Scissors cuts, Y clears")
            self.refresh_view()
            return
        if tools.pen in ("brush", "eraser"):
            if self.ws.edit.editable():
                n = 0
                try:
                    n = self.ws.edit.dab(tools.pen)
                except EDIT_ERRORS as exc:
                    self.app.notify(str(exc), severity="error")
                if n:  # a dab over what is painted already changes nothing: no new version
                    self.ws.labels_changed()
            self.drag = ("paint", iv, plane, s.zyx)
        elif tools.click_fills:
            self.refresh_view()
            self.ws.edit.action_fill()
            return
        else:
            self.drag = ("cursor", iv, plane, s.zyx)
        iv.capture_mouse()
        self.refresh_view()

    def mouse_move(self, event) -> None:
        """Drag steps are coalesced: the moves queued while one is drawn collapse into the latest
        (a stroke joins the positions with a line, so no pixel of the path is skipped)."""
        if self.drag is None:
            return
        pending = self.move_pending
        self.move_pending = event
        if pending is None:
            self.ws.call_later(self.drag_step)

    def drag_step(self) -> None:
        event, self.move_pending = self.move_pending, None
        drag = self.drag
        if drag is None or event is None:
            return
        if drag[0] == "pan":
            self._pan_drag(event)
            return
        if drag[0] == "strip":
            return  # the limits are taken where the button comes up
        got = self._voxel_at(drag[1], event, inside=False)
        if got is None:
            return
        _plane, zyx = got
        s = self.s
        if drag[0] == "box":
            if zyx != self.box_end:
                self.box_end = zyx
                pv = planes.plane_view(s.volume, drag[2])
                s.roi_box = _corner_box(drag[3], zyx, pv.normal, s.shape, s.limits.slices)
                self.refresh_view()
            return
        if zyx == s.zyx:
            return
        before = s.zyx
        s.z, s.y, s.x = zyx
        s.clamp()
        if drag[0] == "paint" and not self.ws.jobs.segmenting:
            self.ws.edit.stroke(before, s.zyx)
        self.refresh_view()

    def _pan_drag(self, event) -> None:
        if self.drag is None:
            return
        _kind, iv, sx0, sy0, c0 = self.drag
        vm = iv.view_map
        if vm is None or self.ws.viewstate.zoom <= 1:
            return
        if iv.mode in PIXEL_MODES:
            cw, ch = (float(v) for v in cell_pixels())
        else:
            cw, ch = 1.0, 2.0  # half blocks: a cell is one pixel wide, two high
        dx = (event.screen_x - sx0) * cw / vm.sx
        dy = (event.screen_y - sy0) * ch / vm.sy
        self.ws.viewstate.pan_to((c0[0] - dx, c0[1] - dy))
        self.refresh_view()

    def mouse_up(self, event) -> None:
        if self.drag is not None and self.move_pending is not None:
            self.drag_step()  # the last queued move first
        drag, self.drag = self.drag, None
        if drag is None:
            return
        drag[1].release_mouse()
        if drag[0] == "strip":
            self._strip_limits(drag[1], drag[2], int(event.screen_x - drag[1].content_region.x))
        elif drag[0] == "box":
            self._finish_box(drag[2], drag[3], self.box_end, previous=drag[4])
        elif drag[0] == "paint":
            lim = self.s.limits
            within = f"; within {lim.describe()}" if lim.slices is not None or lim.values is not None else ""
            box = "; inside the ROI box" if self.s.roi_box is not None else ""
            self.set_status(f"Painted along the drag (brush {mm(self.s.brush)} mm{within}{box}); u undoes step by step")

    def _strip_limits(self, strip: ReviewStrip, z0: int, col: int) -> None:
        """A drag along the review strip from slice ``z0``: the slice limits (edits and propagation
        stay inside them; ``i`` changes or clears them), no slice numbers typed."""
        z1 = strip.slice_at(col, clamp=True)
        if z1 is None or z1 == z0:
            return
        lo, hi = sorted((z0, z1))
        self.s.limits.slices = (lo, hi)
        self.set_status(f"Slice limits {lo}..{hi} from the strip: edits and propagation stay inside (i changes them)")
        self.update_panel()

    def click(self, event) -> None:
        """Clicks on views are handled on press (above); a click on the side panel selects an object."""
        iv = self._image_view(event)
        if iv is not None:
            event.prevent_default()  # the press already moved the cursor (no second handler)
            t = self.ws.edit_tools  # a double click segments from there (S at the cursor its press put there)
            if event.chain == 2 and event.button == 1 and not (event.ctrl or event.shift or event.meta or t.pen or t.polygon_mode or t.box_corner):
                self.ws.segment.action_segment_here()
            return
        w = self._under(event)
        if w is not None and w.id == "panel":
            self._panel_click(w, int(event.screen_y - w.content_region.y + w.scroll_offset.y),
                              int(event.screen_x - w.content_region.x))

    def _pick_range(self, line: str, col: int) -> None:
        """A click on the seed range's line: its text takes the range, two bars of its histogram
        give the two ends (no numbers typed)."""
        start = line.index(" ", len("Seed range here ")) + 1  # the bars follow "Seed range here LO..HI "
        got = self.ws.seed_range.pick(col - start if col >= start else None)
        if got is None:
            self.set_status("One end of the range picked: click the bar of the other end")
            return
        self.s.range_ = got
        self.set_status(f"Range {got[0]:g}..{got[1]:g} picked on the histogram (S and Enter use it; T edits it)")
        self.update_panel()

    def _panel_click(self, panel, row: int, col: int = 0) -> None:
        lines = panel_text(self.ws).plain.split("\n")
        if 0 <= row < len(lines) and lines[row].startswith("Seed range here ") and ".." in lines[row]:
            self._pick_range(lines[row], col)
            return
        if 0 < row < len(lines) and "██" not in lines[row] and lines[row].startswith(" " * 8) and "██" in lines[row - 1]:
            row -= 1  # the figures' line under an object with a long name
        if not 0 <= row < len(lines) or "██" not in lines[row]:
            return
        s = self.s
        vols = self.ws.volumes.of(self.s)
        ids = sorted(set(s.seg.objects) | set(vols) | {s.current})
        k = sum(1 for line in lines[:row] if "██" in line)
        if k < len(ids):
            s.current = ids[k]
            self.set_status(f"Object {s.current} selected")
            self.update_panel()

    def scroll_up(self, event) -> None:
        self._wheel(event, 1)

    def scroll_down(self, event) -> None:
        self._wheel(event, -1)

    def _wheel(self, event, d: int) -> None:
        w = self._under(event)
        if isinstance(w, ReviewStrip):  # the strip's axis is the slice index
            self.ws.review.go_slice(self.s.z + d)
            return
        iv = self._image_view(event)
        if iv is None:
            return
        if event.ctrl:  # zoom on the pointer: the cursor goes there, the point under it stays put
            got = self._voxel_at(iv, event) if d > 0 else None
            region = iv.content_region
            at = iv.display_to_image(int(event.screen_x - region.x), int(event.screen_y - region.y))
            if got is not None:
                self.s.plane = got[0]
                self.s.z, self.s.y, self.s.x = got[1]
            self.ws.nav.action_zoom(d, at=at if _plane_of(self.ws, iv) == self.s.plane else None)
            return
        plane = _plane_of(self.ws, iv)
        if plane != self.s.plane:
            self.s.plane = plane
        self.ws.nav.action_slice(d)

    # ------------------------------------------------------------------ keys
    def action_goto(self) -> None:
        """g: "Z" goes to slice Z; "X,Y" moves the cursor on this slice; "X,Y,Z" both."""
        s = self.s
        nz, ny, nx = s.shape

        def done(val: str | None) -> None:
            if not val or not val.strip():
                return
            try:
                parts = [int(v) for v in val.replace(" ", ",").split(",") if v.strip()]
                if len(parts) not in (1, 2, 3):
                    raise ValueError
            except ValueError:
                self.app.notify(f"Go to: give a slice (40), x,y (120,88) or x,y,z (120,88,40); not {val!r}",
                                severity="error")
                return
            x, y, z = (s.x, s.y, parts[0]) if len(parts) == 1 else (parts[0], parts[1], parts[2] if len(parts) == 3 else s.z)
            if not (0 <= x < nx and 0 <= y < ny and 0 <= z < nz):
                self.app.notify(f"x 0..{nx - 1}, y 0..{ny - 1}, slices 0..{nz - 1}: moved to the nearest voxel",
                                severity="warning", timeout=3)
            s.z, s.y, s.x = z, y, x
            s.clamp()
            self.refresh_view()

        self.app.push_screen(PromptScreen(f"Go to slice (0..{nz - 1}), x,y or x,y,z", str(s.z)), done)

    def action_click_fills(self) -> None:
        fills = self.ws.edit_tools.toggle_click_fills()
        self.set_status("A click on the image fills there (as Enter)" if fills
                        else "A click on the image moves the cursor")
        self.update_panel()

    def action_background_seed(self) -> None:
        s = self.s
        placed = s.toggle_background_seed()
        self.set_status(f"Background seed {'placed' if placed else 'removed'} at x {s.x}, y {s.y}, slice {s.z} "
                        f"({len(s.background_seeds)} in all; the fill and grow keep out of them)")
        self.refresh_view()

    def action_box_corner(self) -> None:
        """y: first press, a corner at the cursor (or drag the box with the mouse); second, the opposite corner."""
        s, tools = self.s, self.ws.edit_tools
        if tools.box_corner is None:
            tools.box_corner = s.zyx
            self.set_status("Box: first corner set. Move and press y again, or drag the box with the mouse (Y: no box)")
            self.refresh_view()
            return
        self._finish_box(s.plane, tools.box_corner, s.zyx, previous=s.roi_box)

    def _finish_box(self, plane: str, a, b, *, previous) -> None:
        """The box of corners ``a``, ``b`` drawn on ``plane``; a zero-size one restores ``previous``."""
        s = self.s
        self.ws.edit_tools.take_corner()
        pv = planes.plane_view(s.volume, plane)
        if a[pv.rows] == b[pv.rows] or a[pv.cols] == b[pv.cols]:
            s.roi_box = previous
            self.app.notify("The box has zero size (both corners on one row or column): box unchanged",
                            severity="warning", timeout=4)
            self.refresh_view()
            return
        s.roi_box = _corner_box(a, b, pv.normal, s.shape, s.limits.slices)
        (z0, z1), (y0, y1), (x0, x1) = s.roi_box
        one = a[0] == b[0] and z0 != z1  # drawn on one axial slice, spanning more: scissors ask which
        self.ws.edit_tools.box_drawn_on = int(a[0]) if one else None
        drawn = f" (drawn on slice {a[0]}: scissors ask which slices)" if one else ""
        self.set_status(f"ROI box x {x0}..{x1}, y {y0}..{y1}, slices {z0}..{z1}{drawn}: fills, painting and edits "
                        "stay inside (Y removes it)")
        self.refresh_view()

    def action_box_clear(self) -> None:
        s = self.s
        s.roi_box = None
        self.ws.edit_tools.clear_shapes()
        self.set_status("ROI box and polygon off")
        self.refresh_view()
