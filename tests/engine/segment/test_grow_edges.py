"""grow stops at the intensity edge between the object and a neighbour of the same range, where the
distance-map competition (the narrowest place, or half-way) does not; compete() is the marker watershed."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from ctui.engine.actions.segment import SegmentOptions, segment
from ctui.engine.core.volume import Volume
from ctui.engine.segment import grow as G


def _touching(seed: int = 0):
    """Two blocks side by side, broad contact (no neck): the object at 100 HU, the neighbour at 150 HU,
    both inside the range 60..190; noise sd 8 HU; air around."""
    rng = np.random.default_rng(seed)
    data = np.full((20, 60, 80), -900.0, np.float32)
    obj = np.zeros(data.shape, bool)
    obj[4:16, 10:50, 10:34] = True
    nbr = np.zeros(data.shape, bool)
    nbr[4:16, 10:50, 34:70] = True
    data[obj] = 100.0
    data[nbr] = 150.0
    data += rng.normal(0, 8, data.shape).astype(np.float32)
    return Volume(np.round(data).astype(np.int16), spacing=(2.0, 1.0, 1.0), modality="CT"), obj


def _dice(a, b):
    return 2.0 * np.count_nonzero(a & b) / (np.count_nonzero(a) + np.count_nonzero(b))


def test_grow_with_a_background_seed_stops_at_the_edge():
    vol, obj = _touching()
    seed, bg = (15, 30, 10), (65, 30, 10)  # x, y, z: the seed near the object's far side, the background far out
    res = segment(vol, [seed], [(60.0, 190.0)], background=[bg], options=SegmentOptions(method="grow", neck_mm=0))
    got = res.segmentation.labels == 1
    assert _dice(got, obj) > 0.95
    # the distance-map competition on the same region puts the boundary elsewhere (no neck between the seeds)
    region = ndimage.binary_dilation(obj, iterations=0) | (vol.data >= 60) & (vol.data <= 190)
    dist = G.compete(region, np.array([[10, 30, 15]]), np.array([[10, 30, 65]]), spacing=vol.spacing)
    assert _dice(dist, obj) < _dice(got, obj) - 0.05


def test_background_seed_without_contact_changes_nothing():
    vol, obj = _touching(1)
    air = (75, 5, 2)
    plain = segment(vol, [(15, 30, 10)], [(60.0, 120.0)], options=SegmentOptions(method="grow"))
    with_bg = segment(vol, [(15, 30, 10)], [(60.0, 120.0)], background=[air], options=SegmentOptions(method="grow"))
    assert np.array_equal(plain.segmentation.labels, with_bg.segmentation.labels)
    assert any("cannot stop anything" in w for w in with_bg.objects[0].warnings)


@pytest.mark.parametrize("case", range(4))
def test_compete_is_the_marker_watershed(case):
    """compete() and its reference path, compete_watershed(), give the same share (phantoms with necks and
    without, seeds deep and on the region's edge)."""
    rng = np.random.default_rng(case)
    region = np.zeros((16, 40, 60), bool)
    region[3:13, 8:32, 5:25] = True
    region[3:13, 8:32, 35:55] = True
    region[6:10, 18:18 + 2 + 4 * case, 25:35] = True  # a neck 2..14 px wide
    region &= rng.random(region.shape) > 0.02  # noise holes
    fg = np.array([[8, 20, 12]])
    bg = np.array([[8, 20, 48], [3, 8, 54]]) if case % 2 else np.array([[8, 20, 48]])
    bg = bg[region[tuple(bg.T)]]
    a = G.compete(region, fg, bg, spacing=(2.0, 1.0, 1.0))
    b = G.compete_watershed(region, fg, bg, spacing=(2.0, 1.0, 1.0))
    assert np.array_equal(a, b)
