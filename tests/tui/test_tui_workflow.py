"""The whole TUI workflow on the bundled phantom, driven by keys with Textual's Pilot:
open, add an opening filter, select a kidney from its truth seed, propagate, render 3D,
export STL and a project, resume the project."""

from __future__ import annotations


import numpy as np
import pytest

from ctui.engine.io.phantom import load_truth
from ctui.screens.app import CtuiApp
from ctui.screens.testing import answer_prompt, choose, goto_voxel, wait_for, wait_workspace

pytestmark = pytest.mark.slow


def _kidney():
    t = load_truth()
    return next(o for o in t["objects"] if o["name"] == "kidney_left")


async def test_open_filter_select_propagate_export_project(tmp_path):
    kid = _kidney()
    app = CtuiApp()
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        s = app.session
        assert s.volume.shape == tuple(load_truth()["shape_zyx"])
        assert s.volume.modality == "CT"

        # f: pipeline editor, a: add, choose "opening", accept default parameters
        await pilot.press("f")
        await pilot.press("a")
        await choose(pilot, "opening")
        await answer_prompt(pilot, "stage=1 shape=ellipse size=3 iterations=1")
        assert [st.name for st in s.pipeline.steps] == ["opening"]
        assert s.pipeline.steps[0].params["shape"] == "ellipse"
        await pilot.press("escape")
        await pilot.pause()
        assert app.screen is app.workspace

        # move to the kidney's seed voxel with the keys, fill with a range
        z, y, x = kid["seed_zyx"]
        await goto_voxel(pilot, app, z, y, x)
        assert (s.z, s.y, s.x) == (z, y, x)
        lo, hi = kid["hu_range"] if "hu_range" in kid else (kid["hu"] - 60, kid["hu"] + 60)
        await pilot.press("T")
        await answer_prompt(pilot, f"{(kid['hu'] + 40) / 2:g}:{kid['hu'] + 200:g}")
        assert s.range_ is not None
        await pilot.press("enter")
        await pilot.pause()
        assert (s.seg.labels[z] == s.current).sum() > 100

        # p: propagate both ways, then accept
        await pilot.press("p")
        await wait_for(pilot, lambda: app.workspace.pending.proposal is not None, what="the propagation proposal")
        await pilot.press("a")
        await pilot.pause()
        vox = int((s.seg.labels == s.current).sum())
        vol_ml = vox * s.volume.voxel_volume_mm3() / 1000.0
        assert abs(vol_ml - kid["volume_ml"]) / kid["volume_ml"] < 0.03, (vol_ml, kid["volume_ml"])
        assert s.dirty

        # undo / redo of the propagation
        await pilot.press("u")
        await pilot.pause()
        assert int((s.seg.labels == s.current).sum()) < vox
        await pilot.press("U")
        await pilot.pause()
        assert int((s.seg.labels == s.current).sum()) == vox

        # e: export the mesh as STL
        stl = tmp_path / "kidney.stl"
        await pilot.press("e")
        await choose(pilot, "stl:current")
        await answer_prompt(pilot, str(stl))
        await wait_for(pilot, lambda: stl.exists(), what="the STL file")
        from ctui.engine.io.meshes import load_mesh

        mesh = load_mesh(stl)
        assert abs(mesh.volume_mm3() / 1000.0 - kid["volume_ml"]) / kid["volume_ml"] < 0.03
        # e: label map as NIfTI
        nii = tmp_path / "labels.nii.gz"
        await pilot.press("e")
        await choose(pilot, "nifti")
        await answer_prompt(pilot, str(nii))
        await wait_for(pilot, lambda: nii.exists(), what="the NIfTI file")
        from ctui.engine.io.labels import load_labels

        lab, _ = load_labels(nii)
        assert np.array_equal(lab, s.seg.labels)

        # Ctrl+S: save the project
        proj = tmp_path / "work.ctui"
        await pilot.press("ctrl+s")
        await answer_prompt(pilot, str(proj))
        await wait_for(pilot, lambda: proj.exists() and not s.dirty, what="the project")
        assert not app.errors, app.errors
        labels = s.seg.labels.copy()
        steps = s.pipeline.to_dict()

    # resume: `ctui open work.ctui`
    app2 = CtuiApp(project=str(proj))
    async with app2.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app2)
        s2 = app2.session
        assert np.array_equal(s2.seg.labels, labels)
        assert s2.pipeline.to_dict() == steps
        assert s2.project_path == str(proj)
        assert not s2.dirty


async def test_render_3d_shows_rendered_pixels(tmp_path):
    render = pytest.importorskip("ctui.engine.render")
    if not render.egl_available():
        pytest.skip("no EGL context on this machine (install libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri)")
    kid = _kidney()
    app = CtuiApp()
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s = app.session
        z, y, x = kid["seed_zyx"]
        await goto_voxel(pilot, app, z, y, x)
        s.range_ = ((kid["hu"] + 40) / 2, kid["hu"] + 200)
        await pilot.press("enter", "p")
        await wait_for(pilot, lambda: app.workspace.pending.proposal is not None, what="proposal")
        await pilot.press("a", "r")
        v3 = app.screen
        await wait_for(pilot, lambda: v3.last_image is not None, timeout=60, what="the first 3D image")
        img = v3.last_image
        tw, th = v3.query_one("#v3-view").target_pixels()
        assert img.shape[:2] == (th, tw)
        # the kidney (object colour, red) is in the picture and the background is not
        assert img.std() > 5
        first = len(v3.shown_requests)
        # a burst of orbit keys: only the newest request is shown
        await pilot.press("right", "right", "right")
        await wait_for(pilot, lambda: len(v3.shown_requests) > first and v3.shown_requests[-1] == v3._req, timeout=60,
                       what="the newest render")
        assert v3.scene.camera.azimuth == 45
        from ctui.screens.view3d import MODES

        assert v3.meshes and v3.mode == "surface"
        before = v3.mode
        await pilot.press("m")
        await wait_for(pilot, lambda: v3.shown_requests[-1] == v3._req, timeout=60, what="the next mode")
        assert v3.mode == MODES[(MODES.index(before) + 1) % len(MODES)]
        # p: the CT slice in place; the picture changes
        shown = len(v3.shown_requests)
        before_img = v3.last_image.copy()
        await pilot.press("p")
        await wait_for(pilot, lambda: len(v3.shown_requests) > shown and v3.shown_requests[-1] == v3._req, timeout=60,
                       what="the slice plane render")
        assert v3.scene.options.slice_plane is not None and v3.scene.options.slice_plane.index == s.z
        assert np.abs(v3.last_image.astype(int) - before_img.astype(int)).mean() > 1
        # s: PNG of the view at 1024x1024; t: a turntable GIF
        png = tmp_path / "view 3d.png"
        await pilot.press("s")
        await answer_prompt(pilot, str(png))
        await wait_for(pilot, lambda: png.exists(), timeout=120, what="the PNG")
        import cv2

        im = cv2.imread(str(png))
        assert im.shape == (1024, 1024, 3) and im.std() > 5
        gif = tmp_path / "turn.gif"
        await pilot.press("t")
        await answer_prompt(pilot, str(gif))
        await wait_for(pilot, lambda: gif.exists(), timeout=180, what="the turntable")
        from PIL import Image

        with Image.open(gif) as g:
            assert g.n_frames == 36
        assert not app.errors, app.errors


async def test_export_all_objects_in_one_mesh_file(tmp_path):
    """e -> 'Meshes of all objects': both kidneys (painted from the phantom's truth
    masks) in one STL, each closed, total volume the sum of the analytic volumes."""
    pytest.importorskip("ctui.engine.io.meshes")
    from ctui.engine.io.meshes import load_mesh
    from ctui.engine.mesh.meshtools import components

    truth = load_truth()
    app = CtuiApp()
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        s = app.session
        total = 0.0
        for name in ("kidney_left", "kidney_right"):
            o = next(o for o in truth["objects"] if o["name"] == name)
            _paint_truth_object(s, o, s.seg.add_object(name))
            total += o["volume_ml"]
        out = tmp_path / "both.stl"
        await pilot.press("e")
        await choose(pilot, "stl")
        await answer_prompt(pilot, str(out))
        await wait_for(pilot, lambda: out.exists(), what="the STL file")
        mesh = load_mesh(out)
        parts = components(mesh)
        assert len(parts) == 2
        assert abs(mesh.volume_mm3() / 1000.0 - total) / total < 0.03
        assert not app.errors, app.errors


def _paint_truth_object(session, obj, object_id):
    """Paint a phantom object as a user's threshold fill would find it: the
    6-connected component of the truth file's HU range holding its seed voxel."""
    from scipy import ndimage

    img = session.volume.data
    lo, hi = obj["hu_range"]
    lab, _ = ndimage.label((img >= lo) & (img <= hi))
    session.seg.paint(lab == lab[tuple(obj["seed_zyx"])], object_id)


async def test_measure_screen_volumes_and_grey_level_sections(tmp_path):
    """M on the phantom's stepped rod: the table's volumes (voxel, mesh, partial
    volume) match the truth; sections run along the centreline; g recomputes them
    from the grey levels, which match the truth's cross-sections within 1 %."""
    truth = load_truth()
    tube = next(o for o in truth["objects"] if o["name"] == "tube")
    app = CtuiApp()
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        s = app.session
        _paint_truth_object(s, tube, s.current)
        await pilot.press("M")
        scr = app.screen
        await wait_for(pilot, lambda: scr.sections is not None and 1 in scr.stats, what="the measurements", timeout=180)
        st = scr.stats[1]
        assert st["volume_pv_ml"] == pytest.approx(tube["volume_ml"], rel=0.005)
        assert st["volume_voxels_ml"] < tube["volume_ml"] * 0.97  # the thresholded mask is small
        first = scr.sections
        await pilot.press("g")
        await wait_for(pilot, lambda: scr.sections is not first, what="grey-level sections", timeout=180)
        s_mm = np.array([r["s_mm"] for r in scr.sections])
        area = np.array([r["area_mm2"] for r in scr.sections], float)
        # the rod's thinnest step (r = 6 mm) lies at one end of the path, away from the drift
        thin = min(tube["steps"], key=lambda st: st["radius_mm"])
        med = float(np.nanmedian(area[np.abs(area - thin["cross_section_mm2"]) < 0.2 * thin["cross_section_mm2"]]))
        assert med == pytest.approx(thin["cross_section_mm2"], rel=0.01)
        assert s_mm[-1] > 0.9 * tube["axis"]["length_mm"]
        assert not app.errors, app.errors


async def test_3d_fly_through_the_current_object(tmp_path):
    """f in the 3D screen flies along the current object's centreline (the phantom's
    rod): frames from inside show the wall all around; f again stops; F saves a GIF."""
    render = pytest.importorskip("ctui.engine.render")
    if not render.egl_available():
        pytest.skip("no EGL context on this machine (install libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri)")
    from PIL import Image

    tube = next(o for o in load_truth()["objects"] if o["name"] == "tube")
    app = CtuiApp()
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s = app.session
        _paint_truth_object(s, tube, s.current)
        await pilot.press("r")
        v3 = app.screen
        await wait_for(pilot, lambda: v3.last_image is not None, timeout=60, what="the first 3D image")
        outside = v3.last_image.copy()
        await pilot.press("f")
        await wait_for(pilot, lambda: v3.fly_frames_shown == v3.FLY_FRAMES and not v3._flying, timeout=180,
                       what="the whole fly-through")
        img = v3.last_image.astype(int)  # the last frame: inside, near the far end
        bg = outside[0, 0].astype(int)  # the background colour of the outside view
        assert (np.abs(img - bg).sum(axis=2) > 12).mean() > 0.8  # walls all around the view
        # f starts again (a long flight: small frames render in milliseconds), f stops it
        v3.FLY_FRAMES = 5000
        await pilot.press("f")
        await wait_for(pilot, lambda: v3.fly_frames_shown >= 2, timeout=60, what="the second flight")
        await pilot.press("f")
        await pilot.pause(0.5)
        stopped_at = v3.fly_frames_shown
        await pilot.pause(0.5)
        assert not v3._flying and v3.fly_frames_shown == stopped_at < v3.FLY_FRAMES
        v3.FLY_FRAMES = 60
        gif = tmp_path / "fly.gif"
        await pilot.press("F")
        await answer_prompt(pilot, str(gif))
        await wait_for(pilot, lambda: gif.exists(), timeout=180, what="the fly-through GIF")
        with Image.open(gif) as g:
            assert g.n_frames == 60
        assert not app.errors, app.errors
