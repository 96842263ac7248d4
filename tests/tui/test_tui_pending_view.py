"""What a pending proposal shows before ``a`` (issue 37's new-user pass), with Textual's Pilot on a
synthetic ball whose volume is known: the objects list gives the proposal's volume beside its object's
0.0 ml, the review strip draws the slice limits it sets, and the 80x24 panel keeps one whole line of each
note instead of cutting the notes at its bottom."""

from __future__ import annotations

import numpy as np

from ctui.engine.core.volume import Volume
from ctui.engine.segment.proposal import Proposal
from ctui.screens.session import Session
from ctui.screens.testing import wait_for, workspace_of
from ctui.screens.ws_keys import panel_text


def _ball() -> tuple[Session, np.ndarray]:
    """A 60 HU ball (r 12 voxels of 1 x 1 x 2 mm: 2 * 7.24 = 14.5 mL) in -100 HU fat; the cursor at its centre."""
    nz, n = 28, 64
    zz, yy, xx = np.mgrid[0:nz, 0:n, 0:n]
    ball = (zz - 14) ** 2 + (yy - 32) ** 2 + (xx - 32) ** 2 <= 144
    data = np.where(ball, 60, -100).astype(np.int16)
    s = Session(Volume(data, spacing=(2.0, 1.0, 1.0), modality="CT"), source_path="synthetic", z=14, y=32, x=32)
    return s, ball


def _pending(ws, ball: np.ndarray) -> float:
    """The ball as object 1's pending proposal (as S leaves it); returns its volume in mL."""
    ws.pending.show(Proposal.of_mask(1, 14, ball), seed=(32, 32, 14))
    ws.update_panel()
    return float(ball.sum()) * 2.0 / 1000.0


async def test_the_objects_list_gives_a_pending_proposals_volume_and_a_takes_it():
    for size in ((160, 50), (80, 24)):
        s, ball = _ball()
        async with workspace_of(s, size) as (app, pilot, ws):
            ml = _pending(ws, ball)
            await pilot.pause()
            lines = panel_text(ws).plain.split("\n")
            row = next(i for i, line in enumerate(lines) if "██ object 1" in line)
            assert "0.0ml" in lines[row]  # nothing accepted yet
            assert f"proposed {ml:.1f} ml" in lines[row + 1]  # the proposal's own volume under it
            assert all(len(line) <= 36 for line in lines[row:row + 2])  # one line each in the panel's 36 cells
            await pilot.press("a")
            await wait_for(pilot, lambda: ws.pending.proposal is None, what="the accepted proposal")
            await wait_for(pilot, lambda: f"{ml:6.1f}ml" in panel_text(ws).plain, what="the object's volume")
            assert "proposed" not in panel_text(ws).plain
            assert s.seg.voxels(1) == int(ball.sum())


async def test_a_drag_along_the_review_strip_draws_the_slice_limits_it_sets():
    from ctui.screens.strip import ReviewStrip
    from ctui.screens.testing import drag

    s, ball = _ball()
    async with workspace_of(s, (80, 24)) as (app, pilot, ws):
        _pending(ws, ball)
        await pilot.pause()
        strip = ws.query_one("#strip", ReviewStrip)
        cols = strip._cols()
        col = {z: next(c for c, (a, b) in enumerate(cols) if a <= z <= b) for z in (8, 20)}
        assert "[" not in strip.render_line(1).text and "]" not in strip.render_line(1).text  # no limits yet
        await drag(pilot, "#strip", [(col[8], 0), (col[20], 0)])
        await pilot.pause()
        lo, hi = s.limits.slices
        assert (lo, hi) == (strip.slice_at(col[8]), strip.slice_at(col[20]))
        markers = strip.render_line(1).text
        assert markers.index("[") == col[8] and markers.index("]") == col[20]  # the limits, bracketed
        bars = list(strip.render_line(0))[:len(cols)]
        for c, ((a, b), seg) in enumerate(zip(cols, bars)):
            if a <= s.z <= b:
                continue  # the slice cursor's column keeps its highlight
            outside = b < lo or a > hi
            # the bars outside the limits dimmed (grey), those inside in the bars' blue
            assert (seg.style.color.triplet.blue < 100) == outside, (c, a, b, seg)
        s.limits.slices = None  # cleared (as i does): the brackets go
        ws.update_panel()
        await pilot.pause()
        assert "[" not in strip.render_line(1).text


_NOTES = ["the object (34 mL) is 34x the ball that fits at the seed: it probably leaked into a neighbour; "
          "add background seeds there, narrow the range, or draw a box",
          "leak guard at slice 17 (forward): area 900 px after 400 px, stopped",
          "the neck cut removed 2.1 mL at slice 9; check it on the review strip",
          "propagation cancelled; result is partial"]


def test_a_notes_essential_line_is_its_first_clause_in_whole_words():
    from ctui.screens.ws_keys import note_line

    assert note_line(_NOTES[1], 34) == "leak guard at slice 17 (forward)"
    assert note_line(_NOTES[3], 34) == "propagation cancelled"
    assert note_line(_NOTES[0], 34) == "the object (34 mL) is 34x the…"  # cut after a whole word


async def test_the_compact_panel_never_cuts_a_proposals_notes_at_its_bottom_and_help_shows_them_whole():
    from rich.console import Console

    from ctui.screens.dialogs import TextScreen
    from ctui.screens.ws_keys import note_line

    for size, crowded in (((80, 24), False), ((80, 29), False), ((80, 24), True)):
        s, ball = _ball()
        if crowded:  # a box and slice limits take the panel's rows: no room for a line per note
            s.roi_box, s.limits.slices = ((0, 27), (0, 63), (0, 63)), (8, 20)
        async with workspace_of(s, size) as (app, pilot, ws):
            await wait_for(pilot, lambda: ws.seed_range.result is not None, what="the seed range")  # the panel settled
            _pending(ws, ball)
            ws.pending.notes = list(_NOTES)
            ws.update_panel()
            await pilot.pause()
            panel = ws.query_one("#panel")  # its size: the text's room inside the padding
            rows = ["".join(seg.text for seg in line).rstrip()
                    for line in Console(width=panel.size.width).render_lines(panel_text(ws), pad=False)]
            assert len(rows) <= panel.size.height, (size, rows)  # every row on screen: nothing cut at the bottom
            below = rows[rows.index("Notes on the proposal") + 1:]
            more = [r for r in below if r.startswith("+")]
            lines = [r.removeprefix("• ") for r in below if r.startswith("• ")]
            # one whole line each (its first clause), then how many more and where they are
            assert lines == [note_line(n, panel.size.width - 2) for n in _NOTES[:len(lines)]], rows
            shown_more = int(more[0].split()[0][1:]) if more else 0
            assert len(lines) + shown_more == len(_NOTES) and (not more or more[0].endswith("? shows them"))
            assert bool(more) == crowded  # a line each fits 80x24 and 80x29 here, not beside the box and limits
            await pilot.press("question_mark")
            await wait_for(pilot, lambda: isinstance(app.screen, TextScreen), what="the help")
            assert all(f"• {n}" in app.screen.body for n in _NOTES)  # the notes in full
            await pilot.press("escape")


async def test_80x24_panel_says_the_method_and_range_in_one_row():
    """At 80x24 the panel's segmentation line is one row (the method and the range S uses), and the
    line on why the seed range ends is left out: the rows go to the objects and the notes."""
    s, _ = _ball()
    async with workspace_of(s, (80, 24)) as (app, pilot, ws):
        def seg_line() -> str:
            return next(x for x in panel_text(ws).plain.splitlines() if x.startswith("Segment "))

        assert seg_line() == "Segment fill slice, range auto"
        s.range_ = (10.0, 200.0)  # a range typed with T: S uses it
        assert seg_line() == "Segment fill slice, range 10:200"
        s.segment_options["range"] = "auto"  # G's range auto: S ignores T's
        assert seg_line() == "Segment fill slice, range auto"
        await wait_for(pilot, lambda: "Seed range here" in panel_text(ws).plain and ws.seed_range.result is not None,
                       what="the seed range")
        assert "a neighbour joins past it" not in panel_text(ws).plain
    s, _ = _ball()
    async with workspace_of(s, (160, 50)) as (app, pilot, ws):  # the full line at 160x50
        assert "neck auto" in next(x for x in panel_text(ws).plain.splitlines() if x.startswith("Segment "))
