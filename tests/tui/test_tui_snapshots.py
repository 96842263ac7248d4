"""Snapshot tests (pytest-textual-snapshot) of the slice workspace and the 3D screen at
two terminal sizes, half-block renderer forced (deterministic). The 3D screen shows a
fixed analytic image (a Lambert-shaded sphere computed here), so the snapshot does not
depend on the GL driver. Update with ``pytest --snapshot-update`` after checking the SVGs."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.io.phantom import load_truth, make_phantom
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.testing import goto_voxel, wait_for

SIZES = [(100, 30), (160, 50)]


@pytest.fixture(scope="module")
def phantom_volume():
    return make_phantom()[0]


def _session(vol) -> Session:
    v = type(vol)(vol.data, spacing=vol.spacing, origin=vol.origin, direction=vol.direction, modality=vol.modality,
                  window=vol.window, source="phantom")
    return Session(v, source_path="sample_data/phantom")


def shaded_sphere(w: int = 240, h: int = 200) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    r = 0.4 * min(w, h)
    nx, ny = (xx - w / 2) / r, (yy - h / 2) / r
    inside = nx**2 + ny**2 <= 1
    nz = np.sqrt(np.clip(1 - nx**2 - ny**2, 0, 1))
    light = np.array([-0.4, -0.5, 0.77])
    lam = np.clip(nx * light[0] + ny * light[1] + nz * light[2], 0, 1)
    img = np.zeros((h, w, 3), np.uint8)
    img[:] = (18, 18, 23)
    col = np.array([230, 60, 60]) * (0.18 + 0.8 * lam[..., None])
    img[inside] = np.clip(col[inside], 0, 255).astype(np.uint8)
    return img


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_workspace_snapshot(snap_compare, phantom_volume, size):
    kid = next(o for o in load_truth()["objects"] if o["name"] == "kidney_left")
    app = CtuiApp(session=_session(phantom_volume))

    async def run_before(pilot):
        await wait_for(pilot, lambda: app.workspace is not None and app.screen is app.workspace, what="workspace")
        z, y, x = kid["seed_zyx"]
        await goto_voxel(pilot, app, z, y, x)
        app.session.range_ = (115.0, 400.0)
        await pilot.press("enter")
        await pilot.pause()
        ws = app.workspace
        ws.update_panel()  # the seed range at the cursor is computed in a thread: wait for it
        await wait_for(pilot, lambda: ws.seed_range.result is not None,
                       what="the seed range")
        ws.update_panel()
        ws.set_status("")
        await pilot.pause()

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_3d_screen_snapshot(snap_compare, phantom_volume, size):
    from ctui.screens.view3d import View3DScreen

    sess = _session(phantom_volume)
    app = CtuiApp(session=sess)

    async def run_before(pilot):
        await wait_for(pilot, lambda: app.workspace is not None and app.screen is app.workspace, what="workspace")
        await app.push_screen(View3DScreen(sess, image=shaded_sphere()))
        await pilot.pause()

    assert snap_compare(app, terminal_size=size, run_before=run_before)
