"""The workspace without traps (issue 37), with Textual's Pilot on small synthetic volumes
whose answers are known: a 3D edit that would take much of an object is drawn and asked
about, an island edit never takes the main body unasked, a box drawn on one slice asks
which slices the scissors cut; no key both confirms a dialog and edits; text that fits."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.volume import Volume
from ctui.screens import planes
from ctui.screens.app import CtuiApp
from ctui.screens.dialogs import ChoiceScreen, ConfirmScreen
from ctui.screens.session import Session
from ctui.screens.testing import cell_of_voxel, choose, drag, wait_for, wait_workspace, wheel


def _body_and_island(nz: int = 20, n: int = 48) -> Session:
    """A cylinder (r 10 px, every slice) labelled as object 1, plus a 4x4x4 island of it
    at (x 3..6, y 3..6, z 8..11); the cursor on the cylinder's axis."""
    yy, xx = np.mgrid[0:n, 0:n]
    disk = (yy - n / 2) ** 2 + (xx - n / 2) ** 2 <= 100
    data = np.full((nz, n, n), -1000, np.int16)
    data[:, disk] = 300
    s = Session(Volume(data, spacing=(2.0, 1.0, 1.0), modality="CT"), source_path="synthetic", z=nz // 2,
                y=n // 2, x=n // 2)
    s.seg.labels[:, disk] = 1
    s.seg.labels[8:12, 3:7, 3:7] = 1
    return s


async def _tool(pilot, name: str) -> None:
    await pilot.press("t")
    await choose(pilot, name)


async def test_island_edit_spares_the_main_body_and_big_edits_ask():
    s = _body_and_island()
    body = int((s.seg.labels == 1).sum()) - 64
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        before = s.seg.labels.copy()
        # remove the island under the cursor, with the cursor on the main body: asked, drawn in red
        await _tool(pilot, "remove_island")
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="the confirmation")
        assert np.array_equal(s.seg.labels, before)  # nothing removed while asking
        assert int(ws.edit_tools.doomed.sum()) == body
        q = app.screen.question
        assert f"{body} voxels" in q and f"{body * 2 / 1000:.1f} mL" in q and "main body" in q
        c, r = planes.cursor_in(planes.plane_view(s.volume, s.plane), s.zyx, s.shape)
        red = ws.plane_image(s.plane)[r, c]
        assert red[0] > 150 > red[1]  # the doomed voxel under the cursor is drawn red
        await pilot.press("enter")  # an Enter out of habit keeps the work (the focus starts on Keep)
        await wait_for(pilot, lambda: app.screen is ws, what="the workspace")
        assert np.array_equal(s.seg.labels, before) and ws.edit_tools.doomed is None
        assert "Nothing removed" in str(ws.query_one("#status").render())
        # the cursor on the small island: removed at once, the body stays
        s.z, s.y, s.x = 9, 4, 4
        await _tool(pilot, "remove_island")
        await pilot.pause()
        assert app.screen is ws and s.seg.voxels(1) == body
        # keep the slice island at slice 9 takes most of the object: asked; y does it
        s.z, s.y, s.x = 9, 24, 24
        await _tool(pilot, "keep_island")  # the only island left: nothing to remove
        assert app.screen is ws and s.seg.voxels(1) == body
        s.roi_box = ((0, 19), (0, 47), (0, 23))
        await _tool(pilot, "scissors_in_box")  # half the cylinder on every slice: 50% > the share
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="the confirmation")
        await pilot.press("y")
        await wait_for(pilot, lambda: app.screen is ws, what="the workspace")
        assert s.seg.voxels(1) == int((before[:, :, 24:] == 1).sum()) - 0
        await pilot.press("u")
        assert s.seg.voxels(1) == body
        assert not app.internal_errors


async def test_box_drawn_on_one_slice_asks_which_slices_to_cut():
    s = _body_and_island()
    s.seg.labels[8:12, 3:7, 3:7] = 0
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        per_slice = int((s.seg.labels[10] == 1).sum())
        await pilot.press("y")
        await drag(pilot, "#main", [cell_of_voxel(app, (10, 14, 14)), cell_of_voxel(app, (10, 34, 34))])
        (z0, z1), _, _ = s.roi_box
        assert (z0, z1) == (0, 19) and ws.edit_tools.box_drawn_on == 10
        panel = str(ws.query_one("#panel").render())
        assert "slices 0..19, drawn on 10" in panel
        await _tool(pilot, "scissors_in_box")
        await wait_for(pilot, lambda: isinstance(app.screen, ChoiceScreen), what="which slices")
        await choose(pilot, "drawn")
        await wait_for(pilot, lambda: app.screen is ws, what="the workspace")
        # only slice 10 lost its voxels inside the box: the rest of the object is whole
        assert (s.seg.labels[10] == 1).sum() < per_slice
        for z in (0, 9, 11, 19):
            assert (s.seg.labels[z] == 1).sum() == per_slice
        assert not app.internal_errors


async def test_second_ctrl_s_says_where_and_its_enter_fills_nothing(tmp_path):
    s = _body_and_island()
    s.seg.labels[:] = 0
    s.range_ = (200.0, 400.0)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: app.screen is not ws, what="the save dialog")
        app.focused.value = str(tmp_path / "p.ctui")
        await pilot.press("enter")  # the dialog's own Enter saves
        await wait_for(pilot, lambda: app.screen is ws and s.project_path, what="the save")
        assert s.seg.voxels(1) == 0
        # the second Ctrl+S has no dialog: the status says where; the habitual Enter fills nothing
        await pilot.press("ctrl+s", "enter")
        await pilot.pause()
        status = str(ws.query_one("#status").render())
        assert "nothing filled" in status and s.seg.voxels(1) == 0 and not s.dirty
        await pilot.press("ctrl+s")
        await pilot.pause()
        assert str(tmp_path / "p.ctui") in str(ws.query_one("#status").render())
        await pilot.press("l", "enter")  # any other key first: Enter fills again
        await pilot.pause()
        assert s.seg.voxels(1) > 0
        assert not app.internal_errors


@pytest.mark.parametrize("size", [(120, 40), (80, 24)])
async def test_zoom_keeps_the_point_under_the_pointer(size):
    s = _body_and_island()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=size) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        iv = ws.main_view
        await pilot.pause()
        cell = cell_of_voxel(app, (s.z, 19, 18))  # off the centre (24, 24): a recentring zoom would move it
        point = iv.display_to_image(*cell)
        for notch in (1, 2, 3):
            await wheel(pilot, "#main", cell, up=True, control=True)
            await pilot.pause()
            assert ws.viewstate.zoom == 2.0 ** notch
            xd, yd = iv.view_map.to_display(*point)
            # within one voxel (the view crops whole voxels) of the pointer, on every notch: no drift
            vm = iv.view_map
            assert abs(xd - (cell[0] + 0.5)) <= max(1.0, vm.sx) and abs(yd - (2 * cell[1] + 1.0)) <= max(2.0, vm.sy), \
                (notch, xd, yd)
        # keys: + and - keep the cursor's point where it is on screen
        s.y, s.x = 20, 20
        ws.refresh_view()
        await pilot.pause()
        before = iv.view_map.to_display(s.x, s.y)
        await pilot.press("minus")
        await pilot.pause()
        after = iv.view_map.to_display(s.x, s.y)
        assert abs(after[0] - before[0]) <= 1.5 and abs(after[1] - before[1]) <= 2.5
        assert not app.internal_errors


async def test_proposal_warnings_go_to_the_panel_not_toasts():
    """A segmentation's warnings are notes in the side panel while its proposal waits (counted on
    the status line), never a toast over the image, the proposal line or the review strip."""
    import time
    from types import SimpleNamespace

    from ctui.engine.segment.propagate import Proposal

    s = _body_and_island()
    s.seg.labels[:] = 0
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        p = Proposal(object_id=1, start_slice=10, shape=s.shape)
        p.masks[11] = (0, 0, s.volume.data[11] > 0)
        report = SimpleNamespace(warnings=["wrapped in a brighter shell: check slice 12"], message=lambda: "1 object")
        run = SimpleNamespace(proposal=p, seed=(24, 24, 10), object_settings={}, started=time.perf_counter(),
                              report=report)
        before = len(app._notifications)
        ws.segment.finished(run)
        await pilot.pause()
        assert len(app._notifications) == before  # no toast
        assert "1 note in the panel" in str(ws.query_one("#status").render())
        assert "brighter shell: check slice 12" in str(ws.query_one("#panel").render())
        await pilot.press("x")  # rejected: the note goes with it
        await pilot.pause()
        assert "brighter shell" not in str(ws.query_one("#panel").render())
        await pilot.press("w")  # a window preset: said on the status line, no toast
        await pilot.pause()
        assert len(app._notifications) == before and "Window" in str(ws.query_one("#status").render())
        assert not app.internal_errors


async def test_text_that_fits_and_keys_that_do_what_they_say():
    data = np.full((20, 48, 48), 100, np.int16)
    s = Session(Volume(data, spacing=(2.0, 1.0, 1.0), modality="MR"), source_path="synthetic", z=10, y=24, x=24)
    s.brush = 3.22266
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        panel = str(ws.query_one("#panel").render())
        assert "brush 3.2 mm" in panel and "3.22" not in panel
        assert "(signal)" in panel and "HU" not in panel  # an MR's values are no Hounsfield units
        # 2 inside the planes' 2x2 shows the sagittal view alone
        await pilot.press("0")
        assert ws.viewstate.ortho_mode
        await pilot.press("2")
        assert not ws.viewstate.ortho_mode and s.plane == "sagittal"
        # Ctrl+P finds every segmentation method ("grow") and picking it sets the method S uses
        cmds = {c.title: c for c in app.get_system_commands(ws)}
        assert "Segmentation method: grow" in cmds
        cmds["Segmentation method: grow"].callback()
        assert s.segment_options["method"] == "grow" and "grow" in str(ws.query_one("#status").render())
        assert not app.internal_errors


async def test_80x24_dialogs_fit_the_objects_show_and_the_readout_stays():
    from ctui.screens.segpanel import SegmentPanel
    from ctui.screens.ws_keys import panel_text

    s = _body_and_island()
    for name in ("liver", "spleen", "kidney_left", "kidney_right"):
        s.seg.add_object(name)
    s.seg.labels[0, 0, 0:5] = 5
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.pause()
        # the objects list, with each volume, is inside the panel's height
        lines = panel_text(ws).plain.splitlines()
        last = max(i for i, line in enumerate(lines) if "kidney_right" in line)
        assert "ml" in lines[last] and last < ws.query_one("#panel").size.height
        # the G dialog's Apply is on screen (the fields scroll above it)
        await pilot.press("G")
        await wait_for(pilot, lambda: isinstance(app.screen, SegmentPanel), what="the G panel")
        await pilot.pause()
        for bid in ("#apply", "#cancel"):
            r = app.screen.query_one(bid).region
            assert r.height > 0 and r.bottom <= 24 and r.right <= 80, (bid, r)
        await pilot.press("escape")
        await wait_for(pilot, lambda: app.screen is ws, what="the workspace")
        # the confirmation of a big edit fits too, its buttons in view
        await _tool(pilot, "remove_island")
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="the confirmation")
        await pilot.pause()
        for bid in ("#yes", "#no"):
            r = app.screen.query_one(bid).region
            assert r.height > 0 and r.bottom <= 24 and r.right <= 80, (bid, r)
        await pilot.press("n")
        await wait_for(pilot, lambda: app.screen is ws, what="the workspace")
        # the panel hidden: the value under the cursor is in the view's caption
        await pilot.press("backslash")
        await pilot.pause()
        assert f"x {s.x} y {s.y} = 300 HU" in str(ws.query_one("#main-caption").render())
        await pilot.press("l")
        await pilot.pause()
        assert f"x {s.x} y {s.y} =" in str(ws.query_one("#main-caption").render())
        assert not app.internal_errors


async def test_a_project_reopens_as_it_was_saved(tmp_path):
    from ctui.engine.actions.project import load_project, save_project
    from ctui.screens.projects import project_from_session, session_from_project
    from ctui.screens.segpanel import SegmentPanel

    s = _body_and_island()
    s.brush = 3.22266
    s.prop_mode = "3d"
    s.segment_options = {"method": "grow", "neck": 5.0, "range": (100.0, 400.0), "fill_holes": False,
                         "keep_largest": True, "min_island": 7, "interpolate": True}
    s.background_seeds = [(3, 40, 2), (44, 5, 17)]
    s.roi_box = ((2, 15), (10, 30), (12, 36))
    s.zoom = 4.0
    path = tmp_path / "p.ctui"
    save_project(path, project_from_session(s))
    proj = load_project(path)
    r = session_from_project(proj, s.volume, str(path))
    assert r.brush == pytest.approx(3.22266) and r.prop_mode == "3d" and r.zoom == 4.0
    assert r.segment_options == s.segment_options
    assert r.background_seeds == s.background_seeds and r.roi_box == s.roi_box
    # odd values (a hand edit, a method this build lacks) are dropped, the project still opens
    proj.meta.update({"roi_box": [[0, 99], [0, 1], [0, 1]], "background_seeds": [[1, 2], [999, 1, 1], [1, 1, 1]],
                      "zoom": "big", "segment_options": {"method": 3, "range": [5, 1], "neck": None}})
    odd = session_from_project(proj, s.volume, str(path))
    assert odd.roi_box is None and odd.background_seeds == [(1, 1, 1)] and odd.zoom == 1.0
    assert odd.segment_options == {}
    # an older project (none of these fields) opens with the defaults
    for key in ("segment_options", "background_seeds", "roi_box", "zoom"):
        proj.meta.pop(key)
    old = session_from_project(proj, s.volume, str(path))
    assert old.segment_options == {} and old.roi_box is None and old.zoom == 1.0
    # the workspace shows it: the zoom, the method in G
    app = CtuiApp(session=r, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        assert app.workspace.viewstate.zoom == 4.0
        await pilot.press("G")
        await wait_for(pilot, lambda: isinstance(app.screen, SegmentPanel), what="the G panel")
        assert app.screen.query_one("#method").value == "grow" and app.screen.query_one("#neck").value == "5"
        assert not app.internal_errors


async def test_sections_from_the_measure_screen_at_the_cursor_and_along_a_two_click_line():
    """A kidney-like ellipsoid (semi-axes 18, 12, 8 mm along x, y, z; not a tube: no automatic
    sections): x gives the section through the cursor normal to the slices' axis (an ellipse
    of pi*12*18 mm² at the centre) or to the object's axis (pi*12*8); P + a click gives a line."""
    from ctui.screens.measure_screen import MeasureScreen

    n = 48
    zz, yy, xx = np.mgrid[0:24, 0:n, 0:n].astype(float)
    ell = ((xx - 24) / 18) ** 2 + ((yy - 24) / 12) ** 2 + ((zz - 12) / 8) ** 2 <= 1.0
    data = np.where(ell, 300, -1000).astype(np.int16)
    s = Session(Volume(data, spacing=(1.0, 1.0, 1.0), modality="CT"), source_path="synthetic", z=12, y=24, x=24)
    s.seg.labels[ell] = 1
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("P")
        s.x = 10
        await pilot.press("P")  # the line's other end: x 10..24 on slice 12
        await pilot.press("M")
        await wait_for(pilot, lambda: isinstance(app.screen, MeasureScreen) and app.screen.stats, what="the measures")
        ms = app.screen
        status = lambda: str(ms.query_one("#ms-status").render())  # noqa: E731
        s.x = 24
        for axis, area in (("z", np.pi * 18 * 12), ("object", np.pi * 12 * 8)):
            await pilot.press("x")
            await wait_for(pilot, lambda: isinstance(app.screen, ChoiceScreen), what="the axes")
            await choose(pilot, axis)
            await wait_for(pilot, lambda a=axis: f"normal to {a}: area" in status(), what=f"the {axis} section")
            got = float(status().split("area ")[1].split(" mm")[0])
            assert got == pytest.approx(area, rel=0.06), (axis, got, area)
        await pilot.press("l")
        await wait_for(pilot, lambda: ms.sections and ms.result is not None and ms.result.path_length_mm < 20,
                       what="the line's sections")
        assert ms.result.path_length_mm == pytest.approx(14.0, abs=0.5) and len(ms.sections) >= 20
        assert ws.edit_tools.polygon  # the line stays for another look
        assert not app.internal_errors


async def test_names_from_a_short_list_of_structures():
    from ctui.engine.actions.defaults import STRUCTURE_NAMES

    s = _body_and_island()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.press("N")
        await wait_for(pilot, lambda: isinstance(app.screen, ChoiceScreen), what="the names")
        await choose(pilot, "kidney_left")
        assert s.seg.objects[1].name == "kidney_left"
        await pilot.press("n", "N")  # a second object: the names taken are not offered again
        await wait_for(pilot, lambda: isinstance(app.screen, ChoiceScreen), what="the names")
        ol = app.screen.query_one("OptionList")
        ids = [ol.get_option_at_index(i).id for i in range(ol.option_count)]
        assert "kidney_left" not in ids and "kidney_right" in ids and len(ids) == len(STRUCTURE_NAMES)
        assert not app.internal_errors


async def test_range_picked_on_the_panels_histogram():
    from ctui.screens.ws_keys import panel_text

    yy, xx = np.mgrid[0:48, 0:48]
    data = np.full((20, 48, 48), -1000, np.int16)
    data[:, (yy - 24) ** 2 + (xx - 24) ** 2 <= 100] = 300
    data = data + np.random.default_rng(0).normal(0, 20, data.shape).astype(np.int16)
    s = Session(Volume(data, spacing=(1.0, 1.0, 1.0), modality="CT"), source_path="synthetic", z=10, y=24, x=24)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await wait_for(pilot, lambda: ws.seed_range.result is not None, what="the seed range")
        await pilot.pause()
        lines = panel_text(ws).plain.split("\n")
        row = next(i for i, line in enumerate(lines) if line.startswith("Seed range here "))
        rc = ws.seed_range.result
        tenth = float(rc.edges[1] - rc.edges[0]) / 10  # the ends are rounded to a tenth of a bar at most
        await pilot.click("#panel", offset=(3, row))  # on the words: the seed range as it is
        assert s.range_ == pytest.approx((float(rc.low), float(rc.high)), abs=tenth)
        start = lines[row].index(" ", len("Seed range here ")) + 1
        await pilot.click("#panel", offset=(1 + start + 1, row))  # bar 1, then bar 4: the range over them
        assert "other end" in str(ws.query_one("#status").render())
        await pilot.click("#panel", offset=(1 + start + 4, row))
        assert s.range_ == pytest.approx((float(rc.edges[1]), float(rc.edges[5])), abs=tenth)
        assert all(v == round(v, max(0, -int(np.floor(np.log10(tenth))))) for v in s.range_)
        assert not app.internal_errors


async def test_80x24_menus_prompts_and_help_are_not_cut():
    from textual.widgets import Label

    from ctui.screens.dialogs import PromptScreen, TextScreen

    s = _body_and_island()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        for key in ("t", "e"):  # the edit tools' menu, the export menu with its note
            await pilot.press(key)
            await wait_for(pilot, lambda: isinstance(app.screen, ChoiceScreen), what=f"the {key} menu")
            await pilot.pause()
            box = app.screen.query_one("Vertical").region
            assert box.bottom <= 24 and box.right <= 80, (key, box)
            for label in app.screen.query(Label):  # every line of the title and the note on screen, uncut
                assert label.region.bottom <= 24
                assert label.size.width * label.size.height >= len(str(label.render()).rstrip()), key
            await pilot.press("escape")
            await wait_for(pilot, lambda: app.screen is ws, what="the workspace")
        await pilot.press("i")  # the limits prompt: its title wraps instead of being cut
        await wait_for(pilot, lambda: isinstance(app.screen, PromptScreen), what="the limits prompt")
        await pilot.pause()
        title = app.screen.query(Label).first()
        text = str(title.render())
        assert "(empty: none)" in text and title.size.width * title.size.height >= len(text) and title.region.right <= 80
        await pilot.press("escape")
        await wait_for(pilot, lambda: app.screen is ws, what="the workspace")
        await pilot.press("question_mark")
        await wait_for(pilot, lambda: isinstance(app.screen, TextScreen), what="the help")
        assert "…" not in str(app.screen.body)
        assert not app.internal_errors


@pytest.mark.parametrize("size", [(80, 24), (160, 50)])
async def test_3d_view_uses_the_width_it_has(size):
    from ctui.screens.view3d import View3DScreen

    s = _body_and_island()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=size) as pilot:
        await wait_workspace(pilot, app)
        app.push_screen(View3DScreen(s, image=np.full((60, 80, 3), 128, np.uint8)))
        await wait_for(pilot, lambda: isinstance(app.screen, View3DScreen), what="the 3D view")
        await pilot.pause()
        view, info = app.screen.query_one("#v3-view"), app.screen.query_one("#v3-info")
        if size[0] < 100:  # the info panel is off: the render gets all 80 columns (it had 50)
            assert view.size.width == size[0] and not info.display
            await pilot.press("backslash")
            await pilot.pause()
            assert info.display and view.size.width == size[0] - 30
        else:
            assert info.display and view.size.width == size[0] - 30
        assert not app.internal_errors
