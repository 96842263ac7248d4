"""The workspace's vessel tool (D: start and waypoints at the cursor, O: the end, then a accepts),
driven with Textual's Pilot, gives the same voxels as ``actions.vessel.vessel`` from the same points."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.actions.vessel import vessel
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.testing import wait_for, wait_workspace
from test_vessel import Z0, u_bend


async def test_vessel_tool_start_waypoint_end_accept():
    vol, truth, _ = u_bend(noise=0.0)
    start, via, end = (30, 20, Z0), (30, 32, 42), (30, 44, Z0)
    want = vessel(vol, start=start, vias=[via], ends=[end]).mask
    s = Session(vol, z=start[2], y=start[1], x=start[0])
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("O")  # no start yet: nothing runs
        await pilot.pause()
        assert ws.pending.proposal is None and not ws.jobs.segmenting
        for p in (start, via):
            s.z, s.y, s.x = p[2], p[1], p[0]
            await pilot.press("D")
        assert "waypoint 1" in str(ws.query_one("#status").render())
        s.z, s.y, s.x = end[2], end[1], end[0]
        await pilot.press("O")
        await wait_for(pilot, lambda: ws.pending.proposal is not None, timeout=120, what="the vessel proposal")
        await wait_for(pilot, lambda: "Vessel proposal: path" in str(ws.query_one("#status").render()),
                       what="the vessel's report in the status line")
        await pilot.press("a")
        await pilot.pause()
        got = s.seg.labels == s.current
        assert np.array_equal(got, want)
        assert 2.0 * (got & truth).sum() / (got.sum() + truth.sum()) >= 0.9


def _path_pixels(ws, plane: str, size=(240, 240)):
    """Display pixels of the vessels' overlay on ``plane`` at the cursor: (bright path (k, 2) x, y,
    the plane's view, the view map), drawn by the workspace's own overlay on a blank image."""
    from ctui.screens import cells, planes
    from ctui.screens.vessel_tool import PATH_COLOR
    from ctui.screens.ws_overlay import draw_overlay

    s = ws.s
    pv = planes.plane_view(s.volume, plane)
    h, w = s.shape[pv.rows], s.shape[pv.cols]
    grid, vm = cells.render_view(np.zeros((h, w, 3), np.uint8), size, spacing_yx=pv.spacing_yx)
    grid = grid.copy()
    draw_overlay(ws, plane, grid, vm)
    ys, xs = np.nonzero(np.all(grid == PATH_COLOR, axis=2))
    return np.stack([xs, ys], axis=1), pv, vm, grid


async def test_vessel_path_on_every_view_and_report_in_measure_screen():
    """The marks while points are placed, the path of the proposal and of the accepted object on
    the three planes (bright where it crosses the plane, at the path's voxels), and the vessel's
    report (length, diameters, max per segment) in the measure screen."""
    from ctui.screens import planes
    from ctui.screens.vessel_tool import START_COLOR

    vol, truth, length = u_bend(noise=0.0)
    start, via, end = (30, 20, Z0), (30, 32, 42), (30, 44, Z0)
    s = Session(vol, z=start[2], y=start[1], x=start[0])
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("D")
        *_, grid = _path_pixels(ws, "axial")
        assert np.all(grid == START_COLOR, axis=2).sum() >= 9  # the start, filled on its slice
        s.z, s.y, s.x = via[2], via[1], via[0]
        await pilot.press("D")
        s.z, s.y, s.x = end[2], end[1], end[0]
        await pilot.press("O")
        await wait_for(pilot, lambda: ws.pending.proposal is not None, timeout=120, what="the vessel proposal")
        assert len(ws.vessel.records()) == 1  # the proposal's path, before it is accepted
        await pilot.press("a")
        await pilot.pause()
        rec = ws.vessel.records()[0]
        path = np.asarray(rec["path"])
        assert np.abs(path[:, 2] - 30).max() <= 1.0  # the tube's axis: x = 30
        # the sagittal plane through x = 30 holds the whole path; the axial plane z = Z0 crosses both legs
        s.x = 30
        pix, pv, vm, _ = _path_pixels(ws, "sagittal")
        assert len(pix) > 100
        img = np.array([vm.to_image(x, y) for x, y in pix])
        vox = np.array([planes.voxel_of(pv, c, r, s.zyx, s.shape) for c, r in img])
        d = np.min(np.linalg.norm(vox[:, None, :] - path[None, :, :], axis=2), axis=1)
        assert np.percentile(d, 95) <= 1.5  # drawn where the path runs
        s.z = Z0
        pix, pv, vm, _ = _path_pixels(ws, "axial")
        cols = np.array([vm.to_image(x, y)[0] for x, y in pix])
        legs = [planes.cursor_in(pv, (Z0, y, 30), s.shape)[0] for y in (20, 44)]
        assert all(np.abs(cols - c).min() <= 1.5 for c in legs)  # both legs crossed, bright
        s.z = 45  # above the arch: the path is off this slice, only its dim projection
        assert len(_path_pixels(ws, "axial")[0]) == 0
        await pilot.press("M")
        info = app.screen.query_one("#ms-info")
        await wait_for(pilot, lambda: "max diameter per segment" in str(info.render()), timeout=120,
                       what="the vessel's report in the measure screen")
        text = str(info.render())
        rep = rec["report"]
        assert f"path {rep['length_mm'][0]:.0f} mm" in text
        assert rep["length_mm"][0] == pytest.approx(length, rel=0.05)
        assert rep["eq_diameter_mm"][1] == pytest.approx(8.0, rel=0.15)  # the tube: radius 4 mm
        assert f"max diameter {rep['max_diameter_mm']:.1f} mm at {rep['max_at_mm']:.0f} mm" in text
