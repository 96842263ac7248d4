"""KeyBar: the footer of the slice workspace. Lists the main keys (bindings with
``show=True``) as "key action" pairs and wraps them onto a second (third) line when the
terminal is narrow, so at 80x24 every pair is readable in full (Textual's Footer cuts the
last ones off: "t Edit to")."""

from __future__ import annotations

from textual.binding import Binding
from textual.widgets import Static

from ctui.screens.keyhelp import _esc, bold_key, key_name


def shown_keys(nodes) -> list[tuple[str, str]]:
    """(key as people write it, description) of the ``show=True`` bindings of ``nodes``
    (the screen, then the app), first key of each binding."""
    out, seen = [], set()
    for node in nodes:
        for b in getattr(node, "BINDINGS", []):
            if not isinstance(b, Binding) or not b.show or (b.key, b.action) in seen:
                continue
            seen.add((b.key, b.action))
            out.append((key_name(b.key.split(",")[0]), b.description or b.action))
    return out


def wrap_pairs(pairs: list[tuple[str, str]], width: int) -> list[list[tuple[str, str]]]:
    """Greedy lines of "key desc" pairs two spaces apart, never splitting a pair
    (a pair longer than the line gets a line of its own)."""
    lines: list[list[tuple[str, str]]] = []
    cur: list[tuple[str, str]] = []
    used = 0
    for key, desc in pairs:
        n = len(key) + 1 + len(desc)
        if cur and used + 2 + n > width:
            lines.append(cur)
            cur, used = [], 0
        used += n + (2 if cur else 0)
        cur.append((key, desc))
    if cur:
        lines.append(cur)
    return lines


class KeyBar(Static):
    """The main keys of the screen it is on, wrapped to the width (height follows)."""

    DEFAULT_CSS = """
    KeyBar { height: auto; max-height: 3; background: $panel; color: $text; padding: 0 1; }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__("", id=id, markup=True)
        self._width = -1

    def on_mount(self) -> None:
        self._fill()

    def on_resize(self) -> None:
        self._fill()

    def _fill(self) -> None:
        width = max(self.size.width - 2, 20) if self.size.width else max(self.app.size.width - 2, 20)
        if width == self._width:
            return
        self._width = width
        pairs = shown_keys((self.screen, self.app))
        text = "\n".join("  ".join(f"{bold_key(k)} {_esc(d)}" for k, d in line)
                          for line in wrap_pairs(pairs, width))
        self.update(text)
