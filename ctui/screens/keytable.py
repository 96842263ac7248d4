"""Key tables: a screen's keys written as rows of text, one binding a row.

A row has three or four columns separated by two or more spaces::

    keys                action               description            flags
    left,h              move(-1,0)           Cursor left            hidden
    tab                 cycle_object         Next object            hidden priority
    pageup              slice(1)             Slice +1

``keys`` and ``action`` are Textual's (comma-separated key names; an action with its
arguments); ``description`` is what the key bar and the ``?`` help show; ``flags`` is
empty or any of ``hidden`` (not in the key bar, still in the help) and ``priority``
(the key wins over the focused widget). Blank lines and lines starting with ``#`` are
skipped.
"""

from __future__ import annotations

import re

from textual.binding import Binding, BindingType

_COLUMNS = re.compile(r"\s{2,}")
_FLAGS = {"hidden", "priority"}


def keys(table: str) -> list[BindingType]:
    """The bindings of a key table (see the module's docstring), in the table's order.

    Raises ValueError naming the row when a row has fewer than three columns or an
    unknown flag (a typing error in the source, found at import)."""
    out: list[BindingType] = []
    for row in table.splitlines():
        row = row.strip()
        if not row or row.startswith("#"):
            continue
        cols = _COLUMNS.split(row)
        if not 3 <= len(cols) <= 4:
            raise ValueError(f"key table row needs keys, action, description [, flags]: {row!r}")
        flags = set(cols[3].split()) if len(cols) == 4 else set()
        if flags - _FLAGS:
            raise ValueError(f"key table row has unknown flags {sorted(flags - _FLAGS)}: {row!r}")
        out.append(Binding(cols[0], cols[1], cols[2], show="hidden" not in flags, priority="priority" in flags))
    return out
