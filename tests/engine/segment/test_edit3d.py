"""3D edits of the engine on phantoms with known voxel counts: keep / remove the island
under a voxel (slice and 3D), the ROI box confining a brush and a fill, scissors inside
and outside a box or polygon on a slice range, smoothing (median, opening, closing) with
a size in mm; each is one undo step, and bad input leaves the labels untouched."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.actions import edit as et
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.volume import Volume
from ctui.engine.segment.selection import Segmentation


def _two_blocks() -> Segmentation:
    """Object 1: block A (z 2..5, y 4..9, x 4..9: 144 voxels) and block B (z 2..5, y 4..9,
    x 14..17: 96 voxels); object 2: one voxel column next to B it must keep."""
    seg = Segmentation((10, 20, 24))
    lab = np.zeros((10, 20, 24), np.uint8)
    lab[2:6, 4:10, 4:10] = 1
    lab[2:6, 4:10, 14:18] = 1
    lab[2:6, 12, 20] = 2
    seg.apply_region((slice(0, 10), slice(0, 20), slice(0, 24)), lab, label="setup")
    return seg


def test_keep_island_under_cursor_3d_and_slice_and_undo():
    seg = _two_blocks()
    assert seg.voxels(1) == 240
    r = et.island(seg, (3, 5, 15), object_id=1)  # on block B
    assert r["removed"] == 144 and seg.voxels(1) == 96 and seg.voxels(2) == 4
    seg.undo()
    assert seg.voxels(1) == 240
    # in the slice only: slice 3 loses block A's 36 pixels, the other slices keep both
    r = et.island(seg, (3, 5, 15), object_id=1, in_slice=True)
    assert r["removed"] == 36 and seg.voxels(1) == 204
    assert (seg.labels[3] == 1).sum() == 24 and (seg.labels[2] == 1).sum() == 60
    seg.undo()
    # remove the island under the cursor
    r = et.island(seg, (4, 6, 6), object_id=1, keep=False)
    assert r["removed"] == 144 and seg.voxels(1) == 96
    # a box limits what is removed: only block B's voxels inside x 14..15
    seg.undo()
    r = et.island(seg, (3, 5, 5), object_id=1, box=((0, 9), (0, 19), (14, 15)))
    assert r["removed"] == 4 * 6 * 2


def test_island_off_the_object_is_an_error_and_changes_nothing():
    seg = _two_blocks()
    before = seg.labels.copy()
    n_undo = len(seg.undo_labels())
    with pytest.raises(CtuiError, match="not on object 1"):
        et.island(seg, (0, 0, 0), object_id=1)
    with pytest.raises(CtuiError, match="off the image"):
        et.island(seg, (3, 50, 5), object_id=1)
    assert np.array_equal(before, seg.labels) and len(seg.undo_labels()) == n_undo


def test_scissors_box_inside_outside_slice_ranges():
    seg = _two_blocks()
    box = et.parse_box("4,4,0,9,9,9", seg.shape)  # x,y,z corners around block A, all slices
    assert et.parse_box("4,4:9,9", seg.shape) == et.parse_box("4,4,0:9,9,9", seg.shape)
    assert box == ((0, 9), (4, 9), (4, 9))
    r = et.cut(seg, object_id=1, box=box)
    assert r["removed"] == 144 and seg.voxels(1) == 96
    seg.undo()
    r = et.cut(seg, object_id=1, box=box, slices=(3, 3))  # this slice only
    assert r["removed"] == 36
    seg.undo()
    r = et.cut(seg, object_id=1, box=box, inside=False, slices=(2, 3))  # outside, two slices
    assert r["removed"] == 2 * 24 and seg.voxels(2) == 4
    seg.undo()
    # a triangle polygon (x, y): lower-left half of block A's 6x6 square on every slice
    r = et.cut(seg, object_id=1, polygon=[(4, 4), (4, 9), (9, 9)])
    assert r["removed"] == 4 * 21  # 6 + 5 + ... + 1 pixels per slice, edges included
    seg.undo()
    assert seg.voxels(1) == 240


def test_scissors_with_nothing_inside_and_bad_boxes():
    seg = _two_blocks()
    before = seg.labels.copy()
    with pytest.raises(CtuiError, match="nothing of object 1"):
        et.cut(seg, object_id=1, box=((0, 9), (15, 19), (0, 3)))
    with pytest.raises(CtuiError, match="zero width"):
        et.parse_box("5,5,0:5,9,3", seg.shape)
    with pytest.raises(CtuiError, match="outside the volume"):
        et.parse_box("100,100,0:120,130,3", seg.shape)
    with pytest.raises(CtuiError, match="3 points"):
        et.cut(seg, object_id=1, polygon=[(1, 1), (5, 5)])
    assert np.array_equal(before, seg.labels)


def test_brush_and_fill_confined_to_box():
    vol = Volume(np.full((5, 30, 30), 100, np.int16), spacing=(1.0, 1.0, 1.0), modality="CT")
    seg = Segmentation(vol.shape)
    box = ((2, 2), (10, 19), (10, 14))
    n = et.dab(seg, vol, (2, 15, 15), axis=0, object_id=1, radius=0, radius_mm=4.0, mode="add",
               limits=et.EditLimits(), box=box)
    # disc of radius 4 px (49 px) cut at x <= 14: the columns x 11..14
    yy, xx = np.mgrid[-4:5, -4:5]
    assert n == int(((yy ** 2 + xx ** 2 <= 16) & (xx <= -1)).sum())
    assert not seg.labels[:, :, 15:].any()
    n, reason, _ = et.fill_slice(seg, vol.data[2].astype(np.float32), 12, 12, 2, object_id=2, mode="add",
                                 tolerance=10, box=box, neck_mm=0)
    assert reason == "" and int((seg.labels == 2).sum()) == 10 * 5 - int((seg.labels == 1).sum())
    with pytest.raises(CtuiError, match="outside the ROI box"):
        et.fill_slice(seg, vol.data[3].astype(np.float32), 12, 12, 3, object_id=2, mode="add", tolerance=10, box=box)


def _sphere(r_mm: float, spacing=(1.0, 1.0, 1.0), n: int = 32) -> Segmentation:
    zz, yy, xx = np.mgrid[0:n, 0:n, 0:n].astype(float)
    c = (n - 1) / 2
    ball = ((zz - c) * spacing[0]) ** 2 + ((yy - c) * spacing[1]) ** 2 + ((xx - c) * spacing[2]) ** 2 <= r_mm ** 2
    seg = Segmentation((n, n, n))
    seg.apply_region((slice(0, n),) * 3, ball.astype(np.uint8), label="setup")
    return seg


def test_smoothing_median_opening_closing_known_counts():
    seg = _sphere(9.0)
    v0 = seg.voxels(1)
    lab = seg.labels.copy()
    lab[16, 16, 26:30] = 1  # a 4-voxel spur sticking out of the sphere (radius 9: surface at x 24.5)
    lab[16, 16, 16] = 0  # a one-voxel hole inside
    seg.apply_region((slice(0, 32),) * 3, lab, label="spur and hole")
    r = et.smooth(seg, object_id=1, method="opening", size_mm=3.0, spacing=(1.0, 1.0, 1.0))
    assert seg.labels[16, 16, 27:30].sum() == 0  # the spur is gone
    assert r["voxels_before"] == v0 + 4 - 1 and r["voxels"] == r["voxels_before"] - r["removed"] + r["added"]
    seg.undo()
    r = et.smooth(seg, object_id=1, method="closing", size_mm=3.0, spacing=(1.0, 1.0, 1.0))
    assert seg.labels[16, 16, 16] == 1 and r["added"] >= 1  # the hole is filled
    seg.undo()
    r = et.smooth(seg, object_id=1, method="median", size_mm=3.0, spacing=(1.0, 1.0, 1.0))
    assert seg.labels[16, 16, 16] == 1 and seg.labels[16, 16, 28:30].sum() == 0
    # a median of a sphere keeps its volume within a few per cent
    assert abs(r["voxels"] - v0) / v0 < 0.05
    assert r["ml"] == pytest.approx(r["voxels"] / 1000.0)
    seg.undo()
    assert seg.voxels(1) == v0 + 3


def test_smoothing_bad_input_changes_nothing():
    seg = _sphere(6.0)
    before = seg.labels.copy()
    with pytest.raises(CtuiError, match="empty"):
        et.smooth(seg, object_id=3, method="median", size_mm=3.0, spacing=(1.0, 1.0, 1.0))
    with pytest.raises(CtuiError, match="under two voxels"):
        et.smooth(seg, object_id=1, method="median", size_mm=1.0, spacing=(1.0, 1.0, 1.0))
    with pytest.raises(CtuiError, match="method"):
        et.smooth(seg, object_id=1, method="blur", size_mm=3.0, spacing=(1.0, 1.0, 1.0))
    assert np.array_equal(before, seg.labels)


def test_smoothing_never_takes_other_objects():
    seg = _sphere(8.0)
    lab = seg.labels.copy()
    lab[16, 16, 16] = 2  # another object's voxel inside the sphere: closing must not take it
    seg.apply_region((slice(0, 32),) * 3, lab, label="other")
    et.smooth(seg, object_id=1, method="closing", size_mm=3.0, spacing=(1.0, 1.0, 1.0))
    assert seg.labels[16, 16, 16] == 2
