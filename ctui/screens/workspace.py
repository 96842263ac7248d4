"""The slice workspace: axial, sagittal and coronal views (one at a time, or 2x2 with
the 3D view), the pipeline's four views of an axial slice (2x2), a shared cursor
(crosshair), the side panel and every segmentation key (:mod:`ctui.screens.ws_edit`).

Slices are numbered from 0 in the TUI as in the CLI ("Slice 40/79": index/last index).
"""

from __future__ import annotations

import cv2
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
from ctui.screens.messages import JobDone, JobFailed, JobProgress, LabelsChanged, Status
from ctui.screens.session import VIEWS, Session
from ctui.screens.ws_edit import EditMixin
from ctui.screens.ws_keys import BINDINGS, NavMixin, panel_text
from ctui.screens.strip import ReviewStrip
from ctui.screens.ws_mouse import MOUSE_BINDINGS, MouseMixin, draw_overlay


def label_counts(labels: np.ndarray) -> np.ndarray:
    """Voxels per label value (int64 (256,)) of a uint8 label volume. OpenCV's histogram in
    slabs of at most 8 M voxels (exact in its float32 bins): 8 ms on 24x512x512 against
    120 ms for np.bincount, which copies the labels to int64 first (a brush stroke step
    recounts them for the side panel)."""
    flat = labels.reshape(-1, labels.shape[-1])
    step = max(1, (8 << 20) // max(labels.shape[-1], 1))
    total = np.zeros(256, np.int64)
    for r in range(0, flat.shape[0], step):
        total += cv2.calcHist([np.ascontiguousarray(flat[r:r + step])], [0], None, [256], [0, 256]).ravel().astype(np.int64)
    return total


class SidePanel(Static):
    DEFAULT_CSS = """
    SidePanel { width: 38; height: 1fr; padding: 0 1; background: $panel; }
    """


class WorkspaceScreen(MouseMixin, EditMixin, NavMixin, GuardMixin, Screen):
    """Slice views + side panel. Thin: every computation is an engine call."""

    BINDINGS = BINDINGS + MOUSE_BINDINGS

    DEFAULT_CSS = """
    WorkspaceScreen #views { height: 1fr; }
    WorkspaceScreen #grid, WorkspaceScreen #ortho { grid-size: 2 2; grid-gutter: 0 1; display: none; width: 1fr; }
    WorkspaceScreen #grid.on, WorkspaceScreen #ortho.on { display: block; }
    WorkspaceScreen #main-box.off { display: none; }
    WorkspaceScreen .cell-label { height: 1; color: $text-muted; }
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
        self.grid_mode = False  # the pipeline's four views of the axial slice
        self.ortho_mode = False  # axial, sagittal, coronal and 3D in 2x2
        self.pan_center: tuple[float, float] | None = None
        self._volumes_cache: tuple[int, dict] | None = None
        self._labels_version = 0
        self._prop = None  # running propagation handle
        self.proposal = None  # pending propagation result (ctui.engine.segment.propagate.Proposal)
        self._proposal_full: tuple[int, np.ndarray] | None = None
        self._views_token = 0
        self._job = None  # the running cancellable worker (3D cell, export...)
        self.last_views = None
        self.last_export: str | None = None

    def track_job(self, worker):
        """Make ``worker`` the running cancellable job (Escape cancels it); returns it."""
        self._job = worker
        return worker

    def track_propagation(self, run) -> None:
        """The running propagation (a ``screens.propagation.PropagationRun``), or None when it ended."""
        self._prop = run

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

    # ------------------------------------------------------------------ geometry of the views
    @property
    def main_view(self) -> ImageView:
        return self.query_one("#main", ImageView)

    def _plane_shape(self, plane: str) -> tuple[int, int]:
        pv = planes.plane_view(self.s.volume, plane)
        return self.s.shape[pv.rows], self.s.shape[pv.cols]

    def _view_center(self, plane: str | None = None) -> tuple[float, float]:
        """(x, y) image pixel the main view centres on (zoomed: follows the cursor)."""
        s = self.s
        plane = plane or s.plane
        pv = planes.plane_view(s.volume, plane)
        cx0, cy0 = planes.cursor_in(pv, s.zyx, s.shape)
        if s.zoom <= 1.0 or plane != s.plane:
            return (cx0, cy0)
        if self.pan_center is None:
            self.pan_center = (float(cx0), float(cy0))
        ny, nx = self._plane_shape(plane)
        half_w, half_h = nx / s.zoom / 2.0, ny / s.zoom / 2.0
        cx, cy = self.pan_center
        if abs(cx0 - cx) > half_w * 0.9 or abs(cy0 - cy) > half_h * 0.9:  # keep the cursor visible
            cx, cy = float(cx0), float(cy0)
        self.pan_center = (min(max(cx, half_w), nx - half_w), min(max(cy, half_h), ny - half_h))
        return self.pan_center

    # ------------------------------------------------------------------ images
    def _proposal_plane(self, pv: planes.PlaneView, index: int) -> np.ndarray | None:
        p = self.proposal
        if p is None:
            return None
        if pv.normal == 0:  # the file's slice plane (axial for an axial acquisition)
            return planes.orient(p.slice_mask(index), pv)
        if self._proposal_full is None or self._proposal_full[0] != id(p):
            full = np.zeros(self.s.shape, bool)
            got = p.mask3d()
            if got is not None:
                (z0, y0, x0), m = got
                full[z0:z0 + m.shape[0], y0:y0 + m.shape[1], x0:x0 + m.shape[2]] = m
            self._proposal_full = (id(p), full)
        return planes.take(self._proposal_full[1], pv, index)

    def plane_image(self, plane: str, view: str = "overlay") -> np.ndarray:
        """The grey (``view`` "original") or composed RGB image of ``plane`` through the cursor."""
        s = self.s
        pv = planes.plane_view(s.volume, plane)
        idx = s.zyx[pv.normal]
        gray = apply_window(planes.take(s.volume.data, pv, idx), s.window)
        if view == "original":
            return gray
        lab = s.labels()
        lab2 = None if lab is None else planes.take(lab, pv, idx)
        pid = self.proposal.object_id if self.proposal is not None else 0
        return planes.compose(gray, lab2, self._proposal_plane(pv, idx), proposal_id=pid)

    def caption(self, plane: str) -> str:
        s = self.s
        pv = planes.plane_view(s.volume, plane)
        axis = "zyx"[pv.normal]
        left, right, top, bottom = pv.letters
        idx, last = s.zyx[pv.normal], s.shape[pv.normal] - 1
        note = "  [yellow]≈ oblique[/]" if pv.note else ""
        return f"{plane} {axis} {idx}/{last}  [b]{left}[/b]◀▶[b]{right}[/b]  [b]{top}[/b]▲▼[b]{bottom}[/b]{note}"

    def _targets(self) -> list[tuple[str, str, ImageView]]:
        """(plane, view, widget) of every visible slice view."""
        s = self.s
        if self.grid_mode:
            sp = planes.slice_plane(s.volume)
            return [(sp, v, self.query_one(f"#g-{v}", ImageView)) for v in VIEWS]
        if self.ortho_mode:
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
                    iv.set_view(zoom=s.zoom, center=center, cursor=cursor)
                    continue
                img = self.plane_image(plane, "original")  # placeholder until the worker answers
            else:
                img = self.plane_image(plane, view)
            iv.set_image(img, token=(s.z, view if view != "overlay" else plane, self._views_token),
                         spacing_yx=pv.spacing_yx, zoom=s.zoom, center=center, cursor=cursor)
        self._captions()
        if need_stage:
            self._views_token += 1
            self.compute_stage_views(s.z, self._views_token)
        self.update_panel()

    def _captions(self) -> None:
        if self.ortho_mode:
            for p in planes.PLANES:
                self.query_one(f"#oc-{p}", Label).update(self.caption(p))
        else:
            self.query_one("#main-caption", Label).update(self.caption(self.s.plane))

    @work(thread=True, exclusive=True, group="views")
    def compute_stage_views(self, z: int, token: int) -> None:
        if z != self.s.z or token != self._views_token:
            return  # superseded before it started (key held down): skip the filtering
        try:
            views = self.s.stage_views(z)
        except Exception as exc:  # never let a filter error escape as a traceback
            self.post_message(JobFailed("Filter pipeline", str(exc)))
            return
        self.post_message(JobDone("stage-views", views, z=z, token=token))

    def _show_stage_views(self, z: int, token: int, views) -> None:
        s = self.s
        if z != s.z:
            return  # superseded
        self.last_views = views
        for plane, view, iv in self._targets():
            if view in ("intermediate", "final"):
                pv = planes.plane_view(s.volume, plane)
                img = planes.orient(s.display(getattr(views, view)), pv)
                iv.set_image(img, token=(z, view, token), spacing_yx=pv.spacing_yx, zoom=s.zoom,
                             center=self._view_center(plane), cursor=planes.cursor_in(pv, s.zyx, s.shape))

    def _object_volumes(self) -> dict[int, float]:
        """Volume (ml) per object; recomputed only when the labels changed."""
        lab = self.s.labels()
        if lab is None:
            return {}
        if self._volumes_cache and self._volumes_cache[0] == self._labels_version:
            return self._volumes_cache[1]
        counts = label_counts(lab)
        vox_ml = self.s.volume.voxel_volume_mm3() / 1000.0
        vols = {i: float(counts[i]) * vox_ml for i in range(1, len(counts)) if counts[i]}
        self._volumes_cache = (self._labels_version, vols)
        return vols

    def labels_changed(self) -> None:
        self._labels_version += 1
        self.s.dirty = True
        if self.ortho_mode:
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

    def action_toggle_panel(self) -> None:
        """\\: hide or show the side panel (the views get its width: 80x24 terminals)."""
        panel = self.query_one("#panel", SidePanel)
        panel.set_class(not panel.has_class("hidden"), "hidden")
        for iv in self.query(ImageView):
            iv.token = None
        self.refresh_view()
        self.set_status("Side panel hidden: \\ shows it" if panel.has_class("hidden") else "Side panel shown: \\ hides it")

    # ------------------------------------------------------------------ messages from workers and screens
    @on(JobDone)
    def _job_done(self, msg: JobDone) -> None:
        if msg.kind == "stage-views":
            self._show_stage_views(msg.info["z"], msg.info["token"], msg.result)
        elif msg.kind == "3d":
            self._job = None
            self.show_progress(None)
            # no image (no EGL, a failure): the cell is emptied and its caption says why
            self.query_one("#o-3d", ImageView).set_image(msg.result, token=("3d", self._labels_version))
            self.query_one("#oc-3d", Label).update(msg.info.get("caption", "3d"))
        elif msg.kind == "propagation":
            from ctui.screens.propagation import finished

            finished(self, msg.result)
        elif msg.kind == "message":
            self._job = None
            self.show_progress(None)
            self.app.notify(str(msg.result), timeout=5)
            self.set_status(str(msg.result))

    @on(JobFailed)
    def _job_failed(self, msg: JobFailed) -> None:
        if msg.what in ("Propagation", "Segmentation"):
            self._prop = None
        else:
            self._job = None
        self.show_progress(None)
        if msg.reason == "cancelled":
            self.set_status(f"{msg.what} cancelled: nothing changed")
            return
        self.app.notify(f"{msg.what} failed: {msg.reason}", severity="error", timeout=10)

    @on(JobProgress)
    def _job_progress(self, msg: JobProgress) -> None:
        self.show_progress(msg.label, msg.done, msg.total if msg.total is not None else 0)

    @on(Status)
    def _status_msg(self, msg: Status) -> None:
        self.set_status(msg.text)

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
        from ctui.screens.ws_jobs import render_cell

        iv = self.query_one("#o-3d", ImageView)
        if not self.ortho_mode:
            return
        if iv.size.width < 4 or iv.size.height < 2:  # the 2x2 layout is not laid out yet: a 1x2 px render
            self.call_after_refresh(self.request_3d)  # would show as one flat colour over the whole cell
            return
        if self._job is not None:
            self._job.cancel()
        self._job = render_cell(self, iv.target_pixels())
