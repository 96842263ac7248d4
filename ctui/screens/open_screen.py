"""Open screen (``o``): browse folders, see the series found in each
(``ctui.engine.io.series.scan``, headers only, in a worker), open one."""

from __future__ import annotations

import os
from pathlib import Path

from rich.text import Text
from textual import work
from textual.worker import get_current_worker
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import DirectoryTree, Footer, Input, Label, OptionList
from textual.widgets.option_list import Option

from ctui.engine.core.progress import Cancelled
from ctui.engine.actions import series as loaders
from ctui.screens.guard import GuardMixin
from ctui.screens.messages import Note, SeriesFound


def describe_series(s: dict) -> str:
    shape = s.get("shape_zyx") or []
    sp = s.get("spacing_zyx_mm") or []
    shape_t = "x".join(str(v) for v in shape) if shape else "?"
    sp_t = "x".join(f"{float(v):g}" for v in sp) if sp else "?"
    desc = (s.get("description") or "").strip() or "(no description)"
    return f"{s.get('modality') or '?':<3} {shape_t:>13}  {sp_t} mm  {s.get('files', '?')} files  {s.get('kind', '')}  {desc[:40]}"


class OpenScreen(GuardMixin, ModalScreen[tuple | None]):
    """Dismisses with (path, series uid or None), or None."""

    DEFAULT_CSS = """
    OpenScreen > Vertical { width: 100%; height: 100%; background: $surface; }
    OpenScreen #op-body { height: 1fr; }
    OpenScreen DirectoryTree { width: 1fr; }
    OpenScreen #op-right { width: 1fr; }
    OpenScreen #op-series { height: 1fr; }
    """
    BINDINGS = [
        Binding("escape", "cancel", "Cancel"),
        Binding("ctrl+o", "open_typed", "Open typed path"),
        Binding("tab", "focus_next", "Next pane", show=False),
    ]

    def __init__(self, start: str | None = None) -> None:
        super().__init__()
        start_p = Path(start) if start else Path.cwd()
        if not start_p.is_dir():
            start_p = Path.cwd()
        self.start = start_p
        self.current: Path | None = None
        self.series: list[dict] = []

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label("[b]Open a series or project[/b]  (arrows browse, Enter on a series opens it, Ctrl+O opens the typed path)")
            yield Input(value=str(self.start), placeholder="path to a folder, file or .ctui project", id="op-path")
            with Horizontal(id="op-body"):
                yield DirectoryTree(str(self.start.parent if self.start.parent != self.start else self.start), id="op-tree")
                with Vertical(id="op-right"):
                    yield Label("Series found:", id="op-status")
                    yield OptionList(id="op-series")
        yield Footer()

    def on_mount(self) -> None:
        self.query_one(DirectoryTree).focus()
        self.scan(self.start)

    def on_directory_tree_directory_selected(self, event: DirectoryTree.DirectorySelected) -> None:
        self.query_one("#op-path", Input).value = str(event.path)
        self.scan(Path(event.path))

    def on_tree_node_highlighted(self, event) -> None:
        if getattr(event.node, "is_root", False):
            return  # the parent folder, highlighted on mount: scanned on Enter only (it may be a large tree)
        data = getattr(event.node, "data", None)
        path = getattr(data, "path", None)
        if path is not None and Path(path).is_dir():
            self.query_one("#op-path", Input).value = str(path)
            self.scan(Path(path))

    def on_directory_tree_file_selected(self, event: DirectoryTree.FileSelected) -> None:
        p = Path(event.path)
        self.query_one("#op-path", Input).value = str(p)
        if p.name.endswith(".ctui") or p.name.endswith(".ctui.autosave"):
            self.dismiss((str(p), None))
        else:
            self.scan(p)

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self.action_open_typed()

    def action_open_typed(self) -> None:
        text = self.query_one("#op-path", Input).value.strip()
        if not text:
            return
        p = Path(os.path.expanduser(text))
        try:
            found = p.exists()
        except (OSError, ValueError) as exc:  # a name over 255 bytes, a NUL: say so, not "Internal error"
            self.app.notify(f"{str(p)[:120]}: cannot open ({getattr(exc, 'strerror', None) or exc})", severity="error")
            return
        if not found:
            self.app.notify(f"{p}: no such file or folder", severity="error")
            return
        self.dismiss((str(p), None))

    @work(thread=True, exclusive=True, group="scan")
    def scan(self, path: Path) -> None:
        """Series in ``path`` (headers only). A newer scan (the user moved on) or closing the
        screen cancels this one between headers: a large tree is not read to the end."""
        worker = get_current_worker()
        self.post_message(Note(f"Scanning {path} ..."))

        def progress(done: float, total: float, message: str = "") -> None:
            if worker.is_cancelled:
                raise Cancelled()
            self.post_message(Note(f"Scanning {path}: {message} {done:g}/{total:g}"))

        try:
            found = loaders.scan(str(path), progress=progress)
            err = None
        except Cancelled:
            return
        except Exception as exc:  # unreadable folder, loader error: a reason, not a traceback
            found, err = [], str(exc)
        if not worker.is_cancelled:
            self.post_message(SeriesFound(path, found, err))

    def on_note(self, msg: Note) -> None:
        self._status(msg.text)

    def _status(self, text: str) -> None:
        self.query_one("#op-status", Label).update(text)

    def on_series_found(self, msg: SeriesFound) -> None:
        path, found, err = msg.path, msg.found, msg.error
        self.current = path
        self.series = list(found or [])
        ol = self.query_one("#op-series", OptionList)
        ol.clear_options()
        if err:
            self._status(f"[red]{err}[/red]")
            return
        if not self.series:
            self._status(f"No series in {path.name or path}")
            return
        self._status(f"{len(self.series)} series in {path.name or path} (Enter opens)")
        for i, s in enumerate(self.series):
            ol.add_option(Option(Text(describe_series(s)), id=str(i)))

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        if self.current is None:
            return
        s = self.series[int(event.option.id or 0)]  # every option has its index as id
        uid = s.get("uid") if len(self.series) > 1 else None
        self.dismiss((str(self.current), uid))

    def action_cancel(self) -> None:
        self.dismiss(None)
