"""The review strip: a one-line sparkline of a pending proposal's area per slice under the
main view, with the slice cursor, the seed slice and the slices marked by
:func:`ctui.engine.segment.review.marks` (the area jumps or the centre moves), and a
second line of markers. A click on it goes to that slice (to the marked slice when the
column holds one); ``{`` / ``}`` jump between marks (``ctui.screens.ws_mouse``). A leak's entry slice
(:mod:`ctui.engine.segment.leaks`) is marked ``L``. The slice limits (a drag along the strip sets them) are
bracketed ``[`` ``]`` on the markers' line, the bars outside them dimmed."""

from __future__ import annotations

import numpy as np
from rich.segment import Segment
from rich.style import Style
from textual.strip import Strip
from textual.widget import Widget

BARS = " ▁▂▃▄▅▆▇█"
_BAR = Style(color="rgb(120,200,255)", bgcolor="rgb(20,20,30)")
_MARK = Style(color="rgb(255,80,80)", bgcolor="rgb(20,20,30)", bold=True)
_SEED = Style(color="rgb(80,230,80)", bgcolor="rgb(20,20,30)")
_CURSOR = Style(color="black", bgcolor="rgb(255,230,0)")
_DIM = Style(color="rgb(150,150,150)", bgcolor="rgb(20,20,30)")
_OUT = Style(color="rgb(70,70,80)", bgcolor="rgb(20,20,30)")  # a bar outside the slice limits
_LIMIT = Style(color="rgb(255,200,0)", bgcolor="rgb(20,20,30)", bold=True)  # the limits' brackets


def columns(nz: int, width: int) -> list[tuple[int, int]]:
    """The slices (first, last inclusive) each column of a strip ``width`` cells wide
    shows: one slice per column (several columns per slice when they fit), or several
    slices per column when there are more slices than columns."""
    width = max(int(width), 1)
    if nz <= 0:
        return []
    if nz <= width:
        k = width // nz
        return [(c // k, c // k) for c in range(nz * k)]
    m = -(-nz // width)  # slices per column, rounded up
    return [(c * m, min((c + 1) * m, nz) - 1) for c in range(-(-nz // m))]


def bars(profile: np.ndarray, cols: list[tuple[int, int]]) -> list[int]:
    """Bar heights 0..8 per column (the column's largest area over the largest area)."""
    if not cols:
        return []
    vals = np.array([int(profile[a:b + 1].max()) for a, b in cols], np.float64)
    top = vals.max()
    if top <= 0:
        return [0] * len(cols)
    h = np.ceil(vals / top * 8).astype(int)
    return [int(v) for v in h]


def fitted(text: str, room: int) -> str:
    """``text`` or a shorter form of it that fits ``room`` cells, never a word cut in half: "proposal · 2 marks:
    } { marks, C cut, A accept to here" -> "2 marks: } { marks, C cut, A accept to here" -> "2 marks: } {
    marks" -> "2 marks"; "slice 16: 8242 px" -> "16: 8242 px" -> "8242 px"."""
    forms = [text]
    if " · " in text:
        forms.append(text.split(" · ", 1)[1])
    last = forms[-1]
    if "," in last:
        forms.append(last.split(",", 1)[0])
    if ":" in last:
        head, tail = last.split(":", 1)
        forms += [head.removeprefix("slice ") + ":" + tail, head] if head.startswith("slice ") else [head]
        if tail.strip().endswith(" px"):
            forms.append(tail.strip())
    for f in forms:
        if len(f) <= room:
            return f
    return ""


class ReviewStrip(Widget):
    """Two lines: the sparkline and the markers (``▲`` the slice, ``s`` the seed, ``!`` a mark, ``L`` where a
    leak enters, ``[`` ``]`` the slice limits' first and last slices; the bars outside the limits dimmed)."""

    DEFAULT_CSS = """
    ReviewStrip { height: 2; width: 1fr; display: none; }
    ReviewStrip.on { display: block; }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.profile: np.ndarray | None = None
        self.marked: set[int] = set()
        self.leaked: set[int] = set()
        self.cursor = 0
        self.seed: int | None = None
        self.hint = ""
        self.limits: tuple[int, int] | None = None

    def set_data(self, profile: np.ndarray | None, marked, cursor: int, seed: int | None, hint: str = "",
                 leaked=(), limits: tuple[int, int] | None = None) -> None:
        """``hint``: a short text drawn right of the bars when it fits (e.g. the keys); ``leaked``: the marked
        slices where a leak enters; ``limits``: the slice limits (first, last inclusive) or None."""
        marked, leaked = set(int(z) for z in marked), {int(z) for z in leaked}
        same_profile = (profile is None and self.profile is None) or (
            profile is not None and self.profile is not None and np.array_equal(profile, self.profile))
        limits = None if limits is None else (int(limits[0]), int(limits[1]))
        if same_profile and (marked, leaked, int(cursor), seed, hint, limits) == (
                self.marked, self.leaked, self.cursor, self.seed, self.hint, self.limits):
            return  # nothing new to draw (the side panel updated for another reason): no repaint
        self.profile = None if profile is None else np.array(profile)  # a copy: compared with the next call's
        self.marked = marked
        self.leaked = leaked
        self.cursor = int(cursor)
        self.seed = seed
        self.hint = hint
        self.limits = limits
        self.refresh()

    def _cols(self) -> list[tuple[int, int]]:
        """The bars' columns: the width less room for the text on the right (on 64 columns or more)."""
        if self.profile is None:
            return []
        w = self.size.width
        return columns(len(self.profile), w - 34 if w >= 64 else w)

    def slice_at(self, col: int, *, clamp: bool = False) -> int | None:
        """The slice a click on column ``col`` goes to (a marked slice in it first); ``clamp``:
        a column beyond the bars gives the first or last bar's (a drag that ran past them)."""
        cols = self._cols()
        if clamp and cols:
            col = min(max(col, 0), len(cols) - 1)
        if not 0 <= col < len(cols):
            return None
        a, b = cols[col]
        inside = sorted(z for z in self.marked if a <= z <= b)
        return inside[0] if inside else (a + b) // 2

    def _inside(self, a: int, b: int) -> bool:
        """Whether slices ``a``..``b`` (a column) reach inside the slice limits (no limits: all do)."""
        lim = self.limits
        return lim is None or (a <= lim[1] and b >= lim[0])

    def _edge(self, a: int, b: int) -> str:
        """``[`` on the column holding the limits' first slice, ``]`` on the last's (``|`` both), else ""."""
        lim = self.limits
        if lim is None:
            return ""
        lo, hi = a <= lim[0] <= b, a <= lim[1] <= b
        return "|" if lo and hi else "[" if lo else "]" if hi else ""

    def render_line(self, y: int) -> Strip:
        cols = self._cols()
        width = self.size.width
        if not cols or y > 1 or self.profile is None:
            return Strip.blank(width)
        segs = []
        profile = self.profile
        if y == 0:
            for (a, b), h in zip(cols, bars(profile, cols)):
                style = _CURSOR if a <= self.cursor <= b else (_MARK if any(a <= z <= b for z in self.marked) else
                                                               _BAR if self._inside(a, b) else _OUT)
                segs.append(Segment(BARS[h], style))
        else:
            for a, b in cols:
                edge, here = self._edge(a, b), a <= self.cursor <= b
                if edge:  # a limit on the cursor's column: the bracket, in the cursor's colours
                    segs.append(Segment(edge, _CURSOR if here else _LIMIT))
                elif here:
                    segs.append(Segment("▲", _CURSOR))
                elif any(a <= z <= b for z in self.marked):
                    segs.append(Segment("L" if any(a <= z <= b for z in self.leaked) else "!", _MARK))
                elif self.seed is not None and a <= self.seed <= b:
                    segs.append(Segment("s", _SEED))
                else:
                    segs.append(Segment(" ", _DIM))
        free = width - len(segs) - 2
        text = self.hint if y == 1 else (f"slice {self.cursor}: {int(profile[self.cursor])} px"
                                         if 0 <= self.cursor < len(profile) else "")
        text = fitted(text, free)
        if text and free >= 5:
            segs.append(Segment("  " + text, _DIM))
        strip = Strip(segs)
        return strip.extend_cell_length(width, _DIM).crop(0, width)
