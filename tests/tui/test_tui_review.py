"""Review of a pending proposal in the workspace (Pilot): the strip under the slice shows
the area per slice and the marks; } and { jump between marked slices, a click on the
strip goes to a slice, C cuts the proposal at the slice keeping the part joined to the
seed, A accepts from the seed to here."""

from __future__ import annotations

import numpy as np

from ctui.engine.core.volume import Volume
from ctui.engine.segment.propagate import Proposal
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.strip import ReviewStrip, columns
from ctui.screens.testing import wait_workspace


def test_strip_columns():
    assert columns(10, 40) == [(c // 4, c // 4) for c in range(40)]
    cols = columns(100, 30)  # 4 slices per column
    assert cols[0] == (0, 3) and cols[-1] == (96, 99) and len(cols) == 25


def _leaky_proposal(shape) -> Proposal:
    """Seed slice 10 (square y, x 10..19 in the labels); slices 11..14 the square, 15 the
    square plus a joined 10x20 block, 16..18 the block only."""
    nz, ny, nx = shape
    sq = np.zeros((ny, nx), bool)
    sq[10:20, 10:20] = True
    leak = np.zeros((ny, nx), bool)
    leak[10:20, 20:40] = True
    p = Proposal(object_id=1, start_slice=10, shape=shape)
    for z in range(11, 15):
        p.masks[z] = (0, 0, sq.copy())
    p.masks[15] = (0, 0, sq | leak)
    for z in (16, 17, 18):
        p.masks[z] = (0, 0, leak.copy())
    p.areas = {z: int(e[2].sum()) for z, e in p.masks.items()}
    return p


async def test_strip_jumps_cut_and_accept_to_here():
    data = np.zeros((30, 48, 48), np.int16)
    s = Session(Volume(data, spacing=(1.0, 1.0, 1.0), modality="CT"), source_path="synthetic", z=10)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        sq = np.zeros((48, 48), bool)
        sq[10:20, 10:20] = True
        s.seg.apply_mask(sq, 1, offset=(10, 0, 0))
        strip = ws.query_one("#strip", ReviewStrip)
        assert not strip.display or "on" not in strip.classes
        ws.pending.show(_leaky_proposal(s.shape))
        ws.refresh_view()
        await pilot.pause()
        assert "on" in strip.classes and strip.profile[15] == 300 and strip.profile[10] == 100
        await pilot.press("right_curly_bracket")
        assert s.z == 15
        await pilot.press("right_curly_bracket")
        assert s.z == 16
        await pilot.press("left_curly_bracket")
        assert s.z == 15
        # a click on the strip's column of slice 12 goes there
        col = next(c for c, (a, b) in enumerate(strip._cols()) if a <= 12 <= b)
        await pilot.click("#strip", offset=(col, 0))
        assert s.z == 12
        # C at slice 14: the leak is cut off
        s.z = 14
        await pilot.press("C")
        assert ws.pending.proposal.slices == (11, 14) and ws.pending.proposal.voxels == 400
        # A at slice 12: accept from the seed to here
        s.z = 12
        await pilot.press("A")
        assert ws.pending.proposal is None
        assert s.seg.voxels(1) == 300 and s.seg.slice_range(1) == (10, 12)
        # no proposal: the strip reviews the object itself (three slices)
        assert "on" in strip.classes and list(strip.profile[9:14]) == [0, 100, 100, 100, 0]
        await pilot.press("u")
        assert s.seg.voxels(1) == 100
        await pilot.pause()
        assert "on" not in strip.classes  # one slice: nothing to review
        assert not app.internal_errors


async def test_strip_reviews_an_accepted_object():
    data = np.zeros((30, 48, 48), np.int16)
    s = Session(Volume(data, spacing=(1.0, 1.0, 1.0), modality="CT"), source_path="synthetic", z=10)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        sq = np.zeros((48, 48), bool)
        sq[10:20, 10:20] = True
        s.seg.apply_mask(sq, 1, offset=(10, 0, 0))
        s.seg.objects[1].seeds.append((15, 15, 10))  # as Enter records it: the review walks out from the seed
        ws.pending.show(_leaky_proposal(s.shape))
        ws.refresh_view()
        await pilot.press("a")  # accept it all, leak included
        assert ws.pending.proposal is None and s.seg.voxels(1) == 100 + 400 + 300 + 600
        strip = ws.query_one("#strip", ReviewStrip)
        assert "on" in strip.classes and strip.profile[15] == 300
        await pilot.press("right_curly_bracket")
        assert s.z == 15  # the leak's slice, found on the accepted object
        assert "keep the island" in str(ws.query_one("#status").render())
        assert not app.internal_errors


async def test_cut_at_a_marked_slice_keeps_the_slice_before_it():
    """The mark is the slice where it leaks (15: the area triples): C there keeps 11..14."""
    data = np.zeros((30, 48, 48), np.int16)
    s = Session(Volume(data, spacing=(1.0, 1.0, 1.0), modality="CT"), source_path="synthetic", z=10)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        sq = np.zeros((48, 48), bool)
        sq[10:20, 10:20] = True
        s.seg.apply_mask(sq, 1, offset=(10, 0, 0))
        ws.pending.show(_leaky_proposal(s.shape))
        ws.refresh_view()
        await pilot.press("right_curly_bracket")
        assert s.z == 15
        await pilot.press("C")
        assert ws.pending.proposal.slices == (11, 14) and ws.pending.proposal.voxels == 400
        assert "before the marked slice 15" in str(ws.query_one("#status").render())
        assert not app.internal_errors


async def test_a_drag_along_the_strip_sets_the_slice_limits():
    from ctui.screens.testing import drag

    data = np.zeros((30, 48, 48), np.int16)
    s = Session(Volume(data, spacing=(1.0, 1.0, 1.0), modality="CT"), source_path="synthetic", z=10)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        sq = np.zeros((48, 48), bool)
        sq[10:20, 10:20] = True
        s.seg.apply_mask(sq, 1, offset=(10, 0, 0))
        ws.pending.show(_leaky_proposal(s.shape))
        ws.refresh_view()
        await pilot.pause()
        strip = ws.query_one("#strip", ReviewStrip)
        col = {z: next(c for c, (a, b) in enumerate(strip._cols()) if a <= z <= b) for z in (11, 14)}
        await drag(pilot, "#strip", [(col[11], 0), (col[14], 0)])
        assert s.limits.slices == (strip.slice_at(col[11]), strip.slice_at(col[14]))
        assert s.limits.slices[0] <= 11 and s.limits.slices[1] >= 14
        assert "Slice limits" in str(ws.query_one("#status").render())
        # a click (no drag) still only goes to the slice
        await pilot.click("#strip", offset=(col[11], 0))
        assert s.z == strip.slice_at(col[11]) and s.limits.slices[1] >= 14
        assert not app.internal_errors
