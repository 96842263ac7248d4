"""Issue 37 (sections from the TUI; PNGs of the 80x24 screens looked at): the measure screen's chart of the
section areas starts at 0 mm². A section through the cursor spans a 2 mm path whose areas differ by a few per
cent; drawn from their own minimum to maximum that was a diagonal from the bottom to the top of the chart (seen
on the 80x24 capture of the workflow's kidney), a change of 1% drawn as one of 100%."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.volume import Volume
from ctui.screens.app import CtuiApp
from ctui.screens.dialogs import ChoiceScreen
from ctui.screens.imageview import ImageView
from ctui.screens.session import Session
from ctui.screens.testing import choose, wait_for, wait_workspace

pytestmark = pytest.mark.slow


async def test_80x24_section_chart_starts_at_zero():
    from ctui.screens.measure_screen import MeasureScreen

    n = 48
    zz, yy, xx = np.mgrid[0:24, 0:n, 0:n].astype(float)
    ell = ((xx - 24) / 18) ** 2 + ((yy - 24) / 12) ** 2 + ((zz - 12) / 8) ** 2 <= 1.0  # a kidney-like ellipsoid
    s = Session(Volume(np.where(ell, 300, -1000).astype(np.int16), spacing=(1.0, 1.0, 1.0), modality="CT"),
                source_path="synthetic", z=12, y=24, x=30)
    s.seg.labels[ell] = 1
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.press("M")
        await wait_for(pilot, lambda: isinstance(app.screen, MeasureScreen) and app.screen.stats, what="the measures")
        ms = app.screen
        await pilot.press("x")
        await wait_for(pilot, lambda: isinstance(app.screen, ChoiceScreen), what="the axes")
        await choose(pilot, "x")  # sagittal sections at x 26..34: areas within a few per cent
        await wait_for(pilot, lambda: ms.sections, what="the sections")
        await pilot.pause()
        area = np.array([r["area_mm2"] for r in ms.sections])
        assert len(area) >= 3 and np.ptp(area) < 0.15 * area.max()
        img = ms.query_one("#ms-plot", ImageView).rgb
        inner = img[2:-2, 2:-2].astype(int)
        drawn = np.argwhere(np.abs(inner - inner[-1, -1]).sum(axis=2) > 60)  # the curve (and its points)
        h = inner.shape[0]
        assert len(drawn) and drawn[:, 0].max() < 0.3 * h  # near the top: all areas close to the largest
        assert "area 0.." in str(ms.query_one("#ms-info").render())
