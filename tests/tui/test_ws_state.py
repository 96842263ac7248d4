"""The workspace's state objects (ctui.screens.ws_state) on their own, without a screen:
a synthetic volume with known boxes, checked voxel by voxel."""

from __future__ import annotations

import numpy as np

from ctui.engine.actions.series import Segmentation
from ctui.engine.core.volume import Volume
from ctui.engine.segment.propagate import Proposal
from ctui.screens import planes
from ctui.screens.session import Session
from ctui.screens.ws_state import EditTools, Jobs, ObjectVolumes, ProposalState, SeedRange, ViewState, label_counts


def _session(shape=(12, 40, 60), spacing=(2.0, 0.5, 0.5)) -> Session:
    return Session(Volume(np.zeros(shape, np.int16), spacing=spacing, modality="CT"), source_path="synthetic",
                   z=6, y=20, x=30)


def _box_proposal(shape) -> tuple[Proposal, np.ndarray]:
    """Object 2: a box z 3..7, y 10..19, x 20..39 proposed from slice 5."""
    mask = np.zeros(shape, bool)
    mask[3:8, 10:20, 20:40] = True
    return Proposal.of_mask(2, 5, mask), mask


def test_view_center_zoom_and_pan_stay_inside_the_plane():
    s, vs = _session(), ViewState()
    pv = planes.plane_view(s.volume, "axial")
    cursor = planes.cursor_in(pv, s.zyx, s.shape)
    assert vs.center(s, "axial") == cursor  # not zoomed: centred on the cursor
    assert vs.zoom_by(1) == 2.0 and vs.zoom_by(1) == 4.0
    assert vs.center(s, "axial") == (float(cursor[0]), float(cursor[1]))
    step = vs.pan_by(s, 1, 0)  # a quarter of the zoomed view: 60 / 4 / 4 pixels
    assert step == (4, 0) and vs.pan_center == (cursor[0] + 3.75, float(cursor[1]))
    vs.pan_to((0.0, 0.0))  # far off: the view stays inside the image, the cursor visible
    s.x, s.y = 2, 2
    cx, cy = vs.center(s, "axial")
    assert (cx, cy) == (60 / 4 / 2, 40 / 4 / 2)
    for _ in range(3):
        vs.zoom_by(-1)
    assert vs.zoom == 1.0 and vs.pan_center is None  # back to the whole plane: no pan
    vs.set_layout(ortho=True)
    assert vs.ortho_mode and not vs.grid_mode and vs.next_token() == 1 and vs.next_token() == 2


def test_window_presets_cycle_in_order():
    vs = ViewState()
    presets = [("a", (40, 400)), ("b", (-600, 1500))]
    assert vs.next_window(presets) == ("a", (40.0, 400.0))
    assert vs.next_window(presets) == ("b", (-600.0, 1500.0))
    assert vs.next_window(presets) == ("a", (40.0, 400.0)) and vs.window_name == "a"


def test_proposal_planes_match_the_mask_and_accept_records_seed_and_settings():
    s = _session()
    p, mask = _box_proposal(s.shape)
    st = ProposalState()
    st.show(p, seed=(25, 12, 5), object_settings={"low": 100.0, "high": 300.0})
    assert st.object_id == 2
    for plane in planes.PLANES:
        pv = planes.plane_view(s.volume, plane)
        for index in range(s.shape[pv.normal]):
            got = st.plane(pv, index, s.shape)
            assert np.array_equal(got, planes.take(mask, pv, index)), (plane, index)
    seg = Segmentation(s.shape)
    seg.add_object("box")  # object 1
    seg.add_object("other")  # object 2
    n, accepted = st.accept(seg)
    assert accepted is p and n == int(mask.sum()) and np.array_equal(seg.labels == 2, mask)
    info = seg.objects[2]
    assert (25, 12, 5) in [tuple(v) for v in info.seeds] and info.settings["low"] == 100.0
    assert st.proposal is None and st.seed is None and st.plane(pv, 0, s.shape) is None
    fresh = Segmentation(s.shape)  # an object segmented before it was ever filled: registered on accept
    st.show(p, seed=(25, 12, 5), object_settings={"method": "fill"})
    st.accept(fresh)
    assert fresh.objects[2].seeds == [(25, 12, 5)] and fresh.objects[2].settings["method"] == "fill"


def test_a_cut_proposal_keeps_its_seed_and_reject_clears_it():
    s = _session()
    p, _mask = _box_proposal(s.shape)
    st = ProposalState()
    st.show(p, seed=(25, 12, 5))
    st.replace(Proposal.of_mask(2, 5, np.zeros(s.shape, bool)))
    assert st.seed == (25, 12, 5) and st.proposal is not p
    assert st.clear() is not None and st.clear() is None and st.seed is None


def test_jobs_cancel_the_segmentation_first_then_the_worker():
    class Handle:
        cancelled = False

        def cancel(self):
            self.cancelled = True

    jobs, worker, run = Jobs(), Handle(), Handle()
    assert jobs.cancel() is None
    jobs.track(worker)
    jobs.segmentation_started(run)
    assert jobs.segmenting
    assert jobs.cancel() == "segmentation" and run.cancelled and not worker.cancelled
    jobs.segmentation_ended()
    assert jobs.cancel() == "job" and worker.cancelled and jobs.worker is None
    first, second = Handle(), Handle()
    jobs.track(first)
    jobs.track(second, replace=True)
    assert first.cancelled and jobs.worker is second


def test_edit_tools_pen_polygon_and_box_corner():
    t = EditTools()
    assert t.toggle_pen("brush") and t.pen == "brush"
    assert t.toggle_pen("eraser") and t.pen == "eraser"  # the other tool takes its place
    assert not t.toggle_pen("eraser") and t.pen is None
    assert not t.lift()
    assert t.add_point(3, 4) == 1 and t.polygon_mode and t.add_point(5, 6) == 2
    t.box_corner = (1, 2, 3)
    assert t.take_corner() == (1, 2, 3) and t.box_corner is None
    t.clear_shapes()
    assert t.polygon == [] and not t.polygon_mode
    assert t.toggle_click_fills() and not t.toggle_click_fills()


def test_object_volumes_follow_the_labels_version():
    s = _session()
    s.seg.labels[2:4, 0:10, 0:10] = 1  # 200 voxels of 0.5 mm3
    vols = ObjectVolumes()
    assert vols.of(s) == {1: 200 * 0.5 / 1000.0}
    s.seg.labels[5, 0:10, 0:10] = 3
    assert 3 not in vols.of(s)  # same version: the counted volumes
    vols.changed()
    assert vols.of(s)[3] == 100 * 0.5 / 1000.0
    assert np.array_equal(label_counts(s.seg.labels), np.bincount(s.seg.labels.ravel(), minlength=256))


def test_seed_range_keeps_only_the_answer_for_the_cursor_asked_last():
    sr = SeedRange()
    assert sr.wants((5, 1, 1)) and not sr.wants((5, 1, 1))  # asked once per cursor position
    assert sr.wants((6, 1, 1))  # the cursor moved on before the first answer
    assert not sr.store((5, 1, 1), "late") and sr.result is None
    assert sr.store((6, 1, 1), "range") and sr.result == "range"
