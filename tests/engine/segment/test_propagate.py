"""Propagation through the series: phantom volumes, leak guard, cancel, 3D mode, real data."""

from __future__ import annotations

import threading

import cv2
import numpy as np
import pytest

from ctui.engine.core.volume import Volume
from ctui.engine.segment.pipeline import Pipeline
from ctui.engine.segment.propagate import (
    PropagationSettings,
    iter_propagation,
    propagate,
    propagate_object,
)
from ctui.engine.segment.selection import Segmentation


def _load_or_skip(path):
    try:
        from ctui.engine.io.series import load
    except ImportError as exc:
        pytest.skip(f"ctui.engine.io.series.load not available yet ({exc})")
    return load(path)


@pytest.fixture(scope="module")
def phantom():
    from ctui.engine.io.phantom import make_phantom

    return make_phantom()


def _segment_object(vol, truth_obj, pipeline, **kw):
    seg = Segmentation(vol.shape)
    z, y, x = truth_obj["seed_zyx"]
    lo, hi = truth_obj["hu_range"]
    res = seg.fill(pipeline.final_slice(vol, z), x, y, z, low=lo, high=hi)
    assert res.accepted, res.reason
    oid = max(seg.objects)
    prop = propagate_object(seg, vol, pipeline, oid, z, PropagationSettings(low=lo, high=hi, **kw))
    prop.accept(seg)
    return seg, oid, prop


@pytest.mark.parametrize("mode", ["slice", "3d"])
def test_phantom_kidneys_volume_within_2_percent(phantom, mode):
    vol, truth = phantom
    kidneys = [o for o in truth["objects"] if o["name"].startswith("kidney")]
    assert len(kidneys) == 2
    for k in kidneys:
        seg, oid, prop = _segment_object(vol, k, Pipeline(), mode=mode)
        ml = seg.voxels(oid) * vol.voxel_volume_mm3() / 1000.0
        assert ml == pytest.approx(k["volume_ml"], rel=0.02), k["name"]
        assert not prop.leaks
        assert all("object ends" in s for s in prop.stops.values())


def test_bundled_phantom_series_through_loader(sample_dir):
    from ctui.engine.io.phantom import SAMPLE_DIR, load_truth

    vol = _load_or_skip(SAMPLE_DIR)
    truth = load_truth()
    p = Pipeline()
    p.add("median", size=3, stage=2)  # with a filter: still within 2%
    for k in (o for o in truth["objects"] if o["name"].startswith("kidney")):
        seg, oid, _ = _segment_object(vol, k, p)
        ml = seg.voxels(oid) * vol.voxel_volume_mm3() / 1000.0
        assert ml == pytest.approx(k["volume_ml"], rel=0.02), k["name"]


def _bridge_volume(bridge_slice: int | None = 12):
    """A thin cylinder along z beside a big block; a one-pixel bridge joins them on one slice."""
    nz, n = 24, 96
    data = np.zeros((nz, n, n), np.int16)
    yy, xx = np.mgrid[:n, :n]
    disk = (xx - 25) ** 2 + (yy - 48) ** 2 <= 6**2
    data[:, disk] = 100
    data[:, 20:80, 40:90] = 100  # neighbouring structure, 2 px away from the disk edge (x 31 -> 40 ... gap)
    data[:, :, 32:40] = 0
    if bridge_slice is not None:
        data[bridge_slice, 48, 31:40] = 100  # one-pixel-wide bridge
    return Volume(data, spacing=(1.0, 1.0, 1.0), modality="CT"), disk


def test_leak_guard_stops_at_one_pixel_bridge():
    vol, disk = _bridge_volume(12)
    seg = Segmentation(vol.shape)
    p = Pipeline()
    assert seg.fill(p.final_slice(vol, 4), 25, 48, 4, low=50, high=150).accepted
    prop = propagate_object(seg, vol, p, 1, 4, PropagationSettings(low=50, high=150, leak_factor=2.0, neck_mm=0))
    assert prop.leaks and prop.leaks[0]["slice"] == 12 and prop.leaks[0]["direction"] == "forward"
    assert prop.slices == (0, 11)
    assert "leak guard at slice 12" in prop.stops["forward"]
    assert any("leak guard" in w for w in prop.warnings())
    before = seg.labels.copy()
    n = prop.accept(seg)
    assert n == 11 * disk.sum()
    assert not (seg.labels[:, 20:80, 40:90] == 1).any()  # the neighbour was not flooded
    seg.undo()  # accept is one undo step
    np.testing.assert_array_equal(seg.labels, before)


def test_leak_guard_confine_continues_past_bridge():
    vol, disk = _bridge_volume(12)
    seg = Segmentation(vol.shape)
    p = Pipeline()
    seg.fill(p.final_slice(vol, 4), 25, 48, 4, low=50, high=150)
    prop = propagate_object(seg, vol, p, 1, 4, PropagationSettings(low=50, high=150, leak_factor=2.5, on_leak="confine",
                                                                          neck_mm=0))
    assert prop.slices == (0, vol.shape[0] - 1)
    assert prop.leaks and "confined" in prop.leaks[0]["action"]
    prop.accept(seg)
    assert not (seg.labels[:, 20:80, 45:90] == 1).any()


@pytest.mark.parametrize("mode", ["slice", "3d"])
def test_neck_cut_default_goes_past_bridge(mode):
    """The default leak guard cuts the one-pixel bridge and follows the disk through every slice."""
    vol, disk = _bridge_volume(12)
    seg = Segmentation(vol.shape)
    p = Pipeline()
    seg.fill(p.final_slice(vol, 4), 25, 48, 4, low=50, high=150)
    prop = propagate_object(seg, vol, p, 1, 4, PropagationSettings(low=50, high=150, mode=mode))
    assert prop.slices == (0, vol.shape[0] - 1) and not prop.leaks
    prop.accept(seg)
    assert not (seg.labels[:, 20:80, 40:90] == 1).any()
    # the disk itself is whole on every slice; on the bridge slice at most a stub of the bridge is added
    assert (seg.labels[:, disk] == 1).all()
    assert seg.voxels(1) - vol.shape[0] * disk.sum() <= 4


@pytest.mark.parametrize("mode", ["slice", "3d"])
def test_neighbourhood_zero_and_slice_limit(mode):
    vol, disk = _bridge_volume(None)
    p = Pipeline()
    prop = propagate(vol, p, disk, 10, PropagationSettings(low=50, high=150, neighbourhood=0, mode=mode))
    assert prop.slices == (0, vol.shape[0] - 1)  # did not stop at the seed slice
    lim = propagate(vol, p, disk, 10, PropagationSettings(low=50, high=150, slices=(6, 15), mode=mode))
    assert lim.slices == (6, 15) and lim.voxels == 10 * disk.sum()
    assert all("slice limit" in v for v in lim.stops.values())


def test_3d_mode_matches_slice_mode_without_leaks():
    vol, disk = _bridge_volume(None)  # no bridge
    vol.data[20:, :, :] = 0  # object ends at slice 19
    start = disk
    p = Pipeline()
    p.add("opening", size=3)
    a = propagate(vol, p, start, 8, PropagationSettings(low=50, high=150))
    b = propagate(vol, p, start, 8, PropagationSettings(low=50, high=150, mode="3d"))
    assert a.slices == b.slices == (0, 19)
    oa, ma = a.mask3d()
    ob, mb = b.mask3d()
    assert oa == ob and np.array_equal(ma, mb)


def test_directions_progress_cancel_and_reject():
    vol, disk = _bridge_volume(None)
    p = Pipeline()
    fwd = propagate(vol, p, disk, 10, PropagationSettings(low=50, high=150, direction="forward"))
    assert fwd.slices == (10, vol.shape[0] - 1)
    bwd = propagate(vol, p, disk, 10, PropagationSettings(low=50, high=150, direction="backward"))
    assert bwd.slices == (0, 10)
    # generator drives progress
    gen = iter_propagation(vol, p, disk, 10, PropagationSettings(low=50, high=150))
    events = []
    try:
        while True:
            events.append(next(gen))
    except StopIteration as stop:
        prop = stop.value
    assert [e.z for e in events] == list(range(11, 24)) + list(range(9, -1, -1))
    assert events[-1].done == events[-1].total == 23 and prop.voxels == 24 * disk.sum()
    # cancel by callback after 3 slices
    seen = []
    part = propagate(vol, p, disk, 10, PropagationSettings(low=50, high=150), progress=lambda e: seen.append(e) or len(seen) < 3)
    assert part.cancelled and len(part.areas) == 4 and any("cancelled" in w for w in part.warnings())
    # cancel by event before starting
    ev = threading.Event()
    ev.set()
    none = propagate(vol, p, disk, 10, PropagationSettings(low=50, high=150), cancel=ev)
    assert none.cancelled and list(none.areas) == [10]
    # reject: a proposal never accepted leaves the labels untouched
    seg = Segmentation(vol.shape)
    propagate(vol, p, disk, 10, PropagationSettings(low=50, high=150), labels=seg.labels)
    assert not seg.labels.any()


def test_object_growing_beyond_crop_is_followed():
    """A cone whose radius grows fast: the crop must grow with it (no clipping)."""
    nz, n = 20, 256
    yy, xx = np.mgrid[:n, :n]
    data = np.zeros((nz, n, n), np.int16)
    truth = np.zeros(data.shape, bool)
    for z in range(nz):
        r = 10 + 5 * z  # area ratio (15/10)^2 = 2.25 on the first step: below the leak guard
        truth[z] = (xx - 128) ** 2 + (yy - 128) ** 2 <= r * r
    data[truth] = 100
    vol = Volume(data, modality="CT")
    prop = propagate(vol, Pipeline(), truth[0], 0, PropagationSettings(low=50, high=150))
    off, m = prop.mask3d()
    full = np.zeros(data.shape, bool)
    full[off[0]:off[0] + m.shape[0], off[1]:off[1] + m.shape[1], off[2]:off[2] + m.shape[2]] = m
    np.testing.assert_array_equal(full, truth)


def test_head_phantom_round_insert_one_object_per_slice():
    from support import shared

    path = shared("ct_head_phantom_philips")
    vol = _load_or_skip(path)
    assert vol.shape == (28, 512, 512)
    # the round insert: a water-like disc (about 100 HU) in air, centre near column 250, row 240
    z0 = 14
    seg = Segmentation(vol.shape)
    p = Pipeline()
    res = seg.fill(p.final_slice(vol, z0), 250, 240, z0, low=50, high=200)
    assert res.accepted, res.reason
    prop = propagate_object(seg, vol, p, 1, z0, PropagationSettings(low=50, high=200))
    prop.accept(seg)
    first, last = seg.slice_range(1)
    assert last - first + 1 >= 4  # 5 mm slices through a disc about 2-3 cm long
    dy, dx = vol.spacing[1], vol.spacing[2]
    areas = []
    for z in range(first, last + 1):
        m = (seg.labels[z] == 1).astype(np.uint8)
        n, _ = cv2.connectedComponents(m, connectivity=8)
        assert n - 1 == 1, f"slice {z}: {n - 1} parts"
        area = int(m.sum())
        (_, _), r = cv2.minEnclosingCircle(np.argwhere(m)[:, ::-1].astype(np.float32))
        assert area / (np.pi * r * r) > 0.8  # round: fills its enclosing circle (a square: 0.64)
        areas.append(area * dx * dy)
    # a cylinder-like insert: same cross-section on the slices it fully crosses
    core = np.array(areas[1:-1]) if len(areas) > 2 else np.array(areas)
    assert core.std() / core.mean() < 0.05


@pytest.mark.parametrize("connectivity", [4, 8])
def test_fill3d_matches_scipy_label(connectivity):
    from scipy import ndimage

    from ctui.engine.segment.propagate import fill3d

    rng = np.random.default_rng(7)
    inr = rng.random((12, 40, 40)) < 0.55
    start = np.zeros((40, 40), bool)
    start[18:22, 18:22] = True
    got = fill3d(inr, 6, start, connectivity=connectivity)
    st = ndimage.generate_binary_structure(3, 1)  # 6-connected
    if connectivity == 8:
        st[1] = True  # plus the in-plane diagonals
    lab, _ = ndimage.label(inr, structure=st)
    ids = np.unique(lab[6][start & inr[6]])
    ref = np.isin(lab, ids[ids > 0])
    np.testing.assert_array_equal(got, ref)


def test_window8_domain_kidney(phantom):
    """The prototype's way: filters and thresholds on windowed 0..255 values."""
    vol, truth = phantom
    k = [o for o in truth["objects"] if o["name"] == "kidney_left"][0]
    centre, width = 40.0, 400.0
    p = Pipeline(domain="window8", window=(centre, width))
    to8 = lambda hu: (hu - (centre - width / 2)) * 255.0 / width
    lo8 = to8(k["hu_range"][0])
    seg = Segmentation(vol.shape)
    z, y, x = k["seed_zyx"]
    final = p.final_slice(vol, z)
    assert final.dtype == np.uint8
    assert seg.fill(final, x, y, z, low=lo8, high=255).accepted
    propagate_object(seg, vol, p, 1, z, PropagationSettings(low=lo8, high=255)).accept(seg)
    ml = seg.voxels(1) * vol.voxel_volume_mm3() / 1000.0
    assert ml == pytest.approx(k["volume_ml"], rel=0.02)
