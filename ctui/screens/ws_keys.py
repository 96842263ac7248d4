"""The workspace's keys (every binding, named in the ``?`` help), its navigation and
view actions (:class:`NavOwner`, composed by :class:`ctui.screens.workspace.WorkspaceScreen`)
and the side panel's text."""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np
from rich.text import Text

from ctui.screens import planes
from ctui.screens.dialogs import PromptScreen
from ctui.screens.keytable import keys
from ctui.screens.session import VIEWS
from ctui.screens.ws_host import Owner, WorkspaceHost
from ctui.screens.ws_state import describe, mm, value_unit

if TYPE_CHECKING:
    from textual.widget import Widget

    from ctui.screens.app import CtuiApp

BINDINGS = keys(via="do", table="""
left,h                move(-1,0)             Cursor left                        hidden
right,l               move(1,0)              Cursor right                       hidden
up,k                  move(0,-1)             Cursor up                          hidden
down,j                move(0,1)              Cursor down                        hidden
shift+left,H          move(-10,0)            Cursor left 10                     hidden
shift+right,L         move(10,0)             Cursor right 10                    hidden
shift+up,K            move(0,-10)            Cursor up 10                       hidden
shift+down,J          move(0,10)             Cursor down 10                     hidden
ctrl+left             pan(-1,0)              Pan left                           hidden
ctrl+right            pan(1,0)               Pan right                          hidden
ctrl+up               pan(0,-1)              Pan up                             hidden
ctrl+down             pan(0,1)               Pan down                           hidden
pageup                slice(1)               Slice +1
pagedown              slice(-1)              Slice -1
home                  slice_to('first')      First slice                        hidden
end                   slice_to('last')       Last slice                         hidden
g                     goto                   Go to slice                        hidden
1                     plane('axial')         Axial view                         hidden
2                     plane('sagittal')      Sagittal view                      hidden
3                     plane('coronal')       Coronal view                       hidden
0                     ortho                  2x2: axial, sagittal, coronal, 3D  hidden
backslash             toggle_panel           Side panel on/off
w                     window_cycle           Window preset                      hidden
W                     window_set             Set window C/W                     hidden
plus,equals_sign      zoom(1)                Zoom in                            hidden
minus                 zoom(-1)               Zoom out                           hidden
v                     view_cycle             Stage view
V                     grid                   2x2 pipeline views                 hidden
f                     filters                Filters
enter                 fill                   Fill
space                 dab                    Paint a brush dab                  hidden
b                     pen('brush')           Brush down/up (moving paints)      hidden
E                     pen('eraser')          Eraser down/up (moving erases)     hidden
comma                 brush_size(-1)         Brush smaller                      hidden
full_stop             brush_size(1)          Brush larger                       hidden
R                     edit_mode              Mode add/replace/subtract          hidden
i                     limits                 Limits: slice range, HU range      hidden
s                     stop_slice             Stop at this slice                 hidden
I                     keep_largest           Keep largest island                hidden
X                     remove_islands         Remove islands under N voxels      hidden
F                     fill_between           Fill between slices                hidden
t                     tools                  Edit tools
left_square_bracket   tolerance(-1)          Tolerance -                        hidden
right_square_bracket  tolerance(1)           Tolerance +                        hidden
T                     range_edit             Edit range/tolerance               hidden
c                     connectivity           4/8 connectivity                   hidden
m                     prop_mode              Propagation slice/3D               hidden
n                     new_object             New object
tab                   cycle_object           Next object                        hidden priority
N                     rename_object          Rename object                      hidden
delete                clear_object           Clear object                       hidden
u                     undo                   Undo
U                     undo(True)             Redo                               hidden
less_than_sign        propagate('backward')  Propagate back                     hidden
greater_than_sign     propagate('forward')   Propagate fwd                      hidden
S                     segment_here           Segment from cursor
G                     segment_panel          Segmentation options
Z                     auto_draft             AI first draft (TotalSegmentator)  hidden
p                     propagate('both')      Propagate
a                     accept                 Accept proposal                    hidden
x                     reject                 Reject proposal                    hidden
escape                cancel                 Cancel job / lift brush            hidden
d                     drift                  Drift
r                     render3d               3D
M                     measure                Measure
e                     export                 Export
o                     open                   Open                               hidden
""")


class NavOwner(Owner):
    """Cursor, slices, planes, zoom, windows and the other screens."""

    # ------------------------------------------------------------------ cursor
    def action_move(self, dx: int, dy: int) -> None:
        """Move the cursor on the current plane (rows of sagittal/coronal run from the top)."""
        s = self.s
        pv = planes.plane_view(s.volume, s.plane)
        before = s.zyx
        s.z, s.y, s.x = planes.moved(pv, before, dx, dy)
        s.clamp()
        if self.ws.edit_tools.pen and s.zyx != before and not self.ws.edit.busy():
            self.ws.edit.stroke(before, s.zyx)
            self.refresh_view()
        elif self.ws.viewstate.ortho_mode:
            self.refresh_view()
        else:
            self.ws.repaint_cursor()

    def action_pan(self, dx: int, dy: int) -> None:
        s = self.s
        if self.ws.viewstate.zoom <= 1:
            self.app.notify("Zoom in (+) first to pan", timeout=2)
            return
        # panning drags the cursor along so it stays visible
        self.action_move(*self.ws.viewstate.pan_by(s, dx, dy))

    def action_slice(self, d: int) -> None:
        """PageUp/PageDown: the next plane along the current view's normal (z for axial)."""
        s = self.s
        pv = planes.plane_view(s.volume, s.plane)
        zyx = list(s.zyx)
        zyx[pv.normal] += d
        s.z, s.y, s.x = zyx
        self.refresh_view()

    def action_slice_to(self, where: str) -> None:
        s = self.s
        pv = planes.plane_view(s.volume, s.plane)
        zyx = list(s.zyx)
        zyx[pv.normal] = 0 if where == "first" else s.shape[pv.normal] - 1
        s.z, s.y, s.x = zyx
        self.refresh_view()

    def action_zoom(self, d: int, at: tuple[float, float] | None = None) -> None:
        """+/- (and Ctrl+wheel): zoom in or out keeping the image point ``at`` (x, y image
        pixel: the pointer's) where it is on screen; with keys, the cursor's point."""
        s, vs = self.s, self.ws.viewstate
        pv = planes.plane_view(s.volume, s.plane)
        iv = next((v for p, _view, v in self.ws.targets() if p == s.plane), None)
        old = vs.zoom
        point = at if at is not None else planes.cursor_in(pv, s.zyx, s.shape)
        seen = None
        if iv is not None and iv.view_map is not None:
            w, h = iv.target_pixels()
            seen = iv.view_map.to_image(w / 2.0, h / 2.0)  # the image point at the view's centre now
        new = s.zoom = vs.zoom_by(d)  # the session keeps it for the project
        if seen is not None and new > 1.0 and new != old:
            k = old / new
            vs.pan_to((point[0] - (point[0] - seen[0]) * k, point[1] - (point[1] - seen[1]) * k), cursor=s.zyx)
        self.ws.repaint_cursor()

    # ------------------------------------------------------------------ windows and views
    def action_window_cycle(self) -> None:
        name, win = self.ws.viewstate.next_window(self.s.window_presets())
        self.s.window = win
        self.refresh_view()
        self.set_status(f"Window {name}: C {win[0]:g} W {win[1]:g}")

    def action_window_set(self) -> None:
        def done(val: str | None) -> None:
            if not val:
                return
            try:
                parts = val.replace(",", " ").replace("/", " ").split()
                c, w = float(parts[0]), float(parts[1])
                if w <= 0:
                    raise ValueError
            except (ValueError, IndexError):
                self.app.notify("Window: give centre and width, e.g. '40 400'", severity="error")
                return
            self.s.window = (c, w)
            self.ws.viewstate.window_name = "custom"
            self.refresh_view()

        c, w = self.s.window
        self.app.push_screen(PromptScreen("Window centre and width (e.g. 40 400)", f"{c:g} {w:g}"), done)

    def action_view_cycle(self) -> None:
        if self.ws.viewstate.grid_mode:
            self.ws.set_layout()
            return
        self.s.plane = planes.slice_plane(self.s.volume)
        self.s.view = VIEWS[(VIEWS.index(self.s.view) + 1) % len(VIEWS)]
        self.ws.set_layout(ortho=self.ws.viewstate.ortho_mode)

    def action_grid(self) -> None:
        self.s.plane = planes.slice_plane(self.s.volume)
        self.ws.set_layout(grid=not self.ws.viewstate.grid_mode)

    def action_plane(self, plane: str) -> None:
        """1/2/3: axial, sagittal or coronal alone (from a 2x2 layout too: a click picks a pane there)."""
        self.s.plane = plane
        self.ws.set_layout()
        self.set_status(f"{plane.capitalize()} view: arrows move in it, PageUp/PageDown step across it")

    def action_ortho(self) -> None:
        if not self.ws.viewstate.ortho_mode and (self.ws.size.width < 100 or self.ws.size.height < 30):
            self.app.notify("The 2x2 layout needs a terminal of at least 100x30: 1/2/3 show one plane",
                            severity="warning", timeout=4)
            return
        self.ws.set_layout(ortho=not self.ws.viewstate.ortho_mode)
        if self.ws.viewstate.ortho_mode:
            self.ws.request_3d()

    # ------------------------------------------------------------------ other screens
    def action_filters(self) -> None:
        from ctui.screens.pipeline_editor import PipelineEditor  # a screen's module loads when it first opens: the workspace paints sooner

        if self.ws.edit.busy():
            return
        self.app.push_screen(PipelineEditor(self.s), lambda _=None: self._after_pipeline())

    def _after_pipeline(self) -> None:
        self.s.dirty = True
        self.ws.set_layout(grid=self.ws.viewstate.grid_mode, ortho=self.ws.viewstate.ortho_mode)

    def action_drift(self) -> None:
        from ctui.screens.drift_screen import DriftScreen  # a screen's module loads when it first opens: the workspace paints sooner

        if not self.ws.edit.busy():
            self.app.push_screen(DriftScreen(self.s), lambda _=None: self._after_drift())

    def _after_drift(self) -> None:
        self.ws.labels_changed()
        self.refresh_view()

    def action_auto_draft(self) -> None:
        from ctui.screens.auto_screen import open_auto  # a screen's module loads when it first opens

        open_auto(self.ws)

    def action_render3d(self) -> None:
        from ctui.screens.view3d import View3DScreen  # a screen's module loads when it first opens: the workspace paints sooner

        self.app.push_screen(View3DScreen(self.s))

    def action_measure(self) -> None:
        from ctui.screens.measure_screen import MeasureScreen  # a screen's module loads when it first opens: the workspace paints sooner

        self.app.push_screen(MeasureScreen(self.s))

    def action_export(self) -> None:
        from ctui.screens.export import export_dialog  # a screen's module loads when it first opens: the workspace paints sooner

        export_dialog(self.ws)

    def action_open(self) -> None:
        cast("CtuiApp", self.app).action_open()  # the workspace runs in no other app


def panel_text(ws: WorkspaceHost) -> Text:
    """The side panel: slice, cursor, value, window, view, tools, pipeline, objects."""
    s, v = ws.s, ws.s.volume
    nz = s.shape[0]
    t = Text()
    t.append("ctui", style="bold")
    src = (s.source_path or v.source or "").rstrip("/").split("/")[-1]
    t.append(f"  {src[:28]}\n", style="dim")
    try:
        xmm, ymm, zmm = s.position_mm()
    except Exception:
        xmm = ymm = zmm = float("nan")
    slice_pos = float(v.slice_positions[s.z]) if v.slice_positions is not None and len(v.slice_positions) == nz else zmm
    t.append(f"Slice {s.z}/{nz - 1}", style="bold")
    t.append(f"  {slice_pos:.1f} mm\n")
    compact = 0 < ws.size.height < 30  # 80x24: the objects (their volumes) must show
    t.append(f"Cursor x {s.x}  y {s.y}\n")
    if not compact:
        t.append(f"  ({xmm:.1f}, {ymm:.1f}, {zmm:.1f}) mm\n", style="dim")
    t.append("Value ", style="bold")
    t.append(f"{s.value():g} {'HU' if v.modality == 'CT' else ''}")
    try:
        fv = s.filtered_value()
    except Exception:  # a filter error is reported by the views; the readout stays
        fv = None
    t.append(f"  filtered {fv:.4g}\n" if fv is not None else "\n")
    if not compact:
        _window_text(ws, t)
    dom = value_unit(s)
    # with no range, S uses the automatic range (shown by _seed_text); the tolerance is Enter's one-slice fill
    t.append(f"Range [{s.range_[0]:g}, {s.range_[1]:g}] {dom}\n" if s.range_ is not None
             else f"Enter fills ±{s.tolerance:g} {dom}\n")
    if not compact:
        t.append(f"Connectivity {s.connectivity}  propagation {s.prop_mode}\n")
    _seed_text(ws, t, compact)
    if not compact:
        _notes_text(ws, t)
    tools = ws.edit_tools
    pen = f" {tools.pen} down" if tools.pen else ""
    t.append(f"Mode {s.edit_mode}  brush {mm(s.brush)} mm{pen}\n")
    if tools.click_fills:
        t.append("Click fills (z)\n", style="yellow")
    if s.roi_box is not None:
        (z0, z1), (y0, y1), (x0, x1) = s.roi_box
        drawn = ws.edit_tools.box_drawn_on
        t.append(f"Box x {x0}..{x1} y {y0}..{y1}\n    slices {z0}..{z1}{'' if drawn is None else f', drawn on {drawn}'}\n",
                 style="rgb(255,150,0)")
    if s.background_seeds:
        t.append(f"Background seeds {len(s.background_seeds)}\n", style="cyan")
    if s.limits.slices is not None or s.limits.values is not None:
        t.append(f"Limits {s.limits.describe()}\n", style="yellow")
    steps = s.pipeline_steps()
    if steps or not compact:
        t.append("\nPipeline", style="bold underline")
        t.append(f" ({len(steps)} steps)\n" if steps else "  (none: f adds)\n")
        for line in steps[:3 if compact else 6]:
            t.append(f" {line[:34]}\n")
    _objects_text(ws, t, compact)
    if s.dirty:
        t.append("\n● unsaved changes", style="yellow")
    if compact:  # 80x24: the objects and their volumes first, the notes after them (the panel scrolls)
        _notes_text(ws, t, lead="\n")
    return t


def _notes_text(ws: WorkspaceHost, t: Text, lead: str = "") -> None:
    """The pending proposal's warnings (in the panel, not toasts over the image). After the objects
    (``lead``: the compact 80x24 panel) they take the rows left: whole when they fit, else one line each
    (:func:`note_line`), else as many lines as fit and "+N notes: ? shows them" (the help lists them whole)."""
    pending = ws.pending
    if pending.proposal is None or not pending.notes:
        return
    notes = pending.notes
    t.append(f"{lead}Notes on the proposal\n", style="bold yellow")
    if not lead:
        for note in notes:
            t.append(f"• {note}\n", style="yellow")
        return
    size = cast("Widget", ws).query_one("#panel").size  # the workspace is a screen
    cells = max(size.width, 20) if size.width else 36  # the text's width (the panel's size is inside its padding)
    rows = size.height - _rows(t.plain, cells) if size.height else len(notes)
    if sum(_rows(f"• {n}", cells) for n in notes) <= rows:
        for note in notes:
            t.append(f"• {note}\n", style="yellow")
        return
    shown = notes if len(notes) <= rows else notes[:max(rows - 1, 0)]
    for note in shown:
        t.append(f"• {note_line(note, cells - 2)}\n", style="yellow")
    if len(shown) < len(notes):
        t.append(f"+{len(notes) - len(shown)} notes: ? shows them\n", style="bold yellow")


def _rows(text: str, cells: int) -> int:
    """The panel rows ``text`` takes, its lines wrapped at ``cells`` (near enough: at words, as the panel)."""
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return sum(max(1, -(-len(line) // cells)) for line in lines)


def note_line(note: str, room: int) -> str:
    """A note's essential line in ``room`` cells: its first clause (up to ": " or "; "), cut after a whole
    word with "…" when still longer; "leak guard at slice 17 (forward): area ..." -> "leak guard at slice
    17 (forward)"."""
    head = note
    for sep in (": ", "; "):
        head = head.split(sep, 1)[0]
    if len(head) <= room:
        return head
    cut = head[:room - 1].rsplit(" ", 1)[0] if " " in head[:room - 1] else head[:room - 1]
    return cut.rstrip(",;:") + "…"


def _window_text(ws: WorkspaceHost, t: Text) -> None:
    s, vs = ws.s, ws.viewstate
    c, w = s.window
    t.append(f"Window C {c:g} W {w:g}")
    if vs.window_name:
        t.append(f" ({vs.window_name})", style="dim")
    view = "2x2 pipeline" if vs.grid_mode else ("2x2 planes" if vs.ortho_mode else s.view)
    t.append(f"\nView {s.plane} {view}  zoom {vs.zoom:g}x\n")


_BARS = " ▁▂▃▄▅▆▇█"


def _seed_text(ws: WorkspaceHost, t: Text, compact: bool = False) -> None:
    """The segmentation settings (G) and the range S would use at the cursor, with the neighbourhood's
    histogram (a sparkline, the range's part bright). ``compact`` (80x24): the settings' first two
    parts and no line on why the range ends (the rows go to the objects and the notes)."""
    s = ws.s
    t.append("Segment ", style="bold")
    if compact:  # the method and the range (G shows the rest)
        o, rng = s.segment_options, s.segment_options.get("range", "given")
        given = s.range_ if rng == "given" else (None if rng == "auto" else rng)  # "given": T's range, if any
        rtxt = "auto" if given is None else f"{given[0]:g}:{given[1]:g}"
        t.append(f"{o.get('method', 'fill')} {s.prop_mode}, range {rtxt}\n", style="dim")
    else:
        t.append(f"{describe(s)}\n", style="dim")
    key = (s.z, s.y, s.x, id(s.pipeline), tuple(s.pipeline_steps()))
    if not ws.seed_range.painted:
        # the segmentation engine (scipy, 0.2-0.3 s on the main thread) loads once the workspace is painted
        ws.seed_range.painted = True
        ws.call_after_refresh(ws.update_panel)
        t.append("Seed range here ...\n", style="dim")
        return
    ws.seed_range.wants(key)  # the side panel computes it once the cursor rests here (SidePanel.follow)
    rc = ws.seed_range.result
    if rc is None:
        t.append("Seed range here ...\n", style="dim")
        return
    t.append(f"Seed range here {rc.low:.0f}..{rc.high:.0f} ", style="bold")
    top = max(rc.hist) or 1
    for h, a, b in zip(rc.hist, rc.edges[:-1], rc.edges[1:]):
        inside = rc.low <= 0.5 * (a + b) <= rc.high
        t.append(_BARS[min(8, round(8 * h / top))], style="green" if inside else "dim")
    t.append("\n")
    stops = getattr(getattr(rc, "steps", None), "stops", None)
    if stops and not compact:  # why the range ends there: a neighbour joins the seed's region past that bound
        t.append(f"  {' and '.join(f'{k} {v:.0f}' for k, v in stops.items())}: a neighbour joins past it\n", style="dim")


def _objects_text(ws: WorkspaceHost, t: Text, compact: bool = False) -> None:
    s = ws.s
    t.append("\nObjects", style="bold underline")
    t.append("  (n new, Tab next)\n")
    objs = sorted(s.seg.objects)
    area = np.bincount(s.seg.labels[s.z].ravel(), minlength=11)
    vols = ws.volumes.of(s)
    px_mm2 = s.volume.spacing[1] * s.volume.spacing[2]
    pending = ws.pending.proposal
    ids = sorted(set(objs) | set(vols) | {s.current} | ({ws.pending.object_id} if pending is not None else set()))
    for i in ids:
        info = s.seg.objects.get(i)
        col = info.color if info is not None else (128, 128, 128)
        t.append("▶" if i == s.current else " ")
        t.append("██", style=f"rgb({col[0]},{col[1]},{col[2]})")
        name = info.name if info is not None else f"object {i}"
        a = int(area[i]) if i < len(area) else 0
        stats = f"{a * px_mm2:7.0f}mm² {vols.get(i, 0.0):6.1f}ml"
        if compact:  # one line each (80x24): the name and the volume
            t.append(f" {name if len(name) <= 20 else name[:19] + '…':<20} {vols.get(i, 0.0):6.1f}ml\n")
        elif len(name) <= 10:
            t.append(f" {name:<10} {stats}\n")
        else:  # a long name gets a line of its own (the panel holds 36 columns), the figures under it
            t.append(f" {name if len(name) <= 32 else name[:31] + '…'}\n{'':15}{stats}\n")
        if pending is not None and i == ws.pending.object_id:  # the hatched proposal's volume: before a accepts it
            _proposed_text(pending, s.volume.spacing, t)


def _proposed_text(p, spacing, t: Text) -> None:
    """The pending proposal's own volume under its object's row (the object's stays as it is until ``a``):
    "proposed 112.3 ml" for one that becomes the object, "proposed +12.3 ml" for one added to it."""
    ml = p.voxels * float(np.prod(spacing)) / 1000.0
    t.append(f"    proposed {'' if getattr(p, 'replace', False) else '+'}{ml:.1f} ml", style="yellow")
    t.append(": a accepts\n", style="dim")  # 34 cells at most: one line in the 36 of the panel
