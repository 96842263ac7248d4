"""Issue 37's leak fix in the whole workflow (``benchmarks/tui_tasks.py --workflow``): the object accepted from
the person's click took in a neighbour on some slices (the right kidney of the shared abdomen, clicked where it
shows on the middle slice, takes in the liver below it). The person, whose eye the reference labels play:

1. drags along the review strip over the slices where the object leaves the organ (the slice limits; the press
   shows the first of them);
2. ``y`` and a drag: the ROI box around the leaked part on that slice (it spans the limits' slices);
3. ``t`` and a click on "Scissors: erase inside the box, its slices", then a click on the box's slices in the
   question that follows (a box drawn on one slice asks); "Remove" when the edit asks first.

Dice and the volume ratio against the reference before and after the fix are returned with the events."""

from __future__ import annotations

import numpy as np


def leak_slices(obj: np.ndarray, ref: np.ndarray, share: float = 0.2) -> tuple[int, int] | None:
    """(first, last): the longest run of slices where over ``share`` of the object's section lies outside the
    reference (what the person sees as the leak); None when there is none."""
    n = obj.sum(axis=(1, 2))
    out = (obj & ~ref).sum(axis=(1, 2))
    bad = (out > share * np.maximum(n, 1)) & (out >= 8)
    best, run = None, None
    for z in range(len(bad)):
        if bad[z]:
            run = (run[0], z) if run is not None else (z, z)
            if best is None or run[1] - run[0] > best[1] - best[0]:
                best = run
        else:
            run = None
    return best


def best_box(obj: np.ndarray, ref: np.ndarray, slices: tuple[int, int]) -> tuple[int, int, int, int] | None:
    """(y0, x0, y1, x1): the rectangle that, cut on ``slices``, removes the most voxels outside the reference
    less those inside it (the box a person draws around the leaked part, by eye); None when none gains."""
    a, b = slices
    out = (obj[a:b + 1] & ~ref[a:b + 1]).sum(axis=0).astype(np.int64)
    keep = (obj[a:b + 1] & ref[a:b + 1]).sum(axis=0).astype(np.int64)
    w = out - keep
    ys, xs = np.nonzero(out)
    if not len(ys):
        return None
    y_lo, y_hi = max(int(ys.min()) - 1, 0), min(int(ys.max()) + 1, w.shape[0] - 1)
    x_lo, x_hi = max(int(xs.min()) - 1, 0), min(int(xs.max()) + 1, w.shape[1] - 1)
    sub = w[y_lo:y_hi + 1, x_lo:x_hi + 1]
    cum = np.zeros((sub.shape[0] + 1, sub.shape[1] + 1), np.int64)
    cum[1:, 1:] = sub.cumsum(0).cumsum(1)
    best, gain = None, 0
    for y0 in range(sub.shape[0]):
        for y1 in range(y0 + 1, sub.shape[0]):  # at least two rows and columns: a box has a size
            rows = cum[y1 + 1] - cum[y0]  # column sums of rows y0..y1, cumulated
            tot = rows[None, :] - rows[:, None]  # [x0, x1+1]
            tot = np.triu(tot, 2)
            i = int(np.argmax(tot))
            x0, x1p = divmod(i, tot.shape[1])
            if tot[x0, x1p] > gain:
                gain, best = int(tot[x0, x1p]), (y0 + y_lo, x0 + x_lo, y1 + y_lo, x1p - 1 + x_lo)
    return best


async def click_option(c, option_id: str) -> None:
    """One click on the option ``option_id`` of the menu shown (scrolled to it first, as a person scrolls)."""
    ol = c.pilot.app.screen.query_one("OptionList")
    index = ol.get_option_index(option_id)
    line = ol._index_to_line[index]
    height = ol.scrollable_content_region.height
    if not int(ol.scroll_offset.y) <= line < int(ol.scroll_offset.y) + height:
        ol.scroll_to(y=line, animate=False)
        await c.pilot.pause()
    top = ol.content_region.y - ol.region.y
    await c.click("OptionList", (4, top + line - int(ol.scroll_offset.y)))
    await c.pilot.pause()


def _proposal_mask(p, shape) -> np.ndarray:
    """The pending proposal ``p`` as a (z, y, x) mask."""
    full = np.zeros(shape, bool)
    for z in p.masks:
        full[z] = p.slice_mask(z)
    return full


async def fix_leak(c, app, ref: np.ndarray, shot=None) -> dict:
    """The fix (see the module docstring) on the pending proposal: the slice limits dragged on its review strip
    (the strip shows a proposal at every terminal size), ``a`` (and ``-`` back to the whole slice), then the box
    and the scissors on the accepted object. Returns the events by kind, the slices, the box, and Dice / volume
    ratio against ``ref`` before (the proposal as accepted) and after. ``shot(name)``: awaited at each dialog
    (the screen captured)."""
    from ctui.screens.dialogs import ChoiceScreen, ConfirmScreen
    from ctui.screens.testing import cell_of_voxel, drag, wait_for

    s, ws, pilot = app.session, app.workspace, c.pilot
    obj = _proposal_mask(ws.pending.proposal, s.shape)
    before = _scores(obj, ref)
    out = {"before": before, "events": 0, "clicks": 0, "typed": 0, "slices": None, "box": None, "after": before}
    n0, k0, t0 = c.n, c.clicks, c.typed
    run = leak_slices(obj, ref)
    box = None if run is None else best_box(obj, ref, run)
    if run is not None and box is not None:
        lo, hi = run
        strip = ws.query_one("#strip")
        cols = strip._cols()
        leak = (obj & ~ref).sum(axis=(1, 2))
        first, last = (hi, lo) if leak[hi] >= leak[lo] else (lo, hi)  # press where the leak shows most

        def col(z: int) -> int:
            return next(i for i, (a, b) in enumerate(cols) if a <= z <= b)
        c.n += 1  # one drag along the strip: the slice limits; the press shows its slice
        c.clicks += 1
        await drag(pilot, "#strip", [(col(first), 0), (col(last), 0)])
        await pilot.pause()
        out.update(slices=run, box=box, limits=s.limits.slices)
        if shot is not None:
            await shot("strip-limits")
    await c.press("a")
    while ws.viewstate.zoom > 1:  # the whole slice, to draw the box on
        await c.press("minus")
    await pilot.pause()
    if run is None or box is None:
        out.update(events=c.n - n0, clicks=c.clicks - k0, typed=c.typed - t0)
        return out
    y0, x0, y1, x1 = box
    await c.press("y")
    c.n += 1  # one drag: the box
    c.clicks += 1
    await drag(pilot, "#main", [cell_of_voxel(app, (s.z, y0, x0)), cell_of_voxel(app, (s.z, y1, x1))])
    await pilot.pause()
    out["roi_box"] = s.roi_box
    await c.press("t")
    await wait_for(pilot, lambda: isinstance(app.screen, ChoiceScreen), timeout=10, what="the edit menu")
    if shot is not None:
        await shot("edit-menu")
    await click_option(c, "scissors_in_box")
    if isinstance(app.screen, ChoiceScreen):  # drawn on one slice: which slices
        out["asked"] = str(app.screen.title_text)
        if shot is not None:
            await shot("cut-which-slices")
        await click_option(c, "box")
    if isinstance(app.screen, ConfirmScreen):  # over a quarter of the object: asked first
        if shot is not None:
            await shot("cut-confirm")
        await c.press("y")
    await pilot.pause()
    after = s.seg.labels == s.current
    out.update(events=c.n - n0, clicks=c.clicks - k0, typed=c.typed - t0, after=_scores(after, ref))
    return out


def _scores(obj: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(Dice, volume ratio) of ``obj`` against ``ref``."""
    s = int(obj.sum()) + int(ref.sum())
    return (2.0 * int((obj & ref).sum()) / s if s else 1.0, float(obj.sum()) / max(int(ref.sum()), 1))
