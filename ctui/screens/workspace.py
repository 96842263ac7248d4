"""The slice workspace: axial, sagittal and coronal views (one at a time, or 2x2 with
the 3D view), the pipeline's four views of an axial slice (2x2), a shared cursor
(crosshair), the side panel and every segmentation key.

The screen draws; its owners (:mod:`ctui.screens.ws_host` lists them) hold the rest and
do the keys: one Textual action, ``do(name, args)``, runs an owner's ``action_<name>``
through the screen's table of actions, and one handler hands the workers' messages to
their owners.

Slices are numbered from 0 in the TUI as in the CLI ("Slice 40/79": index/last index).
"""

from __future__ import annotations

import numpy as np
from typing import Any, Callable, ClassVar

from textual import events, on, work
from textual.app import ComposeResult
from textual.containers import Grid, Horizontal, Vertical
from textual.screen import Screen
from textual.message import Message
from textual.widgets import Label, ProgressBar, Static

from ctui.engine.core.windows import apply_window
from ctui.screens import planes
from ctui.screens.guard import GuardMixin
from ctui.screens.imageview import ImageView
from ctui.screens.keybar import KeyBar
from ctui.screens.sidepanel import SidePanel
from ctui.screens.messages import (AutoReady, CellRendered, JobFailed, JobFinished, JobProgress, LabelsChanged, ProposalReady,
                                   SeedRangeReady, SegmentationFailed, StageViewsReady, Status)
from ctui.screens.session import VIEWS, Session
from ctui.screens.strip import ReviewStrip
from ctui.screens.vessel_tool import VESSEL_BINDINGS, VesselOwner
from ctui.screens.ws_edit import EditOwner
from ctui.screens.ws_host import Owner
from ctui.screens.ws_jobs import JobRunner
from ctui.screens.ws_keys import BINDINGS, NavOwner, panel_text
from ctui.screens.ws_mouse import MOUSE_BINDINGS, MouseOwner
from ctui.screens.ws_overlay import draw_overlay
from ctui.screens.ws_review import ReviewOwner
from ctui.screens.ws_segment import SegmentRunner
from ctui.screens.ws_state import EditTools, Jobs, ObjectVolumes, ProposalState, SeedRange, ViewState
from ctui.screens.ws_tools import ToolOwner


class WorkspaceScreen(GuardMixin, Screen):
    """Slice views + side panel, composed of owners (module docstring). Thin: every computation
    is an engine call."""

    BINDINGS = BINDINGS + MOUSE_BINDINGS + VESSEL_BINDINGS
    #: more owners (built with the screen) whose ``action_<name>`` the key actions ``do('<name>')`` reach:
    #: tools a subclass adds (ARCHITECTURE.md, "A TUI tool or key"; tests/tui/test_tui_tool.py)
    TOOLS: ClassVar[tuple[type[Owner], ...]] = ()

    DEFAULT_CSS = """
    WorkspaceScreen #views { height: 1fr; }
    WorkspaceScreen #grid, WorkspaceScreen #ortho { grid-size: 2 2; grid-gutter: 0 1; display: none; width: 1fr; }
    WorkspaceScreen #grid.on, WorkspaceScreen #ortho.on { display: block; }
    WorkspaceScreen #main-box.off { display: none; }
    WorkspaceScreen .cell-label { height: 1; width: 1fr; color: $text-muted; }
    WorkspaceScreen #oc-3d { height: auto; max-height: 3; }
    WorkspaceScreen #progress-row { height: 1; display: none; }
    WorkspaceScreen #progress-row.on { display: block; }
    WorkspaceScreen #progress-row Label { width: auto; padding: 0 1; }
    WorkspaceScreen #status { height: auto; max-height: 3; background: $boost; padding: 0 1; }
    WorkspaceScreen #panel.hidden { display: none; }
    """

    def __init__(self, session: Session) -> None:
        super().__init__()
        self.s = session
        self.viewstate = ViewState()  # layout, pan, window preset, pipeline-views requests
        self.viewstate.zoom = session.zoom  # as the project was saved
        self.edit_tools = EditTools()  # pen, click fills, box corner, scissors polygon
        self.jobs = Jobs()  # the running worker and segmentation
        self.pending = ProposalState()  # the proposal waiting for a (accept) or x (reject)
        self.volumes = ObjectVolumes()  # labels version, volume per object
        self.seed_range = SeedRange()  # the side panel's range at the cursor
        self._status_lines = 1  # the status line's height (a longer message wraps)
        # the owners: each holds its part of the state and does its keys (ws_host.WorkspaceHost: what they see)
        self.nav = NavOwner(self)  # cursor, slices, planes, zoom, windows, the other screens
        self.edit = EditOwner(self)  # label edits: fill, brush, objects, undo
        self.tools = ToolOwner(self)  # the 3D edit tools of the t menu
        self.mouse = MouseOwner(self)  # clicks, drags, the wheel; the ROI box and background seeds
        self.review = ReviewOwner(self)  # the review strip and its keys
        self.vessel = VesselOwner(self)  # D / O: the vessel tool
        self.segment = SegmentRunner(self)  # S, p, a, x, Escape: the segmentation runs and the proposal
        self.work = JobRunner(self)  # the 3D cell, exports, the AI draft
        owners: list[Owner] = [self.nav, self.edit, self.tools, self.mouse, self.review, self.vessel, self.segment,
                               self.work, *(tool(self) for tool in self.TOOLS)]
        #: the key actions by name: each owner's action_<name> (one owner per name)
        self.actions: dict[str, Callable[..., Any]] = {"toggle_panel": self.toggle_panel}
        for owner in owners:
            for name, fn in owner.actions().items():
                if name in self.actions:
                    raise ValueError(f"two owners of the workspace's action {name!r}")
                self.actions[name] = fn

    # ------------------------------------------------------------------ layout
    def compose(self) -> ComposeResult:
        with Horizontal(id="views"):
            with Vertical(id="main-box"):
                yield Label("", id="main-caption", classes="cell-label")
                yield ImageView(id="main")
                yield ReviewStrip(id="strip")
            with Grid(id="grid"):
                for v in VIEWS:
                    with Vertical(classes="cell"):
                        yield Label(v, classes="cell-label")
                        yield ImageView(id=f"g-{v}")
            with Grid(id="ortho"):
                for p in (*planes.PLANES, "3d"):
                    with Vertical(classes="cell"):
                        yield Label(p, id=f"oc-{p}", classes="cell-label")
                        yield ImageView(id=f"o-{p}")
            yield SidePanel(self.seed_range, id="panel")
        with Horizontal(id="progress-row"):
            yield Label("", id="progress-label")
            yield ProgressBar(total=100, id="progress", show_eta=False)
            yield Label("[dim]Esc cancels[/dim]")
        yield Static("", id="status")
        yield KeyBar(id="keys")  # the main keys, wrapped at narrow widths (80x24)

    def on_mount(self) -> None:
        self.refresh_view()
        if self.s.volume.meta.get("memory_plan"):  # not in memory: say how the voxels are held
            self.set_status(str(self.s.volume.meta["memory_plan"]))

    # ------------------------------------------------------------------ geometry of the views
    @property
    def main_view(self) -> ImageView:
        return self.query_one("#main", ImageView)

    def view_center(self, plane: str | None = None) -> tuple[float, float]:
        """(x, y) image pixel the view of ``plane`` (default: the session's) centres on."""
        return self.viewstate.center(self.s, plane or self.s.plane)

    # ------------------------------------------------------------------ images
    def plane_image(self, plane: str, view: str = "overlay") -> np.ndarray:
        """The grey (``view`` "original") or composed RGB image of ``plane`` through the cursor."""
        s = self.s
        pv = planes.plane_view(s.volume, plane)
        idx = s.zyx[pv.normal]
        gray = apply_window(planes.take(s.volume.data, pv, idx), s.window)
        if view == "original":
            return gray
        lab2 = planes.take(s.seg.labels, pv, idx)
        pending = self.pending
        rgb = planes.compose(gray, lab2, pending.plane(pv, idx, s.shape), proposal_id=pending.object_id)
        if self.edit_tools.doomed is not None:  # an edit waiting for its confirmation: what it removes, in red
            gone = planes.take(self.edit_tools.doomed, pv, idx)
            rgb[gone] = (rgb[gone] * 0.3 + np.array([255, 40, 40]) * 0.7).astype(np.uint8)
        return rgb

    def caption(self, plane: str) -> str:
        s = self.s
        pv = planes.plane_view(s.volume, plane)
        axis = "zyx"[pv.normal]
        left, right, top, bottom = pv.letters
        idx, last = s.zyx[pv.normal], s.shape[pv.normal] - 1
        note = "  [yellow]≈ oblique[/]" if pv.note else ""
        if self.query("#panel") and self.query_one("#panel").has_class("hidden"):  # the panel's readout, here
            unit = " HU" if s.volume.modality == "CT" else ""
            note += f"  x {s.x} y {s.y} = [b]{s.value():g}{unit}[/b]"
        return f"{plane} {axis} {idx}/{last}  [b]{left}[/b]◀▶[b]{right}[/b]  [b]{top}[/b]▲▼[b]{bottom}[/b]{note}"

    def targets(self) -> list[tuple[str, str, ImageView]]:
        """(plane, view, widget) of every visible slice view."""
        s = self.s
        if self.viewstate.grid_mode:
            sp = planes.slice_plane(s.volume)
            return [(sp, v, self.query_one(f"#g-{v}", ImageView)) for v in VIEWS]
        if self.viewstate.ortho_mode:
            return [(p, "overlay", self.query_one(f"#o-{p}", ImageView)) for p in planes.PLANES]
        view = s.view if s.plane == planes.slice_plane(s.volume) else "overlay"
        return [(s.plane, view, self.main_view)]

    # ------------------------------------------------------------------ drawing
    def refresh_view(self) -> None:
        """Repaint the visible view(s) for the current slice/cursor; filtered views
        come from a worker (newest request wins)."""
        if not self.query("#main"):  # not composed yet (or being torn down): try after the next refresh
            if self.is_attached:
                self.call_after_refresh(self.refresh_view)
            return
        s = self.s
        s.clamp()
        need_stage = False
        for plane, view, iv in self.targets():
            pv = planes.plane_view(s.volume, plane)
            cursor = planes.cursor_in(pv, s.zyx, s.shape)
            center = self.view_center(plane)
            iv.overlay = lambda grid, vm, _p=plane: draw_overlay(self, _p, grid, vm)
            if view in ("intermediate", "final"):
                need_stage = True
                if iv.rgb is not None and iv.token is not None and iv.token[0] == s.z:
                    iv.set_view(zoom=self.viewstate.zoom, center=center, cursor=cursor)
                    continue
                img = self.plane_image(plane, "original")  # placeholder until the worker answers
            else:
                img = self.plane_image(plane, view)
            iv.set_image(img, token=(s.z, view if view != "overlay" else plane, self.viewstate.token),
                         spacing_yx=pv.spacing_yx, zoom=self.viewstate.zoom, center=center, cursor=cursor)
        self.captions()
        if need_stage:
            self.compute_stage_views(s.z, self.viewstate.next_token())
        self.update_panel()

    def captions(self) -> None:
        if self.viewstate.ortho_mode:
            for p in planes.PLANES:
                self.query_one(f"#oc-{p}", Label).update(self.caption(p), layout=False)  # fixed size: no relayout
        else:
            self.query_one("#main-caption", Label).update(self.caption(self.s.plane), layout=False)

    @work(thread=True, exclusive=True, group="views")
    def compute_stage_views(self, z: int, token: int) -> None:
        if z != self.s.z or token != self.viewstate.token:
            return  # superseded before it started (key held down): skip the filtering
        try:
            views = self.s.stage_views(z)
        except Exception as exc:  # never let a filter error escape as a traceback
            self.post_message(JobFailed("Filter pipeline", str(exc)))
            return
        self.post_message(StageViewsReady(z, token, views))

    @on(StageViewsReady)
    def _show_stage_views(self, msg: StageViewsReady) -> None:
        s = self.s
        z, token, views = msg.z, msg.token, msg.views
        if z != s.z:
            return  # superseded
        self.viewstate.last_views = views
        for plane, view, iv in self.targets():
            if view in ("intermediate", "final"):
                pv = planes.plane_view(s.volume, plane)
                img = planes.orient(s.display(getattr(views, view)), pv)
                iv.set_image(img, token=(z, view, token), spacing_yx=pv.spacing_yx, zoom=self.viewstate.zoom,
                             center=self.view_center(plane), cursor=planes.cursor_in(pv, s.zyx, s.shape))

    def labels_changed(self) -> None:
        self.volumes.changed()
        self.s.dirty = True
        if self.viewstate.ortho_mode:
            self.request_3d()

    def update_panel(self) -> None:
        panel = self.query_one("#panel", SidePanel)
        panel.update(panel_text(self), layout=False)  # fixed size: no relayout
        panel.follow(self.s)  # the seed range the text asked for, computed by the panel
        self.review.update_strip()

    def set_status(self, msg: str) -> None:
        """The status line; a message longer than the width wraps (up to 3 lines)."""
        lines = 1 + len(str(msg)) // max(self.size.width - 2, 20)
        relayout = lines != self._status_lines
        self._status_lines = lines
        self.query_one("#status", Static).update(msg, layout=relayout)

    def saved_to(self, path: str, *, asked: bool) -> None:
        """The project was saved to ``path``: say where. Saved with no dialog (a second Ctrl+S),
        the next key, if it is Enter (the habit of confirming a save dialog), fills nothing."""
        self.edit_tools.enter_guard = not asked
        again = "; an Enter now fills nothing" if not asked else ""
        self.set_status(f"Project saved to {path} (Ctrl+S saves there again{again})")
        self.update_panel()

    def on_key(self, event) -> None:
        if self.edit_tools.enter_guard:
            self.edit_tools.enter_guard = False
            if event.key == "enter":
                event.prevent_default()
                event.stop()
                self.set_status("Enter right after Ctrl+S: nothing filled (the project is saved); Enter again fills")

    def action_do(self, name: str, args: tuple = ()) -> None:
        """The screen's one Textual action: the owner's action ``name`` with ``args`` (the bindings'
        ``do('move', (-1, 0))``; the command palette and the ``t`` menu call it too)."""
        self.actions[name](*args)

    def toggle_panel(self) -> None:
        """\\: hide or show the side panel (the views get its width: 80x24 terminals)."""
        panel = self.query_one("#panel", SidePanel)
        panel.set_class(not panel.has_class("hidden"), "hidden")
        for iv in self.query(ImageView):
            iv.token = None
        self.refresh_view()
        self.set_status("Side panel hidden: \\ shows it" if panel.has_class("hidden") else "Side panel shown: \\ hides it")

    # ------------------------------------------------------------------ messages from workers and screens
    @on(CellRendered)
    @on(ProposalReady)
    @on(AutoReady)
    @on(JobFinished)
    @on(JobFailed)
    @on(SegmentationFailed)
    @on(JobProgress)
    @on(Status)
    @on(SeedRangeReady)
    @on(LabelsChanged)
    def _message(self, msg: Message) -> None:
        """A worker's (or another screen's) message, to the owner it is for."""
        if isinstance(msg, CellRendered):  # no image (no EGL, a failure): the cell is emptied, its caption says why
            self.jobs.worker_ended()
            self.show_progress(None)
            self.query_one("#o-3d", ImageView).set_image(msg.image, token=("3d", self.volumes.version))
            self.query_one("#oc-3d", Label).update(msg.caption)
        elif isinstance(msg, ProposalReady):
            self.segment.finished(msg.run)
        elif isinstance(msg, SegmentationFailed):
            self.segment.failed(msg.what, msg.reason)
        elif isinstance(msg, AutoReady):
            from ctui.screens.auto_screen import apply_result  # loaded with the draft's dialog

            apply_result(self, msg.result, msg.snapshot)
        elif isinstance(msg, JobFinished):
            self.work.finished(msg.text)
        elif isinstance(msg, JobFailed):
            self.work.failed(msg.what, msg.reason)
        elif isinstance(msg, JobProgress):
            self.show_progress(msg.label, msg.done, msg.total if msg.total is not None else 0)
        elif isinstance(msg, Status):
            self.set_status(msg.text)
        elif isinstance(msg, SeedRangeReady):
            if self.query("#panel"):  # composed (a message may arrive while the screen is taken down)
                self.update_panel()
        elif isinstance(msg, LabelsChanged):
            self.labels_changed()
            self.refresh_view()

    # ------------------------------------------------------------------ the mouse, to its owner
    def on_mouse_down(self, event: events.MouseDown) -> None:
        self.mouse.mouse_down(event)

    def on_mouse_move(self, event: events.MouseMove) -> None:
        self.mouse.mouse_move(event)

    def on_mouse_up(self, event: events.MouseUp) -> None:
        self.mouse.mouse_up(event)

    def on_click(self, event: events.Click) -> None:
        self.mouse.click(event)

    def on_mouse_scroll_up(self, event: events.MouseScrollUp) -> None:
        self.mouse.scroll_up(event)

    def on_mouse_scroll_down(self, event: events.MouseScrollDown) -> None:
        self.mouse.scroll_down(event)

    def show_progress(self, label: str | None, done: float = 0, total: float = 100) -> None:
        row = self.query_one("#progress-row")
        if label is None:
            row.remove_class("on")
            return
        row.add_class("on")
        self.query_one("#progress-label", Label).update(label)
        self.query_one("#progress", ProgressBar).update(total=max(total, 1) if total else None, progress=done)

    def repaint_cursor(self) -> None:
        """The cursor (and the captions, the panel) moved; the images stay."""
        s = self.s
        for plane, _view, iv in self.targets():
            pv = planes.plane_view(s.volume, plane)
            iv.set_view(zoom=self.viewstate.zoom, center=self.view_center(plane), cursor=planes.cursor_in(pv, s.zyx, s.shape))
        self.captions()  # the value readout is in the caption while the panel is hidden
        self.update_panel()

    def set_layout(self, *, grid: bool = False, ortho: bool = False) -> None:
        """One plane (both False), the pipeline's 2x2 views (``grid``) or the planes' 2x2 with 3D (``ortho``)."""
        self.viewstate.set_layout(grid=grid, ortho=ortho)
        self.query_one("#grid").set_class(grid, "on")
        self.query_one("#ortho").set_class(ortho, "on")
        self.query_one("#main-box").set_class(grid or ortho, "off")
        for iv in self.query(ImageView):
            iv.token = None
        self.refresh_view()

    def review_strip(self) -> ReviewStrip | None:
        """The review strip (None before the screen is composed, or while it is taken down)."""
        strips = self.query("#strip")
        return strips.first(ReviewStrip) if strips else None

    # ------------------------------------------------------------------ the 3D cell of the 2x2 layout
    def request_3d(self) -> None:
        iv = self.query_one("#o-3d", ImageView)
        if not self.viewstate.ortho_mode:
            return
        if iv.size.width < 4 or iv.size.height < 2:  # the 2x2 layout is not laid out yet: a 1x2 px render
            # would show as one flat colour over the whole cell. Ask again on a timer: a callback after each
            # refresh kept the message queue busy, so the layout (done when idle) never came and the app
            # spun (a CI run hung in test_3d_cell_shows_shaded_objects_and_follows_edits)
            self.set_timer(0.05, self.request_3d)
            return
        self.jobs.track(self.work.render_cell(iv.target_pixels()), replace=True)
