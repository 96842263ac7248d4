"""Centrelines: automatic centred paths of tubes and user paths, in mm."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.measure.centreline import (
    arc_length,
    centreline,
    index_to_mm,
    mm_to_index,
    parse_points,
    path_from_points,
    path_length,
    resample_path,
)
from ctui.engine.core.errors import CtuiError


def _tube(shape, sp, c, a, r, half):
    zz, yy, xx = np.meshgrid(*[np.arange(n) * s for n, s in zip(shape, sp)], indexing="ij")
    a = np.asarray(a, float) / np.linalg.norm(a)
    p = np.stack([xx, yy, zz], -1) - np.asarray(c, float)
    t = p @ a
    d = np.linalg.norm(p - t[..., None] * a, axis=-1)
    return (d <= r) & (np.abs(t) <= half), a


def _off_axis(path, c, a):
    q = path - np.asarray(c)
    return np.linalg.norm(q - (q @ a)[:, None] * a, axis=1), q @ a


@pytest.mark.parametrize("sp", [(0.5, 0.5, 0.5), (1.2, 0.4, 0.4)], ids=["iso", "aniso-1:3"])
def test_centreline_of_oblique_cylinder_is_its_axis(sp):
    shape = (40, 60, 60) if sp[0] == 0.5 else (17, 75, 75)
    c = (15.1, 14.8, 10.2)
    mask, a = _tube(shape, sp, c, (1.0, 0.6, 0.5), 2.5, 11.0)
    path = centreline(mask, spacing=sp, step_mm=0.5)
    off, t = _off_axis(path, c, a)
    inner = np.abs(t) < 8
    assert off[inner].max() < 0.3, off[inner].max()
    # from one end to the other
    assert abs(t[0]) > 9.5 and abs(t[-1]) > 9.5 and np.sign(t[0]) != np.sign(t[-1])
    # uniform arc-length step
    d = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert np.allclose(d[:-1], 0.5, atol=0.02)
    # straight to the end caps: the path is as long as the cylinder
    assert path_length(path) == pytest.approx(22.0, abs=1.0)


def test_centreline_torus_follows_the_circle_and_respects_geometry():
    """A torus segment with a non-trivial origin and direction (patient mm)."""
    sp = (0.5, 0.5, 0.5)
    shape = (20, 70, 70)
    zz, yy, xx = np.meshgrid(*[np.arange(n) * s for n, s in zip(shape, sp)], indexing="ij")
    cx, cy, cz, rt = 17.3, 17.1, 5.05, 13.0
    rho = np.hypot(xx - cx, yy - cy)
    ang = np.arctan2(yy - cy, xx - cx)
    mask = ((rho - rt) ** 2 + (zz - cz) ** 2 <= 2.0**2) & (ang > 0.1) & (ang < 2.9)
    origin = np.array([-100.0, 50.0, 20.0])
    direction = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # x index -> +y, y index -> -x
    path = centreline(mask, spacing=sp, origin=origin, direction=direction)
    # back to index-space mm
    idx = mm_to_index(path, spacing=sp, origin=origin, direction=direction)
    q = idx[:, ::-1] * 0.5  # (x, y, z) mm in the grid frame
    r = np.hypot(q[:, 0] - cx, q[:, 1] - cy)
    a = np.arctan2(q[:, 1] - cy, q[:, 0] - cx)
    inner = (a > 0.4) & (a < 2.6)
    assert np.abs(r[inner] - rt).max() < 0.25
    assert np.abs(q[inner, 2] - cz).max() < 0.25


def test_centreline_given_endpoints_and_errors():
    sp = (0.5, 0.5, 0.5)
    c = (10.0, 10.0, 10.0)
    mask, a = _tube((40, 40, 40), sp, c, (0, 0, 1), 2.0, 8.0)
    ends = np.array([[10.0, 10.0, 4.0], [10.0, 10.0, 16.0]])
    path = centreline(mask, spacing=sp, endpoints=ends)
    assert np.linalg.norm(path[0] - ends[0]) < 0.6 and np.linalg.norm(path[-1] - ends[1]) < 0.6
    assert path_length(path) == pytest.approx(12.0, abs=0.6)
    # voxel endpoints (z, y, x)
    path2 = centreline(mask, spacing=sp, endpoints=[[8, 20, 20], [32, 20, 20]], endpoints_voxel=True)
    assert path_length(path2) == pytest.approx(12.0, abs=0.6)
    with pytest.raises(CtuiError):
        centreline(np.zeros((5, 5, 5), bool), spacing=sp)
    two = np.zeros((10, 10, 30), bool)
    two[2:5, 2:5, 2:10] = True
    two[2:5, 2:5, 20:28] = True
    with pytest.raises(CtuiError):
        centreline(two, spacing=(1, 1, 1), endpoints=[[3, 3, 3], [3, 3, 25]], endpoints_voxel=True)


def test_path_from_points_interpolates_and_resamples():
    pts = np.array([[0.0, 0, 0], [10, 5, 0], [20, 0, 3], [30, 2, 8]])
    path = path_from_points(pts, step_mm=0.25)
    s = arc_length(path)
    assert np.allclose(np.diff(s)[:-1], 0.25, atol=0.01)
    # the spline passes through the given points
    for p in pts:
        assert np.linalg.norm(path - p, axis=1).min() < 0.15
    assert np.allclose(path[0], pts[0]) and np.allclose(path[-1], pts[-1])
    # voxel indices (z, y, x) with geometry
    sp, org = (2.0, 0.5, 0.5), (10.0, 20.0, 30.0)
    vox = np.array([[0, 0, 0], [5, 10, 20]], float)
    pv = path_from_points(vox, voxel=True, spacing=sp, origin=org, step_mm=0.5)
    assert np.allclose(pv[-1], index_to_mm(vox[-1], spacing=sp, origin=org))
    assert path_length(pv) == pytest.approx(np.linalg.norm([10.0, 5.0, 10.0]), rel=1e-6)


def test_parse_points_and_resample():
    p = parse_points("1,2,3; 4,5,6;7,8,9")
    assert p.shape == (3, 3) and p[1, 2] == 6
    for bad in ("1,2;3,4,5", "a,b,c;1,2,3", "1,2,3"):
        with pytest.raises(CtuiError):
            parse_points(bad)
    line = np.array([[0, 0, 0], [10.0, 0, 0]])
    r = resample_path(line, 3.0)
    assert np.allclose(r[:, 0], [0, 3, 6, 9, 10])
