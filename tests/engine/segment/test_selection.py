"""Threshold flood fill, object bookkeeping and bounding-box undo/redo."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.segment.selection import Segmentation, fill_range, threshold_fill


def _diagonal() -> np.ndarray:
    img = np.zeros((20, 20), np.float32)
    img[2:6, 2:6] = 100
    img[6:10, 6:10] = 100  # touches the first square only at a corner
    return img


def test_connectivity_8_vs_4():
    img = _diagonal()
    m8 = threshold_fill(img, 3, 3, low=50, high=150, connectivity=8)
    m4 = threshold_fill(img, 3, 3, low=50, high=150, connectivity=4)
    assert m8.sum() == 32 and m4.sum() == 16
    assert m4[2:6, 2:6].all() and not m4[6:10, 6:10].any()


def test_tolerance_and_explicit_range():
    assert fill_range(100.0, tolerance=20) == (80.0, 120.0)
    assert fill_range(100.0, low=10, high=30) == (10.0, 30.0)
    with pytest.raises(ValueError):
        fill_range(100.0)
    img = np.zeros((10, 10), np.float32)
    img[:, 5:] = 100
    img[0, 9] = 130  # outside seed +- 20
    m = threshold_fill(img, 6, 5, low=80, high=120)
    assert m.sum() == 49 and not m[0, 9]
    # seed outside an explicit range: empty
    assert not threshold_fill(img, 6, 5, low=0, high=50)[:, 5:].any()


def test_fill_rejects_small_regions_with_reason():
    seg = Segmentation((3, 20, 20))
    img = np.zeros((20, 20), np.float32)
    img[4:6, 4:6] = 100  # 4 px < 5
    r = seg.fill(img, 4, 4, 1, low=50, high=150)
    assert not r.accepted and r.area == 4 and "minimum area" in r.reason
    assert not seg.labels.any() and not seg.can_undo
    r = seg.fill(img, 0, 0, 1, low=50, high=150)
    assert not r.accepted and "outside the range" in r.reason
    with pytest.raises(IndexError):
        seg.fill(img, 25, 4, 1, low=50, high=150)


def test_objects_share_one_label_volume_and_do_not_overwrite():
    seg = Segmentation((2, 30, 30))
    img = np.zeros((30, 30), np.float32)
    img[5:20, 5:20] = 100
    r1 = seg.fill(img, 6, 6, 0, tolerance=10)
    assert r1.accepted and seg.labels.dtype == np.uint8 and seg.voxels(1) == 225
    img2 = np.zeros((30, 30), np.float32)
    img2[10:25, 10:25] = 100  # overlaps object 1
    oid = seg.add_object("second")
    r2 = seg.fill(img2, 24, 24, 0, tolerance=10, object_id=oid)
    assert r2.accepted and r2.area == 225
    assert seg.voxels(1) == 225 and seg.voxels(2) == 225 - 100  # overlap kept by object 1
    assert seg.objects[1].seeds == [(6, 6, 0)] and seg.objects[2].name == "second"
    assert [o["id"] for o in seg.object_list()] == [1, 2]
    summ = seg.summary(spacing=(2.0, 1.0, 1.0))
    assert summ[0]["volume_ml"] == pytest.approx(225 * 2.0 / 1000)


def test_undo_redo_restores_and_stores_only_bbox():
    shape = (50, 256, 256)
    seg = Segmentation(shape)
    img = np.zeros(shape[1:], np.float32)
    img[100:110, 120:130] = 100  # 10 x 10 region
    seg.fill(img, 125, 105, 20, low=50, high=150)
    assert seg.undo_bytes() == 2 * 10 * 10  # before + after of the 1x10x10 box, nothing more
    assert seg.undo_bytes() < seg.labels.nbytes / 1000
    snapshot = seg.labels.copy()
    seg.paint(np.ones((3, 4, 5), bool), 2, offset=(10, 0, 0))
    assert seg.undo_bytes() == 200 + 2 * 3 * 4 * 5
    assert seg.undo() is not None
    np.testing.assert_array_equal(seg.labels, snapshot)
    assert seg.undo() is not None
    assert not seg.labels.any()
    assert seg.undo() is None
    seg.redo()
    np.testing.assert_array_equal(seg.labels, snapshot)
    seg.redo()
    assert seg.voxels(2) == 60
    # a new edit clears the redo stack
    seg.undo()
    seg.erase(np.ones((1, 5, 5), bool), offset=(20, 100, 120))
    assert not seg.can_redo and seg.voxels(1) == 75


def test_clear_object_is_undoable():
    seg = Segmentation((4, 16, 16))
    seg.paint(np.ones((2, 3, 3), bool), 1, offset=(1, 2, 2))
    seg.clear_object(1)
    assert seg.voxels(1) == 0
    seg.undo()
    assert seg.voxels(1) == 18 and seg.slice_range(1) == (1, 2)


@pytest.mark.slow
def test_random_edits_undo_all_and_redo_all():
    from hypothesis import given, settings
    from hypothesis import strategies as st

    box = st.tuples(st.integers(0, 5), st.integers(0, 19), st.integers(0, 19), st.integers(1, 3), st.integers(1, 8),
                    st.integers(1, 8), st.integers(1, 4), st.booleans())

    @settings(max_examples=40, deadline=None)
    @given(st.lists(box, min_size=1, max_size=8))
    def check(ops):
        seg = Segmentation((8, 28, 28))
        states = [seg.labels.copy()]
        for z, y, x, dz, dy, dx, oid, erase in ops:
            m = np.ones((dz, dy, dx), bool)
            if erase:
                seg.erase(m, offset=(z, y, x))
            else:
                seg.paint(m, oid, offset=(z, y, x))
            if not np.array_equal(seg.labels, states[-1]):
                states.append(seg.labels.copy())
        assert len(seg.undo_labels()) == len(states) - 1
        for expected in reversed(states[:-1]):
            seg.undo()
            np.testing.assert_array_equal(seg.labels, expected)
        for expected in states[1:]:
            seg.redo()
            np.testing.assert_array_equal(seg.labels, expected)

    check()
