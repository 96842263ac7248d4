"""Editing tools: brush/eraser in three axes, masking, modes, islands, fill between slices; all undoable."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.errors import CtuiError
from ctui.engine.segment.edit import brush
from ctui.engine.segment.selection import Segmentation


def test_brush_disc_in_each_axis_and_round_in_mm():
    shape = (20, 40, 50)
    off, m = brush(shape, 25, 20, 10, radius=3, axis=0)
    assert off == (10, 17, 22) and m.shape == (1, 7, 7) and m.sum() == 29  # a radius-3 disc
    off, m = brush(shape, 25, 20, 10, radius=3, axis=1)  # coronal: plane (z, x) at row 20
    assert off == (7, 20, 22) and m.shape == (7, 1, 7)
    off, m = brush(shape, 25, 20, 10, radius=3, axis=2)  # sagittal: plane (z, y) at column 25
    assert off == (7, 17, 25) and m.shape == (7, 7, 1)
    # 3 mm slices, 1 mm pixels: round in mm, so one slice either side only
    off, m = brush(shape, 25, 20, 10, radius=3, axis=2, spacing=(3.0, 1.0, 1.0))
    assert m.shape == (3, 7, 1)
    off, m = brush(shape, 0, 0, 0, radius=3)  # clipped at the corner
    assert off == (0, 0, 0) and m.shape == (1, 4, 4)
    with pytest.raises(CtuiError, match="off the image"):
        brush(shape, 50, 0, 0, radius=2)


def test_paint_erase_modes_masking_and_undo():
    seg = Segmentation((10, 30, 30))
    values = np.zeros((10, 30, 30), np.int16)
    values[:, :, 15:] = 100
    n = seg.paint_brush(15, 15, 5, 1, radius=4, axis=1)  # a coronal disc across slices 1..9
    assert n == seg.voxels(1) and set(np.flatnonzero(seg.areas(1))) == set(range(1, 10))
    seg.undo()
    assert seg.voxels(1) == 0
    # limited to slices 4..6 and to values 50..150 (columns >= 15)
    seg.paint_brush(15, 15, 5, 1, radius=4, axis=1, slices=(4, 6), values=values, hu=(50, 150))
    zs, ys, xs = np.nonzero(seg.labels == 1)
    assert zs.min() == 4 and zs.max() == 6 and xs.min() >= 15
    # eraser
    before = seg.voxels(1)
    assert seg.paint_brush(16, 15, 5, 1, radius=1, axis=0, mode="subtract") > 0
    assert seg.voxels(1) < before
    # another object is kept in add mode, taken with overwrite
    seg.paint_brush(20, 15, 5, 2, radius=2)
    assert seg.voxels(2) > 0
    # replace: the object becomes exactly the new mask on the planes it touches
    m = np.zeros((30, 30), bool)
    m[2:5, 2:5] = True
    seg.apply_mask(m, 1, offset=(5, 0, 0), mode="replace")
    assert (seg.labels[5] == 1).sum() == 9 and (seg.labels[4] == 1).sum() > 0 and seg.voxels(2) > 0
    for _ in range(4):
        seg.undo()
    assert seg.voxels(1) == 0 and seg.voxels(2) == 0
    with pytest.raises(CtuiError, match="off the image"):
        seg.paint_brush(40, 1, 1, 1, radius=2)
    assert not seg.labels.any() and seg.can_redo  # nothing lost, redo intact


def test_islands():
    seg = Segmentation((8, 20, 20))
    big = np.zeros((8, 20, 20), bool)
    big[1:6, 2:8, 2:8] = True
    small = np.zeros_like(big)
    small[2:4, 14:16, 14:16] = True  # 8 voxels
    seg.paint(big | small, 1)
    assert seg.remove_islands(1, 9) == 8 and seg.voxels(1) == big.sum()
    seg.undo()
    assert seg.keep_largest_island(1) == 8
    seg.undo()
    assert seg.voxels(1) == big.sum() + 8


def test_fill_between_slices_interpolates_a_cone():
    """Key slices 0 and 10 of a cone (radius 4 -> 14 px): the slices between get the interpolated discs."""
    n = 40
    yy, xx = np.mgrid[:n, :n]
    truth = np.zeros((11, n, n), bool)
    for z in range(11):
        r = 4 + z
        truth[z] = (yy - 20) ** 2 + (xx - 20) ** 2 <= r * r
    seg = Segmentation(truth.shape)
    keys = np.zeros_like(truth)
    keys[[0, 10]] = truth[[0, 10]]
    seg.paint(keys, 1)
    added = seg.fill_between_slices(1)
    assert added > 0 and seg.can_undo
    got = seg.labels == 1
    for z in range(1, 10):
        assert abs(int(got[z].sum()) - int(truth[z].sum())) <= 0.06 * truth[z].sum() + 4
    seg.undo()
    assert seg.voxels(1) == keys.sum()


@pytest.mark.parametrize("kind", ["neck", "bowel", "slow"])
def test_tui_enter_fills_as_ctui_segment_does(kind):
    """The TUI's Enter (actions.edit.fill_slice) and `ctui segment`'s seed slice are one fill:
    cut at the same necks, so a seed in the leak phantom's kidney stays in the kidney."""
    from ctui.engine.actions import edit
    from ctui.engine.actions.segment import SegmentOptions, _seed_fill
    from ctui.engine.segment.phantoms import leak_case
    from ctui.engine.segment.pipeline import Pipeline
    from ctui.engine.segment.selection import Segmentation, threshold_fill

    case = leak_case(kind)
    vol = case.volume
    x, y, z = case.seed
    lo, hi = case.hu_range
    image = Pipeline().final_slice(vol, z)
    seg = Segmentation(vol.shape)
    n, reason, _ = edit.fill_slice(seg, image, x, y, z, object_id=1, mode="add", low=lo, high=hi,
                                   spacing_yx=tuple(vol.spacing[1:]))
    assert not reason and n > 0
    # Enter's fixed 5 mm neck is the seed slice of `ctui segment --neck 5` (S and p use the automatic width)
    cli = _seed_fill(vol, Pipeline(), Segmentation(vol.shape), 1, (x, y, z), (lo, hi),
                     SegmentOptions(neck_mm=5.0, fill_holes=False)).mask
    tui = seg.labels[z] == 1
    assert np.array_equal(tui, cli)
    truth = case.truth[z]
    assert (tui & truth).sum() / truth.sum() > 0.99
    plain = threshold_fill(image, x, y, low=lo, high=hi)
    assert plain.sum() > 1.05 * truth.sum()  # the phantom leaks on the seed slice without the neck cut
    assert tui.sum() <= 1.02 * truth.sum()
