"""The loading screen: a progress bar while a series loads, the series' middle slice as soon
as it is read (a :class:`PreviewReady` from the load worker, before the rest of the series),
or the reasons it could not load (with downsampling and cropping offered when it does not
fit in memory). Esc cancels a load (back to the workspace below, if any)."""

from __future__ import annotations

from typing import Any

import numpy as np
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.message import Message
from textual.screen import Screen
from textual.widgets import Footer, Label, ProgressBar, Static

from ctui.screens.guard import GuardMixin
from ctui.screens.messages import JobProgress


class PreviewReady(Message):
    """The load worker read the middle slice (``preview``: an ``actions.series.Preview``) of
    ``path``; ``labels``: that slice of a project's objects (y, x) uint8, or None."""

    def __init__(self, path: Any, preview: Any, labels: np.ndarray | None = None) -> None:
        super().__init__()
        self.path = path
        self.preview = preview
        self.labels = labels


def preview_image(pv: Any, labels: np.ndarray | None = None) -> tuple[np.ndarray, Any, str]:
    """(image, plane view, plane) of a preview slice as the workspace draws that slice: the
    file's slice plane in the patient's frame (``screens.planes``), the volume's window,
    a project's objects over it."""
    from ctui.engine.core.windows import apply_window
    from ctui.screens import planes  # with the image: the first text on screen does not wait for OpenCV

    vol = pv.volume
    plane = planes.slice_plane(vol)
    view = planes.plane_view(vol, plane)
    gray = apply_window(planes.take(vol.data, view, 0), vol.window)
    lab = None if labels is None else planes.orient(labels, view)
    return planes.compose(gray, lab), view, plane


class LoadingScreen(GuardMixin, Screen):
    """Shown while a series loads (progress bar, then its middle slice), or the reasons it
    could not load."""

    DEFAULT_CSS = """
    LoadingScreen { align: center middle; }
    LoadingScreen > Vertical { width: 80%; height: auto; border: round $accent; padding: 1 2; }
    LoadingScreen > Vertical.preview { width: 100%; height: 1fr; border: none; padding: 0 1; }
    LoadingScreen #load-title { width: 1fr; }  /* a long path wraps instead of running off the box (80x24) */
    LoadingScreen ProgressBar { margin: 1 0; }
    LoadingScreen > Vertical.preview ProgressBar { margin: 0; }
    """
    BINDINGS = [
        Binding("o", "app.open", "Open another"),
        Binding("d", "reduced(2)", "Downsample x2", show=False),
        Binding("D", "reduced(4)", "Downsample x4", show=False),
        Binding("c", "crop", "Crop", show=False),
        Binding("escape", "back", "Cancel / back"),
        Binding("q", "app.quit", "Quit"),
    ]

    def __init__(self, what: str) -> None:
        super().__init__()
        self.what = what
        self.too_big = False  # the series would not fit in memory: offer downsampling/cropping
        self.path: str | None = None
        self.options: dict = {}
        self.preview = None  # the Preview on screen (its z is where the workspace opens)
        self.reading = True  # a load worker is running (Esc cancels it)

    def action_reduced(self, factor: int) -> None:
        if not self.too_big:
            return
        opts = {**self.options, "downsample": int(factor)}
        self.reading = True
        self.app.load_worker(self.path, opts)  # type: ignore[attr-defined]  # CtuiApp's (app.py imports this screen)
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
            self.reading = True
            self.app.load_worker(self.path, {**self.options, "crop": crop})  # type: ignore[attr-defined]  # as above
            self.query_one("#load-progress").display = True

        self.app.push_screen(PromptScreen("Crop z0,z1,y0,y1,x0,x1 (voxel indices)", ""), done)

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(f"Loading [b]{self.what}[/b] ...", id="load-title")
            yield ProgressBar(total=None, id="load-progress", show_eta=False)
            yield Static("", id="load-reasons")
        yield Footer()

    def action_back(self) -> None:
        if self.reading:
            self.app.cancel_load()  # type: ignore[attr-defined]  # CtuiApp's (app.py imports this screen)
            self._hide_preview()
            self.query_one("#load-progress").display = False
            self.query_one("#load-title", Label).update(f"Loading [b]{self.what}[/b] cancelled")
            self.query_one("#load-reasons", Static).update("[dim]o opens another path, q quits[/dim]")
        if len(self.app.screen_stack) > 2:
            self.app.pop_screen()

    def _hide_preview(self) -> None:
        """No load running any more (cancelled, failed): the preview and its caption go."""
        self.reading = False
        self.query_one(Vertical).remove_class("preview")
        for w in self.query("#load-preview, #load-caption"):
            w.display = False

    def show_preview(self, msg: PreviewReady) -> None:
        """The preview slice above the progress bar, captioned like the workspace's view."""
        from ctui.screens.imageview import ImageView  # with the first image, not the first text

        pv = msg.preview
        img, view, plane = preview_image(pv, msg.labels)
        box = self.query_one(Vertical)
        box.add_class("preview")
        if not self.query("#load-preview"):
            box.mount(Label("", id="load-caption", classes="cell-label"), before=self.query_one("#load-progress"))
            box.mount(ImageView(id="load-preview"), before=self.query_one("#load-progress"))
        self.preview = pv
        left, right, top, bottom = view.letters
        self.query_one("#load-caption", Label).update(
            f"{plane} z {pv.z}/{pv.depth - 1}  [b]{left}[/b]◀▶[b]{right}[/b]  [b]{top}[/b]▲▼[b]{bottom}[/b]  "
            f"[dim]preview: reading the other {pv.depth - 1} slices, Esc cancels[/dim]")
        self.query_one("#load-preview", ImageView).set_image(img, token=("preview", pv.z), spacing_yx=view.spacing_yx)

    def on_job_progress(self, msg: JobProgress) -> None:
        if msg.total:
            self.query_one("#load-progress", ProgressBar).update(total=msg.total, progress=msg.done)

    def show_error(self, title: str, reasons: list[str]) -> None:
        self._hide_preview()
        self.query_one("#load-title", Label).update(f"[b red]{title}[/b red]")
        self.query_one("#load-progress").display = False
        body = "\n".join(f"• {r}" for r in reasons) + "\n\n[dim]o opens another path, q quits[/dim]"
        self.query_one("#load-reasons", Static).update(body)
