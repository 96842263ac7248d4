"""The ctui Textual app: loading, the workspace, project save/autosave, quit guard,
help and the command palette."""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from textual import work
from textual.app import App, ComposeResult, SystemCommand
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import Screen
from textual.widgets import Footer, Label, ProgressBar, Static

from ctui.engine.actions.opened import check_source, series_available
from ctui.engine.core.errors import CtuiError
from ctui.engine.io import project
from ctui.engine.io.project import source_load_options
from ctui.engine.segment import pipeline, selection
from ctui.screens.graphics import colour_advice
from ctui.screens.guard import GuardMixin
from ctui.screens.session import Session, load_volume

AUTOSAVE_SECONDS = 180.0


class LoadingScreen(GuardMixin, Screen):
    """Shown while a series loads (progress bar), or the reasons it could not load."""

    DEFAULT_CSS = """
    LoadingScreen { align: center middle; }
    LoadingScreen > Vertical { width: 80%; height: auto; border: round $accent; padding: 1 2; }
    LoadingScreen ProgressBar { margin: 1 0; }
    """
    BINDINGS = [
        Binding("o", "app.open", "Open another"),
        Binding("d", "reduced(2)", "Downsample x2", show=False),
        Binding("D", "reduced(4)", "Downsample x4", show=False),
        Binding("c", "crop", "Crop", show=False),
        Binding("escape", "back", "Back"),
        Binding("q", "app.quit", "Quit"),
    ]

    def __init__(self, what: str) -> None:
        super().__init__()
        self.what = what
        self.too_big = False  # the series would not fit in memory: offer downsampling/cropping
        self.path: str | None = None
        self.options: dict = {}

    def action_reduced(self, factor: int) -> None:
        if not self.too_big:
            return
        opts = {**self.options, "downsample": int(factor)}
        self.app.load_worker(self.path, opts)
        self.query_one("#load-title", Label).update(f"Loading [b]{self.what}[/b] downsampled x{factor} ...")
        self.query_one("#load-progress").display = True
        self.query_one("#load-reasons", Static).update("")

    def action_crop(self) -> None:
        if not self.too_big:
            return
        from ctui.screens.dialogs import PromptScreen

        def done(val: str | None) -> None:
            if not val:
                return
            try:
                crop = tuple(int(v) for v in val.replace(" ", "").split(","))
                if len(crop) != 6:
                    raise ValueError
            except ValueError:
                self.app.notify("Crop: six integers z0,z1,y0,y1,x0,x1", severity="error")
                return
            self.app.load_worker(self.path, {**self.options, "crop": crop})
            self.query_one("#load-progress").display = True

        self.app.push_screen(PromptScreen("Crop z0,z1,y0,y1,x0,x1 (voxel indices)", ""), done)

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(f"Loading [b]{self.what}[/b] ...", id="load-title")
            yield ProgressBar(total=None, id="load-progress", show_eta=False)
            yield Static("", id="load-reasons")
        yield Footer()

    def action_back(self) -> None:
        if len(self.app.screen_stack) > 2:
            self.app.pop_screen()

    def show_error(self, title: str, reasons: list[str]) -> None:
        self.query_one("#load-title", Label).update(f"[b red]{title}[/b red]")
        self.query_one("#load-progress").display = False
        body = "\n".join(f"• {r}" for r in reasons) + "\n\n[dim]o opens another path, q quits[/dim]"
        self.query_one("#load-reasons", Static).update(body)


class CtuiApp(App):
    """ctui: slice series to measured 3D models, from the keyboard."""

    TITLE = "ctui"
    CSS = """
    Screen { background: $background; }
    """
    BINDINGS = [
        Binding("question_mark", "help", "Help"),
        Binding("ctrl+s", "save", "Save project"),
        Binding("q", "request_quit", "Quit"),
        Binding("ctrl+q", "request_quit", "Quit", show=False, priority=True),
        Binding("ctrl+p", "command_palette", "Commands", show=False),
    ]

    def __init__(self, path: str | None = None, *, project: str | None = None, graphics: str | None = None,
                 session: Session | None = None, autosave_s: float = AUTOSAVE_SECONDS, **load_options: Any) -> None:
        super().__init__()
        self.path = path
        self.project_file = project
        self.graphics = graphics
        if graphics:
            from ctui.screens import graphics as _g

            if graphics in ("halfblock", "ascii") or _g._chosen is None:
                _g._chosen = graphics if graphics in ("halfblock", "ascii") else "halfblock"
        self.load_options = load_options
        self.session: Session | None = session
        self.workspace = None
        self.autosave_s = autosave_s
        self._last_autosave = time.monotonic()
        self._colour_warned = False
        self.errors: list[str] = []  # every error notified (tests read it)
        self.internal_errors: list[str] = []  # tracebacks of internal errors (reported, not fatal)

    # ------------------------------------------------------------------ start
    def on_mount(self) -> None:
        if self.session is not None:
            self._start_workspace(self.session)
        elif self.project_file:
            self.push_screen(LoadingScreen(self.project_file))
            self.load_project_worker(self.project_file)
        else:
            self.push_screen(LoadingScreen(self.path or "the bundled sample series"))
            self.load_worker(self.path)
        self.set_interval(30.0, self._autosave_tick)
        self.call_after_refresh(self._check_colours)

    def _check_colours(self) -> None:
        if self._colour_warned:
            return
        advice = colour_advice(getattr(self.console, "color_system", None))
        if advice and not self.is_headless:
            self._colour_warned = True
            self.notify(advice, title="Colours", severity="warning", timeout=15)

    def notify(self, message: str, *, title: str = "", severity: str = "information", timeout: float | None = None, markup: bool = False) -> None:  # type: ignore[override]
        if severity == "error":
            self.errors.append(str(message))
        super().notify(str(message), title=title, severity=severity, timeout=timeout, markup=markup)

    @work(thread=True, exclusive=True, group="load")
    def load_worker(self, path: str | None, options: dict | None = None) -> None:
        options = dict(self.load_options if options is None else options)

        def progress(*a: Any) -> None:
            if len(a) >= 2 and a[1]:
                self.call_from_thread(self._load_progress, float(a[0]), float(a[1]))

        try:
            vol = load_volume(path, progress=progress, **options)
        except CtuiError as exc:
            self.call_from_thread(self._load_failed, path, [str(exc)], options)
            return
        except Exception as exc:  # a loader bug must not become a traceback
            self.call_from_thread(self._load_failed, path, [f"{type(exc).__name__}: {exc}"])
            return
        src = path
        if src is None:
            try:
                from ctui.screens.session import sample_source

                src = sample_source()
            except CtuiError:
                src = ""
        sess = Session(vol, source_path=str(src or ""), source_options=options)
        self.call_from_thread(self._start_workspace, sess)

    def _load_progress(self, done: float, total: float) -> None:
        if isinstance(self.screen, LoadingScreen):
            self.screen.query_one("#load-progress", ProgressBar).update(total=total, progress=done)

    def _load_failed(self, path: str | None, reasons: list[str], options: dict | None = None) -> None:
        self.errors.extend(reasons)
        if isinstance(self.screen, LoadingScreen):
            scr = self.screen
            scr.path, scr.options = path, dict(options or {})
            scr.too_big = any("downsample" in r for r in reasons)
            if scr.too_big:
                reasons = reasons + ["d opens it downsampled x2, D x4, c asks for a crop"]
            scr.show_error(f"Could not open {path or 'the sample series'}", reasons)
        else:
            self.notify(f"Could not open {path}: {'; '.join(reasons)}", severity="error", timeout=10)

    @work(thread=True, exclusive=True, group="load")
    def load_project_worker(self, path: str) -> None:
        try:
            proj = project.load_project(path)
            if not series_available(proj):  # an empty source path must not load the current folder
                raise CtuiError(f"the source series {proj.source_path or '(none)'} is missing; ctui measure, mesh "
                                "and render work from the project alone", path=path)
            vol = load_volume(proj.source_path, **source_load_options(proj))
            check_source(proj, vol, path)  # a series whose voxels changed is refused
            sess = session_from_project(proj, vol, path)
        except CtuiError as exc:
            self.call_from_thread(self._load_failed, path, [str(exc)])
            return
        except Exception as exc:
            self.call_from_thread(self._load_failed, path, [f"{type(exc).__name__}: {exc}"])
            return
        self.call_from_thread(self._start_workspace, sess)

    def _start_workspace(self, session: Session) -> None:
        from ctui.screens.workspace import WorkspaceScreen

        self.session = session
        for w in session.volume.warnings[:3]:
            self.notify(w, title="Series", severity="warning", timeout=6)
        skipped = session.volume.skipped
        if len(skipped) == 1:
            sk = skipped[0]
            self.notify(f"Skipped {sk.get('file')}: {sk.get('reason')}", severity="information", timeout=4)
        elif skipped:
            self.notify(f"{len(skipped)} files skipped (ctui info lists them), e.g. {skipped[0].get('file')}: "
                        f"{skipped[0].get('reason')}", severity="warning", timeout=6)
        ws = WorkspaceScreen(session)
        self.workspace = ws
        # replace whatever is on the stack (loading screen, old workspace)
        while len(self.screen_stack) > 1:
            self.pop_screen()
        self.push_screen(ws)
        self.call_after_refresh(self._offer_recovery, session)

    def _offer_recovery(self, session: Session) -> None:
        """An autosave newer than the project (or of an unsaved source): offer it."""
        try:
            key = session.project_path or session.source_path
            auto = project.find_autosave(key) if key else None
        except Exception:
            return
        if auto is None or str(auto) == str(session.project_path):
            return
        from ctui.screens.dialogs import ConfirmScreen

        def done(ok: bool) -> None:
            if ok:
                self._recover(session, str(auto))
            else:
                try:
                    project.remove_autosave(key)
                except Exception:
                    pass

        self.push_screen(ConfirmScreen(f"Unsaved work from an earlier session was autosaved ({auto.name}). Recover it?",
                                       "Recover", "Discard"), done)

    def _recover(self, session: Session, auto: str) -> None:
        try:
            proj = project.load_project(auto)
            new = session_from_project(proj, session.volume, session.project_path or "")
        except (CtuiError, ValueError) as exc:
            self.notify(f"Autosave not recovered: {exc}", severity="error")
            return
        new.project_path = session.project_path
        new.source_path = session.source_path
        new.dirty = True
        self._start_workspace_no_recovery(new)
        self.notify(f"Recovered {auto}", timeout=4)

    def _start_workspace_no_recovery(self, session: Session) -> None:
        from ctui.screens.workspace import WorkspaceScreen

        self.session = session
        ws = WorkspaceScreen(session)
        self.workspace = ws
        while len(self.screen_stack) > 1:
            self.pop_screen()
        self.push_screen(ws)

    def open_path(self, path: str, series: str | None = None) -> None:
        """Open another series or project (from the open screen)."""
        self.push_screen(LoadingScreen(path))
        if path.endswith(".ctui") or path.endswith(".ctui.autosave"):
            self.load_project_worker(path)
        else:
            self.load_worker(path, {"series": series} if series else {})

    # ------------------------------------------------------------------ actions
    def action_open(self) -> None:
        from ctui.screens.open_screen import OpenScreen

        start = None
        if self.session is not None and self.session.source_path:
            start = str(Path(self.session.source_path).parent)

        def done(choice: tuple | None) -> None:
            if not choice:
                return
            path, series = choice
            if self.session is not None and self.session.dirty:
                from ctui.screens.dialogs import ConfirmScreen

                self.push_screen(ConfirmScreen("Discard unsaved work and open another series?", "Discard", "Keep"),
                                 lambda ok: ok and self.open_path(path, series))
            else:
                self.open_path(path, series)

        self.push_screen(OpenScreen(start), done)

    def action_help(self) -> None:
        from ctui.screens.dialogs import TextScreen, bindings_help

        screen = self.screen
        text = f"[b]Keys on this screen[/b]\n{bindings_help(screen)}\n\n"
        if self.workspace is not None and screen is not self.workspace:
            text += f"[b]Slice workspace[/b]\n{bindings_help(self.workspace)}\n\n"
        text += "[b]Command palette[/b]: Ctrl+P lists every action by name.\n"
        text += "Graphics: --graphics auto|sixel|kitty|halfblock|ascii or CTUI_GRAPHICS.\n"
        self.push_screen(TextScreen("ctui help", text))

    def action_save(self, then_quit: bool = False) -> None:
        s = self.session
        if s is None:
            return
        if s.project_path:
            self._save_to(s.project_path, then_quit)
            return
        from ctui.screens.dialogs import PromptScreen

        default = str(Path.cwd() / (Path(s.source_path or "project").name.replace(" ", "_") + ".ctui"))

        def done(val: str | None) -> None:
            if val:
                p = val.strip()
                if not p.endswith(".ctui"):
                    p += ".ctui"
                self._save_to(p, then_quit)

        self.push_screen(PromptScreen("Save project as", default), done)

    def _save_to(self, path: str, then_quit: bool = False) -> None:
        s = self.session
        try:
            proj = project_from_session(s)
            project.save_project(path, proj)
        except (CtuiError, OSError, ValueError) as exc:
            self.notify(f"Project not saved: {exc}", severity="error", timeout=10)
            return
        s.project_path = path
        s.dirty = False
        try:
            project.remove_autosave(path)
        except Exception:
            pass
        self.notify(f"Project saved: {path}", timeout=3)
        if self.workspace is not None:
            self.workspace.update_panel()
        if then_quit:
            self.exit()

    def _autosave_tick(self) -> None:
        s = self.session
        if s is None or not s.dirty or time.monotonic() - self._last_autosave < self.autosave_s:
            return
        self._last_autosave = time.monotonic()
        self.autosave_worker()

    @work(thread=True, exclusive=True, group="autosave")
    def autosave_worker(self) -> None:
        s = self.session
        try:
            proj = project_from_session(s)
            target = project.autosave(proj, s.project_path or s.source_path)
        except Exception as exc:
            self.call_from_thread(self.notify, f"Autosave failed: {exc}", severity="warning")
            return
        self.call_from_thread(self.notify, f"Autosaved to {target}", timeout=2)

    def action_request_quit(self) -> None:
        s = self.session
        if s is not None and s.dirty:
            from ctui.screens.dialogs import ChoiceScreen

            def done(choice: str | None) -> None:
                if choice == "save":
                    self.action_save(then_quit=True)
                elif choice == "quit":
                    self.exit()

            self.push_screen(ChoiceScreen("Unsaved work. Quit anyway?", [
                ("save", "Save the project, then quit"),
                ("quit", "Quit without saving"),
                ("cancel", "Keep working"),
            ]), done)
            return
        self.exit()

    # ------------------------------------------------------------------ errors
    def _handle_exception(self, error: Exception) -> None:
        """Workers and handlers: report and keep running once the app is up."""
        from ctui.screens.guard import report_internal_error

        if self.is_running and self.screen_stack and not isinstance(error, (KeyboardInterrupt, SystemExit)):
            report_internal_error(self, error)
            return
        super()._handle_exception(error)

    async def _dispatch_action(self, namespace, action_name, params):  # type: ignore[override]
        try:
            return await super()._dispatch_action(namespace, action_name, params)
        except Exception as exc:  # noqa: BLE001
            from ctui.screens.guard import report_internal_error

            report_internal_error(self, exc)
            return True

    def push_screen(self, screen, callback=None, wait_for_dismiss: bool = False):  # type: ignore[override]
        if callback is not None:
            inner = callback

            def callback(result, _inner=inner):  # noqa: F811 - guarded wrapper
                try:
                    return _inner(result)
                except Exception as exc:  # noqa: BLE001
                    from ctui.screens.guard import report_internal_error

                    report_internal_error(self, exc)

        return super().push_screen(screen, callback, wait_for_dismiss=wait_for_dismiss)

    def action_last_error(self) -> None:
        from ctui.screens.dialogs import TextScreen

        body = self.internal_errors[-1] if self.internal_errors else "No internal error so far."
        self.push_screen(TextScreen("Last internal error", body, markup=False))

    # ------------------------------------------------------------------ command palette
    def get_system_commands(self, screen: Screen) -> Iterable[SystemCommand]:
        yield from super().get_system_commands(screen)
        seen = {"quit", "help", "command_palette"}
        targets = [screen] + ([self.workspace] if self.workspace is not None and self.workspace is not screen else [])
        for node in targets:
            for b in node.BINDINGS:
                key, action, desc = (b.key, b.action, b.description) if isinstance(b, Binding) else b
                if action in seen:
                    continue
                seen.add(action)
                keys = key.split(",")[0]
                yield SystemCommand(f"{desc or action}", f"key {keys}", self._palette_callback(node, action))
        yield SystemCommand("Save project", "Ctrl+S", self.action_save)
        yield SystemCommand("Help: all keys", "?", self.action_help)
        yield SystemCommand("Open series or project", "o", self.action_open)
        yield SystemCommand("Show last internal error", "traceback of the last reported internal error", self.action_last_error)

    def _palette_callback(self, node, action: str):
        async def run() -> None:
            await node.run_action(action)

        return run


# ---------------------------------------------------------------------- projects
def project_from_session(s: Session):
    """A ctui.engine.io.project.Project of the session's state."""
    seg = s.seg
    labels = getattr(seg, "labels", None)
    objects = seg.object_list() if seg is not None else []
    return project.Project(
        source_path=str(s.source_path),
        source_options=dict(s.source_options or {}),
        pipeline=s.pipeline.to_dict() if s.pipeline is not None else {},
        labels=labels,
        objects=objects,
        propagation={"tolerance": s.tolerance, "range": list(s.range_) if s.range_ else None,
                     "connectivity": s.connectivity, "current": s.current, "mode": s.prop_mode},
        drift=dict(s.drift_info or {}),
        window=tuple(s.window),
        meta={"z": s.z, "x": s.x, "y": s.y, "view": s.view},
    ).set_source(s.volume, data=getattr(s, "original_data", None))  # geometry + identity (of the voxels as loaded)


def session_from_project(proj, volume, path: str) -> Session:
    """Rebuild a Session from a loaded Project and its source volume."""
    pipeline_mod = pipeline
    labels = proj.labels
    if labels is not None and tuple(labels.shape) != tuple(volume.shape):
        raise CtuiError(f"labels {labels.shape} do not match the series {volume.shape}", path=path)
    seg = selection.Segmentation(volume.shape, labels=labels, objects=proj.objects or [])
    prop = proj.propagation or {}
    meta = proj.meta or {}
    s = Session(volume, source_path=proj.source_path, source_options=dict(proj.source_options or {}),
                pipeline=pipeline_mod.Pipeline.from_dict(proj.pipeline or {}), seg=seg,
                z=meta.get("z"), x=meta.get("x"), y=meta.get("y"))
    if proj.window:
        s.window = (float(proj.window[0]), float(proj.window[1]))
    s.tolerance = float(prop.get("tolerance", s.tolerance))
    s.range_ = tuple(prop["range"]) if prop.get("range") else None
    s.connectivity = int(prop.get("connectivity", 8))
    s.prop_mode = str(prop.get("mode", "slice")) if prop.get("mode") in ("slice", "3d") else "slice"
    s.current = int(prop.get("current", min(seg.objects) if seg.objects else 1))
    s.view = str(meta.get("view", s.view))
    s.drift_info = dict(proj.drift or {})
    s.project_path = path
    return s
