"""A scripted TUI session, as a person with a mouse would do it: open
``../shared/data/totalseg_example/ct_abdomen_3mm.nii.gz``, segment the left kidney (label 3)
and the spleen (label 1) with the TUI's default segmentation, save the project, and print
Dice against ``ct_abdomen_3mm_labels.nii.gz``, the input events per organ and the wall time,
at 160x50 and 80x24 (issue 22; goal <= 25 events per organ, Dice >= 0.90 kidney, >= 0.88
spleen; the keyboard-only kidney of the issue took 433 keys and 8.4 minutes).

The app is the real one (``CtuiApp(path)``) driven by Textual's Pilot with the events a
person sends: keys, mouse clicks, wheel notches (a drag would count as one press). Per
organ, from the workspace at the middle slice:

1. (second organ) ``n``: a new object;
2. to the organ as a person who sees the screen does it: on the slice shown (else the nearest slice
   where the organ's section is at least 8 mm deep; Home/End and wheel notches to it), at the
   deepest point of its section there; Ctrl+wheel notches on it only while a cell is wider than
   half the organ's depth there (a click anywhere in the cell must be inside); ``--hard``: the
   given voxel itself, zoomed until a cell spans under 1.5 voxels;
   with ``--box``, before it: ``y`` and one mouse drag on that slice draw the ROI box around the
   organ (its reference extent in the slice plane + 2 voxels, as a person draws it by eye);
3. a double click there (counted as two clicks): the segmentation from that point (``S`` at the
   click, the TUI's defaults), wait for the proposal;
4. with ``--review``: when the strip marks the seed slice (the fill leaked on it): the ROI box
   (``y`` + a drag) and ``p`` again (it replaces the proposal); then ``}`` to each marked slice and
   ``C`` where the proposal leaves the reference there (the person's eye, played by the reference);
   ``--hard``: when the proposal leaks, a right click in the leak (a background seed) and ``p``;
5. ``a``: accept (and ``-`` back to the whole slice when zoomed).

Then Ctrl+S and Enter (the default name). Events are counted as the Pilot sends them.
The targets come from the reference labels (where the organ shows); the positions and the
mouse cells go through ``ctui.screens.planes`` (the display is in the patient's frame).
Every table splits the events into keys, clicks (wheel notches and drags too) and typed characters.

    python3 benchmarks/tui_tasks.py [--size 160x50 --size 80x24] [--review] [--range] [--box]
    python3 benchmarks/tui_tasks.py --structures   # issue 37: the liver and the MR brain's lateral ventricles
    python3 benchmarks/tui_tasks.py --workflow [--png DIR]   # issue 37: segment, fix a leak, section, 3D, SEG + STL, save, reopen
    python3 benchmarks/tui_tasks.py --hard [--only liver]   (issue 34: the msd spleen, the abdomen's kidneys, spleen and liver from their least
        uniform part, one background click where the proposal leaks)
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("TEXTUAL_COLOR_SYSTEM", "truecolor")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # screen_capture

import numpy as np  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "totalseg_example"
ORGANS = (("kidney_left", 3), ("spleen", 1))


def seeds_and_truth(labels_path: Path, spacing) -> tuple[np.ndarray, dict]:
    """The reference labels and, per organ, its deepest voxel (z, y, x) and its 5-95th percentile range."""
    from scipy import ndimage

    from ctui.engine.actions.opened import open_input

    lab = open_input(str(labels_path)).labels
    out = {}
    for name, k in ORGANS:
        m = np.pad(lab == k, 1)
        dt = ndimage.distance_transform_edt(m, sampling=spacing)[1:-1, 1:-1, 1:-1]
        out[name] = tuple(int(v) for v in np.unravel_index(int(np.argmax(dt)), lab.shape))
    return lab, out


def dice(a: np.ndarray, b: np.ndarray) -> float:
    s = int(a.sum()) + int(b.sum())
    return 2.0 * int((a & b).sum()) / s if s else 1.0


class Counter:
    """The pilot's input events, counted (keys, clicks, wheel notches)."""

    def __init__(self, pilot) -> None:
        self.pilot = pilot
        self.n = 0
        self.clicks = 0  # of n: clicks, wheel notches, drags
        self.typed = 0  # of n: characters typed into prompts (the rest are keys)

    async def press(self, *keys: str) -> None:
        self.n += len(keys)
        await self.pilot.press(*keys)

    async def type(self, text: str) -> None:
        await self.press(*[{",": "comma", ":": "colon", "-": "minus", ".": "full_stop"}.get(c, c) for c in text])

    async def click(self, widget: str, offset) -> None:
        self.n += 1
        self.clicks += 1
        await self.pilot.click(widget, offset=offset)

    async def double_click(self, widget: str, offset) -> None:
        """Two clicks (counted as two events)."""
        self.n += 2
        self.clicks += 2
        await self.pilot.double_click(widget, offset=offset)

    async def right_click(self, widget: str, offset) -> None:
        self.n += 1
        self.clicks += 1
        await self.pilot.click(widget, offset=offset, button=3)

    async def wheel(self, widget: str, up: bool) -> None:
        from ctui.screens.testing import wheel

        self.n += 1
        self.clicks += 1
        await wheel(self.pilot, widget, up=up)

    async def wheel_at(self, widget: str, offset, *, control: bool = False) -> None:
        from ctui.screens.testing import wheel

        self.n += 1
        self.clicks += 1
        await wheel(self.pilot, widget, offset, up=True, control=control)



async def save_project(c: Counter, pilot, s) -> int:
    """Ctrl+S and Enter (the save dialog's default name), until the project is on disk: the events."""
    from ctui.screens.testing import wait_for

    n_save = c.n
    await c.press("ctrl+s")
    await pilot.pause()
    await c.press("enter")
    await wait_for(pilot, lambda: s.project_path is not None and Path(s.project_path).exists(), timeout=60,
                   what="the saved project")
    return c.n - n_save

async def _wait_proposal(pilot, ws, timeout: float = 300.0) -> bool:
    end = time.monotonic() + timeout
    await pilot.pause(0.05)
    while time.monotonic() < end:
        if not ws.jobs.segmenting:
            return ws.pending.proposal is not None
        await pilot.pause(0.05)
    return False


async def _review(c: Counter, ws, truth_mask: np.ndarray) -> None:
    """``}`` through the marks; ``C`` at the first one where the proposal's slice overlaps the
    reference less than half (what the person sees as the leak) - then the rest is gone."""
    s = ws.s
    for _ in range(12):
        before = s.z
        await c.press("right_curly_bracket")
        if s.z == before or ws.pending.proposal is None:
            return
        prop = ws.pending.proposal.slice_mask(s.z)
        ref = truth_mask[s.z]
        if prop.any() and dice(prop, ref) < 0.5:
            await c.press("C")
            return


async def _box(c: Counter, app, truth_mask: np.ndarray, z: int) -> None:
    """``y`` and a drag between two corners of the organ's extent (+2 voxels) on slice ``z``."""
    from ctui.screens.testing import cell_of_voxel, drag

    s = app.session
    ys, xs = np.nonzero(truth_mask.any(axis=0))
    ny, nx = s.shape[1:]
    a = (z, max(int(ys.min()) - 2, 0), max(int(xs.min()) - 2, 0))
    b = (z, min(int(ys.max()) + 2, ny - 1), min(int(xs.max()) + 2, nx - 1))
    await c.press("y")
    c.n += 1  # one drag
    c.clicks += 1
    await drag(c.pilot, "#main", [cell_of_voxel(app, a), cell_of_voxel(app, b)])


def cell_mm(ws) -> float:
    """The width in mm that one terminal cell of the main view covers (the larger of its two sides)."""
    vm = ws.main_view.view_map
    sp = ws.s.volume.spacing
    return max(float(sp[2]) / vm.sx, 2.0 * float(sp[1]) / vm.sy)


def in_slice_depth(mask2d: np.ndarray, spacing_yx) -> np.ndarray:
    """mm from each pixel of ``mask2d`` to its outline on that slice."""
    from scipy import ndimage

    return ndimage.distance_transform_edt(np.pad(mask2d, 1), sampling=spacing_yx)[1:-1, 1:-1]


def seen_target(mask: np.ndarray, z_now: int, spacing, min_mm: float) -> tuple[int, int, int]:
    """What a person who sees the screen clicks: the nearest slice to ``z_now`` (the one shown first) where the
    organ's section is at least ``min_mm`` deep, at its deepest point there (z, y, x); else its deepest voxel."""
    zs = [z for z in np.flatnonzero(mask.any(axis=(1, 2)))]
    for z in sorted(zs, key=lambda k: (abs(int(k) - z_now), k)):
        dt = in_slice_depth(mask[z], spacing[1:])
        if dt.max() >= min_mm:
            y, x = np.unravel_index(int(np.argmax(dt)), dt.shape)
            return int(z), int(y), int(x)
    return deepest(mask, spacing)


async def _to_target(c: Counter, app, target, truth_mask: np.ndarray | None, *, exact: bool) -> tuple[int, int]:
    """Wheel notches to the target's slice and Ctrl+wheel notches on it until a click lands where it should:
    ``exact`` (a given voxel) until a cell spans under 1.5 voxels; else until the cell is under half the
    organ's depth there (a click anywhere in the cell is inside). Returns the cell to click."""
    from ctui.screens.testing import cell_of_voxel

    ws, s, pilot = app.workspace, app.session, c.pilot
    z, y, x = target
    last = s.shape[0] - 1
    if min(z, last - z) + 1 < abs(z - s.z):  # Home / End, then the wheel: fewer events than the wheel alone
        await c.press("home" if z < last - z else "end")
    while s.z != z:
        await c.wheel("#main", up=z > s.z)
    await pilot.pause()

    def off_view() -> bool:
        col, row = cell_of_voxel(app, (z, y, x))
        region = ws.main_view.content_region
        return not (0 <= col < region.width and 0 <= row < region.height)
    while ws.viewstate.zoom > 1 and off_view():  # zoomed in elsewhere: out until the target shows
        await c.press("minus")
        await pilot.pause()
    if exact:
        def fine() -> bool:
            vm = ws.main_view.view_map
            return max(1.0 / vm.sx, 2.0 / vm.sy) <= 1.5
    else:
        depth = float(in_slice_depth(truth_mask[z], s.volume.spacing[1:])[y, x])

        def fine() -> bool:
            return cell_mm(ws) <= depth / 2
    for _ in range(4):
        if fine():
            break
        await c.wheel_at("#main", cell_of_voxel(app, (z, y, x)), control=True)
        await pilot.pause()
    return cell_of_voxel(app, (z, y, x))


async def _organ(c: Counter, app, name: str, seed, truth_mask: np.ndarray, *, first: bool, review: bool,
                 rng: tuple[float, float] | None, box: bool = False, exact: bool = False,
                 accept: bool = True) -> dict:
    """One organ: (``n``), (``T`` + its range), to a slice where the organ shows and a double click on it (the
    segmentation from there), ``a``. ``exact``: the click is on ``seed`` itself (issue 34's least uniform seed),
    else where a person sees the organ (:func:`seen_target`)."""
    from ctui.screens.testing import answer_prompt

    ws, s = app.workspace, app.session
    pilot = c.pilot
    n0, k0, y0, t0 = c.n, c.clicks, c.typed, time.perf_counter()
    if not first:
        await c.press("n")
    if rng is not None:
        await c.press("T")
        c.n += len(f"{rng[0]:g}:{rng[1]:g}") + 1  # typed into the prompt, then Enter
        c.typed += len(f"{rng[0]:g}:{rng[1]:g}")
        await answer_prompt(pilot, f"{rng[0]:g}:{rng[1]:g}")
    target = tuple(seed) if exact else seen_target(truth_mask, s.z, s.volume.spacing, 8.0)
    z, y, x = target
    if box:
        while s.z != z:
            await c.wheel("#main", up=z > s.z)
        await _box(c, app, truth_mask, z)
    cell = await _to_target(c, app, target, truth_mask, exact=exact)
    await c.double_click("#main", cell)  # the cursor there and the segmentation from it
    got = await _wait_proposal(pilot, ws)
    filled = 0
    if got and review and any(m.kind == "seed" for m in ws.review.review_marks()):
        # the strip marks the seed slice itself: the fill leaked there. Box the organ, segment again (p: the
        # proposal's own seed; the box confines the fill and the propagation)
        await _box(c, app, truth_mask, z)
        await c.press("p")
        got = await _wait_proposal(pilot, ws)
    if got and review:
        await _review(c, ws, truth_mask)
    failed = "" if got else "; ".join(n.message for n in list(app._notifications)[-2:])
    if got and accept:
        await c.press("a")
        while app.workspace.viewstate.zoom > 1:  # back to the whole slice for the next organ
            await c.press("minus")
    await pilot.pause()
    info = s.seg.objects.get(s.current)
    used = tuple(info.seeds[-1]) if info is not None and info.seeds else (ws.pending.seed if not accept else None)
    return {"organ": name, "object": s.current, "seed_xyz": (x, y, z), "seed_used": used, "seed_fill": filled, "proposal": got,
            "failed": failed,
            "events": c.n - n0, "clicks": c.clicks - k0, "typed": c.typed - y0,
            "seconds": time.perf_counter() - t0, "cursor": s.zyx}


async def session(size: tuple[int, int], image: Path, labels: Path, *, review: bool, use_range: bool,
                  out_dir: Path, box: bool = False) -> dict:
    from ctui.screens import graphics
    from ctui.screens.app import CtuiApp
    from ctui.screens.testing import wait_workspace

    graphics._chosen = "halfblock"
    os.chdir(out_dir)
    os.environ["CTUI_AUTOSAVE_DIR"] = str(out_dir / "autosave")
    app = CtuiApp(str(image), autosave_s=1e9)
    rows = []
    t_start = time.perf_counter()
    async with app.run_test(size=size) as pilot:
        await wait_workspace(pilot, app)
        await pilot.pause()
        s = app.session
        truth, seeds = seeds_and_truth(labels, s.volume.spacing)
        c = Counter(pilot)
        for i, (name, k) in enumerate(ORGANS):
            rng = None
            if use_range:
                vals = s.volume.data[truth == k]
                rng = (float(np.percentile(vals, 5)), float(np.percentile(vals, 95)))
            rows.append(await _organ(c, app, name, seeds[name], truth == k, first=i == 0, review=review, rng=rng,
                                     box=box))
        save_events = await save_project(c, pilot, s)
        proj_path = s.project_path
        errors = list(app.internal_errors) if hasattr(app, "internal_errors") else []
    wall = time.perf_counter() - t_start
    from ctui.engine.actions.project import load_project

    saved = load_project(proj_path).labels
    for r, (_name, k) in zip(rows, ORGANS):
        got = saved == r["object"]
        ref = truth == k
        r["dice"] = dice(got, ref)
        r["volume_ratio"] = float(got.sum()) / max(int(ref.sum()), 1)
    return {"size": size, "organs": rows, "save_events": save_events, "wall_s": wall, "project": proj_path,
            "errors": errors}


async def _choose_by_keys(c: Counter, option_id: str) -> None:
    """A menu choice as a person makes it: Down to the option, then Enter (every key counted)."""
    ol = c.pilot.app.screen.query_one("OptionList")
    ids = [ol.get_option_at_index(i).id for i in range(ol.option_count)]
    await c.press(*(["down"] * ids.index(option_id)), "enter")


async def _dialog(c: Counter, app, step: str, shots: dict, png: Path | None) -> None:
    """The screen shown now, captured (``shots[step]``: the problems with its dialog's buttons, [] when none)."""
    from screen_capture import capture, dialog_problems

    await c.pilot.pause()
    w, h = app.size
    text = capture(app, f"{w}x{h}-{step}", png)
    shots[step] = dialog_problems(app, text) if app.screen is not app.workspace else []


WORKFLOW_LABEL = 2  # the right kidney: clicked where it shows on the middle slice, it takes in the liver below


async def _back_on(c: Counter, app, ref: np.ndarray) -> None:
    """A click on the object where it is deepest on the slice shown (when the cursor is off it), for the section
    through the cursor."""
    s = app.session
    obj = s.seg.labels[s.z] == s.current
    if obj[s.y, s.x] or not (obj & ref[s.z]).any():
        return
    from ctui.screens.testing import cell_of_voxel

    dt = in_slice_depth(obj & ref[s.z], s.volume.spacing[1:])
    y, x = np.unravel_index(int(np.argmax(dt)), dt.shape)
    await c.click("#main", cell_of_voxel(app, (s.z, int(y), int(x))))
    await c.pilot.pause()


async def workflow(size: tuple[int, int], image: Path, labels: Path, *, out_dir: Path, png: Path | None = None) -> dict:
    """Issue 37's whole workflow on the abdomen CT written as a DICOM series (a SEG needs its source images):
    the right kidney as in :func:`session` (clicked where it shows on the middle slice, the proposal takes in the
    liver below it), the leak fixed on the slices the person drags on the review strip with a box and the
    scissors (:mod:`tui_tasks_fix`; Dice and volume before and after), a click back on the kidney and a section
    through it at the cursor (``M``, ``x``, the object's axis), the 3D
    view (``r``, Escape), the DICOM-SEG and the kidney's STL (``e``), the project saved and reopened with its
    set-up. Events split by kind: keys, clicks (and wheel notches, drags), typed characters. Every dialog is
    captured (``png``: its PNG written there) and its buttons checked in view."""
    from ctui.engine.io.phantom import write_series
    from ctui.engine.io.series import load
    from ctui.screens import graphics
    from ctui.screens.app import CtuiApp
    from ctui.screens.imageview import ImageView
    from ctui.screens.measure_screen import MeasureScreen
    from ctui.screens.testing import wait_for, wait_workspace
    from ctui.screens.view3d import View3DScreen
    from tui_tasks_fix import fix_leak

    graphics.use_graphics("halfblock")
    os.chdir(out_dir)
    os.environ["CTUI_AUTOSAVE_DIR"] = str(out_dir / "autosave")
    series = out_dir / "series"
    write_series(series, load(str(image)), description="abdomen CT")  # the same grid (values below -1024 clipped)
    app = CtuiApp(str(series), autosave_s=1e9)
    out: dict = {"size": size}
    shots: dict = {}
    async with app.run_test(size=size) as pilot:
        await wait_workspace(pilot, app)
        await pilot.pause()
        s = app.session
        truth, seeds = seeds_and_truth(labels, s.volume.spacing)
        c = Counter(pilot)
        await _dialog(c, app, "workspace", shots, png)
        ref = truth == WORKFLOW_LABEL
        organ = await _organ(c, app, "kidney_right", None, ref, first=True, review=False, rng=None, accept=False)
        out["organ_events"] = organ["events"]
        await _dialog(c, app, "kidney", shots, png)
        async def shot(step: str) -> None:
            await _dialog(c, app, step, shots, png)
        out["fix"] = await fix_leak(c, app, ref, shot)  # the strip's slices, accept, a box, scissors on them
        organ["object"] = s.current
        await _dialog(c, app, "fixed", shots, png)
        await _back_on(c, app, ref)
        await c.press("M")  # the section through the cursor, which the click left in the kidney
        await wait_for(pilot, lambda: isinstance(app.screen, MeasureScreen) and app.screen.stats, timeout=120,
                       what="the measures")
        ms = app.screen
        await c.press("x")
        await _dialog(c, app, "section-menu", shots, png)
        await _choose_by_keys(c, "object")
        await wait_for(pilot, lambda: "at x" in str(ms.query_one("#ms-status").render()), timeout=120,
                       what="the section")
        out["section"] = str(ms.query_one("#ms-status").render())
        await _dialog(c, app, "measure", shots, png)
        await c.press("escape")
        await c.press("r")
        await wait_for(pilot, lambda: isinstance(app.screen, View3DScreen)
                       and app.screen.query_one(ImageView).rgb is not None, timeout=180, what="the 3D view")
        out["view3d"] = tuple(app.screen.query_one(ImageView).rgb.shape[:2])
        await _dialog(c, app, "3d", shots, png)
        await c.press("escape")
        for kind, pattern in (("dicom-seg", "*.dcm"), ("stl", "*.stl")):
            await c.press("e")
            await _dialog(c, app, f"export-{kind}", shots, png)
            await _choose_by_keys(c, kind)
            await _dialog(c, app, f"export-{kind}-name", shots, png)
            await c.press("enter")  # the default name
            await wait_for(pilot, lambda p=pattern: any(out_dir.glob(p)), timeout=120, what=kind)
        await c.press("ctrl+s")
        await _dialog(c, app, "save", shots, png)
        await c.press("enter")
        await wait_for(pilot, lambda: s.project_path is not None and Path(s.project_path).exists(), timeout=60,
                       what="the saved project")
        out["events"] = c.n
        out["clicks"] = c.clicks
        out["typed"] = c.typed
        out["errors"] = list(app.internal_errors)
        proj = s.project_path
        await c.press("G")  # not counted: the segmentation options dialog, captured at this size
        await _dialog(c, app, "segmentation-options", shots, png)
        await c.press("escape")
    app2 = CtuiApp(project=proj, autosave_s=1e9)
    async with app2.run_test(size=size) as pilot:
        await wait_workspace(pilot, app2)
        got = app2.session.seg.labels == organ["object"]
        out["reopened_dice"] = dice(got, ref)
    out["files"] = sorted(p.name for p in out_dir.iterdir() if p.suffix in (".stl", ".dcm"))
    out["dialogs"] = shots
    return out



MR_BRAIN = Path(__file__).resolve().parents[2] / "shared" / "data" / "itksnap_brain_mr"

def deepest(mask: np.ndarray, spacing) -> tuple[int, int, int]:
    """The voxel (z, y, x) of ``mask`` farthest from its surface (the seed a person picks in the middle)."""
    from scipy import ndimage

    dt = ndimage.distance_transform_edt(np.pad(mask, 1), sampling=spacing)[1:-1, 1:-1, 1:-1]
    return tuple(int(v) for v in np.unravel_index(int(np.argmax(dt)), mask.shape))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", action="append", default=None, help="terminal WxH (repeatable; default 160x50 and 80x24)")
    ap.add_argument("--data", default=str(DATA), help="the totalseg_example folder")
    ap.add_argument("--review", action="store_true", help="review the proposal's marked slices and cut at a leak")
    ap.add_argument("--range", action="store_true", help="type the organ's 5-95th percentile range (T) first")
    ap.add_argument("--box", action="store_true", help="draw the ROI box around the organ (y + a drag) before the fill")
    ap.add_argument("--only", action="append", default=None, help="with --hard: only these organs (repeatable)")
    ap.add_argument("--hard", action="store_true", help="issue 34: the msd spleen and the left kidney from the seed in "
                    "their least uniform part, with one background click where the proposal leaks")
    ap.add_argument("--workflow", action="store_true", help="issue 37's whole workflow (kidney, leak fix, section, "
                    "3D, SEG + STL, save, reopen) instead of the organs")
    ap.add_argument("--structures", action="store_true", help="issue 37's liver and MR lateral ventricles "
                    "instead of the kidney and spleen")
    ap.add_argument("--mr", default=str(MR_BRAIN), help="the itksnap_brain_mr folder")
    ap.add_argument("--vessel", action="store_true", help="issue 35: the aorta with the vessel tool in tmux "
                    "(benchmarks/tui_vessel.py)")
    ap.add_argument("--png", default=None, help="with --workflow or --structures: write a PNG (and SVG) of each "
                    "screen there")
    args = ap.parse_args(argv)
    if args.vessel:
        from tui_vessel import main as vessel_main

        return vessel_main([f"--size={v}" for v in args.size or []])
    data = Path(args.data)
    image, labels = data / "ct_abdomen_3mm.nii.gz", data / "ct_abdomen_3mm_labels.nii.gz"
    if not image.exists():
        print(f"skipped: {image} is missing")
        return 0
    sizes = [tuple(int(v) for v in s.lower().split("x")) for s in (args.size or ["160x50", "80x24"])]
    if args.workflow:
        return print_workflow(sizes, image, labels, None if args.png is None else Path(args.png).resolve())
    if args.structures:
        from tui_tasks_structures import print_structures

        return print_structures(sizes, data, Path(args.mr), use_range=args.range,
                                png=None if args.png is None else Path(args.png).resolve())
    if args.hard:
        from tui_tasks_hard import print_hard

        return print_hard(sizes, data.parent, args.only)
    print(f"ctui TUI tasks on {image.name}: left kidney (label 3), spleen (label 1); "
          f"{'review marks; ' if args.review else ''}{'typed 5-95% range; ' if args.range else ''}"
          f"{'ROI box drawn; ' if args.box else ''}"
          "defaults otherwise")
    print(f"{'size':>7} {'organ':<12} {'events':>6} {'keys':>5} {'clicks':>6} {'typed':>5} {'seconds':>8} {'Dice':>6} "
          f"{'vol ratio':>9}  clicked x,y,z")
    for size in sizes:
        with tempfile.TemporaryDirectory() as tmp:
            res = asyncio.run(session(size, image, labels, review=args.review, use_range=args.range, out_dir=Path(tmp),
                                      box=args.box))
        for r in res["organs"]:
            keys = r["events"] - r["clicks"] - r["typed"]
            print(f"{size[0]:>3}x{size[1]:<3} {r['organ']:<12} {r['events']:>6} {keys:>5} {r['clicks']:>6} {r['typed']:>5} "
                  f"{r['seconds']:>8.1f} {r['dice']:>6.3f} "
                  f"{r['volume_ratio']:>9.2f}  {','.join(map(str, r['seed_xyz']))}"
                  f"{'' if r['seed_used'] in (None, r['seed_xyz']) else ' (clicked ' + ','.join(map(str, r['seed_used'])) + ')'}"
                  f"{'' if r['proposal'] else '  (no proposal: ' + r['failed'][:120] + ')'}")
        print(f"{'':>7} save: {res['save_events']} events; session wall time {res['wall_s']:.1f} s"
              f"{'; errors: ' + str(res['errors']) if res['errors'] else ''}")
    print("issue 22 baseline (keyboard only, by hand): one kidney 433 keys / 8.4 min; kidney + spleen 959 keys / 9.9 min")
    return 0


def print_workflow(sizes, image: Path, labels: Path, png: Path | None = None) -> int:
    print(f"ctui TUI workflow on {image.name} written as a DICOM series: right kidney (label 2), its leak fixed "
          "(strip slices, box, scissors), a section through it, the 3D view, DICOM-SEG and STL, save, reopen")
    print(f"{'size':>7} {'events':>6} {'keys':>5} {'clicks':>6} {'typed':>5} {'organ':>5}  reopened Dice  3D px   files; section")
    for size in sizes:
        with tempfile.TemporaryDirectory() as tmp:
            r = asyncio.run(workflow(size, image, labels, out_dir=Path(tmp), png=png))
        print(f"{size[0]:>3}x{size[1]:<3} {r['events']:>6} {r['events'] - r['clicks'] - r['typed']:>5} {r['clicks']:>6} "
              f"{r['typed']:>5} "
              f"{r['organ_events']:>5}  {r['reopened_dice']:>13.3f}  {r['view3d'][1]}x{r['view3d'][0]}  "
              f"{', '.join(r['files'])}; {r['section'][:70]}"
              f"{'; errors: ' + str(len(r['errors'])) if r['errors'] else ''}")
        f = r["fix"]
        if f["slices"] is None:
            print(f"{'':>7} fix: no leak (Dice {f['before'][0]:.3f}, volume {f['before'][1]:.2f}x the reference)")
        else:
            print(f"{'':>7} fix: slices {f['slices'][0]}..{f['slices'][1]} (strip limits {f.get('limits')}), box "
                  f"{f.get('roi_box')}: {f['events']} events ({f['events'] - f['clicks'] - f['typed']} keys, "
                  f"{f['clicks']} clicks, {f['typed']} typed); Dice {f['before'][0]:.3f} -> {f['after'][0]:.3f}, "
                  f"volume {f['before'][1]:.2f} -> {f['after'][1]:.2f}x the reference")
        bad = {k: v for k, v in r["dialogs"].items() if v}
        print(f"{'':>7} screens captured: {', '.join(r['dialogs'])}; "
              + ("every dialog's buttons in view" if not bad else f"PROBLEMS: {bad}"))
    if png is not None:
        print(f"(PNGs of the screens in {png})")
    return 0


# --------------------------------------------------------------- issue 34: a seed in the organ's least uniform part

if __name__ == "__main__":
    sys.exit(main())
