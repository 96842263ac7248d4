"""Borders: ordered polygons, holes, orientation, parts, mm coordinates."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.borders import Border, border_mm, borders_for_mric, object_borders, signed_area, slice_borders
from ctui.engine.core.volume import Volume


def test_square_with_hole_orientation_and_area():
    m = np.zeros((40, 40), bool)
    m[5:25, 8:30] = True  # 20 rows x 22 columns
    m[10:15, 12:20] = False  # hole 5 x 8
    bs = slice_borders(m)
    assert [b.hole for b in bs] == [False, True]
    outer, hole = bs
    assert outer.signed_area > 0 and hole.signed_area < 0
    # pixel-centre polygons: outer spans (w-1)x(h-1); the hole border runs through the
    # object pixels around the hole: (w+1)x(h+1) less its 4 corners, cut diagonally
    # (an 8-connected chain; half a pixel each)
    assert outer.signed_area == pytest.approx(21 * 19)
    assert -hole.signed_area == pytest.approx(9 * 6 - 4 * 0.5)
    xs, ys = outer.points[:, 0], outer.points[:, 1]
    assert (xs.min(), xs.max(), ys.min(), ys.max()) == (8, 29, 5, 24)
    # ordered: consecutive points are 8-neighbours
    d = np.abs(np.diff(np.vstack([outer.points, outer.points[:1]]), axis=0)).max(axis=1)
    assert d.max() == 1


def test_several_parts_and_nested_island():
    m = np.zeros((60, 60), np.uint8)
    m[5:15, 5:15] = 1
    m[30:55, 30:55] = 1
    m[35:50, 35:50] = 0  # hole
    m[40:45, 40:45] = 1  # island inside the hole: its own outer border
    bs = slice_borders(m)
    outers = [b for b in bs if not b.hole]
    holes = [b for b in bs if b.hole]
    assert len(outers) == 3 and len(holes) == 1
    assert all(b.signed_area > 0 for b in outers) and holes[0].signed_area < 0
    # each hole follows its parent
    i = [k for k, b in enumerate(bs) if b.hole][0]
    assert not bs[i - 1].hole and bs[i - 1].points[:, 0].min() == 30


def test_disk_area_close_to_pixel_count_and_single_pixel():
    yy, xx = np.mgrid[:100, :100]
    m = (xx - 50) ** 2 + (yy - 50) ** 2 <= 30**2
    (b,) = slice_borders(m)
    # centre-line polygon misses about half a pixel along the perimeter
    assert m.sum() - 0.5 * 2 * np.pi * 30 - 5 < b.signed_area < m.sum()
    one = np.zeros((5, 5), bool)
    one[2, 3] = True
    (p,) = slice_borders(one)
    assert not p.hole and p.points.tolist() == [[3.0, 2.0]]
    assert slice_borders(np.zeros((4, 4), bool)) == []


def test_object_borders_per_slice_match_slice_borders_and_mm():
    labels = np.zeros((4, 50, 60), np.uint8)
    labels[1, 10:20, 0:15] = 2  # touches the image edge
    labels[2, 30:40, 40:60] = 2
    labels[2, 5:8, 5:8] = 1
    per = object_borders(labels, 2)
    assert len(per) == 4 and per[0] == [] and per[3] == []
    for z in (1, 2):
        ref = slice_borders(labels[z] == 2)
        assert len(per[z]) == len(ref)
        for a, b in zip(per[z], ref):
            np.testing.assert_array_equal(a.points, b.points)
    vol = Volume(np.zeros((4, 50, 60), np.int16), spacing=(3.0, 0.5, 0.7), origin=(10.0, 20.0, 30.0))
    mm = border_mm(per[2][0], vol, 2)
    assert mm.shape == (len(per[2][0]), 3)
    np.testing.assert_allclose(mm[:, 2], 30.0 + 2 * 3.0)
    np.testing.assert_allclose(mm[:, 0], 10.0 + per[2][0].points[:, 0] * 0.7)
    np.testing.assert_allclose(mm[:, 1], 20.0 + per[2][0].points[:, 1] * 0.5)


def test_borders_for_mric_layout():
    labels = np.zeros((3, 20, 20), np.uint8)
    labels[0, 2:6, 2:6] = 1
    labels[0, 10:15, 10:15] = 2
    labels[2, 4:9, 4:9] = 2
    out = borders_for_mric(labels)
    assert len(out) == 3 and len(out[0]) == 2 and out[1] == [] and len(out[2]) == 1
    assert out[0][0][0].dtype == np.int32 and out[0][0][0].shape[1] == 2


def test_signed_area_convention():
    # (x, y) numbers going counter-clockwise in the x-right, y-up sense: positive
    assert signed_area(np.array([[0, 0], [1, 0], [1, 1], [0, 1]])) == 1.0
    assert Border(np.array([[0, 0], [0, 1], [1, 1], [1, 0]]), hole=True).signed_area == -1.0
