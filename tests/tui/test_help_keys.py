"""Help by task: ``?`` groups the workspace's keys under Segment, Review, Edit, Views,
3D and measure, Files, Navigate with the main actions first, and the README's key table
is the one generated from the app's bindings (so it cannot drift from them)."""

from __future__ import annotations

import re

from ctui.screens import help as keyhelp
from ctui.screens.app import CtuiApp
from ctui.screens.workspace import WorkspaceScreen
from support import ROOT


def test_readme_key_table_is_the_apps_bindings():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    table = text.split("<!-- keys:start -->\n", 1)[1].split("\n<!-- keys:end -->", 1)[0]
    assert table == keyhelp.markdown_table(), "README key table out of date: run python -m ctui.screens.help --write-readme"
    # every workspace binding is in it, with its description
    for b in WorkspaceScreen.BINDINGS:
        assert f"| {b.description.replace('|', '/')} |" in table, b.description
    # the views are 1/2/3/0 and v cycles the pipeline's stages (not "views and 2x2 grid")
    assert "`v`/`V` views and 2x2 grid" not in text
    rows = {r.split(" | ")[2].rstrip(" |"): r.split(" | ")[1] for r in table.splitlines()[2:]}
    assert rows["Axial view"] == "`1`" and rows["2x2: axial, sagittal, coronal, 3D"] == "`0`"
    assert rows["Stage view"] == "`v`"


def test_help_groups_main_actions_first():
    rows = keyhelp.task_rows((WorkspaceScreen, CtuiApp))
    tasks = [t for t, _k, _d in rows]
    order = [t for i, t in enumerate(tasks) if t not in tasks[:i]]
    assert order[:7] == ["Segment", "Review", "Edit", "Views", "3D and measure", "Files", "Navigate"][:len(order[:7])]
    assert order[0] == "Segment" and "Navigate" in order
    first = [d for _t, _k, d in rows[:6]]
    assert first[0] == "Fill" and "Propagate" in first  # the main actions of a task first
    assert [d for t, _k, d in rows if t == "Edit"][0] == "Undo"
    # at 160x50 the help box shows ~40 lines of text 138 wide: every group, no scrolling
    text = keyhelp.task_help((WorkspaceScreen, CtuiApp), width=138)
    lines = [re.sub(r"\[/?b\]", "", x).replace("\\[", "[") for x in text.splitlines()]
    assert len(lines) <= 40 and max(len(x) for x in lines) <= 138
    top = "\n".join(lines)
    for word in ("Propagate", "Undo", "Fill", "Accept proposal", "3D", "Export", "Measure", "Cursor left"):
        assert word in top, word
    narrow = keyhelp.task_help((WorkspaceScreen, CtuiApp)).splitlines()
    assert narrow.index("[b]Segment[/b]") < narrow.index("[b]Navigate[/b]")
    assert keyhelp.key_name("pageup") == "PgUp" and keyhelp.key_name("ctrl+s") == "Ctrl+S"
    assert keyhelp.key_name("shift+left") == "Shift+←" and keyhelp.key_name("backslash") == "\\"


async def test_question_mark_shows_help_by_task(monkeypatch, tmp_path):
    import numpy as np

    from ctui.engine.core.volume import Volume
    from ctui.screens import graphics
    from ctui.screens.session import Session
    from ctui.screens.testing import wait_workspace

    monkeypatch.setattr(graphics, "_chosen", "halfblock")
    monkeypatch.setenv("CTUI_AUTOSAVE_DIR", str(tmp_path / "autosave"))
    s = Session(Volume(np.zeros((4, 16, 16), np.int16), modality="CT"), source_path="synthetic", z=2, y=8, x=8)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.press("question_mark")
        await pilot.pause()
        body = str(app.screen.body)
        assert body.index("Segment") < body.index("Review") and body.index("Edit") < body.index("Navigate")
        assert body.index("Fill") < body.index("Cursor left")
        assert len(body.splitlines()) < 46  # every group on one 160x50 screen


def test_no_two_workspace_actions_share_a_key():
    """Every key of the workspace does one thing: two tools added at once once both took ``D`` (the vessel's
    start and the AI draft), and Textual silently ran only one of them."""
    owners: dict[str, list[str]] = {}
    for binding in WorkspaceScreen.BINDINGS:
        for key in binding.key.split(","):
            owners.setdefault(key.strip(), []).append(binding.action)
    shared = {key: actions for key, actions in owners.items() if len(actions) > 1}
    assert shared == {}
