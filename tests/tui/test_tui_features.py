"""Workspace features one by one (Pilot, bundled phantom, half-block or ascii forced):
views and the 2x2 grid, windows, zoom/pan, the kernel editor, objects, the open screen,
the command palette, help, autosave, MRIC/PNG export, the ascii renderer."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from ctui.engine.io.phantom import SAMPLE_DIR, load_truth
from ctui.engine.io.project import autosave_path
from ctui.screens import graphics
from ctui.screens.app import CtuiApp
from ctui.screens.imageview import ImageView
from ctui.screens.testing import answer_prompt, choose, goto_voxel, wait_for, wait_workspace

pytestmark = pytest.mark.slow


def _obj(name):
    return next(o for o in load_truth()["objects"] if o["name"] == name)


async def test_views_grid_window_zoom_pan():
    app = CtuiApp()
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        s, ws = app.session, app.workspace
        assert s.view == "overlay"
        await pilot.press("v")
        assert s.view == "intermediate"
        await pilot.press("V")
        assert ws.viewstate.grid_mode
        views = {v: ws.query_one(f"#g-{v}", ImageView) for v in ("original", "overlay", "intermediate", "final")}
        await wait_for(pilot, lambda: all(iv.rgb is not None and iv.size.width > 0 for iv in views.values()), what="4 views")
        await wait_for(pilot, lambda: views["final"].token is not None and views["final"].token[1] == "final", what="final view")
        await pilot.press("V")
        assert not ws.viewstate.grid_mode
        # window presets cycle and a typed window
        w0 = s.window
        await pilot.press("w", "w")
        assert s.window != w0
        await pilot.press("W")
        await answer_prompt(pilot, "400 1800")
        assert s.window == (400.0, 1800.0)
        await pilot.press("W")
        await answer_prompt(pilot, "nonsense")
        assert s.window == (400.0, 1800.0) and app.errors  # reported, unchanged
        app.errors.clear()
        # zoom: the view shows a quarter of the width; panning moves the view
        await pilot.press("plus", "plus")
        assert app.workspace.viewstate.zoom == 4
        mv = ws.main_view
        await pilot.pause()
        vm = mv.view_map
        assert vm is not None and vm.sx > 1  # magnified
        c0 = ws.viewstate.pan_center
        await pilot.press("ctrl+right")
        await pilot.pause()
        assert ws.viewstate.pan_center[0] > c0[0]
        await pilot.press("minus", "minus")
        assert app.workspace.viewstate.zoom == 1
        assert not app.errors


async def test_kernel_editor_sets_a_custom_kernel():
    app = CtuiApp()
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        s = app.session
        await pilot.press("f", "a")
        await choose(pilot, "closing")
        await answer_prompt(pilot, "stage=2 size=3")
        await pilot.press("K")
        await pilot.pause()
        assert type(app.screen).__name__ == "KernelEditor"
        # grow to 5x5, clear, set a vertical line through the centre
        await pilot.press("plus", "c")
        await pilot.press("up", "up", "space", "down", "space", "down", "space", "down", "space", "down", "space")
        await pilot.press("enter")
        await pilot.pause()
        st = s.pipeline.steps[0]
        assert st.stage == 2 and st.params["shape"] == "custom"
        k = np.array(st.params["kernel"])
        assert k.shape == (5, 5) and k[:, 2].tolist() == [1, 1, 1, 1, 1] and k.sum() == 5
        # reorder / toggle / remove
        await pilot.press("a")
        await choose(pilot, "median")
        await answer_prompt(pilot, "stage=1 size=3")
        assert [x.name for x in s.pipeline.steps] == ["closing", "median"]
        await pilot.press("shift+up")
        assert [x.name for x in s.pipeline.steps] == ["median", "closing"]
        await pilot.press("space")
        assert not s.pipeline.steps[0].enabled
        await pilot.press("x")
        assert [x.name for x in s.pipeline.steps] == ["closing"]
        await pilot.press("escape")
        await pilot.pause()
        assert app.screen is app.workspace
        assert "closing" in " ".join(s.pipeline_steps())
        assert not app.errors


async def test_two_objects_tab_undo_and_exports(tmp_path):
    app = CtuiApp()
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        s = app.session
        for i, name in enumerate(("kidney_left", "spine")):
            o = _obj(name)
            if i:
                await pilot.press("n")
            z, y, x = o["seed_zyx"]
            await goto_voxel(pilot, app, z, y, x)
            await pilot.press("T")
            await answer_prompt(pilot, f"{(o['hu'] + 40) / 2:g}:{o['hu'] + 300:g}")
            await pilot.press("enter")
            await pilot.pause()
        assert sorted(s.seg.objects) == [1, 2]
        assert s.current == 2
        await pilot.press("tab")
        assert s.current == 1
        assert (s.seg.labels == 1).any() and (s.seg.labels == 2).any()
        await pilot.press("u")
        await pilot.pause()
        assert not (s.seg.labels == 2).any()
        await pilot.press("U")
        await pilot.pause()
        assert (s.seg.labels == 2).any()
        # MRIC contours of both objects
        mric = tmp_path / "contours.mric"
        await pilot.press("e")
        await choose(pilot, "mric")
        await answer_prompt(pilot, str(mric))
        await wait_for(pilot, lambda: mric.exists(), what="the MRIC file")
        from ctui.engine.io.mric import read_mric

        m = read_mric(mric)
        assert (m.width, m.height) == s.shape[:0:-1]
        z = o["seed_zyx"][0]
        assert len(m.slices[z]) == 2  # two objects on the seed slice
        # the current image as PNG
        png = tmp_path / "slice.png"
        await pilot.press("e")
        await choose(pilot, "image")
        await answer_prompt(pilot, str(png))
        await wait_for(pilot, lambda: png.exists(), what="the PNG")
        import cv2

        img = cv2.imread(str(png))
        assert img.shape[:2] == s.shape[1:]
        assert not app.errors, app.errors


async def test_open_screen_scans_and_opens(tmp_path):
    src = tmp_path / "data" / "series A"
    shutil.copytree(SAMPLE_DIR, src)
    app = CtuiApp()
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        first = app.workspace
        await pilot.press("o")
        await pilot.pause()
        scr = app.screen
        assert type(scr).__name__ == "OpenScreen"
        await pilot.pause(0.5)  # let the folder tree settle (it scans what it highlights)
        scr.scan(src)
        await wait_for(pilot, lambda: scr.current == src and scr.series, what="the scan")
        assert scr.series[0]["modality"] == "CT"
        assert list(scr.series[0]["shape_zyx"])[1:] == [128, 128]
        from textual.widgets import OptionList

        ol = scr.query_one("#op-series", OptionList)
        ol.focus()
        ol.highlighted = 0
        await pilot.press("enter")
        await wait_for(pilot, lambda: app.workspace is not first and app.screen is app.workspace, what="the new workspace")
        assert app.session.source_path == str(src)
        assert not app.errors, app.errors


async def test_command_palette_lists_actions_and_help_lists_keys():
    app = CtuiApp()
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        titles = [c.title for c in app.get_system_commands(app.screen)]
        for want in ("Propagate", "Fill", "Filters", "3D", "Measure", "Export", "Drift", "Save project", "Undo", "Redo"):
            assert any(want in t for t in titles), (want, titles)
        # run one from the palette machinery: "2x2 pipeline views"
        cmd = next(c for c in app.get_system_commands(app.screen) if c.title == "2x2 pipeline views")
        await cmd.callback()
        await pilot.pause()
        assert app.workspace.viewstate.grid_mode
        await pilot.press("question_mark")
        await pilot.pause()
        assert type(app.screen).__name__ == "TextScreen"
        body = str(app.screen.body)
        for key in ("PgUp", "Enter", "<", "Ctrl+S", "?"):  # as people write them (ctui.screens.help.key_name)
            assert key in body


async def test_autosave_writes_when_dirty(tmp_path):
    app = CtuiApp(autosave_s=0.0)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        o = _obj("kidney_right")
        await goto_voxel(pilot, app, *o["seed_zyx"])
        app.session.range_ = (130.0, 400.0)
        await pilot.press("enter")
        await pilot.pause()
        assert app.session.dirty
        app._autosave_tick()
        final = autosave_path(app.session.project_path or app.session.source_path)
        assert final.parent == tmp_path / "autosave"
        # the final file (put in place by an atomic rename), never any file: the writer's temporary file
        # is in the same folder while it writes
        await wait_for(pilot, lambda: final.exists(), what="the autosave")
        from ctui.engine.io.project import load_project

        p = load_project(final)
        assert np.array_equal(p.labels, app.session.seg.labels)


async def test_ascii_mode_draws_a_character_ramp(monkeypatch):
    monkeypatch.setattr(graphics, "_chosen", "ascii")
    app = CtuiApp()
    async with app.run_test(size=(100, 30)) as pilot:
        await wait_workspace(pilot, app)
        mv = app.workspace.main_view
        assert mv.mode == "ascii"
        await wait_for(pilot, lambda: mv._strips is not None, what="a paint")
        text = "\n".join("".join(seg.text for seg in st) for st in mv._strips)
        assert "\u2580" not in text
        assert "@" in text and " " in text and "+" in text  # bright spine, air, cursor
        # no colour in the cells
        assert all(seg.style is None or seg.style.color is None for st in mv._strips for seg in st)


async def test_autosave_is_offered_on_next_start(tmp_path):
    o = _obj("kidney_right")
    app = CtuiApp()
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        await goto_voxel(pilot, app, *o["seed_zyx"])
        app.session.range_ = (130.0, 400.0)
        await pilot.press("enter")
        await pilot.pause()
        labels = app.session.seg.labels.copy()
        worker = app.autosave_worker()
        final = autosave_path(app.session.project_path or app.session.source_path)
        # the final file, once the writer has finished (its temporary file, or a write still deciding
        # whether it is stale, is no autosave yet: waiting on any file raced the writer)
        await wait_for(pilot, lambda: worker.is_finished and final.exists(), what="the autosave")
        assert final.parent == tmp_path / "autosave"
        app.session.dirty = False  # as if the app was killed: no save, no question
    app2 = CtuiApp()
    async with app2.run_test(size=(120, 40)) as pilot:
        await wait_for(pilot, lambda: type(app2.screen).__name__ == "ConfirmScreen", what="the recovery question")
        await pilot.press("y")
        await wait_for(pilot, lambda: app2.session is not None and app2.session.seg.labels.any(), what="recovered labels")
        assert np.array_equal(app2.session.seg.labels, labels)
        assert app2.session.dirty


async def test_propagation_3d_mode_and_reject():
    o = _obj("kidney_left")
    app = CtuiApp()
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s, ws = app.session, app.workspace
        await goto_voxel(pilot, app, *o["seed_zyx"])
        s.range_ = ((o["hu"] + 40) / 2, o["hu"] + 200)
        await pilot.press("enter", "m")
        assert s.prop_mode == "3d"
        # reject first: labels unchanged
        before = int((s.seg.labels == 1).sum())
        await pilot.press("p")
        await wait_for(pilot, lambda: ws.pending.proposal is not None, what="proposal")
        await pilot.press("x")
        await pilot.pause()
        assert ws.pending.proposal is None and int((s.seg.labels == 1).sum()) == before
        # then accept: the kidney's analytic volume within 3%
        await pilot.press("p")
        await wait_for(pilot, lambda: ws.pending.proposal is not None, what="proposal")
        await pilot.press("a")
        await pilot.pause()
        ml = int((s.seg.labels == 1).sum()) * s.volume.voxel_volume_mm3() / 1000
        assert abs(ml - o["volume_ml"]) / o["volume_ml"] < 0.03, ml
        assert not app.errors, app.errors


async def test_mouse_click_moves_the_cursor():
    app = CtuiApp()
    async with app.run_test(size=(100, 30)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.pause()
        mv = app.workspace.main_view
        vm = mv.view_map
        # the cell showing image pixel (40, 90): click it
        xd, yd = vm.to_display(40, 90)
        await pilot.click("#main", offset=(int(xd), int(yd) // 2))
        await pilot.pause()
        assert abs(app.session.x - 40) <= 2 and abs(app.session.y - 90) <= 2


async def test_rename_and_clear_object():
    o = _obj("spine")
    app = CtuiApp()
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s = app.session
        await goto_voxel(pilot, app, *o["seed_zyx"])
        s.range_ = (370.0, 1000.0)
        await pilot.press("enter")
        await pilot.pause()
        n = int((s.seg.labels == 1).sum())
        assert n > 50
        await pilot.press("N")
        await choose(pilot, "_type")  # not one of the common structures: typed
        await answer_prompt(pilot, "spine L1")
        assert s.seg.objects[1].name == "spine L1"
        await pilot.press("delete", "y")
        await pilot.pause()
        assert not (s.seg.labels == 1).any()
        await pilot.press("u")
        await pilot.pause()
        assert int((s.seg.labels == 1).sum()) == n
        assert not app.errors
