"""Measure screen messages: a closed object with a cavity raises no orientation warning
(a turned-over component outside the others still does); the table compares the voxel
volume with the grey levels' partial-volume estimate (a comparison that can differ);
an object with no cross-sections says why and suggests a path; ``s`` after ``c``
explains instead of "No sections computed yet"."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.meshdata import Mesh
from ctui.engine.core.volume import Volume
from ctui.engine.measure.stats import mesh_stats
from ctui.engine.mesh.surface import mask_surface
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.testing import wait_for, wait_workspace


def _r(n=40):
    zz, yy, xx = np.mgrid[:n, :n, :n]
    return np.sqrt((zz - n / 2) ** 2 + (yy - n / 2) ** 2 + (xx - n / 2) ** 2)


def test_cavity_is_not_an_orientation_fault():
    r = _r()
    shell = (r < 15) & ~(r < 6)  # a closed organ with a hole inside
    st = mesh_stats(mask_surface(shell, spacing=(1.0, 1.0, 1.0)))
    assert st["n_components"] == 2 and st["n_cavities"] == 1
    assert st["warnings"] == []
    assert st["volume_mm3"] == pytest.approx(shell.sum(), rel=0.01)
    # two separate balls, one turned inside out: that one is a fault
    ball = mask_surface(r < 6, spacing=(1.0, 1.0, 1.0))
    v, f = np.asarray(ball.vertices), np.asarray(ball.faces)
    both = Mesh(np.concatenate([v, v + 40.0]), np.concatenate([f, f[:, ::-1] + len(v)]))
    st = mesh_stats(both)
    assert st["n_cavities"] == 0
    assert any("flipped faces" in w for w in st["warnings"])


def _slab_session() -> Session:
    """A flat 300 HU slab (5 x 21 x 21 voxels) in air, labelled one voxel too wide."""
    n = 40
    zz, yy, xx = np.mgrid[:n, :n, :n]
    slab = (abs(zz - 20) <= 2) & (abs(yy - 20) <= 10) & (abs(xx - 20) <= 10)
    wide = (abs(zz - 20) <= 3) & (abs(yy - 20) <= 11) & (abs(xx - 20) <= 11)
    s = Session(Volume(np.where(slab, 300, -1000).astype(np.int16), modality="CT"), source_path="synthetic",
                z=20, y=20, x=20)
    s.seg.labels[wide] = 1
    return s


@pytest.mark.slow
async def test_measure_screen_messages():
    s = _slab_session()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.press("M")
        await wait_for(pilot, lambda: getattr(app.screen, "stats", None), what="the measure row", timeout=60)
        ms = app.screen
        table = ms.query_one("#ms-table")
        labels = [str(c.label) for c in table.columns.values()]
        assert "PV-vox %" in labels and not any("mesh" in x for x in labels)
        row = table.get_row("1")
        diff = float(str(row[labels.index("PV-vox %")]))
        vox, pv = ms.stats[1]["volume_voxels_ml"], ms.stats[1]["volume_pv_ml"]
        # the label is a voxel wider than the bright slab on every side: the grey levels say so
        assert pv < vox and diff == pytest.approx(100 * (pv - vox) / vox, abs=0.06) and diff < -20
        assert not ms.stats[1]["warnings"]
        await pilot.press("c")
        info = ms.query_one("#ms-info")
        await wait_for(pilot, lambda: "No cross-sections" in str(info.render()), what="the reason", timeout=60)
        text = str(info.render())
        assert "--path" in text and ("end cap" in text or "elongated" in text)
        await pilot.press("s")
        await pilot.pause()
        status = str(ms.query_one("#ms-status").render())
        assert "No sections computed yet" not in status
        assert "Nothing to save for object 1" in status and "--path" in status
        assert not app.internal_errors


async def test_measure_table_fits_80_columns():
    s = _slab_session()
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.press("M")
        await wait_for(pilot, lambda: getattr(app.screen, "stats", None), what="the measure row", timeout=60)
        await pilot.pause()
        table = app.screen.query_one("#ms-table")
        assert "PV-vox %" in [str(c.label) for c in table.columns.values()]
        width = sum(c.get_render_width(table) for c in table.columns.values())
        assert width <= 80, width  # every column on screen, none cut
        assert not app.internal_errors
