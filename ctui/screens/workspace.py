"""The slice workspace: slice view(s), cursor, side panel and every segmentation key."""

from __future__ import annotations

import numpy as np
from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import Footer, Label, ProgressBar, Static

from ctui.engine.core.errors import CtuiError
from ctui.screens.guard import GuardMixin
from ctui.screens.imageview import ImageView
from ctui.screens.session import VIEWS, Session


class SidePanel(Static):
    DEFAULT_CSS = """
    SidePanel { width: 38; height: 1fr; padding: 0 1; background: $panel; }
    """


class WorkspaceScreen(GuardMixin, Screen):
    """Slice view + side panel. Thin: every computation is an engine call."""

    DEFAULT_CSS = """
    WorkspaceScreen #views { height: 1fr; }
    WorkspaceScreen #grid { grid-size: 2 2; grid-gutter: 0 1; display: none; width: 1fr; }
    WorkspaceScreen #grid.on { display: block; }
    WorkspaceScreen #main.off { display: none; }
    WorkspaceScreen .cell-label { height: 1; color: $text-muted; }
    WorkspaceScreen #progress-row { height: 1; display: none; }
    WorkspaceScreen #progress-row.on { display: block; }
    WorkspaceScreen #progress-row Label { width: auto; padding: 0 1; }
    WorkspaceScreen #status { height: 1; background: $boost; padding: 0 1; }
    """

    BINDINGS = [
        Binding("left,h", "move(-1,0)", "Cursor left", show=False),
        Binding("right,l", "move(1,0)", "Cursor right", show=False),
        Binding("up,k", "move(0,-1)", "Cursor up", show=False),
        Binding("down,j", "move(0,1)", "Cursor down", show=False),
        Binding("shift+left,H", "move(-10,0)", "Cursor left 10", show=False),
        Binding("shift+right,L", "move(10,0)", "Cursor right 10", show=False),
        Binding("shift+up,K", "move(0,-10)", "Cursor up 10", show=False),
        Binding("shift+down,J", "move(0,10)", "Cursor down 10", show=False),
        Binding("ctrl+left", "pan(-1,0)", "Pan left", show=False),
        Binding("ctrl+right", "pan(1,0)", "Pan right", show=False),
        Binding("ctrl+up", "pan(0,-1)", "Pan up", show=False),
        Binding("ctrl+down", "pan(0,1)", "Pan down", show=False),
        Binding("pageup", "slice(1)", "Slice +1"),
        Binding("pagedown", "slice(-1)", "Slice -1"),
        Binding("home", "slice_to('first')", "First slice", show=False),
        Binding("end", "slice_to('last')", "Last slice", show=False),
        Binding("g", "goto", "Go to slice", show=False),
        Binding("w", "window_cycle", "Window preset", show=False),
        Binding("W", "window_set", "Set window C/W", show=False),
        Binding("plus,equals_sign", "zoom(1)", "Zoom in", show=False),
        Binding("minus", "zoom(-1)", "Zoom out", show=False),
        Binding("v", "view_cycle", "View"),
        Binding("V", "grid", "2x2 views", show=False),
        Binding("f", "filters", "Filters"),
        Binding("enter", "fill", "Fill"),
        Binding("left_square_bracket", "tolerance(-1)", "Tolerance -", show=False),
        Binding("right_square_bracket", "tolerance(1)", "Tolerance +", show=False),
        Binding("T", "range_edit", "Edit range/tolerance", show=False),
        Binding("c", "connectivity", "4/8 connectivity", show=False),
        Binding("m", "prop_mode", "Propagation slice/3D", show=False),
        Binding("n", "new_object", "New object"),
        Binding("tab", "cycle_object", "Next object", show=False, priority=True),
        Binding("N", "rename_object", "Rename object", show=False),
        Binding("delete", "clear_object", "Clear object", show=False),
        Binding("u", "undo", "Undo"),
        Binding("U", "redo", "Redo", show=False),
        Binding("less_than_sign", "propagate('backward')", "Propagate back", show=False),
        Binding("greater_than_sign", "propagate('forward')", "Propagate fwd", show=False),
        Binding("p", "propagate('both')", "Propagate"),
        Binding("a", "accept", "Accept proposal", show=False),
        Binding("x", "reject", "Reject proposal", show=False),
        Binding("escape", "cancel", "Cancel", show=False),
        Binding("d", "drift", "Drift"),
        Binding("r", "render3d", "3D"),
        Binding("M", "measure", "Measure"),
        Binding("e", "export", "Export"),
        Binding("o", "open", "Open", show=False),
    ]

    def __init__(self, session: Session) -> None:
        super().__init__()
        self.s = session
        self.grid_mode = False
        self.pan_center: tuple[float, float] | None = None
        self._volumes_cache: tuple[int, dict] | None = None
        self._labels_version = 0
        self._prop = None  # running propagation handle
        self.proposal = None  # pending propagation result (ctui.engine.segment.propagate.Proposal)
        self._views_token = 0
        self.last_views = None

    # ------------------------------------------------------------------ layout
    def compose(self) -> ComposeResult:
        with Horizontal(id="views"):
            yield ImageView(id="main")
            with Grid(id="grid"):
                for v in VIEWS:
                    with Vertical(classes="cell"):
                        yield Label(v, classes="cell-label")
                        yield ImageView(id=f"g-{v}")
            yield SidePanel(id="panel")
        with Horizontal(id="progress-row"):
            yield Label("", id="progress-label")
            yield ProgressBar(total=100, id="progress", show_eta=False)
            yield Label("[dim]Esc cancels[/dim]")
        yield Static("", id="status")
        yield Footer()

    def on_mount(self) -> None:
        self.refresh_view()

    # ------------------------------------------------------------------ drawing
    @property
    def main_view(self) -> ImageView:
        return self.query_one("#main", ImageView)

    def _view_center(self) -> tuple[float, float]:
        s = self.s
        if s.zoom <= 1.0:
            return (s.x, s.y)
        if self.pan_center is None:
            self.pan_center = (float(s.x), float(s.y))
        # keep the cursor visible: recentre when it leaves the visible part
        ny, nx = s.shape[1:]
        half_w = nx / s.zoom / 2.0
        half_h = ny / s.zoom / 2.0
        cx, cy = self.pan_center
        if abs(s.x - cx) > half_w * 0.9 or abs(s.y - cy) > half_h * 0.9:
            cx, cy = float(s.x), float(s.y)
        cx = min(max(cx, half_w), nx - half_w)
        cy = min(max(cy, half_h), ny - half_h)
        self.pan_center = (cx, cy)
        return self.pan_center

    def _quick_image(self, view: str) -> np.ndarray | None:
        """Original/overlay straight from the volume (no filtering): instant."""
        s = self.s
        from ctui.engine.core.windows import apply_window

        gray = apply_window(s.volume.data[s.z], s.window)
        if view == "original":
            return gray
        if view == "overlay":
            from ctui.engine.segment.pipeline import overlay

            lab = s.labels()
            lab2 = None if lab is None else lab[s.z]
            if self.proposal is not None and self.proposal.masks.get(s.z) is not None:
                lab2 = lab2.copy()
                lab2[self.proposal.slice_mask(s.z) & (lab2 == 0)] = self.proposal.object_id
            return overlay(gray, lab2)
        return None

    def refresh_view(self) -> None:
        """Repaint the visible view(s) for the current slice/cursor; filtered views
        come from a worker (newest request wins)."""
        if not self.query("#main"):  # not composed yet (or being torn down): try after the next refresh
            if self.is_attached:
                self.call_after_refresh(self.refresh_view)
            return
        s = self.s
        s.clamp()
        token = (s.z, s.view, self._views_token)
        center = self._view_center()
        spacing = s.volume.spacing[1:]
        targets = [(v, self.query_one(f"#g-{v}", ImageView)) for v in VIEWS] if self.grid_mode else [(s.view, self.main_view)]
        need_stage = False
        for view, iv in targets:
            img = self._quick_image(view)
            if img is None:
                need_stage = True
                if iv.rgb is None or iv.token is None or iv.token[0] != s.z:
                    img = self._quick_image("original")  # placeholder until the worker answers
                else:
                    iv.set_view(zoom=s.zoom, center=center, cursor=(s.x, s.y))
                    continue
            iv.set_image(img, token=token, spacing_yx=spacing, zoom=s.zoom, center=center, cursor=(s.x, s.y))
        if need_stage:
            self._views_token += 1
            self.compute_stage_views(s.z, self._views_token)
        self.update_panel()

    @work(thread=True, exclusive=True, group="views")
    def compute_stage_views(self, z: int, token: int) -> None:
        if z != self.s.z or token != self._views_token:
            return  # superseded before it started (key held down): skip the filtering
        try:
            views = self.s.stage_views(z)
        except Exception as exc:  # never let a filter error escape as a traceback
            self.app.call_from_thread(self.app.notify, f"Filter pipeline failed: {exc}", severity="error")
            return
        self.app.call_from_thread(self._show_stage_views, z, token, views)

    def _show_stage_views(self, z: int, token: int, views) -> None:
        s = self.s
        if z != s.z:
            return  # superseded
        self.last_views = views
        center = self._view_center()
        targets = [(v, self.query_one(f"#g-{v}", ImageView)) for v in VIEWS] if self.grid_mode else [(s.view, self.main_view)]
        for view, iv in targets:
            if view in ("intermediate", "final"):
                img = s.display(getattr(views, view))
                iv.set_image(img, token=(z, view, token), spacing_yx=s.volume.spacing[1:], zoom=s.zoom, center=center, cursor=(s.x, s.y))

    def _object_volumes(self) -> dict[int, float]:
        """Volume (ml) per object; recomputed only when the labels changed."""
        lab = self.s.labels()
        if lab is None:
            return {}
        if self._volumes_cache and self._volumes_cache[0] == self._labels_version:
            return self._volumes_cache[1]
        counts = np.bincount(lab.ravel(), minlength=11)
        vox_ml = self.s.volume.voxel_volume_mm3() / 1000.0
        vols = {i: float(counts[i]) * vox_ml for i in range(1, len(counts)) if counts[i]}
        self._volumes_cache = (self._labels_version, vols)
        return vols

    def labels_changed(self) -> None:
        self._labels_version += 1
        self.s.dirty = True

    def update_panel(self) -> None:
        s = self.s
        nz = s.shape[0]
        v = s.volume
        t = Text()
        t.append("ctui", style="bold")
        src = (s.source_path or v.source or "").rstrip("/").split("/")[-1]
        t.append(f"  {src[:28]}\n", style="dim")
        try:
            xmm, ymm, zmm = s.position_mm()
        except Exception:
            xmm = ymm = zmm = float("nan")
        slice_pos = zmm
        if v.slice_positions is not None and len(v.slice_positions) == nz:
            slice_pos = float(v.slice_positions[s.z])
        t.append(f"Slice {s.z + 1}/{nz}", style="bold")
        t.append(f"  {slice_pos:.1f} mm\n")
        t.append(f"Cursor x {s.x}  y {s.y}\n")
        t.append(f"  ({xmm:.1f}, {ymm:.1f}, {zmm:.1f}) mm\n", style="dim")
        unit = "HU" if v.modality == "CT" else ""
        t.append("Value ", style="bold")
        t.append(f"{s.value():g} {unit}\n")
        c, w = s.window
        t.append(f"Window C {c:g} W {w:g}", style="")
        if getattr(self, "_window_name", None):
            t.append(f" ({self._window_name})", style="dim")
        t.append("\n")
        view = "2x2 grid" if self.grid_mode else s.view
        t.append(f"View {view}  zoom {s.zoom:g}x\n")
        dom = "HU" if s.pipeline is None or s.pipeline.domain == "hu" else "0..255"
        if s.range_ is not None:
            t.append(f"Range [{s.range_[0]:g}, {s.range_[1]:g}] {dom}\n")
        else:
            t.append(f"Tolerance ±{s.tolerance:g} {dom}\n")
        t.append(f"Connectivity {s.connectivity}  propagation {s.prop_mode}\n")
        t.append("\nPipeline", style="bold underline")
        steps = s.pipeline_steps()
        t.append(f" ({len(steps)} steps)\n" if steps else "  (none: f adds)\n")
        for line in steps[:6]:
            t.append(f" {line[:34]}\n")
        t.append("\nObjects", style="bold underline")
        t.append("  (n new, Tab next)\n")
        lab = s.labels()
        objs = sorted(getattr(s.seg, "objects", {}) or {})
        if lab is not None:
            area = np.bincount(lab[s.z].ravel(), minlength=11)
            vols = self._object_volumes()
            px_mm2 = s.volume.spacing[1] * s.volume.spacing[2]
            ids = sorted(set(objs) | set(vols))
            if s.current not in ids:
                ids = sorted(ids + [s.current])
            for i in ids:
                col = s.seg.objects[i].color if i in s.seg.objects else (128, 128, 128)
                mark = "▶" if i == s.current else " "
                t.append(mark)
                t.append("██", style=f"rgb({col[0]},{col[1]},{col[2]})")
                name = s.seg.objects[i].name if i in s.seg.objects else f"object {i}"
                a = int(area[i]) if i < len(area) else 0
                t.append(f" {name[:10]:<10} {a * px_mm2:7.0f}mm² {vols.get(i, 0.0):6.1f}ml\n")
        else:
            t.append(" (selection engine missing)\n", style="dim")
        if s.dirty:
            t.append("\n● unsaved changes", style="yellow")
        self.query_one("#panel", SidePanel).update(t, layout=False)  # fixed size: no relayout

    def set_status(self, msg: str) -> None:
        self.query_one("#status", Static).update(msg, layout=False)

    # ------------------------------------------------------------------ navigation
    def action_move(self, dx: int, dy: int) -> None:
        self.s.x += dx
        self.s.y += dy
        self.s.clamp()
        self._repaint_cursor()

    def _repaint_cursor(self) -> None:
        s = self.s
        center = self._view_center()
        if self.grid_mode:
            for v in VIEWS:
                self.query_one(f"#g-{v}", ImageView).set_view(zoom=s.zoom, center=center, cursor=(s.x, s.y))
        else:
            self.main_view.set_view(zoom=s.zoom, center=center, cursor=(s.x, s.y))
        self.update_panel()

    def action_pan(self, dx: int, dy: int) -> None:
        s = self.s
        if s.zoom <= 1:
            self.app.notify("Zoom in (+) first to pan", timeout=2)
            return
        ny, nx = s.shape[1:]
        cx, cy = self.pan_center or (s.x, s.y)
        step_x, step_y = nx / s.zoom / 4, ny / s.zoom / 4
        cx, cy = cx + dx * step_x, cy + dy * step_y
        # panning drags the cursor along so it stays visible
        s.x = int(round(min(max(s.x + dx * step_x, 0), nx - 1)))
        s.y = int(round(min(max(s.y + dy * step_y, 0), ny - 1)))
        self.pan_center = (cx, cy)
        self._repaint_cursor()

    def action_slice(self, dz: int) -> None:
        self.s.z += dz
        self.refresh_view()

    def action_slice_to(self, where: str) -> None:
        self.s.z = 0 if where == "first" else self.s.shape[0] - 1
        self.refresh_view()

    def action_goto(self) -> None:
        from ctui.screens.dialogs import PromptScreen

        def done(val: str | None) -> None:
            if not val:
                return
            try:
                z = int(val.strip()) - 1
            except ValueError:
                self.app.notify(f"Not a slice number: {val!r}", severity="error")
                return
            self.s.z = z
            self.refresh_view()

        self.app.push_screen(PromptScreen(f"Go to slice (1..{self.s.shape[0]})", str(self.s.z + 1)), done)

    def action_zoom(self, d: int) -> None:
        s = self.s
        s.zoom = min(max(s.zoom * (2.0 if d > 0 else 0.5), 1.0), 16.0)
        if s.zoom == 1.0:
            self.pan_center = None
        self._repaint_cursor()

    def action_window_cycle(self) -> None:
        presets = self.s.window_presets()
        idx = getattr(self, "_window_idx", -1) + 1
        name, win = presets[idx % len(presets)]
        self._window_idx = idx % len(presets)
        self._window_name = name
        self.s.window = (float(win[0]), float(win[1]))
        self.refresh_view()
        self.app.notify(f"Window {name}: C {win[0]:g} W {win[1]:g}", timeout=2)

    def action_window_set(self) -> None:
        from ctui.screens.dialogs import PromptScreen

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
            self._window_name = "custom"
            self.refresh_view()

        c, w = self.s.window
        self.app.push_screen(PromptScreen("Window centre and width (e.g. 40 400)", f"{c:g} {w:g}"), done)

    def action_view_cycle(self) -> None:
        if self.grid_mode:
            self.action_grid()
            return
        i = VIEWS.index(self.s.view)
        self.s.view = VIEWS[(i + 1) % len(VIEWS)]
        self.main_view.token = None
        self.refresh_view()

    def action_grid(self) -> None:
        self.grid_mode = not self.grid_mode
        self.query_one("#grid").set_class(self.grid_mode, "on")
        self.main_view.set_class(self.grid_mode, "off")
        for v in VIEWS:
            self.query_one(f"#g-{v}", ImageView).token = None
        self.main_view.token = None
        self.refresh_view()

    def on_click(self, event) -> None:
        """Click on a view moves the cursor there."""
        widget = getattr(event, "widget", None)
        if isinstance(widget, ImageView):
            off = event.get_content_offset(widget)
            if off is None:
                return
            pos = widget.display_to_image(off.x, off.y)
            if pos is not None:
                self.s.x, self.s.y = int(round(pos[0])), int(round(pos[1]))
                self.s.clamp()
                self._repaint_cursor()

    # ------------------------------------------------------------------ selection
    def _need_seg(self) -> bool:
        if self.s.seg is None or self.s.pipeline is None:
            self.app.notify("The selection engine is not available in this build", severity="error")
            return False
        return True

    def _busy(self) -> bool:
        """Label edits wait while a propagation reads the labels (Escape cancels it)."""
        if self._prop is not None:
            self.app.notify("A propagation is running: wait for it or press Escape to cancel", severity="warning", timeout=3)
            return True
        return False

    def action_fill(self) -> None:
        if self._busy():
            return
        if not self._need_seg():
            return
        s = self.s
        try:
            with s._lock:
                image = s.pipeline.final_slice(s.volume, s.z)
            kw = {"low": s.range_[0], "high": s.range_[1]} if s.range_ else {"tolerance": s.tolerance}
            s.seg.add_object(object_id=s.current)
            res = s.seg.fill(image, s.x, s.y, s.z, object_id=s.current, connectivity=s.connectivity, **kw)
        except (CtuiError, ValueError, IndexError) as exc:
            self.app.notify(str(exc), severity="error")
            return
        if not res.accepted:
            self.app.notify(f"Fill rejected: {res.reason}", severity="warning")
            return
        self.labels_changed()
        lo, hi = res.range or (0, 0)
        self.set_status(f"Filled {res.area} px into object {s.current} (range {lo:g}..{hi:g}); p propagates, u undoes")
        self.refresh_view()

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
        from ctui.screens.dialogs import PromptScreen

        def done(val: str | None) -> None:
            if val is None:
                return
            val = val.strip()
            try:
                if ":" in val or ".." in val:
                    lo, hi = [float(p) for p in val.replace("..", ":").split(":")]
                    if hi < lo:
                        lo, hi = hi, lo
                    self.s.range_ = (lo, hi)
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

    def action_new_object(self) -> None:
        if not self._need_seg():
            return
        try:
            self.s.current = self.s.seg.add_object()
        except ValueError as exc:
            self.app.notify(str(exc), severity="error")
            return
        self.s.dirty = True
        self.update_panel()

    def action_rename_object(self) -> None:
        from ctui.screens.dialogs import PromptScreen

        s = self.s
        if not self._need_seg():
            return
        s.seg.add_object(object_id=s.current)
        info = s.seg.objects[s.current]

        def done(val: str | None) -> None:
            if val and val.strip():
                info.name = val.strip()[:40]
                s.dirty = True
                self.update_panel()

        self.app.push_screen(PromptScreen(f"Name of object {s.current}", info.name), done)

    def action_clear_object(self) -> None:
        from ctui.screens.dialogs import ConfirmScreen

        s = self.s
        if not self._need_seg() or self._busy():
            return

        def done(ok: bool) -> None:
            if ok:
                n = s.seg.clear_object(s.current)
                self.labels_changed()
                self.set_status(f"Cleared {n} voxels of object {s.current} (u undoes)")
                self.refresh_view()

        self.app.push_screen(ConfirmScreen(f"Erase every voxel of object {s.current}? (u undoes)", "Erase", "Keep"), done)

    def action_cycle_object(self) -> None:
        if self.s.seg is None:
            return
        ids = sorted(self.s.seg.objects) or [1]
        if self.s.current in ids:
            self.s.current = ids[(ids.index(self.s.current) + 1) % len(ids)]
        else:
            self.s.current = ids[0]
        self.update_panel()

    def action_undo(self) -> None:
        if self._busy():
            return
        if self.s.seg is None:
            return
        label = self.s.seg.undo()
        self.app.notify(f"Undone: {label}" if label else "Nothing to undo", timeout=2)
        if label:
            self.labels_changed()
            self.refresh_view()

    def action_redo(self) -> None:
        if self._busy():
            return
        if self.s.seg is None:
            return
        label = self.s.seg.redo()
        self.app.notify(f"Redone: {label}" if label else "Nothing to redo", timeout=2)
        if label:
            self.labels_changed()
            self.refresh_view()

    # ------------------------------------------------------------------ propagation
    def show_progress(self, label: str | None, done: float = 0, total: float = 100) -> None:
        row = self.query_one("#progress-row")
        if label is None:
            row.remove_class("on")
            return
        row.add_class("on")
        self.query_one("#progress-label", Label).update(label)
        bar = self.query_one("#progress", ProgressBar)
        bar.update(total=max(total, 1), progress=done)

    def action_propagate(self, direction: str) -> None:
        from ctui.screens.propagation import start_propagation

        if not self._need_seg():
            return
        start_propagation(self, direction)

    def action_accept(self) -> None:
        from ctui.screens.propagation import accept

        if self._busy():
            return
        accept(self)

    def action_reject(self) -> None:
        from ctui.screens.propagation import reject

        reject(self)

    def action_cancel(self) -> None:
        if self._prop is not None:
            self._prop.cancel()
            self.set_status("Cancelling propagation...")

    # ------------------------------------------------------------------ other screens
    def action_filters(self) -> None:
        if self._busy():
            return
        from ctui.screens.pipeline_editor import PipelineEditor

        if self.s.pipeline is None:
            self.app.notify("The pipeline engine is not available in this build", severity="error")
            return
        self.app.push_screen(PipelineEditor(self.s), lambda _=None: self._after_pipeline())

    def _after_pipeline(self) -> None:
        self.s.dirty = True
        for v in VIEWS:
            self.query_one(f"#g-{v}", ImageView).token = None
        self.main_view.token = None
        self.refresh_view()

    def action_drift(self) -> None:
        if self._busy():
            return
        from ctui.screens.drift_screen import DriftScreen

        self.app.push_screen(DriftScreen(self.s), lambda _=None: (self.labels_changed(), self.refresh_view()))

    def action_render3d(self) -> None:
        from ctui.screens.view3d import View3DScreen

        self.app.push_screen(View3DScreen(self.s))

    def action_measure(self) -> None:
        from ctui.screens.measure_screen import MeasureScreen

        self.app.push_screen(MeasureScreen(self.s))

    def action_export(self) -> None:
        from ctui.screens.export import export_dialog

        export_dialog(self)

    def action_open(self) -> None:
        self.app.action_open()
