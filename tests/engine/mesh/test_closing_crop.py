"""A closed isosurface pads only the box that holds the surface (issue 27: half the copy of a
CT), and gives the mesh that padding the whole volume gives: same faces, vertices and
gradient normals to float32 rounding, on both kernels."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.mesh import surface
from ctui.engine.mesh.marching import marching_cubes


def _whole_volume_padded(data, level, spacing, origin):
    """The previous closing: the whole volume padded by one voxel of the fill value."""
    aff = surface.affine_from(spacing, origin, None)
    lo = data.min()
    fill = lo if lo <= level else level
    if np.issubdtype(data.dtype, np.integer) and fill > level - 1:
        fill = np.floor(level)
    shift = np.eye(4)
    shift[:3, 3] = -1.0
    v, f, n = marching_cubes(np.pad(data, 1, constant_values=fill), level, affine=aff @ shift)
    return v, surface._fix_handedness(f, aff @ shift), n


@pytest.mark.parametrize("kernels", ["compiled", "numpy"])
def test_cropped_closing_equals_whole_volume_padding(monkeypatch, kernels):
    monkeypatch.setenv("CTUI_KERNELS", kernels)
    rng = np.random.default_rng(2)
    checked = 0
    for k in range(6):
        d = rng.normal(size=(12, 14, 16)).astype(np.float32) - 3.0
        z0, y0, x0 = rng.integers(0, 5, 3)
        z1, y1, x1 = rng.integers(8, 17, 3)
        d[z0:z1, y0:y1, x0:x1] += 4.0  # a noisy block touching some of the borders
        for data, level in ((d, 0.3), ((d * 100).astype(np.int16), 30.0)):
            if not surface._touches_border(data, level):
                continue
            v, f, n = _whole_volume_padded(data, level, (1.5, 0.8, 0.7), (10.0, -3.0, 5.0))
            m = surface.isosurface(data, level, spacing=(1.5, 0.8, 0.7), origin=(10.0, -3.0, 5.0), close=True)
            np.testing.assert_array_equal(m.faces, f)
            np.testing.assert_allclose(m.vertices, v, atol=1e-4)
            np.testing.assert_allclose(m.normals, n, atol=1e-3)
            checked += 1
    assert checked >= 6


def test_closing_crop_is_the_box_grown_by_two():
    d = np.zeros((20, 30, 40), np.int16)
    d[0:5, 10:12, 20:31] = 500  # touches the first slice only
    sls, pads, off = surface._closing_crop(d, 300.0)
    assert sls == (slice(0, 7), slice(8, 14), slice(18, 33))
    assert pads == [(1, 0), (0, 0), (0, 0)]
    assert off == [-1, 8, 18]
