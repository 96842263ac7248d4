"""MIP/MinIP from an overview where the image cannot show more detail: block max/min
keeps every bright (dark) voxel; full resolution when the image can show every voxel."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.render.volume_gpu import block_reduce, overview_step


def test_block_reduce_equals_numpy_blocks():
    rng = np.random.default_rng(1)
    d = rng.integers(-1000, 3000, size=(13, 10, 7)).astype(np.int16)
    for step in (2, 3):
        got = block_reduce(d, step, "max")
        pad = [(0, -n % step) for n in d.shape]
        p = np.pad(d, pad, constant_values=np.iinfo(np.int16).min)
        want = p.reshape(p.shape[0] // step, step, p.shape[1] // step, step, p.shape[2] // step, step).max(axis=(1, 3, 5))
        np.testing.assert_array_equal(got, want)
        assert got.dtype == d.dtype
    assert block_reduce(d, 2, "min").min() == d.min()


def test_overview_step():
    assert overview_step((1.0, 0.7, 0.7), 1.15) == 1  # 300 slices at 512 px: every voxel
    assert overview_step((1.0, 0.7, 0.7), 4.03) == 2  # 2,000 slices at 512 px
    assert overview_step((0.5, 0.5, 0.5), 0.4) == 1


@pytest.mark.egl
@pytest.mark.parametrize("mode", ["mip", "minip"])
def test_tall_series_renders_from_an_overview_like_full_resolution(mode, monkeypatch):
    from ctui.engine.render import (
        Camera,
        EGLUnavailable,
        Scene,
        SceneVolume,
        get_renderer,
        gl,
    )

    try:
        r = get_renderer()
    except EGLUnavailable as exc:
        pytest.skip(f"no EGL context: {exc}")
    rng = np.random.default_rng(2)
    d = rng.integers(0, 100, size=(400, 64, 64)).astype(np.int16)
    z, y, x = np.ogrid[:400, :64, :64]
    d[(z - 201) ** 2 + (y - 33) ** 2 + (x - 35) ** 2 <= 36] = 1000 if mode == "mip" else -1000  # a ball, r 6
    scene = Scene(volume=SceneVolume(d, spacing=(1.0, 1.0, 1.0)), mode=mode)
    scene.camera = Camera(azimuth=0, elevation=0)
    scene.options.window = (500.0, 1000.0) if mode == "mip" else (-500.0, 1000.0)  # (centre, width)
    scene.options.background = (0.5, 0.5, 0.5)  # neither the ball nor the rest

    def render():
        r.clear_cache() if hasattr(r, "clear_cache") else None
        img = r.render(scene, size=(100, 100))[..., 0].astype(int)
        g = r.volumes[id(d)] if hasattr(r, "volumes") else r.engine.volumes[id(d)]
        return img, g.step, g.dims

    img, step, dims = render()
    assert step >= 2 and dims[2] <= 200  # an overview: at most half the slices on the GPU
    monkeypatch.setattr(gl, "overview_step", lambda *a: 1)
    full, step1, _ = render()
    assert step1 == 1
    ball = full >= 200 if mode == "mip" else full <= 50
    assert ball.sum() >= 4  # the ball shows at full resolution ...
    assert np.abs(img - full)[ball].max() <= 40  # ... and from the overview
    assert np.abs(img - full).mean() <= 3
