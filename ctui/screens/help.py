"""The README's key table: the workspace's and the app's keys by task, as Markdown
(``python -m ctui.screens.help`` prints it, ``--write-readme`` rewrites README.md's; a test keeps
the README's table equal to it). The grouping and key names are :mod:`ctui.screens.keyhelp`'s.

This module sits above the screens it reads (the app and the workspace import ``keyhelp``, never
this module), so ``screens/`` holds no import circle.
"""

from __future__ import annotations

from pathlib import Path

from ctui.engine.core.atomic import write_text
from ctui.screens.app import CtuiApp
from ctui.screens.keyhelp import key_name, task_help, task_rows  # noqa: F401 - the help's API, read here and by tests
from ctui.screens.workspace import WorkspaceScreen


def workspace_nodes():
    """The workspace's and the app's bindings, as the ``?`` help and the README list them."""
    return (WorkspaceScreen, CtuiApp)


def markdown_table(nodes=None) -> str:
    """The README's key table: | task | keys | action |."""
    rows = ["| task | keys | action |", "|---|---|---|"]
    for task, keys, desc in task_rows(nodes or workspace_nodes()):
        k = " ".join(f"`{x}`" for x in keys.split(" ")).replace("|", "\\|")
        rows.append(f"| {task} | {k} | {desc.replace('|', '/')} |")
    return "\n".join(rows)


def write_readme(path) -> bool:
    """Replace the table between ``<!-- keys:start -->`` and ``<!-- keys:end -->`` in a
    README with :func:`markdown_table`; True when it changed."""

    text = Path(path).read_text(encoding="utf-8")
    head, rest = text.split("<!-- keys:start -->\n", 1)
    _old, tail = rest.split("\n<!-- keys:end -->", 1)
    new = f"{head}<!-- keys:start -->\n{markdown_table()}\n<!-- keys:end -->{tail}"
    if new != text:
        write_text(path, new)
    return new != text


if __name__ == "__main__":  # pragma: no cover - prints the table, or rewrites README.md's
    import sys

    if sys.argv[1:] == ["--write-readme"]:
        print("README.md updated" if write_readme("README.md") else "README.md already up to date")
    else:
        print(markdown_table())
