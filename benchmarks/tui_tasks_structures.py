"""Issue 37's structure tasks (``benchmarks/tui_tasks.py --structures``): the shared abdomen's liver and
the MR brain's lateral ventricles, from a click where the screen shows them, with the range picked on the
side panel's histogram where the default leaks; events counted by kind, Dice against the reference."""
from __future__ import annotations

import asyncio
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from tui_tasks import Counter, save_project, _dialog, _organ, _to_target, _wait_proposal, deepest, dice, seen_target  # noqa: E402




async def one_structure(size: tuple[int, int], image: Path, truth_mask: np.ndarray, name: str, *,
                        out_dir: Path, use_range: bool = False, png: Path | None = None) -> dict:
    """One structure as :func:`session` does an organ (its deepest voxel as the seed, the TUI's defaults;
    ``use_range``: its 5-95th percentile range typed first), then Ctrl+S and Enter; Dice of the saved
    object, events split by kind (keys, clicks, typed)."""
    from ctui.engine.actions.project import load_project
    from ctui.screens import graphics
    from ctui.screens.app import CtuiApp
    from ctui.screens.testing import wait_workspace

    graphics.use_graphics("halfblock")
    os.chdir(out_dir)
    os.environ["CTUI_AUTOSAVE_DIR"] = str(out_dir / "autosave")
    app = CtuiApp(str(image), autosave_s=1e9)
    async with app.run_test(size=size) as pilot:
        await wait_workspace(pilot, app)
        await pilot.pause()
        s = app.session
        c = Counter(pilot)
        vals = s.volume.data[truth_mask]
        rng = (float(np.percentile(vals, 5)), float(np.percentile(vals, 95))) if use_range else None
        if name == "lateral_ventricles" and not use_range:
            row = await _dark_structure(c, app, name, truth_mask, png)
        else:
            row = await _organ(c, app, name, deepest(truth_mask, s.volume.spacing), truth_mask, first=True,
                               review=False, rng=rng)
        row.update(save_events=await save_project(c, pilot, s), clicks=c.clicks, typed=c.typed, errors=list(app.internal_errors))
        proj = s.project_path
    got = load_project(proj).labels == row["object"]
    row["dice"] = dice(got, truth_mask)
    row["volume_ratio"] = float(got.sum()) / max(int(truth_mask.sum()), 1)
    return row


def _histogram_bars(rc) -> tuple[int, int]:
    """The two bars of the side panel's histogram a person picks for a dark structure in brighter tissue: from
    the first bar that shows (>= 5% of the tallest) to the bar before the valley that follows the dark peak."""
    h = np.asarray(rc.hist, float)
    first = int(np.flatnonzero(h >= 0.05 * h.max())[0])
    peak = first
    while peak + 1 < len(h) and h[peak + 1] >= h[peak]:
        peak += 1
    valley = peak
    while valley + 1 < len(h) and h[valley + 1] <= h[valley]:
        valley += 1
    return first, max(first, valley - 1)


async def _panel_bar_click(c: Counter, app, bar: int) -> bool:
    """A click on bar ``bar`` of the side panel's "Seed range here" histogram (where the screen shows it);
    False when the line is not on screen."""
    from ctui.screens.ws_keys import panel_text

    ws = app.workspace
    panel = ws.query_one("#panel")
    lines = panel_text(ws).plain.split("\n")
    row = next((i for i, line in enumerate(lines) if line.startswith("Seed range here ") and ".." in line), None)
    if row is None or panel.has_class("hidden"):
        return False
    line = lines[row]
    col = line.index(" ", len("Seed range here ")) + 1 + bar
    cr, r = panel.content_region, panel.region
    y = row - int(panel.scroll_offset.y)
    if not 0 <= y < cr.height or col >= cr.width:
        return False
    await c.click("#panel", (col + cr.x - r.x, y + cr.y - r.y))
    return True


async def _dark_structure(c: Counter, app, name: str, truth_mask: np.ndarray, png: Path | None = None) -> dict:
    """The MR lateral ventricles: a click where they show (the side panel's histogram of the neighbourhood there),
    the range picked on it with two clicks (the dark peak up to the valley), ``m`` (3D: the two ventricles join
    across slices), ``S`` from the cursor and ``a`` (the automatic neck keeps their horns: the leak's bridges are
    thinner than one sweep voxel, ``segment_start.sub_grid_neck``; it took ``G`` Tab Tab ``0`` Enter before)."""
    from ctui.screens.testing import wait_for

    ws, s, pilot = app.workspace, app.session, c.pilot
    n0, t0 = c.n, time.perf_counter()
    target = seen_target(truth_mask, s.z, s.volume.spacing, 4.0)
    cell = await _to_target(c, app, target, truth_mask, exact=False)
    await c.click("#main", cell)
    await wait_for(pilot, lambda: ws.seed_range.result is not None, timeout=60, what="the seed range")
    await pilot.pause()
    lo_bar, hi_bar = _histogram_bars(ws.seed_range.result)
    picked = await _panel_bar_click(c, app, lo_bar) and await _panel_bar_click(c, app, hi_bar)
    if not picked:  # no panel on screen: typed
        rc = ws.seed_range.result
        text = f"{rc.edges[lo_bar]:.0f}:{rc.edges[hi_bar + 1]:.0f}"
        from ctui.screens.testing import answer_prompt

        await c.press("T")
        c.n += len(text) + 1
        c.typed += len(text)
        await answer_prompt(pilot, text)
    await c.press("m")
    shots: dict = {}
    await c.press("S")
    got = await _wait_proposal(pilot, ws)
    await _dialog(c, app, "mr-proposal", shots, png)
    if got:
        await c.press("a")
    failed = "" if got else "; ".join(n.message for n in list(app._notifications)[-2:])
    z, y, x = target
    return {"organ": name, "object": s.current, "seed_xyz": (x, y, z), "seed_used": None, "proposal": got,
            "failed": failed, "events": c.n - n0, "seconds": time.perf_counter() - t0, "cursor": s.zyx,
            "range": s.range_, "options": dict(s.segment_options), "mode": s.prop_mode, "dialogs": shots}


def liver_task(size: tuple[int, int], data: Path, out_dir: Path, use_range: bool = False) -> dict | str:
    """The liver (label 5) of ``ct_abdomen_3mm.nii.gz``; a string says why it was skipped."""
    from ctui.engine.actions.opened import open_input

    image, labels = data / "ct_abdomen_3mm.nii.gz", data / "ct_abdomen_3mm_labels.nii.gz"
    if not image.exists():
        return f"{image} is missing"
    truth = open_input(str(labels)).labels == 5
    return asyncio.run(one_structure(size, image, truth, "liver", out_dir=out_dir, use_range=use_range))


def ventricles_task(size: tuple[int, int], data: Path, out_dir: Path, use_range: bool = False,
                    png: Path | None = None) -> dict | str:
    """The lateral ventricles (label 1, "vent-lat") of ITK-SNAP's MR brain sample. ctui reads no GIPL:
    the image and its labels are written as NIfTI into ``out_dir`` (SimpleITK) first."""
    orig, seg = data / "MRIcrop-orig.gipl.gz", data / "MRIcrop-seg.gipl.gz"
    if not orig.exists():
        return f"{orig} is missing"
    try:
        import SimpleITK as sitk
    except ImportError:
        return "SimpleITK (to read GIPL) is not installed"
    folder = out_dir / "mr"
    folder.mkdir(exist_ok=True)
    image, labels = folder / "brain_mr.nii.gz", folder / "brain_mr_labels.nii.gz"
    sitk.WriteImage(sitk.ReadImage(str(orig)), str(image))
    sitk.WriteImage(sitk.ReadImage(str(seg)), str(labels))
    from ctui.engine.actions.opened import open_input

    truth = open_input(str(labels)).labels == 1
    return asyncio.run(one_structure(size, image, truth, "lateral_ventricles", out_dir=out_dir,
                                     use_range=use_range, png=png))


def _picked(r: dict) -> str:
    """What the ventricles' task chose in the TUI (range, mode, neck), or ""."""
    if r.get("range") is None:
        return ""
    lo, hi = r["range"]
    return f"  range {lo:g}..{hi:g} picked, {r['mode']}, neck {r['options'].get('neck')}"


def print_structures(sizes, data: Path, mr: Path, *, use_range: bool = False, png: Path | None = None) -> int:
    """Issue 37's liver and MR lateral ventricles at each size: events by kind and Dice."""
    print("ctui TUI tasks: liver (ct_abdomen_3mm, label 5), lateral ventricles (ITK-SNAP MR brain, label 1); "
          f"deepest voxel as the seed, {'typed 5-95% range, ' if use_range else ''}the TUI's defaults")
    print(f"{'size':>7} {'structure':<19} {'events':>6} {'keys':>5} {'clicks':>6} {'typed':>5} {'save':>4} "
          f"{'seconds':>8} {'Dice':>6} {'vol ratio':>9}")
    for size in sizes:
        for task, folder in ((liver_task, data), (ventricles_task, mr)):
            with tempfile.TemporaryDirectory() as tmp:
                r = task(size, folder, Path(tmp), use_range, **({"png": png} if task is ventricles_task else {}))
            if isinstance(r, str):
                print(f"{size[0]:>3}x{size[1]:<3} skipped: {r}")
                continue
            keys = r["events"] - r["clicks"] - r["typed"]
            print(f"{size[0]:>3}x{size[1]:<3} {r['organ']:<19} {r['events']:>6} {keys:>5} {r['clicks']:>6} "
                  f"{r['typed']:>5} {r['save_events']:>4} {r['seconds']:>8.1f} {r['dice']:>6.3f} "
                  f"{r['volume_ratio']:>9.2f}"
                  f"{'' if r['proposal'] else '  (no proposal: ' + r['failed'][:100] + ')'}"
                  f"{'; errors: ' + str(len(r['errors'])) if r['errors'] else ''}"
                  f"{_picked(r)}")
            if r.get("dialogs"):
                bad = {k: v for k, v in r["dialogs"].items() if v}
                print(f"{'':>7} screens captured: {', '.join(r['dialogs'])}; "
                      + ("every dialog's buttons in view" if not bad else f"PROBLEMS: {bad}"))
    print("(events: the structure's, from the workspace to the accepted object; save: Ctrl+S and Enter)")
    return 0
