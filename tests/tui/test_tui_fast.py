"""The side panel's object volumes and the review strip's object stack follow edits from the
voxels they changed, with the same results as a whole recount (issue 40, item 4)."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.actions.series import label_counts
from ctui.engine.core.volume import Volume
from ctui.engine.segment import review
from ctui.engine.segment.selection import Segmentation
from ctui.screens import graphics, ws_state
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.testing import wait_workspace
from ctui.screens.ws_state import ObjectVolumes


def _old_of_labels(labels, object_id, start_slice=None):
    """The whole-volume scan review.of_labels did before (the reference)."""
    masks, areas = {}, {}
    eq = labels == object_id
    for z in np.flatnonzero(eq.any(axis=(1, 2))):
        ys, xs = np.flatnonzero(eq[z].any(axis=1)), np.flatnonzero(eq[z].any(axis=0))
        ya, yb, xa, xb = int(ys[0]), int(ys[-1]) + 1, int(xs[0]), int(xs[-1]) + 1
        masks[int(z)], areas[int(z)] = (ya, xa, eq[z, ya:yb, xa:xb].copy()), int(eq[z].sum())
    if start_slice is None or start_slice not in masks:
        start_slice = max(areas, key=areas.get) if areas else 0
    return int(start_slice), masks, areas


def _same_stack(stack, ref) -> None:
    start, masks, areas = ref
    assert stack.start_slice == start
    assert list(stack.masks) == list(masks) and stack.areas == areas
    for z, (y0, x0, m) in masks.items():
        a0, b0, mm = stack.masks[z]
        assert (a0, b0) == (y0, x0) and np.array_equal(mm, m)


def _edits(seg: Segmentation):
    """A sequence of brush, erase, undo and redo edits across slices and objects; yields after each."""
    steps = [
        lambda: seg.paint_brush(20, 20, 5, 1, radius=4),
        lambda: seg.paint_brush(24, 20, 6, 1, radius=4),
        lambda: seg.paint_brush(22, 22, 20, 1, radius=3),
        lambda: seg.paint_brush(30, 30, 6, 2, radius=5),
        lambda: seg.paint_brush(26, 22, 6, 2, radius=4, overwrite=True),
        lambda: seg.paint_brush(21, 20, 5, 1, radius=2, mode="subtract"),
        seg.undo, seg.undo, seg.redo,
        lambda: seg.paint_brush(20, 20, 3, 1, radius=3),  # a new edit drops the redo
        seg.undo, seg.undo, seg.undo, seg.redo, seg.redo,
        lambda: seg.paint_brush(20, 20, 5, 1, radius=6, mode="subtract"),
    ]
    for step in steps:
        step()
        yield


class _Session:
    def __init__(self, seg):
        self.seg = seg
        self.volume = Volume(np.zeros(seg.shape, np.int16), spacing=(2.0, 0.5, 0.5), modality="CT")


def test_object_volumes_follow_edits_like_a_full_recount(monkeypatch):
    seg = Segmentation((24, 48, 48))
    seg.add_object()
    seg.add_object()
    vols, session = ObjectVolumes(), _Session(seg)
    recounts = []
    monkeypatch.setattr(ws_state, "label_counts", lambda a: recounts.append(1) or label_counts(a))
    vols.of(session)
    for _ in _edits(seg):
        vols.changed()
        truth = label_counts(seg.labels)
        assert np.array_equal(vols.counts(seg), truth)
        vml = 2.0 * 0.5 * 0.5 / 1000.0
        assert vols.of(session) == {i: float(truth[i]) * vml for i in range(1, 256) if truth[i]}
    assert len(recounts) == 1  # only the first count read the whole label volume
    # a write outside the journal (a version with no edit): recounted, still right
    seg.labels[0, :3, :3] = 2
    vols.changed()
    assert np.array_equal(vols.counts(seg), label_counts(seg.labels)) and len(recounts) == 2
    # another label array: recounted
    seg.labels = seg.labels.copy()
    seg.labels[1, :2, :2] = 1
    vols.changed()
    assert np.array_equal(vols.counts(seg), label_counts(seg.labels)) and len(recounts) == 3


def test_journal_gives_up_past_its_length():
    seg = Segmentation((4, 16, 16))
    seg.add_object()
    assert seg.changes_since(0)[1] == []
    for k in range(70):
        seg.apply_region((slice(0, 1), slice(0, 1), slice(0, 1)), np.full((1, 1, 1), 1 + k % 2, np.uint8))
    assert seg.revision == 70 and seg.changes_since(0) is None
    delta, boxes = seg.changes_since(seg.revision - 3)
    assert (int(delta[1]), int(delta[2]), int(abs(delta).sum())) == (-1, 1, 2)  # 1 -> 2 -> 1 -> 2: one voxel moved
    assert len(boxes) == 3


def test_review_stack_follows_edits_like_the_full_scan():
    seg = Segmentation((24, 48, 48))
    seg.add_object()
    seg.add_object()
    stack, rev = review.of_labels(seg.labels, 1), seg.revision
    _same_stack(stack, _old_of_labels(seg.labels, 1))
    for _ in _edits(seg):
        _, boxes = seg.changes_since(rev)
        stack, rev = review.restack(stack, seg.labels, 1, boxes), seg.revision
        _same_stack(stack, _old_of_labels(seg.labels, 1))
        _same_stack(review.of_labels(seg.labels, 1, 6), _old_of_labels(seg.labels, 1, 6))
        _same_stack(review.restack(stack, seg.labels, 1, [], 20), _old_of_labels(seg.labels, 1, 20))
        assert review.marks(stack) == review.marks(review.Stack(*_stack_args(seg.labels, 1)))


def _stack_args(labels, oid):
    start, masks, areas = _old_of_labels(labels, oid)
    return start, labels.shape, masks, areas


@pytest.fixture
def _halfblock(monkeypatch, tmp_path):
    monkeypatch.setenv("CTUI_AUTOSAVE_DIR", str(tmp_path / "autosave"))
    monkeypatch.chdir(tmp_path)
    with graphics.using_graphics("halfblock"):
        yield


async def test_workspace_strip_and_volumes_after_brush_and_undo(_halfblock, monkeypatch):
    scans = []
    full_scan = review.of_labels
    monkeypatch.setattr(review, "of_labels", lambda *a, **k: scans.append(1) or full_scan(*a, **k))
    n, nz = 48, 20
    yy, xx = np.mgrid[0:n, 0:n]
    data = np.full((nz, n, n), -1000, np.int16)
    data[:, (yy - n / 2) ** 2 + (xx - n / 2) ** 2 <= 100] = 300
    s = Session(Volume(data, spacing=(1.0, 1.0, 1.0), modality="CT"), source_path="synthetic", z=8, y=24, x=24)
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        s.brush = 3
        for keys in (("space",), ("pageup", "space"), ("pageup", "space"), ("b", "l", "l", "b"), ("u",),
                     ("pageup", "pageup", "space"), ("E", "space", "E"), ("u",), ("U",), ("pagedown", "space")):
            await pilot.press(*keys)
            await pilot.pause()
            truth = label_counts(s.seg.labels)
            assert np.array_equal(ws.volumes.counts(s.seg), truth)
            src = ws.review.review_source()
            ref = _old_of_labels(s.seg.labels, s.current)
            if max(ref[1], default=0) - min(ref[1], default=0) >= 2:
                _same_stack(src, ref)
                assert [m.z for m in ws.review.review_marks()] == [m.z for m in review.marks(review.Stack(*_stack_args(s.seg.labels, s.current)))]
            else:
                assert src is None
        assert len(scans) == 1  # the object was read whole once; each edit re-read only its slices
        assert not app.internal_errors
