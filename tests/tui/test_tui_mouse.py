"""The workspace's mouse with Textual's Pilot on a small synthetic volume with known
answers: a click moves the cursor, right/Ctrl-click places and removes a background
seed, a click outside the image changes nothing, click-fills fills, a drag paints and
erases with the brush (radius in mm), the wheel steps slices and Ctrl+wheel zooms, a
click on the side panel selects an object, "go to x,y,z", the ROI box dragged with the
mouse confines painting, and the 3D tools' bad input leaves labels and undo intact."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.volume import Volume
from ctui.screens import graphics
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.testing import answer_prompt, cell_of_voxel, choose, drag, wait_workspace, wheel


def _cylinder(nz: int = 30, n: int = 48, r: float = 10.0) -> Session:
    yy, xx = np.mgrid[0:n, 0:n]
    disk = (yy - n / 2) ** 2 + (xx - n / 2) ** 2 <= r**2
    data = np.full((nz, n, n), -1000, np.int16)
    data[:, disk] = 300
    return Session(Volume(data, spacing=(1.0, 1.0, 1.0), modality="CT"), source_path="synthetic", z=nz // 2,
                   y=n // 2, x=n // 2)


def _near(a, b, tol: int = 1) -> bool:
    return all(abs(int(u) - int(v)) <= tol for u, v in zip(a, b))


async def test_click_seed_outside_and_wheel():
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.pause()
        z = s.z
        # a click moves the cursor to the voxel under it
        target = (z, 10, 35)
        await pilot.click("#main", offset=cell_of_voxel(app, target))
        assert s.z == z and _near(s.zyx, target), s.zyx
        assert f"Cursor x {s.x}  y {s.y}" in str(app.workspace.query_one("#panel").render())
        # right click: a background seed there; Ctrl+click on it removes it
        at = (z, 30, 12)
        await pilot.click("#main", offset=cell_of_voxel(app, at), button=3)
        assert len(s.background_seeds) == 1
        x, y, zz = s.background_seeds[0]
        assert zz == z and _near((y, x), at[1:])
        await pilot.click("#main", offset=cell_of_voxel(app, (z, y, x)), control=True)
        assert s.background_seeds == []
        await pilot.press("B")
        assert s.background_seeds == [(s.x, s.y, s.z)]
        # a click outside the image (the letterbox left of it): nothing changes
        before = s.zyx
        iv = app.workspace.main_view
        assert iv.view_map.ox > 2
        await pilot.click("#main", offset=(0, 5))
        assert s.zyx == before
        assert "outside" in str(app.workspace.query_one("#status").render())
        # the wheel steps slices; Ctrl+wheel zooms
        await wheel(pilot, "#main", up=True)
        assert s.z == z + 1
        await wheel(pilot, "#main", up=False)
        await wheel(pilot, "#main", up=False)
        assert s.z == z - 1
        at = (s.z, 12, 14)
        await wheel(pilot, "#main", cell_of_voxel(app, at), up=True, control=True)
        assert app.workspace.viewstate.zoom == 2.0 and _near(s.zyx, at)  # zoomed in on the pointer: the cursor is there
        await pilot.pause()
        cx, cy = app.workspace.main_view.view_map.to_display(*app.workspace.main_view.cursor)
        w, h = app.workspace.main_view.size
        assert 0 < cx < w and 0 < cy < 2 * h  # and in view
        assert not app.internal_errors


async def test_click_fills_and_drag_paints_and_erases():
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.pause()
        z = s.z
        s.range_ = (200.0, 400.0)
        await pilot.press("z")
        assert app.workspace.edit_tools.click_fills
        await pilot.click("#main", offset=cell_of_voxel(app, (z, 24, 20)))
        area = int((s.volume.data[z] == 300).sum())
        assert s.seg.voxels(1) == area
        await pilot.press("z", "n")  # click moves again; a new object 2
        assert s.current == 2
        # brush down (radius 1 mm = 1 px here) then drag along row 5 from x 5 to x 30
        s.brush = 1.0
        app.workspace.edit_tools.pen = "brush"
        cells = [cell_of_voxel(app, (z, 5, x)) for x in (5, 12, 20, 30)]
        await drag(pilot, "#main", cells)
        lab = s.seg.labels[z] == 2
        ys, xs = np.nonzero(lab)
        a, b = int(xs.min()) + 1, int(xs.max()) - 1  # the dab centres at the ends
        rows = sorted(set(int(v) for v in ys))
        assert rows == list(range(rows[0], rows[0] + 3)) and abs(rows[1] - 5) <= 1  # one row (+-1 for the cell)
        assert int(lab.sum()) == 3 * (b - a + 1) + 2  # a 3-px-wide band with a one-pixel cap at each end
        assert (s.seg.labels[z] == 1).sum() == area  # the other object untouched
        # eraser drag over the middle of the band
        app.workspace.edit_tools.pen = "eraser"
        await drag(pilot, "#main", [cell_of_voxel(app, (z, 5, x)) for x in (14, 18)])
        assert (s.seg.labels[z] == 2).sum() < lab.sum()
        assert not (s.seg.labels[z, rows[1], 16] == 2)
        assert not app.internal_errors


@pytest.mark.slow
async def test_panel_click_goto_and_box_drag_confines_paint():
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.pause()
        ws = app.workspace
        await pilot.press("n", "n")
        assert s.current == 2
        from ctui.screens.ws_keys import panel_text

        lines = panel_text(ws).plain.split("\n")
        row = next(i for i, line in enumerate(lines) if "██" in line)  # object 1's line
        await pilot.click("#panel", offset=(6, row))
        assert s.current == 1
        # an object with a long name takes two lines: a click on either selects it
        s.seg.objects[2].name = "left kidney upper pole"
        ws.update_panel()
        lines = panel_text(ws).plain.split("\n")
        row2 = next(i for i, line in enumerate(lines) if "left kidney upper pole" in line)
        await pilot.click("#panel", offset=(20, row2 + 1))
        assert s.current == 2
        await pilot.click("#panel", offset=(6, row))
        assert s.current == 1
        # go to x,y,z
        await pilot.press("g")
        await answer_prompt(pilot, "10,12,5")
        assert s.zyx == (5, 12, 10)
        # y then a drag: the ROI box (all slices: drawn in one axial slice)
        await pilot.press("y")
        await drag(pilot, "#main", [cell_of_voxel(app, (5, 10, 10)), cell_of_voxel(app, (5, 20, 20))])
        assert s.roi_box is not None and s.zyx == (5, 12, 10)  # the cursor stays while the box is drawn
        (z0, z1), (y0, y1), (x0, x1) = s.roi_box
        assert (z0, z1) == (0, s.shape[0] - 1) and _near((y0, x0, y1, x1), (10, 10, 20, 20))
        # a big brush dab at the box corner paints only inside it
        s.brush = 6.0
        s.z, s.y, s.x = 5, y0, x0
        await pilot.press("space")
        lab = s.seg.labels == 1
        zz, yy, xx = np.nonzero(lab)
        assert lab.any() and yy.min() >= y0 and xx.min() >= x0
        # a zero-size box (two corners at one voxel) is refused: box unchanged
        box = s.roi_box
        await pilot.press("y", "y")
        assert s.roi_box == box
        # by the mouse too: a drag out and back to where it started
        await pilot.press("y")
        a = cell_of_voxel(app, (5, 30, 30))
        await drag(pilot, "#main", [a, (a[0] + 6, a[1] + 3), a])
        assert s.roi_box == box and ws.edit_tools.box_corner is None
        await pilot.press("Y")
        assert s.roi_box is None
        # typed corners (as ctui segment/edit --box); a zero-size one is refused
        await pilot.press("t")
        await choose(pilot, "box_typed")
        await answer_prompt(pilot, "5,6,2,20,30,9")
        assert s.roi_box == ((2, 9), (6, 30), (5, 20))
        await pilot.press("t")
        await choose(pilot, "box_typed")
        await answer_prompt(pilot, "5,6,2,5,30,9")
        assert s.roi_box == ((2, 9), (6, 30), (5, 20))
        assert not app.internal_errors


@pytest.mark.slow
async def test_edit_tools_bad_input_keeps_labels_and_undo():
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s.range_ = (200.0, 400.0)
        await pilot.press("enter")
        before = s.seg.labels.copy()
        undo = list(s.seg.undo_labels())
        # scissors with no box, smoothing an empty object, keep-island off the object
        await pilot.press("t")
        await choose(pilot, "scissors_in_slice")
        s.current = 3
        await pilot.press("t")
        await choose(pilot, "smooth")
        await answer_prompt(pilot, "median 3")
        s.current = 1
        s.x, s.y = 2, 2
        await pilot.press("t")
        await choose(pilot, "keep_island")
        # scissors with nothing inside the box
        s.roi_box = ((0, 29), (0, 5), (0, 5))
        await pilot.press("t")
        await choose(pilot, "scissors_in_box")
        assert np.array_equal(before, s.seg.labels) and list(s.seg.undo_labels()) == undo
        # and a real cut: the box's slices, inside (half the object: asked first, y does it)
        s.roi_box = ((s.z, s.z), (0, 47), (0, 23))
        await pilot.press("t")
        await choose(pilot, "scissors_in_box")
        assert np.array_equal(before, s.seg.labels)
        await pilot.press("y")
        await pilot.pause()
        assert s.seg.voxels(1) == int(before[s.z, :, 24:].astype(bool).sum())
        await pilot.press("u")
        assert np.array_equal(before, s.seg.labels)
        assert not app.internal_errors


async def test_help_names_the_mouse():
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.press("question_mark")
        await pilot.pause()
        from textual.widgets import Static

        text = " ".join(str(w.render()) for w in app.screen.query(Static))
        assert "Mouse" in text and "right click" in text and "wheel" in text


async def test_brush_footprint_drawn_at_any_zoom():
    """With the brush down its footprint (a green circle of the brush radius in mm) is drawn
    around the cursor: its radius on screen is the radius in mm times the zoom's pixels per mm."""
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        iv = app.workspace.main_view
        s.brush = 4.0
        app.workspace.edit_tools.pen = "brush"
        for zoom in (1.0, 4.0):
            app.workspace.viewstate.zoom = zoom
            app.workspace.refresh_view()
            await pilot.pause()
            grid = iv._grid((iv.size.width, 2 * iv.size.height))
            ys, xs = np.nonzero(np.all(grid == (80, 255, 80), axis=2))
            assert ys.size > 8
            cx, cy = iv.view_map.to_display(*iv.cursor)
            r = np.hypot(xs - cx, ys - cy)
            expect = (4.0 + 0.5) * iv.view_map.sx
            assert abs(float(np.median(r)) - expect) <= 1.5, (zoom, float(np.median(r)), expect)
        app.workspace.edit_tools.pen = None
        app.workspace.refresh_view()
        await pilot.pause()
        grid = iv._grid((iv.size.width, 2 * iv.size.height))
        assert not np.all(grid == (80, 255, 80), axis=2).any()  # lifted: no footprint


async def test_value_readout_raw_and_filtered():
    s = _cylinder()
    s.volume.data[s.z, s.y, s.x] = 0  # one dark voxel in the bright cylinder: a median removes it
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        panel = app.workspace.query_one("#panel")
        assert "Value 0 HU" in str(panel.render()) and "filtered" not in str(panel.render())
        s.pipeline.add("median", size=3)
        app.workspace.refresh_view()
        await pilot.pause()
        text = str(panel.render())
        assert "Value 0 HU" in text and "filtered 300" in text
        # the fill compares the filtered value: a range around 0 rejects it, and says why
        s.range_ = (-50.0, 50.0)
        await pilot.press("enter")
        await pilot.pause()
        assert s.seg.voxels(1) == 0
        assert any("filtered value 300" in n.message and "raw 0" in n.message for n in app._notifications)


async def test_polygon_scissors_by_clicks():
    """P then clicks: a triangle on the slice; scissors inside it on this slice erase exactly
    the engine's polygon mask there (one undo step)."""
    from ctui.engine.segment.edit import polygon_mask

    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s.range_ = (200.0, 400.0)
        await pilot.press("enter")
        z = s.z
        before = s.seg.labels.copy()
        s.x, s.y = 14, 14
        await pilot.press("P")
        for v in ((z, 34, 14), (z, 34, 34)):
            await pilot.click("#main", offset=cell_of_voxel(app, v))
        assert len(app.workspace.edit_tools.polygon) == 3 and s.zyx[0] == z
        await pilot.press("t")
        await choose(pilot, "scissors_in_slice")
        await pilot.press("y")  # half of a one-slice object: asked first
        await pilot.pause()
        cut = polygon_mask(app.workspace.edit_tools.polygon, s.shape[1:]) & (before[z] == 1)
        assert cut.sum() > 50
        assert s.seg.voxels(1) == int((before == 1).sum()) - int(cut.sum())
        assert np.array_equal(s.seg.labels[z + 1], before[z + 1])
        await pilot.press("u")
        assert np.array_equal(before, s.seg.labels)
        await pilot.press("Y")
        assert app.workspace.edit_tools.polygon == [] and not app.workspace.edit_tools.polygon_mode
        assert not app.internal_errors


@pytest.mark.slow
async def test_shift_drag_pans_and_ortho_click_sets_plane():
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("plus", "plus")
        assert app.workspace.viewstate.zoom == 4.0
        await pilot.pause()
        c0 = ws.viewstate.pan_center or ws.view_center()
        cursor = s.zyx
        w, h = ws.main_view.size
        await drag(pilot, "#main", [(w // 2, h // 2), (w // 2 + 8, h // 2), (w // 2 + 16, h // 2)], shift=True)
        c1 = ws.viewstate.pan_center
        assert c1 is not None and c1[0] < c0[0] - 2 and abs(c1[1] - c0[1]) < 1  # dragged right: the view moves left
        assert s.zyx == cursor  # panning does not move the cursor
        # the 2x2 layout: a click in the sagittal view moves y and z, keeps x, makes it the active plane
        await pilot.press("minus", "minus", "0")
        await pilot.pause()
        x = s.x
        target = (5, 30, x)
        await pilot.click("#o-sagittal", offset=cell_of_voxel(app, target, "#o-sagittal", "sagittal"))
        assert s.plane == "sagittal" and s.x == x and _near(s.zyx, target), s.zyx
        assert not app.internal_errors


async def test_roi_box_confines_fill_and_propagation():
    """The contract with the segmentation panel: Session.roi_box confines the fill (Enter)
    and the proposal (p) to the box's rows, columns and slices."""
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        s.range_ = (200.0, 400.0)
        z = s.z
        s.roi_box = ((z - 3, z + 3), (14, 30), (10, 24))
        await pilot.press("enter")
        lab = s.seg.labels == 1
        zz, yy, xx = np.nonzero(lab)
        assert lab.any() and yy.min() >= 14 and yy.max() <= 30 and xx.max() <= 24
        await pilot.press("p")
        from ctui.screens.testing import wait_for

        await wait_for(pilot, lambda: not ws.jobs.segmenting and ws.pending.proposal is not None, what="the proposal")
        got = ws.pending.proposal.mask3d()
        (z0, y0, x0), m = got
        pz, py, px = np.nonzero(m)
        assert (pz + z0).min() >= z - 3 and (pz + z0).max() <= z + 3
        assert (py + y0).min() >= 14 and (py + y0).max() <= 30 and (px + x0).max() <= 24
        assert not app.internal_errors


@pytest.mark.parametrize("mode", ["sixel", "kitty"])
async def test_click_and_drag_in_pixel_graphics_modes(monkeypatch, mode):
    """In sixel/kitty modes the widget under the mouse is the view's image child: clicks and
    drags still reach the view (the cell -> pixel scale is the terminal's cell size)."""
    monkeypatch.setattr(graphics, "_chosen", mode)
    s = _cylinder()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.pause()
        assert app.workspace.main_view.mode == mode
        z = s.z
        await pilot.click("#main", offset=cell_of_voxel(app, (z, 10, 35)))
        assert _near(s.zyx, (z, 10, 35))
        app.workspace.edit_tools.pen, s.brush = "brush", 1.0
        await drag(pilot, "#main", [cell_of_voxel(app, (z, 30, x)) for x in (5, 20)])
        lab = s.seg.labels[z] == 1
        ys, xs = np.nonzero(lab)
        assert int(lab.sum()) == 3 * (int(xs.max()) - int(xs.min()) - 1) + 2 and xs.max() - xs.min() >= 14
        assert not app.internal_errors
