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
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager

PIXEL_MODES = ("sixel", "kitty")  # images drawn by the terminal (pixels), not with characters
CELL_MODES = ("halfblock", "ascii")  # images drawn with characters
MODES = ("auto", *PIXEL_MODES, *CELL_MODES)
#: ``ctui web`` sets ``CTUI_WEB=1`` for the TUI it serves to a browser: sixel images (xterm.js draws
#: them; the kitty protocol blanks the page and "auto" finds no tty), at most WEB_MAX_PIXELS
#: (w, h) each (sixel bytes grow with the area), redrawn at most every WEB_DEBOUNCE_S seconds
WEB_ENV = "CTUI_WEB"
WEB_MAX_PIXELS = (1280, 960)
WEB_DEBOUNCE_S = 0.04

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
    if web_mode() and mode in ("auto", "kitty"):
        mode = "sixel"  # in a browser: never kitty, and auto would fall back to half-blocks (no tty)
    if mode in CELL_MODES:
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


def use_graphics(mode: str | None, *, unless_chosen: bool = False) -> str | None:
    """Record ``mode`` as the graphics mode without probing the terminal (``unless_chosen``:
    keep a mode :func:`prepare_graphics` already chose; None: none chosen). Returns the mode
    chosen before, to give back (:func:`using_graphics` does)."""
    global _chosen
    previous = _chosen
    if not (unless_chosen and _chosen is not None):
        _chosen = mode
    return previous


@contextmanager
def using_graphics(mode: str | None) -> Iterator[None]:
    """Use ``mode`` inside the block (a test's fixed renderer), the previous choice after it."""
    previous = use_graphics(mode)
    try:
        yield
    finally:
        use_graphics(previous)


def web_mode(env=None) -> bool:
    """True in the TUI ``ctui web`` serves to a browser."""
    return (os.environ if env is None else env).get(WEB_ENV) == "1"


def pixel_cap() -> tuple[int, int] | None:
    """The largest (w, h) of an image in pixels: :data:`WEB_MAX_PIXELS` in web mode, else None."""
    return WEB_MAX_PIXELS if web_mode() else None


def graphics_mode() -> str:
    """The mode chosen by :func:`prepare_graphics` (``halfblock`` if it never ran)."""
    return _chosen or "halfblock"


def cell_pixels() -> tuple[int, int]:
    """Terminal cell size in pixels (width, height), as textual-image measured it."""
    return _cell_px


#: TERM_PROGRAM values of terminals that always draw 24-bit colour
TRUECOLOR_PROGRAMS = ("iTerm.app", "WezTerm", "vscode", "ghostty", "Hyper", "rio", "Tabby")
TMUX_FIX = "set -ga terminal-overrides ',*:RGB' in ~/.tmux.conf (or start tmux with -T RGB)"


def tmux_rgb(env=None) -> bool | None:
    """Inside tmux: whether tmux passes 24-bit colour to the terminal it is drawn on
    (its client's features name RGB or Tc); None outside tmux or when tmux does not say
    (a detached session, tmux before 3.2)."""
    env = os.environ if env is None else env
    if not env.get("TMUX"):
        return None
    try:
        out = subprocess.run(["tmux", "display-message", "-p", "#{client_termfeatures}"], capture_output=True,
                             text=True, timeout=1.0).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    if not out:
        return None
    feats = {f.strip() for f in out.split(",")}
    return bool(feats & {"RGB", "Tc"})


def truecolor_available(env=None) -> bool:
    """Whether the terminal takes 24-bit colour although COLORTERM does not say so
    (tmux with RGB passed through, or a terminal that always does)."""
    env = os.environ if env is None else env
    if str(env.get("COLORTERM", "")).lower() in ("truecolor", "24bit"):
        return True
    if env.get("TMUX"):
        return bool(tmux_rgb(env))
    return env.get("TERM_PROGRAM", "") in TRUECOLOR_PROGRAMS or str(env.get("TERM", "")).endswith("-direct")


def enable_truecolor() -> bool:
    """Before the app starts: set COLORTERM=truecolor when the terminal takes 24-bit
    colour but does not say so (Rich would fall back to 256 colours and grey slices
    would band). Never overrides TEXTUAL_COLOR_SYSTEM. True when truecolor is on."""
    if os.environ.get("TEXTUAL_COLOR_SYSTEM"):
        return os.environ["TEXTUAL_COLOR_SYSTEM"] == "truecolor"
    if truecolor_available():
        os.environ["COLORTERM"] = "truecolor"
        return True
    return False


def colour_advice(color_system: str | None, env=None) -> str | None:
    """A one-time hint when the terminal really only gets 256 (or fewer) colours.

    Grey CT slices band visibly in 256 colours. Inside tmux the one-line fix is tmux's
    RGB feature (:data:`TMUX_FIX`); over SSH COLORTERM is usually not forwarded.
    """
    env = os.environ if env is None else env
    if color_system in (None, "truecolor", "windows"):
        return None
    over_ssh = bool(env.get("SSH_CONNECTION") or env.get("SSH_TTY"))
    where = "over SSH " if over_ssh else ""
    head = f"Terminal {where}reports only {color_system} colours, so grey slices band. "
    if env.get("TMUX"):
        head += f"Inside tmux: {TMUX_FIX}, then reattach. "
    return head + (
        "If your terminal does truecolor, start ctui with TEXTUAL_COLOR_SYSTEM=truecolor "
        "(or COLORTERM=truecolor)" + (", or add 'SendEnv COLORTERM' to ~/.ssh/config "
                                      "(and 'AcceptEnv COLORTERM' on the server)." if over_ssh or not env.get("TMUX")
                                      else ".")
    )


def is_tty() -> bool:
    return bool(sys.__stdout__ and sys.__stdout__.isatty())
