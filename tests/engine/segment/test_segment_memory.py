"""The segment path's memory cuts change no result (issue 41: segment peak over loading; issue 40 point 2).

* the run fill (:func:`ctui.engine.segment.fill3d._runs`, used before numba's kernel is loaded, so a command
  that fills one organ never loads numba) equals scipy's labelling and the numba kernel, voxel for voxel;
* the leak check's distance transform (:func:`ctui.engine.segment.leaks.edt`) equals scipy's, bit for bit;
* a whole segmentation (phantom kidney, and the real abdomen's kidneys when ../shared/data is there), slice and
  3D mode, is identical with the new paths and with the old ones forced (numba kernel, scipy's EDT): labels, and
  every reported figure and warning.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from ctui.engine.segment import fill3d, leaks
from support import shared


def _run_fill(inr: np.ndarray, seeds: np.ndarray, connectivity: int) -> np.ndarray:
    runs = fill3d._runs(inr, limit=10**9)
    return fill3d._paint_runs(inr.shape, runs, fill3d._run_components(runs, inr.shape, seeds, connectivity))


@pytest.mark.parametrize("connectivity", [4, 8])
def test_run_fill_equals_labelling_and_kernel(connectivity):
    rng = np.random.default_rng(3)
    kernel = fill3d._scanline_kernel()
    for _ in range(60):
        shape = tuple(int(v) for v in rng.integers(1, 24, 3))
        inr = rng.random(shape) < rng.uniform(0.2, 0.85)
        seeds = np.column_stack([rng.integers(0, s, 4) for s in shape]).astype(np.int32)
        got = _run_fill(inr, seeds, connectivity)
        np.testing.assert_array_equal(got, fill3d._label_fill(inr, seeds, connectivity))
        if kernel is not None:
            out = np.zeros(shape, np.uint8)
            kernel(inr.view(np.uint8), seeds, out, connectivity == 8)
            np.testing.assert_array_equal(got, out.view(bool))
    empty = np.zeros((3, 4, 5), bool)
    assert not _run_fill(empty, np.array([[1, 1, 1]], np.int32), connectivity).any()


def test_large_sparse_fill_does_not_load_the_kernel(monkeypatch):
    """Over SMALL_FILL voxels with few runs, fill3d_seeds joins runs and never asks for numba's kernel."""
    monkeypatch.setattr(fill3d, "_SCAN", [])

    def no_kernel():
        raise AssertionError("the numba kernel was loaded for a mask with few runs")

    monkeypatch.setattr(fill3d, "_scanline_kernel", no_kernel)
    inr = np.zeros((40, 256, 256), bool)
    zz, yy, xx = np.ogrid[:40, :256, :256]
    inr |= (zz - 20) ** 2 / 15 ** 2 + (yy - 100) ** 2 / 40 ** 2 + (xx - 90) ** 2 / 30 ** 2 <= 1  # the seed's blob
    inr |= (zz - 20) ** 2 / 15 ** 2 + (yy - 100) ** 2 / 40 ** 2 + (xx - 180) ** 2 / 30 ** 2 <= 1  # a separate one
    inr[:, 100, 90:180] = True  # a one-voxel bridge joins them ...
    inr[20, 200:230, 20:240] = True  # ... and this slab joins nothing
    got = fill3d.fill3d_seeds(inr, np.array([[20, 100, 90]]), connectivity=4)
    assert inr.size > fill3d.SMALL_FILL
    np.testing.assert_array_equal(got, fill3d._label_fill(inr, np.array([[20, 100, 90]], np.int32), 4))
    assert got[20, 100, 180] and not got[20, 210, 100]


def test_edt_equals_scipy_bit_for_bit():
    rng = np.random.default_rng(5)
    for k in range(40):
        shape = tuple(int(v) for v in rng.integers(1, 30, 3))
        m = rng.random(shape) < rng.uniform(0.3, 0.95)
        if k % 2:
            m = ndimage.binary_opening(m)
        sp = tuple(float(v) for v in rng.uniform(0.3, 5.0, 3))
        ref = ndimage.distance_transform_edt(m, sampling=sp)
        assert np.array_equal(leaks.edt(m, sp), ref)
        r = float(rng.uniform(0.0, 8.0))
        assert np.array_equal(leaks.edt(m, sp, at_most=r), ref <= r)


def _old_edt(mask, spacing, *, at_most=None):
    d = ndimage.distance_transform_edt(mask, sampling=spacing)
    return d if at_most is None else d <= at_most


def _segment(volume, seed, mode, monkeypatch, *, old: bool):
    from ctui.engine.actions.segment import SegmentOptions, segment

    with monkeypatch.context() as m:
        m.setattr(fill3d, "SMALL_FILL", 0)  # every fill of these small volumes takes the large-volume path
        m.setattr(fill3d, "_SCAN", [])  # as in a fresh process: the kernel not loaded yet
        if old:  # what ran before: numba's kernel for every large fill, scipy's distance transform
            m.setattr(fill3d, "RUN_FILL_RUNS", -1)
            m.setattr(leaks, "edt", _old_edt)
        else:
            m.setattr(fill3d, "_scanline_kernel", lambda: None)  # the run fill or scipy's labelling only
        res = segment(volume, [seed], [], options=SegmentOptions(mode=mode))
    return res.segmentation.labels.copy(), res.to_dict()


def _same_both_ways(volume, seed, monkeypatch):
    for mode in ("slice", "3d"):
        new_labels, new = _segment(volume, seed, mode, monkeypatch, old=False)
        old_labels, old = _segment(volume, seed, mode, monkeypatch, old=True)
        assert np.count_nonzero(new_labels) > 1000
        np.testing.assert_array_equal(new_labels, old_labels)
        assert new == old


def test_phantom_kidney_identical_with_the_old_paths(monkeypatch):
    from ctui.engine.io.phantom import make_phantom

    vol, truth = make_phantom(shape=(60, 128, 128), spacing=(3.0, 2.0, 2.0), drift=False, supersample=2)
    k = next(o for o in truth["objects"] if o.get("shape") == "ellipsoid")
    z, y, x = k["seed_zyx"]
    _same_both_ways(vol, (x, y, z), monkeypatch)


@pytest.mark.slow
def test_real_kidneys_identical_with_the_old_paths(monkeypatch):
    from ctui.engine.actions.opened import open_input
    from ctui.engine.io.series import load

    tot = shared("totalseg_example")
    vol = load(tot / "ct_abdomen_3mm.nii.gz")
    labels = open_input(tot / "ct_abdomen_3mm_labels.nii.gz").labels
    for lab in (2, 3):  # right and left kidney, seeded at their deepest points
        dt = ndimage.distance_transform_edt(np.pad(labels == lab, 1), sampling=vol.spacing)[1:-1, 1:-1, 1:-1]
        z, y, x = np.unravel_index(int(np.argmax(dt)), dt.shape)
        _same_both_ways(vol, (int(x), int(y), int(z)), monkeypatch)
