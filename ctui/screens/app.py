"""The ctui Textual app: loading, the workspace, project save/autosave, quit guard,
help and the command palette. Loading and autosave run in thread workers that post
messages (:mod:`ctui.screens.messages`) to the app."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from textual import events, on, work
from textual.app import App, SystemCommand
from textual.binding import Binding
from textual.notifications import SeverityLevel
from textual.screen import Screen
from textual.worker import get_current_worker

from ctui.engine.actions.formats import output_name
from ctui.engine.actions.opened import check_source, labels_only_volume, series_available
from ctui.engine.actions.project import save_project
from ctui.engine.core.errors import CtuiError
from ctui.engine.actions import project
from ctui.engine.actions.mesh import warm_up
from ctui.engine.actions.project import source_load_options
from ctui.engine.actions.series import preview
from ctui.engine.core.progress import Cancelled
from ctui.screens.dialogs import PromptScreen
from ctui.screens.graphics import CELL_MODES, colour_advice
from ctui.screens.loading import LoadingScreen, PreviewReady
from ctui.screens.messages import JobProgress, LoadFailed, SessionReady
from ctui.screens.projects import project_from_session, session_from_project
from ctui.screens.session import Session, load_volume, safe_cwd, sample_source

if TYPE_CHECKING:  # annotations only: the workspace is imported when a series opens (startup time)
    from ctui.screens.workspace import WorkspaceScreen

__all__ = ["AUTOSAVE_SECONDS", "CtuiApp", "LoadingScreen", "project_from_session", "session_from_project"]

AUTOSAVE_SECONDS = 180.0


#: a series with fewer voxels loads about as fast as its middle slice: no preview first
PREVIEW_MIN_VOXELS = 16_000_000

SIDECARS = (".json", ".txt", ".md", ".csv", ".xml", ".html", ".pdf", ".log", ".yaml", ".yml", ".py", ".sh")


class CtuiApp(App):
    """ctui: slice series to measured 3D models, from the keyboard."""

    TITLE = "ctui"
    CSS = """
    Screen { background: $background; }
    ModalScreen { background: $background 50%; }
    ModalScreen.at-bottom { background: $background 10%; }
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
            from ctui.screens.graphics import use_graphics

            if graphics in CELL_MODES:
                use_graphics(graphics)
            else:  # sixel/kitty need the terminal probed before Textual starts: half-blocks unless it was
                use_graphics("halfblock", unless_chosen=True)
        self.load_options = load_options
        self.session: Session | None = session
        self.workspace: WorkspaceScreen | None = None
        self.autosave_s = autosave_s
        self._last_autosave = time.monotonic()
        self._colour_warned = False
        self.errors: list[str] = []  # every error notified (tests read it)
        self.internal_errors: list[str] = []  # tracebacks of internal errors (reported, not fatal)
        self._quitting = False
        self._warm_started = False

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

    def warm_worker(self) -> None:
        """Compile (or load from numba's cache) the meshing kernels while the user looks at
        slices, so the first 3D view does not wait for a compiler. A daemon thread, not a
        Textual worker: a compile cannot be interrupted and quitting must not wait for it.
        Started once, after the first workspace is painted: importing and starting numba
        holds the GIL for ~0.5 s, which delayed loading and the first paint."""
        if self._warm_started:
            return
        self._warm_started = True
        threading.Thread(target=self._warm, name="ctui-warm-up", daemon=True).start()

    def _warm(self) -> None:
        try:
            warm_up()
        except Exception as exc:  # the vectorised path still works; say why it stays slow
            if self.is_running:
                self.notify(f"Meshing kernels not compiled ({exc}); 3D views use the slower numpy path",
                            severity="warning", timeout=6)

    def _check_colours(self) -> None:
        if self._colour_warned:
            return
        advice = colour_advice(getattr(self.console, "color_system", None))
        if advice and not self.is_headless:
            self._colour_warned = True
            self.colour_note(advice)

    def colour_note(self, advice: str, tries: int = 0) -> None:
        """The colour advice on the workspace's status line, below the views, once the workspace shows
        (retried each 0.5 s for a minute while a load or dialog is in front). A 15 s toast of it covered
        11 of 24 rows at 80x24, the status line too. Its first sentence shortened, the fix (tmux's, then
        TEXTUAL_COLOR_SYSTEM=truecolor) stays within the status line's 3 lines at 80 columns."""
        ws = self.workspace
        if ws is None or self.screen is not ws:
            if tries < 120:
                self.set_timer(0.5, lambda: self.colour_note(advice, tries + 1))
            return
        head, _, fix = advice.partition(". ")
        ws.set_status(f"{head.split('only ')[-1].split(',')[0]} only: grey slices band. {fix}" if fix else advice)

    def notify(self, message: str, *, title: str = "", severity: SeverityLevel = "information", timeout: float | None = None, markup: bool = False) -> None:
        if severity == "error":
            self.errors.append(str(message))
        super().notify(str(message), title=title, severity=severity, timeout=timeout, markup=markup)

    def _load_progress_of(self):
        """The load worker's progress callback: posts JobProgress, raises Cancelled once the
        worker is cancelled (Esc on the loading screen, or another load started)."""
        worker = get_current_worker()
        last = [-1.0]

        def progress(*a: Any) -> None:
            if worker.is_cancelled:
                raise Cancelled()
            if len(a) >= 2 and a[1]:
                frac = float(a[0]) / float(a[1])
                if frac - last[0] >= 0.02 or frac >= 1.0:  # a repaint per 2%, not per slice
                    last[0] = frac
                    self.post_message(JobProgress("Loading", float(a[0]), float(a[1])))

        return worker, progress

    def _post_preview(self, worker, path: str, options: dict, project_labels=None, pv=None) -> Any:
        """Read (unless ``pv`` is that Preview already) and post the middle slice of ``path`` (a
        large series) before the rest; the Preview or None. ``project_labels``: a project's
        objects, drawn over it."""
        try:
            pv = pv or preview(path, min_voxels=PREVIEW_MIN_VOXELS, **options)
        except Exception:  # the full read reports whatever is wrong with the input
            return None
        if pv is None or worker.is_cancelled:
            return None
        lab = None
        if project_labels is not None and project_labels.shape == (pv.depth, *pv.volume.shape[1:]):
            lab = project_labels[pv.z]
        self.post_message(PreviewReady(path, pv, lab))
        return pv

    @on(PreviewReady)
    def _preview_ready(self, msg: PreviewReady) -> None:
        if isinstance(self.screen, LoadingScreen) and self.screen.reading:
            self.screen.show_preview(msg)

    def cancel_load(self) -> None:
        """Stop the running load (its worker raises Cancelled at its next slice)."""
        self.workers.cancel_group(self, "load")

    @work(thread=True, exclusive=True, group="load")
    def load_worker(self, path: str | None, options: dict | None = None) -> None:
        options = dict(self.load_options if options is None else options)
        worker, progress = self._load_progress_of()
        try:
            src = path if path is not None else sample_source()
            pv = self._post_preview(worker, src, options)
            vol = load_volume(path, progress=progress, **options)
        except Cancelled:
            return
        except CtuiError as exc:
            self.post_message(LoadFailed(path, [str(exc)], options))
            return
        except Exception as exc:  # a loader bug must not become a traceback
            self.post_message(LoadFailed(path, [f"{type(exc).__name__}: {exc}"]))
            return
        if worker.is_cancelled:
            return
        z = pv.z if pv is not None and pv.depth == vol.shape[0] else vol.shape[0] // 2  # on the slice the preview showed
        self.post_message(SessionReady(Session(vol, source_path=str(src or ""), source_options=options, z=z)))

    @on(JobProgress)
    def _load_progress(self, msg: JobProgress) -> None:
        if isinstance(self.screen, LoadingScreen):
            self.screen.on_job_progress(msg)

    @on(LoadFailed)
    def _load_failed(self, msg: LoadFailed) -> None:
        path, reasons = msg.path, list(msg.reasons)
        self.errors.extend(reasons)
        if isinstance(self.screen, LoadingScreen):
            scr = self.screen
            scr.path, scr.options = path, dict(msg.options)
            scr.too_big = any("downsample" in r for r in reasons)
            if scr.too_big:
                reasons = reasons + ["d opens it downsampled x2, D x4, c asks for a crop"]
            scr.show_error(f"Could not open {path or 'the sample series'}", reasons)
        else:
            self.notify(f"Could not open {path}: {'; '.join(reasons)}", severity="error", timeout=10)

    @on(SessionReady)
    def _session_ready(self, msg: SessionReady) -> None:
        self._start_workspace(msg.session)

    @work(thread=True, exclusive=True, group="load")
    def load_project_worker(self, path: str) -> None:
        worker, progress = self._load_progress_of()
        try:
            head = project.load_project(path, with_labels=False)  # project.json: the series to preview
            pv = self._post_preview(worker, head.source_path, source_load_options(head)) \
                if series_available(head) else None
            proj = project.load_project(path)
            if pv is not None and proj.labels is not None:  # the objects over the preview
                self._post_preview(worker, head.source_path, {}, proj.labels, pv)
            if series_available(proj):  # an empty source path must not load the current folder
                opts = source_load_options(proj)
                vol = load_volume(proj.source_path, progress=progress, **opts)
                check_source(proj, vol, path)  # a series whose voxels changed is refused
            else:  # the series moved: the objects on the recorded geometry, no grey levels
                vol = labels_only_volume(proj, path)
            sess = session_from_project(proj, vol, path)
        except Cancelled:
            return
        except CtuiError as exc:
            self.post_message(LoadFailed(path, [str(exc)]))
            return
        except Exception as exc:
            self.post_message(LoadFailed(path, [f"{type(exc).__name__}: {exc}"]))
            return
        if not worker.is_cancelled:
            self.post_message(SessionReady(sess))

    def make_workspace(self, session: Session) -> WorkspaceScreen:
        """The workspace on ``session``. An app with more tools returns a subclass with them
        (ARCHITECTURE.md, "A TUI tool or key"; tests/tui/test_tui_tool.py)."""
        from ctui.screens.workspace import WorkspaceScreen  # imported when a series opens (startup time)

        return WorkspaceScreen(session)

    def _start_workspace(self, session: Session, *, recovery: bool = True) -> None:
        self.session = session
        for w in sorted(session.volume.warnings, key=lambda w: w not in session.volume.assumptions)[:3] if recovery else []:
            self.notify(w, title="Series", severity="warning", timeout=6)
        # sidecar files (the sample's truth.json, notes, tables) are not images anyone expected
        # to load: listed by `ctui info`, not announced
        skipped = [sk for sk in (session.volume.skipped if recovery else [])
                   if not str(sk.get("file", "")).lower().endswith(SIDECARS)]
        if len(skipped) == 1:
            sk = skipped[0]
            self.notify(f"Skipped {sk.get('file')}: {sk.get('reason')}", severity="information", timeout=4)
        elif skipped:
            self.notify(f"{len(skipped)} files skipped (ctui info lists them), e.g. {skipped[0].get('file')}: "
                        f"{skipped[0].get('reason')}", severity="warning", timeout=6)
        ws = self.make_workspace(session)
        self.workspace = ws
        # replace whatever is on the stack (loading screen, old workspace)
        while len(self.screen_stack) > 1:
            self.pop_screen()
        self.push_screen(ws)
        if recovery:
            self.call_after_refresh(self._offer_recovery, session)
        self.call_after_refresh(self.set_timer, 0.3, self.warm_worker)  # once the workspace is on screen

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
        self._start_workspace(new, recovery=False)
        self.notify(f"Recovered {auto}", timeout=4)

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
                                 lambda ok: self.open_path(path, series) if ok else None)
            else:
                self.open_path(path, series)

        self.push_screen(OpenScreen(start), done)

    def action_help(self) -> None:
        from ctui.screens.dialogs import TextScreen, bindings_help

        from ctui.screens.keyhelp import task_help

        screen = self.screen
        cols = int(self.size.width * 0.9) - 6  # the help box's text width: groups side by side when it fits
        if screen is self.workspace:  # by task, the main actions first
            text = f"[b]Keys on this screen[/b], by task\n\n{task_help((screen, self), width=cols)}\n\n"
            if screen.pending.proposal is not None and screen.pending.notes:  # whole (80x24's panel has no room)
                from rich.markup import escape

                text = "".join(f"• {escape(n)}\n" for n in screen.pending.notes).join(("[b]Notes on the proposal[/b]\n", "\n")) + text
        else:
            text = f"[b]Keys on this screen[/b]\n{bindings_help(screen)}\n\n"
        if self.workspace is not None and screen is not self.workspace:
            text += f"[b]Slice workspace[/b]\n{task_help((self.workspace, self), width=cols)}\n\n"
        if self.workspace is not None:
            from ctui.screens.ws_mouse import MOUSE_HELP

            text += MOUSE_HELP
        text += "[b]Command palette[/b]: Ctrl+P lists every action by name.\n"
        text += "Graphics: --graphics auto|sixel|kitty|halfblock|ascii or CTUI_GRAPHICS.\n"
        self.push_screen(TextScreen("ctui help", text))

    def action_save(self, then_quit: bool = False) -> None:
        s = self.session
        if s is None:
            return
        if s.project_path:
            self._save_to(s.project_path, then_quit, asked=False)
            return
        from ctui.screens.dialogs import PromptScreen

        default = str(safe_cwd() / output_name(s.source_path, ".ctui"))  # ct.nii.gz -> ct.ctui

        def done(val: str | None) -> None:
            if val:
                p = val.strip()
                if not p.endswith(".ctui"):
                    p += ".ctui"
                self._save_to(p, then_quit)

        self.push_screen(PromptScreen("Save project as", default), done)

    def _save_to(self, path: str, then_quit: bool = False, *, asked: bool = True) -> None:
        """Save the project to ``path``; ``asked``: the path came from a dialog (False: a
        second Ctrl+S, saved where the first one did)."""
        s = self.session
        if s is None:
            return
        try:
            p = Path(path).expanduser()
            if not p.is_absolute():  # relative to where ctui started (the folder may be gone: then home)
                p = safe_cwd() / p
            proj = project_from_session(s)
            save_project(str(p), proj)  # the CLI's writer: refuses the source folder and the inputs
        except (CtuiError, OSError, ValueError) as exc:
            self.notify(f"Project not saved: {exc}", severity="error", timeout=10)
            return
        old_key = s.project_path or s.source_path
        s.project_path = str(p)
        s.dirty = False
        self._remove_autosaves(old_key, s.project_path)
        ws = self.workspace
        if ws is not None and self.screen is ws:  # said on the status line, not in a toast over the image
            ws.saved_to(str(p), asked=asked)
        else:
            self.notify(f"Project saved: {p}", timeout=3)
        if then_quit:
            self._exit_clean()

    def _remove_autosaves(self, *keys: str | None) -> None:
        """Forget the autosaves of these projects/sources (the work is saved or discarded)."""
        for key in {k for k in keys if k}:
            try:
                project.remove_autosave(key)
            except Exception:  # a read-only folder: the prompt will offer it, nothing lost
                pass

    def _exit_clean(self) -> None:
        """Exit with nothing unsaved: no autosave may survive to prompt next time."""
        self._quitting = True
        s = self.session
        if s is not None:
            self._remove_autosaves(s.project_path, s.source_path)
        self.exit()

    def _autosave_tick(self) -> None:
        s = self.session
        if s is None or not s.dirty or self._quitting or time.monotonic() - self._last_autosave < self.autosave_s:
            return
        self._last_autosave = time.monotonic()
        self.autosave_worker()

    @work(thread=True, exclusive=True, group="autosave")
    def autosave_worker(self) -> None:
        s = self.session
        if s is None:
            return
        key = s.project_path or s.source_path
        try:
            proj = project_from_session(s)
            target = project.autosave(proj, key)
        except Exception as exc:
            self.notify(f"Autosave failed: {exc}", severity="warning")  # notify posts a message: thread-safe
            return
        if self._quitting or not s.dirty:  # saved or quit meanwhile: this autosave is stale already
            self._remove_autosaves(key)
            return
        self.notify(f"Autosaved to {target}", timeout=2)

    def action_request_quit(self) -> None:
        s = self.session
        if s is not None and s.dirty:
            from ctui.screens.dialogs import ChoiceScreen

            def done(choice: str | None) -> None:
                if choice == "save":
                    self.action_save(then_quit=True)
                elif choice == "quit":  # the user discards the work: its autosave goes too
                    self._exit_clean()

            self.push_screen(ChoiceScreen("Unsaved work. Quit anyway?", [
                ("save", "Save the project, then quit"),
                ("quit", "Quit without saving"),
                ("cancel", "Keep working"),
            ]), done)
            return
        self._exit_clean()

    def _on_key(self, event: events.Key) -> None:  # type: ignore[override]  # Textual's private hook, overridden on purpose (textual pinned to the tested minor)
        """A key sent to a screen that is no longer on top (a burst after the key that
        opened a prompt, or closed one) goes to the screen on top, not to its bindings.
        (Textual then runs App._on_key, the bindings, unless the default is prevented.)"""
        src = getattr(event, "ctui_screen", None)
        if src is None or src is self.screen or self._quitting:
            return
        event.prevent_default()
        top = self.screen
        if isinstance(top, PromptScreen):
            top.feed_key(event.key, event.character)
            return
        key = events.Key(event.key, event.character)
        key.ctui_screen = top  # type: ignore[attr-defined]  # ctui's mark on Textual's Key event: the screen it was typed at
        (top.focused or top)._forward_event(key)

    # ------------------------------------------------------------------ errors
    def _handle_exception(self, error: Exception) -> None:
        """Workers and handlers: report and keep running once the app is up."""
        from ctui.screens.guard import report_internal_error

        if self.is_running and self.screen_stack and not isinstance(error, (KeyboardInterrupt, SystemExit)):
            report_internal_error(self, error)
            return
        super()._handle_exception(error)

    async def _dispatch_action(self, namespace, action_name, params):
        try:
            return await super()._dispatch_action(namespace, action_name, params)
        except Exception as exc:
            from ctui.screens.guard import report_internal_error

            report_internal_error(self, exc)
            return True

    def push_screen(self, screen, callback=None, wait_for_dismiss: bool = False):  # type: ignore[override]  # one signature for Textual's overloads: the callback is wrapped, nothing else changes
        if callback is not None:
            inner = callback

            def callback(result, _inner=inner):
                try:
                    return _inner(result)
                except Exception as exc:
                    from ctui.screens.guard import report_internal_error

                    report_internal_error(self, exc)

        return super().push_screen(screen, callback, wait_for_dismiss=wait_for_dismiss)  # type: ignore[call-overload]  # a pass-through: Textual's overloads split on a Literal wait_for_dismiss

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
                bb = b if isinstance(b, Binding) else Binding(*b)
                key, action, desc = bb.key, bb.action, bb.description
                if action in seen:
                    continue
                seen.add(action)
                keys = key.split(",")[0]
                yield SystemCommand(f"{desc or action}", f"key {keys}", self._palette_callback(node, action))
        yield from self._method_commands()
        yield SystemCommand("Save project", "Ctrl+S", self.action_save)
        yield SystemCommand("Help: all keys", "?", self.action_help)
        yield SystemCommand("Open series or project", "o", self.action_open)
        yield SystemCommand("Show last internal error", "traceback of the last reported internal error", self.action_last_error)

    def _method_commands(self) -> Iterable[SystemCommand]:
        """One command per segmentation method of the registry ("grow" finds "Segmentation
        method: grow"): it becomes the method S and p use, as in the G panel."""
        ws, session = self.workspace, self.session
        if ws is None or session is None:
            return
        from ctui.engine.actions.segment import METHODS  # the registry loads the segmentation with the palette

        for name, m in METHODS.items():
            def pick(_name=name) -> None:
                session.segment_options["method"] = _name
                ws.set_status(f"Segmentation method {_name}: S segments from the cursor (G shows every option)")
                ws.update_panel()

            yield SystemCommand(f"Segmentation method: {name}", m.help, pick)

    def _palette_callback(self, node, action: str):
        async def run() -> None:
            await node.run_action(action)

        return run
