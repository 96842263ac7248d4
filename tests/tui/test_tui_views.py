"""The 2x2 layout's 3D cell draws the objects with the 3D view's renderer (a shaded
surface, not one flat colour), redraws after an edit, and says why when there is no
OpenGL; the exported view PNG has the physical aspect ratio."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine import render
from ctui.engine.core.volume import Volume
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.testing import wait_for, wait_workspace


def _ball_session(n: int = 40) -> Session:
    """A 300 HU ball (radius 8 px) in air, labelled as object 1."""
    zz, yy, xx = np.mgrid[:n, :n, :n]
    ball = (zz - n / 2) ** 2 + (yy - n / 2) ** 2 + (xx - n / 2) ** 2 <= 64
    data = np.where(ball, 300, -1000).astype(np.int16)
    s = Session(Volume(data, modality="CT"), source_path="synthetic", z=n // 2, y=n // 2, x=n // 2)
    s.seg.labels[ball] = 1
    return s


def _egl():
    try:
        render.get_renderer()
    except render.EGLUnavailable as exc:
        pytest.skip(f"no EGL: {exc}")


async def test_3d_cell_shows_shaded_objects_and_follows_edits():
    _egl()
    s = _ball_session()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("0")
        iv = ws.query_one("#o-3d")
        await wait_for(pilot, lambda: iv.rgb is not None and iv.rgb.shape[0] > 8, what="the 3D cell", timeout=60)
        img = iv.rgb
        w, h = iv.target_pixels()
        assert (img.shape[1], img.shape[0]) == (w, h)  # rendered at the cell's size, not 1x2 px
        red = (img[:, :, 0].astype(int) - img[:, :, 1]) > 40  # the object's colour
        assert 0.02 < red.mean() < 0.6  # an object on a background, not a filled rectangle
        assert np.unique(img[red][:, 0]).size > 10  # shaded: many levels of red
        area = red.sum()
        # an edit (a bigger object) redraws the cell
        version = ws.volumes.version
        s.seg.labels[:, 4:36, 4:36] = np.maximum(s.seg.labels[:, 4:36, 4:36], 1)
        ws.labels_changed()
        await wait_for(pilot, lambda: iv.token == ("3d", version + 1) and iv.rgb is not img, what="the redraw",
                       timeout=60)
        assert ((iv.rgb[:, :, 0].astype(int) - iv.rgb[:, :, 1]) > 40).sum() > area
        assert "object" in str(ws.query_one("#oc-3d").render())
        assert not app.internal_errors


async def test_3d_cell_without_egl_says_so(monkeypatch):
    def no_egl():
        raise render.EGLUnavailable("cannot create an offscreen OpenGL (EGL) context (test)")

    monkeypatch.setattr(render, "get_renderer", no_egl)
    s = _ball_session(24)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        await pilot.press("0")
        cap = ws.query_one("#oc-3d")
        await wait_for(pilot, lambda: "unavailable" in str(cap.render()), what="the caption", timeout=30)
        text = str(cap.render())
        assert "EGL" in text and "libegl1" in text
        assert ws.query_one("#o-3d").rgb is None  # nothing drawn, no flat rectangle


async def test_view_png_has_the_physical_aspect(tmp_path):
    import cv2

    from ctui.screens.export import run_export

    n, nz = 48, 20
    data = np.full((nz, n, n), -1000, np.int16)
    data[:, 8:40, 8:40] = 40
    s = Session(Volume(data, spacing=(3.0, 0.75, 0.75), modality="CT"), source_path="synthetic", z=10, y=24, x=24)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        for key, (rows_mm, cols_mm) in (("1", (n * 0.75, n * 0.75)), ("2", (nz * 3.0, n * 0.75)),
                                        ("3", (nz * 3.0, n * 0.75))):
            await pilot.press(key)
            await pilot.pause()
            path = tmp_path / f"view{key}.png"
            run_export(ws, "image", str(path))
            img = cv2.imread(str(path))
            h, w = img.shape[:2]
            assert abs((h / w) / (rows_mm / cols_mm) - 1) < 0.02, (key, img.shape)
            assert max(h, w) >= n  # never shrunk below the voxel grid
