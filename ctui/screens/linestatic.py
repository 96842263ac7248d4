"""LineStatic: a Static that repaints only the lines of its text that changed.

The side panel is rewritten on every slice step and brush dab, yet only a few of its ~45 lines
change (the slice, the cursor, the value, an object's area). Static repaints them all (Textual's
per-line styling, padding and filters: most of the panel's cost). Given rich Text with as many
lines as before, each on as many rows as before (a line wider than the panel wraps: its rows are
counted as Textual wraps it), :meth:`update` marks only the changed lines' rows dirty; anything
else takes Static's own full update. What is drawn is the same: the unchanged rows' strips are
those Textual made for the same text.
"""

from __future__ import annotations

from rich.text import Text
from textual.content import Content
from textual.geometry import Region
from textual.visual import VisualType, visualize
from textual.widgets import Static


_WRAPPED: dict[tuple, int] = {}  # (line key, width) -> rows of a line wider than the width


def text_rows(content: object, width: int) -> list[tuple[tuple, int]] | None:
    """(key: the line's text and styles, rows it takes) per line of ``content``, or None when it is
    not rich Text."""
    if not isinstance(content, Text) or width <= 0:
        return None
    rows = []
    for line in content.split("\n", allow_blank=True):
        key = (line.plain, tuple(line.spans), str(line.style))
        n = 1
        if line.cell_len > width:  # wrapped as Static wraps it
            n = _WRAPPED.get((key, width), 0)
            if not n:
                if len(_WRAPPED) > 1000:
                    _WRAPPED.clear()
                n = _WRAPPED[(key, width)] = max(len(Content.from_rich_text(line).wrap(width)), 1)
        rows.append((key, n))
    return rows


class LineStatic(Static):
    """A Static whose :meth:`update` with ``layout=False`` repaints only the rows that changed."""

    _rows: list[tuple] | None = None

    def update(self, content: VisualType = "", *, layout: bool = True) -> None:
        old, self._rows = self._rows, text_rows(content, self.content_size.width)
        private = hasattr(self, "_Static__content") and hasattr(self, "_Static__visual")
        if layout or not private or not self.is_mounted or old is None or self._rows is None \
                or len(old) != len(self._rows):
            super().update(content, layout=layout)
            return
        if any(a[1] != b[1] for a, b in zip(old, self._rows)):  # a line now on more or fewer rows
            super().update(content, layout=layout)
            return
        regions, y, width = [], 0, self.content_size.width
        for (was, n), (now, _) in zip(old, self._rows):
            if was != now:
                regions.append(Region(0, y, width, n))
            y += n
        self._Static__content = content  # what Static.update sets, without repainting every row
        self._Static__visual = visualize(self, content, markup=self._render_markup)
        if regions:
            self.refresh(*regions)
