"""Help by task: the workspace's keys grouped under Segment, Review, Edit, Views, 3D and
measure, Files and Navigate, the main actions first (``?``), and the short key names the
help and the key bar use. The README's Markdown table is :mod:`ctui.screens.help`'s (it
reads the workspace and the app, which import this module: no circle).

Bindings are read from the screens' ``BINDINGS``, so a new key shows up by itself: its
group comes from :data:`ACTION_TASK` (by action name), else from words in its action.
"""

from __future__ import annotations

import itertools

from ctui.screens.keytable import action_name


TASKS = ("Segment", "Review", "Edit", "Views", "3D and measure", "Files", "Navigate", "More")

#: action name (without arguments) -> task, in the order shown within the task
ACTION_TASK: dict[str, str] = {
    # Segment: seed, fill, propagate, the objects
    "fill": "Segment", "propagate": "Segment", "new_object": "Segment", "cycle_object": "Segment",
    "filters": "Segment", "tolerance": "Segment", "range_edit": "Segment", "connectivity": "Segment",
    "prop_mode": "Segment", "limits": "Segment", "stop_slice": "Segment", "rename_object": "Segment",
    "click_fills": "Segment", "background_seed": "Segment", "box_corner": "Segment", "box_clear": "Segment",
    "auto_draft": "Segment",
    # Review: proposals, what the pipeline sees, windows, drift
    "accept": "Review", "reject": "Review", "accept_to_here": "Review", "cut_here": "Review", "mark": "Review",
    "cancel": "Review", "view_cycle": "Review", "grid": "Review",
    "window_cycle": "Review", "window_set": "Review", "drift": "Review",
    # Edit: undo and the hand tools
    "undo": "Edit", "tools": "Edit", "pen": "Edit", "dab": "Edit", "brush_size": "Edit", "edit_mode": "Edit",
    "keep_largest": "Edit", "remove_islands": "Edit", "fill_between": "Edit", "clear_object": "Edit",
    # Views
    "plane": "Views", "ortho": "Views", "zoom": "Views", "pan": "Views", "toggle_panel": "Views",
    # 3D and measure
    "render3d": "3D and measure", "measure": "3D and measure",
    # Files (and the app's own keys)
    "export": "Files", "save": "Files", "open": "Files", "help": "Files", "request_quit": "Files",
    "command_palette": "Files",
    # Navigate
    "move": "Navigate", "slice": "Navigate", "slice_to": "Navigate", "goto": "Navigate",
}

#: words in an unlisted action's name -> its task (keys other screens' authors add)
_GUESS = (
    (("segment", "seg_", "propagat", "object", "tolerance", "threshold"), "Segment"),
    (("island", "box", "scissor", "smooth", "seed", "brush", "erase", "paint", "lasso", "wand", "grow"), "Edit"),
    (("review", "jump", "next", "prev", "flag", "accept", "reject"), "Review"),
    (("view", "plane", "zoom", "pan", "panel", "layout", "window"), "Views"),
    (("render", "3d", "measure", "mesh", "section"), "3D and measure"),
    (("export", "save", "open", "load", "quit"), "Files"),
    (("move", "slice", "cursor", "goto", "scroll"), "Navigate"),
)

_NAMES = {
    "pageup": "PgUp", "pagedown": "PgDn", "enter": "Enter", "space": "Space", "escape": "Esc", "tab": "Tab",
    "delete": "Del", "home": "Home", "end": "End", "left": "←", "right": "→", "up": "↑", "down": "↓",
    "plus": "+", "equals_sign": "=", "minus": "-", "comma": ",", "full_stop": ".", "less_than_sign": "<",
    "greater_than_sign": ">", "left_square_bracket": "[", "right_square_bracket": "]", "question_mark": "?",
    "backslash": "\\", "slash": "/", "left_curly_bracket": "{", "right_curly_bracket": "}", "backspace": "Backspace", "insert": "Ins",
}


def key_name(key: str) -> str:
    """A Textual key ("pageup", "shift+left", "ctrl+s", "equals_sign") as people write it
    ("PgUp", "Shift+←", "Ctrl+S", "=")."""
    parts = key.strip().split("+")
    mods = [p.capitalize() for p in parts[:-1]]
    last = parts[-1]
    name = _NAMES.get(last, last.upper() if mods and len(last) == 1 else last)
    if len(last) > 1 and last.startswith("f") and last[1:].isdigit():
        name = last.upper()
    return "+".join([*mods, name])


def task_of(action: str) -> str:
    """The task group of a binding's action ("propagate('both')" -> "Segment")."""
    base = action_name(action)
    if base in ACTION_TASK:
        return ACTION_TASK[base]
    low = base.lower()
    for words, task in _GUESS:
        if any(w in low for w in words):
            return task
    return "More"


def _bindings(nodes) -> list[tuple[str, str, str]]:
    """(keys, action, description) of every binding of ``nodes`` (screen classes or
    instances, the app), first definition of a (key, action) pair kept."""
    out, seen = [], set()
    for node in nodes:
        for b in getattr(node, "BINDINGS", []):
            key, action, desc = (list(b) + ["", ""])[:3] if isinstance(b, tuple) else (b.key, b.action, b.description)
            if (key, action) in seen:
                continue
            seen.add((key, action))
            out.append((key, action, desc or action))
    return out


def task_rows(nodes) -> list[tuple[str, str, str]]:
    """(task, keys as people write them, description), grouped in :data:`TASKS` order,
    within a task in :data:`ACTION_TASK` order (then as bound)."""
    order = {a: i for i, a in enumerate(ACTION_TASK)}
    rows = []
    for i, (key, action, desc) in enumerate(_bindings(nodes)):
        task = task_of(action)
        keys = " ".join(key_name(k) for k in key.split(","))
        rank = order.get(action_name(action), len(order))
        rows.append((TASKS.index(task), rank, i, task, keys, desc))
    rows.sort()
    return [(task, keys, desc) for *_r, task, keys, desc in rows]


def _groups(nodes) -> list[tuple[str, list[tuple[str, str]]]]:
    groups: list[tuple[str, list[tuple[str, str]]]] = []
    for task, keys, desc in task_rows(nodes):
        if not groups or groups[-1][0] != task:
            groups.append((task, []))
        groups[-1][1].append((keys, desc))
    return groups


def _esc(text: str) -> str:
    """Text for Textual markup: "[" escaped (a lone backslash stays literal unless a "["
    follows it: see :func:`bold_key`)."""
    return text.replace("[", "\\[")


def bold_key(key: str) -> str:
    """A key name in bold markup; a trailing backslash (the ``\\`` key) is put after the
    closing tag, where it cannot escape the tag's "["."""
    if key.endswith("\\"):
        return f"[b]{_esc(key[:-1])}[/b]\\" if key[:-1] else "\\"
    return f"[b]{_esc(key)}[/b]"


def _cell(keys: str, desc: str, key_w: int, width: int) -> str:
    """One "key  description" entry, exactly ``width`` characters of text (markup added)."""
    room = width - key_w - 1
    if len(desc) > room:
        desc = desc[: max(room - 1, 1)] + "…"
    return f"{bold_key(keys)}{' ' * max(key_w - len(keys), 0)} {_esc(desc)}{' ' * (room - len(desc))}"


def _wrapped(keys: str, desc: str, room: int) -> list[tuple[str, str]]:
    """One entry as rows of at most ``room`` characters of description: the words that do not
    fit go on rows of their own under it (never cut off with "…")."""
    rows, line = [], ""
    for word in desc.split():
        if line and len(line) + 1 + len(word) > room:
            rows.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    rows.append(line)
    return [(keys if i == 0 else "", r) for i, r in enumerate(rows)]


def _balanced(blocks: list[list], ncol: int) -> list[list]:
    """The blocks in order split into at most ``ncol`` columns, the tallest as short as
    possible (every split tried: a handful of groups)."""
    n = len(blocks)
    best, best_h = [sum(blocks, [])], sum(len(b) for b in blocks)
    for k in range(1, min(ncol, n)):
        for cuts in itertools.combinations(range(1, n), k):
            edges = (0, *cuts, n)
            cols = [sum(blocks[a:b], []) for a, b in zip(edges, edges[1:])]
            h = max(len(c) for c in cols)
            if h < best_h:
                best, best_h = cols, h
    return best


def task_help(nodes, *, width: int | None = None) -> str:
    """Help text (Rich markup) of ``nodes``' keys grouped by task, the main actions of
    each task first. With ``width`` (characters) the groups are laid out in as many
    columns of at least 44 characters as fit, in task order down each column, so a
    160x50 terminal shows every group without scrolling; descriptions too long for a
    column go on on the next row."""
    groups = _groups(nodes)
    ncol = max(1, min(4, (width or 0) // 44))
    if ncol == 1:
        out: list[str] = []
        for task, items in groups:
            out += ([""] if out else []) + [f"[b]{task}[/b]"]
            out += [f"  {bold_key(k)}{' ' * max(18 - len(k), 1)}{_esc(d)}" for k, d in items]
        return "\n".join(out)
    key_w = min(max((len(k) for _t, items in groups for k, _d in items), default=4), 12)
    col_w = (int(width or 0) - 2 * (ncol - 1)) // ncol
    room = col_w - key_w - 1
    blocks = [[(task, None)] + [row for k, d in items for row in _wrapped(k, d, room)] + [("", None)]
              for task, items in groups]
    cols = _balanced(blocks, ncol)
    lines = []
    for r in range(max(len(c) for c in cols)):
        parts = []
        for c in cols:
            k, d = c[r] if r < len(c) else ("", None)
            if d is None:
                parts.append(f"[b]{k}[/b]{' ' * (col_w - len(k))}" if k else " " * col_w)
            else:
                parts.append(_cell(k, d, key_w, col_w))
        lines.append("  ".join(parts).rstrip())
    return "\n".join(lines).rstrip()
