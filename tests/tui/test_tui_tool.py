"""A TUI tool added the way ARCHITECTURE.md says ("A TUI tool or key"): an owner with an
``action_<name>``, a row of a key table routed through the workspace's ``do`` action, a workspace
subclass listing the owner in ``TOOLS`` and an app that makes that workspace. Driven by its key
with Textual's Pilot, it changes the labels (one undo step), the help lists it, and an owner that
takes an action name another owner has is refused when the screen is built."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.volume import Volume
from ctui.screens.app import CtuiApp
from ctui.screens.keyhelp import task_rows
from ctui.screens.keytable import keys
from ctui.screens.session import Session
from ctui.screens.testing import wait_for, wait_workspace
from ctui.screens.workspace import WorkspaceScreen
from ctui.screens.ws_host import Owner


class Stamp(Owner):
    """The tiny tool: ``ctrl+t`` gives the voxel under the cursor to the current object."""

    def action_stamp(self) -> None:
        s = self.s
        if not self.ws.edit.editable():  # edits wait while a segmentation runs
            return
        box = (slice(s.z, s.z + 1), slice(s.y, s.y + 1), slice(s.x, s.x + 1))
        s.seg.apply_region(box, np.full((1, 1, 1), s.current, np.uint8), label="stamp")
        self.ws.edit.edited(f"Stamped x {s.x} y {s.y} slice {s.z} (u undoes)")  # undo, autosave, panel follow


class StampWorkspace(WorkspaceScreen):
    TOOLS = (Stamp,)
    BINDINGS = [*WorkspaceScreen.BINDINGS, *keys("ctrl+t  stamp  Stamp the cursor's voxel  hidden", via="do")]


class StampApp(CtuiApp):
    def make_workspace(self, session: Session) -> WorkspaceScreen:
        return StampWorkspace(session)


def _session() -> Session:
    return Session(Volume(np.zeros((5, 20, 20), np.int16), modality="CT"), source_path="synthetic", z=2, y=6, x=9)


async def test_a_tool_added_as_an_owner_changes_the_labels_by_its_key():
    s = _session()
    app = StampApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        assert isinstance(ws, StampWorkspace) and "stamp" in ws.actions
        await pilot.press("ctrl+t")
        await wait_for(pilot, lambda: int((s.seg.labels > 0).sum()) == 1, what="the stamped voxel")
        assert s.seg.labels[2, 6, 9] == s.current  # that voxel, the current object, nothing else
        assert "Stamped x 9 y 6 slice 2" in str(ws.query_one("#status").render())
        assert s.dirty and ws.volumes.version > 0  # the edit went through edited(): volumes recounted, unsaved
        await pilot.press("l", "ctrl+t")  # the cursor one right, then the key again
        await wait_for(pilot, lambda: int((s.seg.labels > 0).sum()) == 2, what="the second voxel")
        assert s.seg.labels[2, 6, 10] == s.current
        await pilot.press("u")  # one undo step per stamp
        await wait_for(pilot, lambda: int((s.seg.labels > 0).sum()) == 1, what="the undo")
        assert s.seg.labels[2, 6, 10] == 0 and s.seg.labels[2, 6, 9] == s.current
    # the ? help and the README's table read the bindings: the tool is listed, under Edit (its name says stamp:
    # no task word) or More, with its description
    rows = task_rows((StampWorkspace, CtuiApp))
    assert [(k, d) for _t, k, d in rows if d == "Stamp the cursor's voxel"] == [("Ctrl+T", "Stamp the cursor's voxel")]


def test_two_owners_of_one_action_are_refused():
    class Fill(Owner):
        def action_fill(self) -> None:  # the EditOwner's Enter
            pass

    class Clash(WorkspaceScreen):
        TOOLS = (Fill,)

    with pytest.raises(ValueError, match="'fill'"):
        Clash(_session())
