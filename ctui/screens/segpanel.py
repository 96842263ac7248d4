"""The segmentation panel (``G``): every option of ``ctui segment`` for the TUI's seeds.

The panel edits ``Session.segment_options`` (a dict of :class:`SegmentOptions` fields plus
``range``); :func:`options_for` turns it, the session's mode, slice limits, ROI box and
background seeds into the same ``SegmentOptions`` and thresholds the CLI builds from its
flags, so ``S``/``p`` in the TUI and ``ctui segment`` give the same mask for the same seed.
The method list is the engine's registry (``actions.segment.METHODS``).
"""

from __future__ import annotations

from typing import Any

from textual.app import ComposeResult
from textual import events
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Button, Checkbox, Input, Label, Select

from ctui.engine.actions.segment import METHODS, SegmentOptions
from ctui.engine.core.errors import CtuiError
from ctui.screens.session import Session
from ctui.screens.ws_state import describe  # noqa: F401 - the panel's one-line summary, read with the panel


def options_for(session: Session, direction: str = "both") -> tuple[SegmentOptions, list]:
    """(SegmentOptions, thresholds) for the session: the panel's choices, the propagation mode (``m`` in the
    panel), the slice limits (``i``), the ROI box and the background seeds' owner is the caller."""
    o = session.segment_options
    rng = o.get("range", "given")
    if rng == "given" and session.range_ is not None:  # the range the user typed (T); Enter's default
        th: list = [tuple(session.range_)]          # tolerance is no choice of theirs, so it does not count
    elif rng in ("auto", "given"):  # nothing given: from the seed's neighbourhood
        th = [None]
    else:
        th = [rng]
    lim = session.limits.slices
    opts = SegmentOptions(method=o.get("method", "fill"), mode=session.prop_mode, direction=direction,
                          connectivity=int(session.connectivity), neck_mm=o.get("neck"),
                          fill_holes=bool(o.get("fill_holes", True)), box=session.roi_box,
                          slices=None if lim is None else (int(lim[0]), int(lim[1])),
                          keep_largest=bool(o.get("keep_largest", False)), min_island=int(o.get("min_island", 0)),
                          interpolate=bool(o.get("interpolate", False)))
    return opts, th


class Tick(Checkbox):
    """A checkbox whose unchecked box is empty (Textual draws a dim X there, read as "on")."""

    @property
    def BUTTON_INNER(self) -> str:  # type: ignore[override]  # Textual reads the class attribute per render
        return "X" if self.value else " "


class SegmentPanel(ModalScreen):
    """Method, mode, neck, range, holes and clean-ups; Enter or Apply keeps them, Escape cancels."""

    DEFAULT_CSS = """
    SegmentPanel { align: center middle; }
    SegmentPanel > Vertical { width: 72; max-width: 100%; height: auto; max-height: 100%; border: round $accent;
                              padding: 0 1; background: $panel; }
    SegmentPanel #fields { height: auto; }
    SegmentPanel #buttons { height: 3; }
    SegmentPanel Horizontal { height: auto; }
    SegmentPanel Label { width: 18; padding: 1 0 0 0; }
    SegmentPanel Input, SegmentPanel Select { width: 1fr; }
    SegmentPanel .hint { width: 1fr; color: $text-muted; padding: 0; }
    """
    BINDINGS = [("escape", "dismiss_panel", "Cancel")]

    def __init__(self, session: Any) -> None:
        super().__init__()
        self.s = session

    def compose(self) -> ComposeResult:
        o = dict(self.s.segment_options)
        rng = o.get("range", "given")
        rtxt = rng if isinstance(rng, str) else f"{rng[0]:g}:{rng[1]:g}"
        neck = o.get("neck")
        with Vertical():
            yield Label("Segmentation (S segments from the cursor, p from the object's seed)", classes="hint")
            with VerticalScroll(id="fields"):  # scrolls on a small terminal; the buttons stay in view
                yield from self._fields(o, rtxt, neck)
            with Horizontal(id="buttons"):
                yield Button("Apply", id="apply", variant="primary")
                yield Button("Cancel", id="cancel")

    def _fields(self, o: dict, rtxt: str, neck) -> ComposeResult:
        with Horizontal():
            yield Label("Method")
            yield Select([(m, m) for m in METHODS], value=o.get("method") if o.get("method") in METHODS else "fill",
                   allow_blank=False, id="method")
        with Horizontal():
            yield Label("Mode")
            yield Select([("slice by slice", "slice"), ("3D", "3d")], value=self.s.prop_mode, allow_blank=False,
                         id="mode")
        with Horizontal():
            yield Label("Neck (mm|auto)")
            yield Input("auto" if neck is None else f"{neck:g}", id="neck", placeholder="auto, 0 (off) or mm")
        with Horizontal():
            yield Label("Range")
            yield Input(rtxt, id="range", placeholder="given (the range typed with T; else auto), auto, or LO:HI")
        with Horizontal():
            yield Label("Min island (vox)")
            yield Input(str(int(o.get("min_island", 0))), id="min_island", placeholder="0 = keep all")
        yield Tick("Fill holes inside the object", value=bool(o.get("fill_holes", True)), id="fill_holes")
        yield Tick("Keep the largest 3D island", value=bool(o.get("keep_largest", False)), id="keep_largest")
        yield Tick("Fill between key slices", value=bool(o.get("interpolate", False)), id="interpolate")
        yield Label("Fields are pre-filled: Ctrl+U clears one. Enter applies, Escape cancels.", classes="hint")

    def on_resize(self, event: events.Resize) -> None:
        """The fields get what the screen leaves once the title line, the buttons and the border are in."""
        self.query_one("#fields").styles.max_height = max(event.size.height - 6, 3)

    def on_mount(self) -> None:
        self.query_one("#fields").styles.max_height = max(self.app.size.height - 6, 3)
        self.query_one("#method", Select).focus()  # the first field, not the scrolling box around the fields

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "apply":
            self._apply()
        else:
            self.dismiss(False)

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self._apply()

    def action_dismiss_panel(self) -> None:
        self.dismiss(False)

    def _apply(self) -> None:
        try:
            opts = parse_panel(self.query_one("#neck", Input).value, self.query_one("#range", Input).value,
                               self.query_one("#min_island", Input).value)
        except CtuiError as exc:
            self.app.notify(str(exc), severity="error")
            return
        opts["method"] = self.query_one("#method", Select).value
        for key in ("fill_holes", "keep_largest", "interpolate"):
            opts[key] = bool(self.query_one(f"#{key}", Checkbox).value)
        self.s.segment_options = opts
        self.s.prop_mode = str(self.query_one("#mode", Select).value)
        self.dismiss(True)


def parse_panel(neck: str, rng: str, min_island: str) -> dict[str, Any]:
    """The panel's text fields as options; CtuiError with a one-line message when one is wrong."""
    out: dict[str, Any] = {}
    n = neck.strip().lower()
    if n in ("", "auto"):
        out["neck"] = None
    else:
        try:
            out["neck"] = float(n)
        except ValueError:
            raise CtuiError(f"neck {neck!r}: give auto, 0 (off) or a width in mm") from None
        if not 0 <= out["neck"] <= 1000:
            raise CtuiError(f"neck {neck!r}: give a width from 0 to 1000 mm")
    r = rng.strip().lower()
    if r in ("", "auto", "given"):
        out["range"] = r or "given"
    else:
        lo, sep, hi = r.partition(":")
        try:
            a, b = float(lo), float(hi)
            if not sep:
                raise ValueError
        except ValueError:
            raise CtuiError(f"range {rng!r}: give auto, given, or LO:HI") from None
        out["range"] = (min(a, b), max(a, b))
    try:
        out["min_island"] = max(0, int(min_island.strip() or 0))
    except ValueError:
        raise CtuiError(f"min island {min_island!r}: give a whole number of voxels") from None
    return out
