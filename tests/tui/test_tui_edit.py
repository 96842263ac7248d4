"""Editing tools and orthogonal views of the workspace, driven by keys with Textual's
Pilot on small synthetic volumes with known answers: brush and eraser voxel counts,
replace and subtract modes, slice and HU limits, stop-at-slice propagation, islands,
fill between slices, sagittal/coronal views with orientation letters and the true
aspect of anisotropic voxels, the proposal drawn apart from accepted voxels."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.volume import Volume
from ctui.screens import planes
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.testing import answer_prompt, wait_for, wait_workspace


def _cylinder(nz: int = 30, n: int = 48, spacing=(1.0, 1.0, 1.0), r: float = 10.0) -> Session:
    """A bright (300 HU) cylinder of radius ``r`` px along z in -1000 HU air."""
    yy, xx = np.mgrid[0:n, 0:n]
    disk = (yy - n / 2) ** 2 + (xx - n / 2) ** 2 <= r**2
    data = np.full((nz, n, n), -1000, np.int16)
    data[:, disk] = 300
    return Session(Volume(data, spacing=spacing, modality="CT"), source_path="synthetic", z=nz // 2,
                   y=n // 2, x=n // 2)


def _disk_count(r: int) -> int:
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return int((yy**2 + xx**2 <= r * r + 1e-6).sum())


@pytest.mark.slow
async def test_brush_and_eraser_counts_and_undo():
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s.brush = 3
        await pilot.press("space")
        assert s.seg.voxels(1) == _disk_count(3)
        # brush down, two steps right: a stroke of dabs
        await pilot.press("b", "l", "l", "b")
        assert s.seg.voxels(1) == _disk_count(3) + 2 * 7  # each 1-px step adds one new column of 7
        # eraser smaller than the brush removes its disk
        s.brush = 1
        await pilot.press("E", "space", "E")  # eraser down, a dab of it, lifted
        assert s.seg.voxels(1) == _disk_count(3) + 14 - _disk_count(1)
        await pilot.press("u")
        assert s.seg.voxels(1) == _disk_count(3) + 14
        # brush off the image: a message, nothing changed
        before = s.seg.labels.copy()
        ws = app.workspace
        with pytest.raises(Exception):
            ws.edit.dab("brush", (s.z, -5, 3))
        assert np.array_equal(before, s.seg.labels)
        assert not app.internal_errors


async def test_brush_down_paints_nothing_until_it_moves():
    """A painter's brush (issue 37): b b paints nothing; b then a move paints from where it went down
    to where it stops (both ends), as a drag would; lifting and putting it down again starts afresh."""
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s.brush = 3
        await pilot.press("b", "b")
        assert s.seg.voxels(1) == 0 and s.seg.undo_labels() == []
        await pilot.press("b")
        assert s.seg.voxels(1) == 0 and "Brush down" in str(app.workspace.query_one("#status").render())
        x0 = s.x
        await pilot.press("l", "l", "b")
        want = np.zeros(s.shape[1:], bool)
        yy, xx = np.mgrid[0:s.shape[1], 0:s.shape[2]]
        for cx in (x0, x0 + 1, x0 + 2):  # the dab where it went down, then one per step
            want |= (yy - s.y) ** 2 + (xx - cx) ** 2 <= 9 + 1e-6
        assert np.array_equal(s.seg.labels[s.z] == 1, want) and s.seg.voxels(1) == _disk_count(3) + 2 * 7
        await pilot.press("b", "b")  # down and up again somewhere painted: nothing new
        assert s.seg.voxels(1) == _disk_count(3) + 2 * 7


async def test_paint_limited_to_hu_range_and_slices():
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("i")
        await answer_prompt(pilot, f"slices {s.z - 1}:{s.z + 1} hu 200:400")
        assert s.limits.slices == (s.z - 1, s.z + 1) and s.limits.values == (200.0, 400.0)
        # a big brush centred on the rim: only the cylinder's voxels are painted
        s.x = s.x + 10
        s.brush = 6
        await pilot.press("space")
        lab = s.seg.labels == 1
        assert lab.any() and np.all(s.volume.data[lab] == 300)
        # in the sagittal view the brush spans slices, but the slice limit holds
        await pilot.press("2")
        s.brush = 8
        await pilot.press("space")
        zs = np.flatnonzero((s.seg.labels == 1).any(axis=(1, 2)))
        assert zs.min() == s.z - 1 and zs.max() == s.z + 1
        assert not app.internal_errors
        del ws


async def test_fill_modes_replace_and_subtract():
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s.range_ = (200.0, 400.0)
        area = int((s.volume.data[s.z] == 300).sum())
        # object 1 painted by brush outside the cylinder, then Enter in replace mode
        s.x, s.y = 3, 3
        await pilot.press("space")
        assert s.seg.voxels(1) > 0
        s.x, s.y = 24, 24
        await pilot.press("R")
        assert s.edit_mode == "replace"
        await pilot.press("enter")
        assert s.seg.voxels(1) == area  # the brush pixels on this slice were replaced by the fill
        await pilot.press("u")
        assert s.seg.voxels(1) == _disk_count(3)  # one undo step brings the brush pixels back
        await pilot.press("U", "R")
        assert s.edit_mode == "subtract"
        s.brush = 2
        await pilot.press("space")
        assert s.seg.voxels(1) == area - _disk_count(2)
        await pilot.press("R")
        assert s.edit_mode == "add"
        assert not app.internal_errors


async def test_stop_at_slice_limits_propagation():
    s = _cylinder(nz=30)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        s.range_ = (200.0, 400.0)
        z0 = s.z
        await pilot.press("enter")
        await pilot.press("g", *str(z0 + 5), "enter", "s")  # stop 5 slices above
        await pilot.press("g", *str(z0 - 3), "enter", "s")  # and 3 below
        assert s.limits.slices == (z0 - 3, z0 + 5)
        await pilot.press("g", *str(z0), "enter", "p")
        await wait_for(pilot, lambda: ws.pending.proposal is not None, what="the proposal")
        assert ws.pending.proposal.slices == (z0 - 3, z0 + 5)
        await pilot.press("a")
        zs = np.flatnonzero((s.seg.labels == 1).any(axis=(1, 2)))
        assert (zs.min(), zs.max()) == (z0 - 3, z0 + 5)
        assert not app.internal_errors


async def test_fill_between_slices_and_islands():
    s = _cylinder(nz=30)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s.range_ = (200.0, 400.0)
        area = int((s.volume.data[0] == 300).sum())
        for z in (5, 15):
            await pilot.press("g", *str(z), "enter", "enter")
        assert s.seg.voxels(1) == 2 * area
        await pilot.press("F")
        assert s.seg.voxels(1) == 11 * area  # slices 6..14 interpolated: the same disk
        # a stray island far away, removed by "keep largest island"
        s.z, s.x, s.y, s.brush = 25, 2, 2, 1
        await pilot.press("space")
        assert s.seg.voxels(1) == 11 * area + _disk_count(1)
        await pilot.press("I")
        assert s.seg.voxels(1) == 11 * area
        await pilot.press("u")
        await pilot.press("X")
        await answer_prompt(pilot, "10")
        assert s.seg.voxels(1) == 11 * area
        assert not app.internal_errors


async def test_sagittal_and_coronal_views_with_orientation_and_aspect():
    s = _cylinder(nz=20, n=40, spacing=(3.0, 1.0, 1.0))
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(140, 44)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        mv = ws.main_view
        await pilot.press("2")
        assert s.plane == "sagittal"
        cap = str(ws.query_one("#main-caption").render())
        assert "sagittal" in cap and "A" in cap and "P" in cap and "S" in cap and "I" in cap
        await wait_for(pilot, lambda: mv.rgb is not None and mv.rgb.shape[:2] == (20, 40), what="the sagittal plane")
        assert mv.spacing_yx == (3.0, 1.0)
        # the view keeps the physical aspect: 60 mm tall, 40 mm wide
        await pilot.pause()
        vm = mv.view_map
        assert abs((vm.h / vm.w) - 60 / 40) < 0.1
        # PageUp in the sagittal view moves along x; arrows move y and z (up = superior)
        x0, z0 = s.x, s.z
        await pilot.press("pageup", "up")
        assert s.x == x0 + 1 and s.z == z0 + 1
        await pilot.press("3")
        cap = str(ws.query_one("#main-caption").render())
        assert "coronal" in cap and "R" in cap and "L" in cap
        assert mv.rgb.shape[:2] == (20, 40)
        # the 2x2 layout: three planes and the 3D cell
        await pilot.press("0")
        assert ws.viewstate.ortho_mode
        for p in planes.PLANES:
            await wait_for(pilot, lambda p=p: ws.query_one(f"#o-{p}").rgb is not None, what=p)
        await pilot.press("0", "1")
        assert s.plane == "axial" and not ws.viewstate.ortho_mode
        assert not app.internal_errors


async def test_proposal_drawn_apart_from_accepted_voxels():
    s = _cylinder(nz=12)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        s.range_ = (200.0, 400.0)
        await pilot.press("enter", "p")
        await wait_for(pilot, lambda: ws.pending.proposal is not None, what="the proposal")
        await pilot.press("pageup")
        img = ws.plane_image("axial")
        assert (img == planes.PROPOSAL_EDGE).all(axis=2).any()  # the yellow outline of a proposal
        await pilot.press("2")
        img = ws.plane_image("sagittal")
        assert (img == planes.PROPOSAL_EDGE).all(axis=2).any()
        await pilot.press("a")
        img = ws.plane_image("sagittal")
        assert not (img == planes.PROPOSAL_EDGE).all(axis=2).any()


async def test_help_names_every_new_key():
    app = CtuiApp(session=_cylinder(), autosave_s=1e9)
    async with app.run_test(size=(140, 44)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.press("question_mark")
        await pilot.pause()
        text = str(app.screen.body)
        for words in ("Brush down", "Eraser down", "Brush larger", "Mode add/replace/subtract", "Limits",
                      "Stop at this slice", "Keep largest island", "Remove islands", "Fill between slices",
                      "Sagittal view", "Coronal view", "Axial view", "2x2: axial, sagittal, coronal, 3D"):
            assert words in text, words
