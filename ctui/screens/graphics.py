"""Terminal graphics: choose how images reach the terminal, before Textual starts.

Modes
-----
``halfblock``
    ctui's own numpy-to-cells renderer (U+2580 with truecolor fg/bg: two pixel rows
    per cell). The default in tmux, over SSH and whenever nothing better is detected.
``ascii``
    a character ramp without colour, for terminals without Unicode or colour.
``sixel`` / ``kitty``
    textual-image's SixelImage / TGPImage widgets (pixel-exact images).
``auto``
    textual-image's detection (a 0.1 s terminal query); half-block when it finds
    neither sixel nor kitty graphics.

``--graphics`` and ``CTUI_GRAPHICS`` override the detection (it can time out over slow
SSH and silently fall back). :func:`prepare_graphics` must run *before* the app starts:
textual-image queries the terminal on import, which no longer works once Textual
owns stdin.
"""

from __future__ import annotations

import os
import sys

MODES = ("auto", "sixel", "kitty", "halfblock", "ascii")

_chosen: str | None = None
_cell_px: tuple[int, int] = (10, 20)


def prepare_graphics(mode: str | None = None) -> str:
    """Resolve the graphics mode (argument, else ``CTUI_GRAPHICS``, else ``auto``).

    Imports textual-image only for modes that need it (auto, sixel, kitty) so its
    terminal query happens now, before Textual takes over the terminal. Returns one
    of ``sixel``, ``kitty``, ``halfblock``, ``ascii``.
    """
    global _chosen, _cell_px
    mode = (mode or os.environ.get("CTUI_GRAPHICS") or "auto").strip().lower()
    aliases = {"half": "halfblock", "halfcell": "halfblock", "tgp": "kitty", "text": "ascii"}
    mode = aliases.get(mode, mode)
    if mode not in MODES:
        raise ValueError(f"unknown graphics mode {mode!r}; choose one of {', '.join(MODES)}")
    if mode in ("halfblock", "ascii"):
        _chosen = mode
        return mode
    try:
        import textual_image.renderable as tir
        import textual_image.widget  # noqa: F401
        from textual_image._terminal import get_cell_size

        cs = get_cell_size()
        _cell_px = (max(int(cs.width), 1), max(int(cs.height), 1))
    except Exception:  # no terminal, closed stdout...: half-block always works
        _chosen = "halfblock"
        return _chosen
    if mode == "auto":
        from textual_image.renderable.sixel import Image as SixelR
        from textual_image.renderable.tgp import Image as TGPR

        if tir.Image is SixelR:
            mode = "sixel"
        elif tir.Image is TGPR:
            mode = "kitty"
        else:
            mode = "halfblock"
    _chosen = mode
    return mode


def use_graphics(mode: str, *, unless_chosen: bool = False) -> None:
    """Record ``mode`` as the graphics mode without probing the terminal (``unless_chosen``:
    keep a mode :func:`prepare_graphics` already chose)."""
    global _chosen
    if not (unless_chosen and _chosen is not None):
        _chosen = mode


def graphics_mode() -> str:
    """The mode chosen by :func:`prepare_graphics` (``halfblock`` if it never ran)."""
    return _chosen or "halfblock"


def cell_pixels() -> tuple[int, int]:
    """Terminal cell size in pixels (width, height), as textual-image measured it."""
    return _cell_px


def colour_advice(color_system: str | None) -> str | None:
    """A one-time hint when the terminal only gets 256 (or fewer) colours.

    Grey CT slices band visibly in 256 colours; over SSH COLORTERM is usually not
    forwarded, so Rich falls back to 256 colours even on truecolor terminals.
    """
    if color_system in (None, "truecolor", "windows"):
        return None
    over_ssh = bool(os.environ.get("SSH_CONNECTION") or os.environ.get("SSH_TTY"))
    where = "over SSH " if over_ssh else ""
    return (
        f"Terminal {where}reports only {color_system} colours, so grey slices band. "
        "If your terminal does truecolor, start ctui with TEXTUAL_COLOR_SYSTEM=truecolor "
        "(or COLORTERM=truecolor), or add 'SendEnv COLORTERM' to ~/.ssh/config "
        "(and 'AcceptEnv COLORTERM' on the server)."
    )


def is_tty() -> bool:
    return bool(sys.__stdout__ and sys.__stdout__.isatty())
