"""The TUI shows a series' middle slice before the rest is read, with progress, then swaps in
the full series at that slice; Esc cancels a load. The full read is held back (an Event)
until the preview has been seen, so the order is certain on any machine."""

from __future__ import annotations

import threading
from contextlib import asynccontextmanager

import numpy as np
import pytest

from support import shared
from ctui.screens import app as app_mod
from ctui.screens.app import CtuiApp, LoadingScreen
from ctui.screens.testing import wait_for, wait_workspace


@pytest.fixture(autouse=True)
def _preview_small(monkeypatch):
    monkeypatch.setattr(app_mod, "PREVIEW_MIN_VOXELS", 0)  # the real data set is small: preview it anyway


def _held_load(monkeypatch) -> tuple[threading.Event, list]:
    """The full read waits for ``go``; ``progress`` gets the worker's progress calls."""
    go = threading.Event()
    calls: list = []
    real = app_mod.load_volume

    def held(path, *, progress=None, **options):
        assert go.wait(60), "the test never released the full read"
        if progress is not None:
            progress(0, 1)  # a cancelled worker raises here
            calls.append(1)
        return real(path, progress=progress, **options)

    monkeypatch.setattr(app_mod, "load_volume", held)
    return go, calls


def _preview_shown(app) -> bool:
    scr = app.screen
    return isinstance(scr, LoadingScreen) and scr.preview is not None and bool(scr.query("#load-preview"))


@asynccontextmanager
async def _on_preview(monkeypatch):
    """The app opening the Philips phantom, its full read held back, once the preview is shown:
    (app, pilot, the read's release Event, its progress calls)."""
    go, calls = _held_load(monkeypatch)
    app = CtuiApp(str(shared("ct_head_phantom_philips")))
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_for(pilot, lambda: _preview_shown(app), what="the preview slice")
        yield app, pilot, go, calls


async def test_preview_then_full_series(monkeypatch):
    async with _on_preview(monkeypatch) as (app, pilot, go, _calls):
        scr = app.screen
        pv = scr.preview
        caption = str(scr.query_one("#load-caption").render())
        assert f"z {pv.z}/{pv.depth - 1}" in caption and "preview" in caption
        shown = scr.query_one("#load-preview").rgb.copy()
        assert app.workspace is None  # the rest is not read yet
        go.set()
        await wait_workspace(pilot, app)
        s = app.session
        assert s.volume.shape[0] == pv.depth and s.z == pv.z  # the workspace opens on the previewed slice
        assert np.array_equal(s.volume.data[pv.z], pv.volume.data[0])
        # the workspace draws that slice exactly as the preview did
        plane = app.workspace.main_view
        assert np.array_equal(plane.rgb if plane.rgb.ndim == 3 else np.repeat(plane.rgb[..., None], 3, 2), shown)
        assert not app.internal_errors and not app.errors


async def test_esc_cancels_the_load(monkeypatch):
    async with _on_preview(monkeypatch) as (app, pilot, go, calls):
        await pilot.press("escape")
        await pilot.pause()
        assert not app.screen.reading
        assert "cancelled" in str(app.screen.query_one("#load-title").render())
        assert not app.screen.query_one("#load-preview").display  # no stale "reading ..." preview
        go.set()
        for w in list(app.workers):
            if w.group == "load":
                await w.wait()
        await pilot.pause(0.2)
        assert app.workspace is None and not calls  # the full read stopped at its first progress call
        assert not app.internal_errors


async def test_project_preview_shows_its_objects(monkeypatch, tmp_path):
    from ctui.engine.actions.project import new_project, save_project
    from ctui.engine.actions.series import load

    path = shared("ct_head_phantom_philips")
    vol = load(path)
    labels = np.zeros(vol.shape, np.uint8)
    z = vol.shape[0] // 2
    labels[z, 200:300, 200:300] = 1
    proj = new_project(vol, source_path=path, labels=labels, objects=[{"id": 1, "name": "box"}])
    save_project(tmp_path / "p.ctui", proj)
    go, _ = _held_load(monkeypatch)
    app = CtuiApp(project=str(tmp_path / "p.ctui"))
    async with app.run_test(size=(120, 40)) as pilot:
        def coloured() -> bool:  # the preview, then the object drawn over it
            if not _preview_shown(app):
                return False
            rgb = app.screen.query_one("#load-preview").rgb
            return bool(rgb is not None and (rgb[..., 0] != rgb[..., 1]).any())

        await wait_for(pilot, coloured, what="the preview with the project's object")
        assert app.screen.preview.z == z
        go.set()
        await wait_workspace(pilot, app)
        assert app.session.z == z and int(app.session.seg.labels[z, 250, 250]) == 1
        assert not app.internal_errors and not app.errors


async def test_esc_on_a_second_load_returns_to_the_workspace(monkeypatch):
    """Opening another series from a workspace: its preview comes up over the workspace;
    Esc cancels that load and returns to the workspace, its series untouched."""
    path = shared("ct_head_phantom_philips")
    app = CtuiApp()  # the bundled sample first (small: no preview)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        first = app.session
        go, calls = _held_load(monkeypatch)
        app.open_path(str(path))
        await wait_for(pilot, lambda: _preview_shown(app), what="the second series' preview")
        await pilot.press("escape")
        await pilot.pause()
        assert app.screen is app.workspace and app.session is first
        go.set()
        for w in list(app.workers):
            if w.group == "load":
                await w.wait()
        await pilot.pause(0.2)
        assert app.session is first and not calls and not app.internal_errors
