"""The loading screen: a progress bar while a series loads, or the reasons it could not
load (with downsampling and cropping offered when it does not fit in memory)."""

from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import Screen
from textual.widgets import Footer, Label, ProgressBar, Static

from ctui.screens.guard import GuardMixin
from ctui.screens.messages import JobProgress


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

    def on_job_progress(self, msg: JobProgress) -> None:
        if msg.total:
            self.query_one("#load-progress", ProgressBar).update(total=msg.total, progress=msg.done)

    def show_error(self, title: str, reasons: list[str]) -> None:
        self.query_one("#load-title", Label).update(f"[b red]{title}[/b red]")
        self.query_one("#load-progress").display = False
        body = "\n".join(f"• {r}" for r in reasons) + "\n\n[dim]o opens another path, q quits[/dim]"
        self.query_one("#load-reasons", Static).update(body)
