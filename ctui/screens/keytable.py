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

``keys(table, via="do")`` routes every row through one parametrised action of the screen:
``move(-1,0)`` becomes ``do('move', (-1, 0))``, so the workspace has one Textual action that
runs its owners' actions by name (:mod:`ctui.screens.ws_host`). :func:`action_name` reads the
routed action's name back ("move"), for the help and the command palette.
"""

from __future__ import annotations

import re

from textual.actions import parse
from textual.binding import Binding, BindingType

_COLUMNS = re.compile(r"\s{2,}")
_FLAGS = {"hidden", "priority"}


def routed(action: str, via: str) -> str:
    """``action`` ("move(-1,0)") as an argument of the action ``via``: "do('move', (-1, 0))"."""
    _ns, name, params = parse(action)
    return f"{via}({name!r}, {tuple(params)!r})" if params else f"{via}({name!r})"


def action_name(action: str) -> str:
    """The name of a binding's action without its arguments: "propagate('both')" -> "propagate",
    and of a routed one, "do('propagate', ('both',))" -> "propagate"."""
    _ns, name, params = parse(action)
    if name == "do" and params and isinstance(params[0], str):
        return params[0]
    return name


def keys(table: str, *, via: str | None = None) -> list[BindingType]:
    """The bindings of a key table (see the module's docstring), in the table's order; ``via``:
    each row's action routed through that action (module docstring).

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
        action = cols[1] if via is None else routed(cols[1], via)
        out.append(Binding(cols[0], action, cols[2], show="hidden" not in flags, priority="priority" in flags))
    return out
