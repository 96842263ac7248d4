"""The workspace's vessel tool (D: start and waypoints at the cursor, O: the end, then a accepts),
driven with Textual's Pilot, gives the same voxels as ``actions.vessel.vessel`` from the same points."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.actions.vessel import vessel
from ctui.screens import graphics
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.testing import wait_for, wait_workspace
from test_vessel import Z0, u_bend


@pytest.fixture(autouse=True)
def _env(monkeypatch, tmp_path):
    monkeypatch.setattr(graphics, "_chosen", "halfblock")
    monkeypatch.setenv("CTUI_AUTOSAVE_DIR", str(tmp_path / "autosave"))
    monkeypatch.chdir(tmp_path)


async def test_vessel_tool_start_waypoint_end_accept():
    vol, truth, _ = u_bend(noise=0.0)
    start, via, end = (30, 20, Z0), (30, 32, 42), (30, 44, Z0)
    want = vessel(vol, start=start, vias=[via], ends=[end]).mask
    s = Session(vol, z=start[2], y=start[1], x=start[0])
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("O")  # no start yet: nothing runs
        await pilot.pause()
        assert ws.pending.proposal is None and not ws.jobs.segmenting
        for p in (start, via):
            s.z, s.y, s.x = p[2], p[1], p[0]
            await pilot.press("D")
        assert "waypoint 1" in str(ws.query_one("#status").render())
        s.z, s.y, s.x = end[2], end[1], end[0]
        await pilot.press("O")
        await wait_for(pilot, lambda: ws.pending.proposal is not None, timeout=120, what="the vessel proposal")
        await wait_for(pilot, lambda: "Vessel proposal: path" in str(ws.query_one("#status").render()),
                       what="the vessel's report in the status line")
        await pilot.press("a")
        await pilot.pause()
        got = s.seg.labels == s.current
        assert np.array_equal(got, want)
        assert 2.0 * (got & truth).sum() / (got.sum() + truth.sum()) >= 0.9
