"""The workspace's AI first draft (``D``) with Pilot and the stand-in ``TotalSegmentator`` of
``test_ai_totalseg`` on PATH: the classes come in as named objects on the series' grid beside the
user's object, as one undo step; Escape kills a running TotalSegmentator and changes nothing; a
missing executable is one line; a subset that would not fit the TUI's objects is refused."""

from __future__ import annotations

import json
import os
import stat
import sys
import time

import numpy as np
import pytest

pytest.importorskip("nibabel")

from test_ai_totalseg import SHAPE, env, truth  # noqa: F401  (env: the fixture)

from ctui.engine.core.colors import MAX_OBJECTS
from ctui.screens.app import CtuiApp
from ctui.screens.auto_screen import AutoScreen, fit_problem
from ctui.screens.session import Session, load_volume
from ctui.screens.testing import wait_for, wait_workspace

ABDOMEN = ["liver", "spleen", "kidney_left", "kidney_right", "pancreas", "gallbladder", "stomach"]


def _session(series) -> tuple[Session, np.ndarray]:
    s = Session(load_volume(str(series)), source_path=str(series), z=6, y=15, x=20)
    mine = np.zeros(SHAPE, bool)
    mine[5:8, 10:20, 10:30] = True  # the user's object across the liver and the spleen
    s.seg.add_object("tumour", object_id=2)
    s.seg.labels[mine] = 2
    return s, mine


def _status(ws) -> str:
    return str(ws.query_one("#status").render())


@pytest.mark.slow
async def test_draft_imports_named_objects_as_one_undo_step(env):  # noqa: F811
    series, _, bindir = env
    s, mine = _session(series)
    before = s.seg.labels.copy()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("Z")
        await wait_for(pilot, lambda: isinstance(app.screen, AutoScreen), what="the draft's dialog")
        run = app.screen.query_one("#au-run")
        assert run.region.bottom <= 24 and not run.disabled  # the Run button fits at 80x24
        await pilot.press("enter")  # Run has the focus: the default set (abdominal organs), merge add
        await wait_for(pilot, lambda: len(s.seg.objects) == 4, timeout=60, what="the draft's objects")
        args = json.loads((bindir / "TotalSegmentator.args.json").read_text())
        i = args.index("--roi_subset")
        assert args[i + 1:i + 1 + len(ABDOMEN)] == ABDOMEN and args[args.index("--device") + 1] == "cpu"
        _, want = truth()
        names = {o.name: i for i, o in s.seg.objects.items()}
        assert set(names) == {"tumour", "liver", "spleen", "kidney_left"} and max(names.values()) <= MAX_OBJECTS
        assert names["liver"] == 5 and names["spleen"] == 1 and names["tumour"] == 2  # its numbers when free
        for name in ("liver", "spleen", "kidney_left"):  # on the series' grid; the user's voxels stay theirs
            assert np.array_equal(s.seg.labels == names[name], want[name] & ~mine), name
        assert np.array_equal(s.seg.labels == 2, mine)
        assert s.seg.objects[5].color == (0, 255, 255)  # TotalSegmentator's colour from its class map
        assert "3 object(s) from TotalSegmentator total" in _status(ws) and "liver" in _status(ws)
        await pilot.press("u")  # one undo step takes the whole draft back
        await pilot.pause()
        assert np.array_equal(s.seg.labels, before)


@pytest.mark.slow
async def test_replace_takes_the_place_of_the_object_of_that_name(env):  # noqa: F811
    series, _, _ = env
    s, mine = _session(series)
    s.seg.objects[2].name = "liver"  # the user's own liver (object 2), across the model's liver and spleen
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.press("Z")
        await wait_for(pilot, lambda: isinstance(app.screen, AutoScreen), what="the draft's dialog")
        app.screen.query_one("#au-merge").value = "replace"
        app.screen.query_one("#au-names").value = "liver,spleen"
        await pilot.pause()
        await pilot.click("#au-run")
        await wait_for(pilot, lambda: len(s.seg.objects) == 2 and s.seg.voxels(1) > 0, timeout=60,
                       what="the draft")
        _, want = truth()
        assert {i: o.name for i, o in s.seg.objects.items()} == {1: "spleen", 2: "liver"}
        assert np.array_equal(s.seg.labels == 2, want["liver"])  # the model's liver, in the object's place
        assert np.array_equal(s.seg.labels == 1, want["spleen"])  # the classes' voxels win
        assert s.seg.objects[2].color == (0, 255, 255)


SLOW = r'''#!{python}
import os, sys, time
from pathlib import Path
Path(sys.argv[0] + ".pid").write_text(str(os.getpid()))
print("Predicting part 1 of 2 ...", flush=True)
time.sleep(120)  # then silent, as TotalSegmentator is while it loads a model: Escape must still stop it
'''


async def test_escape_kills_the_run_and_changes_nothing(env):  # noqa: F811
    """Escape while TotalSegmentator prints nothing: the process is killed, the labels are as they were."""
    series, _, bindir = env
    exe = bindir / "TotalSegmentator"
    exe.write_text(SLOW.format(python=sys.executable))
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    s, _ = _session(series)
    before = s.seg.labels.copy()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("Z")
        await wait_for(pilot, lambda: isinstance(app.screen, AutoScreen), what="the draft's dialog")
        await pilot.press("enter")
        pidfile = bindir / "TotalSegmentator.pid"
        await wait_for(pilot, lambda: pidfile.exists() and "part" in str(ws.query_one("#progress-label").render()),
                       timeout=60, what="TotalSegmentator's progress")
        await pilot.press("escape")
        await wait_for(pilot, lambda: "cancelled: nothing changed" in _status(ws), timeout=30, what="the cancel")
        pid = int(pidfile.read_text())
        end = time.monotonic() + 10
        while time.monotonic() < end and _alive(pid):
            await pilot.pause(0.05)
        assert not _alive(pid)  # the subprocess was killed
        assert np.array_equal(s.seg.labels, before) and set(s.seg.objects) == {2}


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie that was reaped late still answers kill 0: read its state
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


async def test_missing_totalsegmentator_is_one_line(env, monkeypatch, tmp_path):  # noqa: F811
    monkeypatch.setenv("PATH", str(tmp_path / "nothing"))
    s, _ = _session(env[0])
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        palette = {c.title: c for c in app.get_system_commands(ws)}  # Ctrl+P finds it by name
        assert "AI first draft (TotalSegmentator)" in palette
        await palette["AI first draft (TotalSegmentator)"].callback()
        await pilot.pause()
        assert app.screen is ws  # no dialog to fill for nothing
        text = _status(ws)
        assert "TotalSegmentator is not installed" in text and "pip install TotalSegmentator" in text
        assert len(text.strip().splitlines()) <= 3  # one line (wrapped by the status bar's width at most)


async def test_a_subset_that_does_not_fit_is_refused(env):  # noqa: F811
    s, _ = _session(env[0])
    for i in range(3, 8):
        s.seg.add_object(f"mine {i}", object_id=i)  # 6 objects: 4 free
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.press("Z")
        await wait_for(pilot, lambda: isinstance(app.screen, AutoScreen), what="the draft's dialog")
        dlg = app.screen
        assert dlg.query_one("#au-run").disabled
        assert "7 classes need 7 new objects and 4 of 10 are free" in str(dlg.query_one("#au-note").render())
        dlg.query_one("#au-names").value = "liver,spleen"
        await pilot.pause()
        assert not dlg.query_one("#au-run").disabled and dlg.choice()["roi_subset"] == ["liver", "spleen"]
        await pilot.press("escape")
        await pilot.pause()
        assert app.screen is app.workspace and len(s.seg.objects) == 6


def test_fit_counts_what_the_policy_adds():
    objs = {1: "liver", 2: "spleen"}
    assert fit_problem(["liver", "spleen", "stomach"], "keep", objs) == ""
    assert fit_problem(["liver"] * 1 + [f"c{i}" for i in range(8)], "replace", objs) == ""  # 8 new, 8 free
    assert "9 classes need 9 new objects and 8 of 10 are free" in fit_problem(
        ["liver"] + [f"c{i}" for i in range(8)], "add", objs)
