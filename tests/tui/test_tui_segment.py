"""The TUI segments through actions.segment: S (segment from the cursor) then a (accept), driven
with Textual's Pilot, gives the same mask as ``ctui segment`` with the same seed and settings."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ctui.cli import main as cli_main
from ctui.engine.io.labels import load_labels
from ctui.engine.io.series import load
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.testing import wait_for, wait_workspace
from support import shared


@pytest.mark.shared_data
@pytest.mark.parametrize("mode", ["slice", "3d"])
async def test_tui_segment_equals_cli(tmp_path, capsys, mode):
    ct = shared("totalseg_example") / "ct_abdomen_3mm.nii.gz"
    seed = (31, 33, 8)  # the left kidney's deepest point
    mask_out = tmp_path / "cli.nii.gz"
    rc = cli_main(["segment", str(ct), "--seed", ",".join(map(str, seed)), "--mode", mode, "--mask", str(mask_out),
                   "--json"])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    cli = load_labels(str(mask_out))[0] == 1

    vol = load(str(ct))
    s = Session(vol, source_path=str(ct), z=seed[2], y=seed[1], x=seed[0])
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        if mode == "3d":  # the panel: mode 3D, everything else left at its default
            await pilot.press("G")
            await wait_for(pilot, lambda: type(app.screen).__name__ == "SegmentPanel" and bool(app.screen.query("#mode")),
                           what="the panel")
            from textual.widgets import Select

            panel = app.screen
            panel.query_one("#mode", Select).value = "3d"
            panel._apply()
            await wait_for(pilot, lambda: app.screen is ws, what="the workspace")
            assert s.prop_mode == "3d" and s.segment_options["neck"] is None
        s.z, s.y, s.x = seed[2], seed[1], seed[0]
        from ctui.screens.ws_keys import panel_text

        ws.update_panel()
        lo, hi = report["objects"][0]["range"]
        want = f"Seed range here {lo:.0f}..{hi:.0f}"  # the range S will use, before the fill, as the CLI reports it
        await wait_for(pilot, lambda: want in str(panel_text(ws)), what="the seed range in the side panel")
        await pilot.press("S")
        await wait_for(pilot, lambda: ws.pending.proposal is not None, timeout=120, what="the proposal")
        status = str(ws.query_one("#status").render())
        assert "neck" in status and "auto" in status
        await pilot.press("a")
        await pilot.pause()
        tui = s.seg.labels == s.current
        assert np.count_nonzero(tui) == report["objects"][0]["voxels"]
        assert np.array_equal(tui, cli)
        info = s.seg.objects[s.current]  # the object keeps its seed and settings, as after a fill
        assert tuple(seed) in [tuple(v) for v in info.seeds]  # p propagates from it later
        assert (info.settings["low"], info.settings["high"]) == pytest.approx((lo, hi), abs=1e-3)  # the report rounds
        await pilot.press("u")  # one undo step takes it back
        assert not (s.seg.labels == s.current).any()
