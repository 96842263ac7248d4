"""The slice workspace: axial, sagittal and coronal views (one at a time, or 2x2 with
the 3D view), the pipeline's four views of an axial slice (2x2), a shared cursor
(crosshair), the side panel and every segmentation key (:mod:`ctui.screens.ws_edit`).

Slices are numbered from 0 in the TUI as in the CLI ("Slice 40/79": index/last index).
"""

from __future__ import annotations

import numpy as np
from textual import on, work
from textual.app import ComposeResult
from textual.containers import Grid, Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import Label, ProgressBar, Static

from ctui.engine.core.windows import apply_window
from ctui.screens import planes
from ctui.screens.guard import GuardMixin
from ctui.screens.imageview import ImageView
from ctui.screens.keybar import KeyBar
from ctui.screens.linestatic import LineStatic
from ctui.screens.messages import (AutoReady, CellRendered, JobFailed, JobFinished, JobProgress, LabelsChanged, ProposalReady,
                                   SeedRangeReady, SegmentationFailed, StageViewsReady, Status)
from ctui.screens.session import VIEWS, Session
from ctui.screens.ws_edit import EditMixin
from ctui.screens.ws_keys import BINDINGS, NavMixin, panel_text
from ctui.screens.strip import ReviewStrip
from ctui.screens.ws_mouse import MOUSE_BINDINGS, MouseMixin
from ctui.screens.ws_overlay import draw_overlay
from ctui.screens.vessel_tool import VESSEL_BINDINGS, VesselMixin
from ctui.screens.ws_state import EditTools, Jobs, ObjectVolumes, ProposalState, SeedRange, ViewState


class SidePanel(LineStatic):  # a step repaints only the panel's lines that changed
    DEFAULT_CSS = """
    SidePanel { width: 38; height: 1fr; padding: 0 1; background: $panel; }
    """


class WorkspaceScreen(VesselMixin, MouseMixin, EditMixin, NavMixin, GuardMixin, Screen):
    """Slice views + side panel. Thin: every computation is an engine call."""

    BINDINGS = BINDINGS + MOUSE_BINDINGS + VESSEL_BINDINGS

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
            yield SidePanel(id="panel")
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

    def _view_center(self, plane: str | None = None) -> tuple[float, float]:
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

    def _targets(self) -> list[tuple[str, str, ImageView]]:
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
        for plane, view, iv in self._targets():
            pv = planes.plane_view(s.volume, plane)
            cursor = planes.cursor_in(pv, s.zyx, s.shape)
            center = self._view_center(plane)
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
        self._captions()
        if need_stage:
            self.compute_stage_views(s.z, self.viewstate.next_token())
        self.update_panel()

    def _captions(self) -> None:
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
        for plane, view, iv in self._targets():
            if view in ("intermediate", "final"):
                pv = planes.plane_view(s.volume, plane)
                img = planes.orient(s.display(getattr(views, view)), pv)
                iv.set_image(img, token=(z, view, token), spacing_yx=pv.spacing_yx, zoom=self.viewstate.zoom,
                             center=self._view_center(plane), cursor=planes.cursor_in(pv, s.zyx, s.shape))

    def labels_changed(self) -> None:
        self.volumes.changed()
        self.s.dirty = True
        if self.viewstate.ortho_mode:
            self.request_3d()

    def update_panel(self) -> None:
        self.query_one("#panel", SidePanel).update(panel_text(self), layout=False)  # fixed size: no relayout
        self.update_strip()

    def set_status(self, msg: str) -> None:
        """The status line; a message longer than the width wraps (up to 3 lines)."""
        lines = 1 + len(str(msg)) // max(self.size.width - 2, 20)
        relayout = lines != getattr(self, "_status_lines", 1)
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

    def action_toggle_panel(self) -> None:
        """\\: hide or show the side panel (the views get its width: 80x24 terminals)."""
        panel = self.query_one("#panel", SidePanel)
        panel.set_class(not panel.has_class("hidden"), "hidden")
        for iv in self.query(ImageView):
            iv.token = None
        self.refresh_view()
        self.set_status("Side panel hidden: \\ shows it" if panel.has_class("hidden") else "Side panel shown: \\ hides it")

    # ------------------------------------------------------------------ messages from workers and screens
    @on(CellRendered)
    def _cell_rendered(self, msg: CellRendered) -> None:
        self.jobs.worker_ended()
        self.show_progress(None)
        # no image (no EGL, a failure): the cell is emptied and its caption says why
        self.query_one("#o-3d", ImageView).set_image(msg.image, token=("3d", self.volumes.version))
        self.query_one("#oc-3d", Label).update(msg.caption)

    @on(ProposalReady)
    def _proposal_ready(self, msg: ProposalReady) -> None:
        from ctui.screens.propagation import finished  # propagation imports the engine's segmentation

        finished(self, msg.run)

    @on(AutoReady)
    def _auto_ready(self, msg: AutoReady) -> None:
        from ctui.screens.auto_screen import apply_result  # loaded with the draft's dialog

        apply_result(self, msg.result, msg.snapshot)

    @on(JobFinished)
    def _job_finished(self, msg: JobFinished) -> None:
        self.jobs.worker_ended()
        self.show_progress(None)
        self.set_status(msg.text)  # the status line, not a toast over the image and the review strip

    @on(JobFailed)
    def _job_failed(self, msg: JobFailed) -> None:
        self.jobs.worker_ended()
        self._failed(msg.what, msg.reason)

    @on(SegmentationFailed)
    def _segmentation_failed(self, msg: SegmentationFailed) -> None:
        self.jobs.segmentation_ended()
        self._failed(msg.what, msg.reason)

    def _failed(self, what: str, reason: str) -> None:
        self.show_progress(None)
        if reason == "cancelled":
            self.set_status(f"{what} cancelled: nothing changed")
            return
        self.app.notify(f"{what} failed: {reason}", severity="error", timeout=10)

    @on(JobProgress)
    def _job_progress(self, msg: JobProgress) -> None:
        self.show_progress(msg.label, msg.done, msg.total if msg.total is not None else 0)

    @on(Status)
    def _status_msg(self, msg: Status) -> None:
        self.set_status(msg.text)

    @on(SeedRangeReady)
    def _seed_range_ready(self, _msg: SeedRangeReady) -> None:
        if self.query("#panel"):  # composed (a message may arrive while the screen is taken down)
            self.update_panel()

    @on(LabelsChanged)
    def _labels_msg(self, _msg: LabelsChanged) -> None:
        self.labels_changed()
        self.refresh_view()

    def show_progress(self, label: str | None, done: float = 0, total: float = 100) -> None:
        row = self.query_one("#progress-row")
        if label is None:
            row.remove_class("on")
            return
        row.add_class("on")
        self.query_one("#progress-label", Label).update(label)
        self.query_one("#progress", ProgressBar).update(total=max(total, 1) if total else None, progress=done)

    # ------------------------------------------------------------------ the 3D cell of the 2x2 layout
    def request_3d(self) -> None:
        from ctui.screens.ws_jobs import render_cell  # the renderer loads with the first 3D cell

        iv = self.query_one("#o-3d", ImageView)
        if not self.viewstate.ortho_mode:
            return
        if iv.size.width < 4 or iv.size.height < 2:  # the 2x2 layout is not laid out yet: a 1x2 px render
            # would show as one flat colour over the whole cell. Ask again on a timer: a callback after each
            # refresh kept the message queue busy, so the layout (done when idle) never came and the app
            # spun (a CI run hung in test_3d_cell_shows_shaded_objects_and_follows_edits)
            self.set_timer(0.05, self.request_3d)
            return
        self.jobs.track(render_cell(self, iv.target_pixels()), replace=True)
