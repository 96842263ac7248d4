"""Review of a propagation proposal (engine): the area profile, marks where the area
jumps or the centre moves, cut here (joined to the seed) and keep from the seed to here,
on a phantom proposal with a known leak."""

from __future__ import annotations

import numpy as np

from ctui.engine.segment import review
from ctui.engine.segment.propagate import Proposal
from ctui.engine.segment.selection import Segmentation


def _proposal() -> tuple[Proposal, np.ndarray]:
    """Seed slice 10: a 10x10 square at y, x 10..19. Slices 11..14 the same square;
    slice 15 leaks: the square plus a 10x20 block beside it (joined); slices 16..18 hold
    only the block (the leak continues, the organ has ended); slices 5..9 the square.
    And on slice 12 an unjoined speck at y, x 40..41 (4 px)."""
    ny = nx = 50
    sq = np.zeros((ny, nx), bool)
    sq[10:20, 10:20] = True
    leak = np.zeros((ny, nx), bool)
    leak[10:20, 20:40] = True
    p = Proposal(object_id=1, start_slice=10, shape=(30, ny, nx))
    for z in list(range(5, 10)) + list(range(11, 15)):
        m = sq.copy()
        if z == 12:
            m[40:42, 40:42] = True
        p.masks[z] = (0, 0, m)
    p.masks[15] = (0, 0, sq | leak)
    for z in (16, 17, 18):
        p.masks[z] = (0, 0, leak.copy())
    p.areas = {z: int(e[2].sum()) for z, e in p.masks.items()}
    return p, sq


def test_profile_and_marks_find_the_leak():
    p, sq = _proposal()
    prof = review.profile(p, 30, seed_area=100)
    assert prof[10] == 100 and prof[15] == 300 and prof[16] == 200 and prof[4] == 0 and prof[19] == 0
    found = review.marks(p, seed_mask=sq)
    zs = [m.z for m in found]
    assert 15 in zs  # +200 %
    assert 16 in zs  # the centre jumps 10 px to the right
    assert all(z >= 15 for z in zs)  # the clean slices are not marked
    by_z = {m.z: m for m in found}
    assert "jump" in by_z[15].kind and "shift" in by_z[16].kind
    assert review.next_mark(found, 10, 1) == 15 and review.next_mark(found, 15, 1) == 16
    assert review.next_mark(found, 15, -1) is None and review.next_mark(found, 20, -1) == max(zs)


def test_cut_here_keeps_the_part_joined_to_the_seed():
    p, sq = _proposal()
    cut = review.cut_at(p, 14, seed_mask=sq)
    assert sorted(cut.masks) == [5, 6, 7, 8, 9, 11, 12, 13, 14]  # the other side kept
    assert cut.areas[12] == 100  # the unjoined speck is dropped
    assert cut.voxels == 9 * 100
    assert p.voxels == 9 * 100 + 4 + 300 + 3 * 200  # the input is unchanged
    # cutting at the leak's slice keeps its joined block, drops the rest
    cut15 = review.cut_at(p, 15, seed_mask=sq)
    assert cut15.areas[15] == 300 and 16 not in cut15.masks
    # backward: cut at 7 drops 5, 6
    assert sorted(review.cut_at(p, 7, seed_mask=sq).masks)[:2] == [7, 8]


def test_keep_from_seed_to_here_and_accept():
    p, sq = _proposal()
    kept = review.keep_to(p, 13, seed_mask=sq)
    assert sorted(kept.masks) == [11, 12, 13] and kept.voxels == 300
    seg = Segmentation((30, 50, 50))
    seg.apply_mask(sq, 1, offset=(10, 0, 0))
    assert kept.accept(seg) == 300
    assert seg.voxels(1) == 400 and seg.slice_range(1) == (10, 13)
    # without a seed mask, the proposal's slices next to the seed are the root
    assert review.keep_to(p, 14).voxels == 400


def test_marks_on_an_accepted_object():
    p, sq = _proposal()
    seg = Segmentation((30, 50, 50))
    seg.apply_mask(sq, 1, offset=(10, 0, 0))
    p.accept(seg)
    st = review.of_labels(seg.labels, 1, start_slice=10)
    assert st.areas[10] == 100 and st.areas[15] == 300 and st.areas[12] == 104
    zs = [m.z for m in review.marks(st)]
    assert 15 in zs and 16 in zs and all(z >= 15 for z in zs)
    assert review.of_labels(seg.labels, 1).start_slice == 15  # default: the largest slice


def test_a_leak_on_the_seed_slice_is_marked():
    """The seed slice filled the whole body (a leak every other slice grew from): marked."""
    ny = nx = 50
    sq = np.zeros((ny, nx), bool)
    sq[10:20, 10:20] = True
    body = np.zeros((ny, nx), bool)
    body[5:45, 5:45] = True
    p = Proposal(object_id=1, start_slice=10, shape=(20, ny, nx))
    for z in range(7, 14):
        p.masks[z] = (0, 0, body.copy() if z == 10 else sq.copy())
    p.areas = {z: int(e[2].sum()) for z, e in p.masks.items()}
    by_z = {m.z: m for m in review.marks(p)}
    assert by_z[10].kind == "seed" and "1600 px" in by_z[10].why
    p.masks[10] = (0, 0, sq.copy())
    assert 10 not in {m.z for m in review.marks(p)}
