"""Issue 37's leak fix with the mouse, at 80x24, on the shared abdomen: the right kidney double-clicked where it
shows on the middle slice takes in the liver below it (slices 0-9); a drag along the review strip over those
slices sets the slice limits, ``a`` accepts, ``y`` and a drag draw the ROI box beside the kidney on the slice
the strip press showed, and ``t`` -> "Scissors: erase inside the box, its slices" -> "its slices" cuts the liver
on those slices only. Checked against the reference labels: Dice up, no voxel changed outside the limits.
Figures: ``python3 benchmarks/tui_tasks.py --workflow`` (the "fix:" lines)."""

from __future__ import annotations

import numpy as np
import pytest
from support import shared

from ctui.engine.actions.opened import open_input
from ctui.engine.io.series import load
from ctui.screens.dialogs import ChoiceScreen
from ctui.screens.session import Session
from ctui.screens.testing import cell_of_voxel, drag, wait_for, workspace_of

pytestmark = [pytest.mark.slow, pytest.mark.shared_data]


def _dice(a: np.ndarray, b: np.ndarray) -> float:
    return 2.0 * float((a & b).sum()) / float(a.sum() + b.sum())


async def _pick(pilot, app, option_id: str) -> None:
    """A click on ``option_id`` of the menu shown."""
    ol = app.screen.query_one("OptionList")
    line = ol._index_to_line[ol.get_option_index(option_id)]
    top = ol.content_region.y - ol.region.y
    await pilot.click("OptionList", offset=(4, top + line - int(ol.scroll_offset.y)))
    await pilot.pause()


async def test_80x24_leak_cut_on_the_slices_dragged_on_the_strip():
    d = shared("totalseg_example")
    vol = load(str(d / "ct_abdomen_3mm.nii.gz"))
    ref = open_input(str(d / "ct_abdomen_3mm_labels.nii.gz")).labels == 2  # the right kidney
    s = Session(vol, source_path="abdomen", z=15, y=37, x=77)
    async with workspace_of(s, (80, 24)) as (app, pilot, ws):
        await pilot.double_click("#main", offset=cell_of_voxel(app, (15, 37, 77)))
        await wait_for(pilot, lambda: not ws.jobs.segmenting and ws.pending.proposal is not None, timeout=120,
                       what="the proposal")
        strip = ws.query_one("#strip")
        assert strip.display and strip.has_class("on")  # at 80x24 the strip shows the proposal
        cols = strip._cols()

        def col(z: int) -> int:
            return next(i for i, (a, b) in enumerate(cols) if a <= z <= b)
        await drag(pilot, "#strip", [(col(9), 0), (col(0), 0)])
        await pilot.pause()
        assert s.limits.slices == (0, 9) and s.z == 9  # the press showed slice 9
        await pilot.press("a")
        await pilot.pause()
        before = (s.seg.labels == s.current).copy()
        assert _dice(before, ref) < 0.82 and before.sum() > 1.2 * ref.sum()  # the liver came with it
        assert (before[:10] & ~ref[:10]).sum() > 1000
        await pilot.press("y")
        await drag(pilot, "#main", [cell_of_voxel(app, (9, 28, 91)), cell_of_voxel(app, (9, 57, 103))])
        await pilot.pause()
        assert s.roi_box == ((0, 9), (28, 57), (91, 103))  # drawn on one slice: it spans the limits
        await pilot.press("t")
        await wait_for(pilot, lambda: isinstance(app.screen, ChoiceScreen), timeout=10, what="the edit menu")
        await _pick(pilot, app, "scissors_in_box")
        assert isinstance(app.screen, ChoiceScreen)  # a box drawn on one slice asks which slices
        await _pick(pilot, app, "box")
        await pilot.pause()
        after = s.seg.labels == s.current
        assert np.array_equal(after[10:], before[10:])  # nothing outside the dragged slices
        assert _dice(after, ref) > _dice(before, ref) + 0.07
        assert 0.9 < after.sum() / ref.sum() < 1.1
