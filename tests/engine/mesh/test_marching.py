"""Marching squares / cubes kernels: the worked examples, closedness, agreement with scikit-image."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.mesh.marching import NTRI, TRI_TABLE, marching_cubes, marching_squares
from ctui.engine.core.meshdata import Mesh
from ctui.engine.mesh.meshtools import mesh_report


def _grid_3x3() -> np.ndarray:
    g = np.zeros((3, 3))
    for x, y, v in [(0, 0, 0), (1, 0, 5), (2, 0, 9), (0, 1, 4), (0, 2, 20), (1, 1, 13), (1, 2, 8), (2, 1, 25), (2, 2, 5)]:
        g[y, x] = v  # given as (x, y, value): a[y, x]
    return g


def test_marching_squares_worked_example():
    want = np.array([(1, 0.75), (2, 0.125), (2, 1.7), (1, 1.4), (0.75, 2), (0, 1.4375), (0.7778, 1)])
    got = np.unique(np.round(np.concatenate(marching_squares(_grid_3x3(), 11)), 6), axis=0)
    assert len(got) == 7
    for p in want:
        assert np.min(np.abs(got - p).max(axis=1)) < 1e-3, p
    for p in got:
        assert np.min(np.abs(want - p).max(axis=1)) < 1e-3, p


def test_marching_cubes_worked_example():
    c = np.zeros((2, 2, 2))
    vals = {(0, 0, 0): 0, (1, 0, 0): 15, (1, 1, 0): 19, (0, 1, 0): 14,
            (0, 0, 1): 20, (1, 0, 1): 25, (1, 1, 1): 19, (0, 1, 1): 14}
    for (x, y, z), v in vals.items():
        c[z, y, x] = v
    v, f, n = marching_cubes(c, 12)
    assert f.shape == (1, 3)
    tri = v[f[0]]
    want = np.array([(0.8, 0, 0), (0, 0.857, 0), (0, 0, 0.6)])
    for p in want:
        assert np.min(np.abs(tri - p).max(axis=1)) < 1e-3
    # outward = towards the low corner (0, 0, 0): the normal points to -(1, 1, 1)
    nrm = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    assert nrm.sum() < 0
    assert (n @ np.array([1.0, 1.0, 1.0]) < 0).all()


def test_case_table_is_complementary_and_bounded():
    assert NTRI[0] == 0 and NTRI[255] == 0
    assert NTRI.max() <= TRI_TABLE.shape[1]
    # single-corner cases give one triangle
    for c in range(8):
        assert NTRI[1 << c] == 1 and NTRI[255 ^ (1 << c)] == 1


def _edges_ok(f: np.ndarray) -> tuple[bool, bool]:
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, cnt = np.unique(e, axis=0, return_counts=True)
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    return bool((cnt == 2).all()), len(np.unique(d, axis=0)) == len(d)


@pytest.mark.parametrize("dtype", [np.int16, np.float32, np.uint8])
def test_random_noise_is_closed_and_consistent(dtype):
    # white noise has ambiguous faces everywhere: a consistent face rule keeps it closed
    rng = np.random.default_rng(1)
    a = np.zeros((14, 15, 16), dtype)
    a[1:-1, 1:-1, 1:-1] = rng.integers(0, 100, size=(12, 13, 14)).astype(dtype)
    v, f, n = marching_cubes(a, 49.5)
    assert len(f) > 1000
    closed, consistent = _edges_ok(f)
    assert closed and consistent
    assert Mesh(v, f).volume_mm3() > 0  # outward orientation


def test_agrees_with_scikit_image():
    from scipy.ndimage import gaussian_filter
    from skimage.measure import marching_cubes as sk_mc

    rng = np.random.default_rng(3)
    a = gaussian_filter(rng.normal(size=(30, 34, 38)), 2.5).astype(np.float32)
    a = np.pad(a, 1, constant_values=a.min())
    level = float(np.percentile(a, 70))
    v, f, _ = marching_cubes(a, level)
    sv, sf, _, _ = sk_mc(a, level)
    assert len(v) == len(sv)  # one vertex per crossed edge in both
    mine, theirs = Mesh(v, f), Mesh(np.ascontiguousarray(sv[:, ::-1]), sf)
    assert abs(mine.area_mm2() / theirs.area_mm2() - 1) < 1e-3
    assert abs(abs(mine.volume_mm3()) / abs(theirs.volume_mm3()) - 1) < 1e-3
    assert mesh_report(mine)["watertight"]


def test_sphere_normals_and_affine():
    z, y, x = np.mgrid[:40, :42, :44].astype(np.float32)
    c = np.array([21.5, 20.2, 19.7])  # x, y, z index centre
    d = np.sqrt((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2)
    vol = (1000 - 60 * d).astype(np.int16)  # inside where d < 16.67
    v, f, n = marching_cubes(vol, 0.0)
    radial = v - c
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert np.mean(np.sum(radial * n, axis=1)) > 0.995
    assert np.allclose(np.linalg.norm(v - c, axis=1), 1000 / 60, atol=0.05)
    aff = np.eye(4)
    aff[:3, :3] = np.diag([0.7, 0.8, 2.5])
    aff[:3, 3] = (-10, 20, 30)
    v2, f2, _ = marching_cubes(vol, 0.0, affine=aff)
    assert np.array_equal(f, f2)
    assert np.allclose(v2, v * [0.7, 0.8, 2.5] + [-10, 20, 30], atol=1e-3)


def test_levels_outside_range_give_empty():
    a = np.arange(27, dtype=np.int16).reshape(3, 3, 3)
    for lv in (-100.0, 1e6):
        v, f, _ = marching_cubes(a, lv)
        assert len(v) == 0 and len(f) == 0
