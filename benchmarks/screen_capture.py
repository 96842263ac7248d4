"""The TUI's screen as a person sees it, from a running Pilot app: its text (the characters of every cell,
dialogs over the dimmed workspace included) and, on request, an SVG and a PNG of it (CairoSVG), to look at;
and the check that a dialog's buttons and controls are inside the screen and drawn on it.

    text = capture(app, "80x24-export", out_dir)   # out_dir None: the text only
    problems = dialog_problems(app, text)         # [] when every button is in view
"""

from __future__ import annotations

import io
from pathlib import Path


def capture(app, name: str, out_dir: Path | None = None) -> str:
    """The screen's text, one line per row; with ``out_dir``, ``<name>.svg`` and ``<name>.png`` written there."""
    from rich.console import Console

    width, height = app.size
    console = Console(width=width, height=height, file=io.StringIO(), force_terminal=True, color_system="truecolor",
                      record=True, legacy_windows=False, safe_box=False)
    console.print(app.screen._compositor.render_update(full=True, screen_stack=app._background_screens))
    text = console.export_text(clear=False)
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        svg = console.export_svg(title=name)
        (out_dir / f"{name}.svg").write_text(svg)
        try:
            import cairosvg
        except ImportError:  # the SVG is there to look at
            return text
        # Rich names Fira Code (a web font): a local monospace font keeps the cells in their columns
        mono = svg.replace('"Fira Code"', '"DejaVu Sans Mono"').replace("Fira Code, monospace", "DejaVu Sans Mono, monospace")
        cairosvg.svg2png(bytestring=mono.encode(), write_to=str(out_dir / f"{name}.png"))
    return text


def dialog_problems(app, text: str) -> list[str]:
    """What a person could not reach on the dialog shown (the app's top screen): each Button and OptionList must
    lie inside the screen and each button's label be drawn (in ``text``, the capture); a prompt's one Input must
    be inside with the focus (the fields of a form that scrolls, as ``G``'s, are reached by scrolling)."""
    from textual.widgets import Button, Input, OptionList

    width, height = app.size
    out = []
    inputs = [w for w in app.screen.query(Input) if w.display]
    for w in [*app.screen.query("Button, OptionList"), *(inputs if len(inputs) == 1 else [])]:
        if not w.display:
            continue
        r = w.region
        if r.height <= 0 or r.width <= 0 or r.bottom > height or r.right > width or r.x < 0 or r.y < 0:
            out.append(f"{type(w).__name__} {w.id or ''} at {tuple(r)} is outside the {width}x{height} screen")
        if isinstance(w, Button) and str(w.label).strip() not in text:
            out.append(f"button {str(w.label)!r} is not drawn")
        if isinstance(w, OptionList) and w.highlighted is not None and w.option_count:
            label = str(w.get_option_at_index(w.highlighted).prompt).strip()[:20]
            if label and label not in text:
                out.append(f"the highlighted option {label!r} is not drawn")
        if isinstance(w, Input) and not w.has_focus:
            out.append(f"input {w.id or ''} has not the focus")
    return out
