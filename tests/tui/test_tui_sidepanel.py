"""The side panel owns its seed-range worker (issue 36): the text builder only says which range it
wants; the panel computes it in a worker of its own once the cursor rests, and posts a message.
A held key (many steps) computes one range, the one where the cursor stopped, and the panel
shows the range ``actions.segment.suggest_range`` gives there."""

from __future__ import annotations

import numpy as np

import ctui.engine.actions.segment as seg_actions
from ctui.engine.core.volume import Volume
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens import sidepanel
from ctui.screens.sidepanel import SidePanel
from ctui.screens.testing import wait_for, wait_workspace
from ctui.screens.ws_keys import panel_text


def _volume() -> Volume:
    """A 60 HU block (noise sd 5) in -100 HU, 1 mm voxels: the seed range at its centre brackets 60."""
    rng = np.random.default_rng(3)
    a = np.full((12, 40, 40), -100, np.int16)
    a[2:10, 8:32, 8:32] = 60
    a += rng.normal(0, 5, a.shape).astype(np.int16)
    return Volume(a, spacing=(1.0, 1.0, 1.0), modality="CT")


async def test_a_held_key_computes_one_seed_range_where_the_cursor_rests(monkeypatch):
    calls: list[tuple[int, int, int]] = []
    real = seg_actions.suggest_range

    def counting(volume, xyz, **kw):
        calls.append(tuple(xyz))
        return real(volume, xyz, **kw)

    monkeypatch.setattr(seg_actions, "suggest_range", counting)
    s = Session(_volume(), source_path="synthetic", z=6, y=20, x=12)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        panel = ws.query_one("#panel", SidePanel)
        await wait_for(pilot, lambda: "Seed range here" in str(panel_text(ws)) and ".." in str(panel_text(ws)).split(
            "Seed range here")[1].split("\n")[0], what="the first seed range")
        calls.clear()
        monkeypatch.setattr(sidepanel, "SEED_RANGE_REST_S", 1e4)  # a held key: steps faster than the rest time
        for _ in range(7):
            await pilot.press("right")
        monkeypatch.setattr(sidepanel, "SEED_RANGE_REST_S", 0.01)  # the key let go: the cursor rests
        await pilot.press("right")
        await wait_for(pilot, lambda: ws.seed_range.result is not None and ws.seed_range.key[2] == s.x,
                       what="the seed range where the cursor stopped")
        assert s.x == 20
        assert calls == [(20, 20, 6)]  # one computation, at the voxel where the cursor rested
        rc = real(s.volume, (s.x, s.y, s.z), pipeline=s.pipeline)
        assert rc.low < 60 < rc.high  # the block's value, not the background's
        await pilot.pause()
        assert f"Seed range here {rc.low:.0f}..{rc.high:.0f}" in str(panel_text(ws))
        assert not [w for w in ws.workers if w.group == "seed-range"]  # the panel's, not the screen's
        assert panel.seed_range is ws.seed_range
