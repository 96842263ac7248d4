"""The numba threshold level set: regrows an object to its in-range boundary; the curvature term keeps
the front out of a narrow channel that a plain threshold front floods; the band runs, the signed
distance, the work box, the convergence stop and the run-start seeds against their references."""

from __future__ import annotations

import numpy as np

from ctui.engine.segment.levelset import evolve, threshold_speed


def _disc_with_channel(width: int):
    n = 64
    yy, xx = np.mgrid[:n, :n]
    sl = np.where((yy - 32) ** 2 + (xx - 24) ** 2 <= 14**2, 200.0, 40.0)
    sl[32 - width // 2:32 - width // 2 + width, 38:60] = 200.0  # a channel to the right
    img = np.repeat(sl[None], 5, axis=0).astype(np.float32)
    disc = (yy - 32) ** 2 + (xx - 24) ** 2 <= 14**2
    return img, disc


def test_speed_and_regrowth():
    sp = threshold_speed(np.array([120.0, 210.0, 300.0, 0.0, 1000.0]), 120, 300)
    np.testing.assert_allclose(sp, [0.0, 1.0, 0.0, -1.0, -1.0])
    img, disc = _disc_with_channel(0)
    init = np.zeros(img.shape, bool)
    r = np.zeros_like(disc)
    yy, xx = np.mgrid[:64, :64]
    r = (yy - 32) ** 2 + (xx - 24) ** 2 <= 11**2
    init[:] = r
    got = evolve(img, init, low=120, high=300, spacing=(3.0, 1.0, 1.0), curvature=0.5, iterations=40)
    assert abs(int(got[2].sum()) - int(disc.sum())) <= 0.03 * disc.sum()
    assert not (got[2] & ~disc).sum() > 4


def test_curvature_keeps_the_front_out_of_a_narrow_channel():
    img, disc = _disc_with_channel(2)
    init = np.repeat(disc[None], 5, axis=0)
    plain = evolve(img, init, low=120, high=300, spacing=(3.0, 1.0, 1.0), curvature=0.0, iterations=60)
    smooth = evolve(img, init, low=120, high=300, spacing=(3.0, 1.0, 1.0), curvature=3.0, iterations=300)
    assert plain[2, 31:33, 50:60].all()  # a threshold front runs down the channel
    assert not smooth[2, :, 44:].any()  # with the curvature term it stays out
    assert smooth[2][disc].mean() > 0.97


def test_band_runs_cover_exactly_the_band():
    from ctui.engine.segment.levelset import _kernel

    rng = np.random.default_rng(1)
    phi = rng.uniform(-3, 3, (4, 9, 17)).astype(np.float32)
    phi[1, 2, :] = 0.1  # a run to the end of the row
    runs = _kernel("band")(phi, np.float32(1.0))
    got = np.zeros(phi.shape, bool)
    for z, y, x0, x1 in runs:
        assert x1 > x0
        got[z, y, x0:x1] = True
    np.testing.assert_array_equal(got, np.abs(phi) <= 1.0)


def test_signed_distance_close_to_the_exact_one():
    """OpenCV's 5x5 chamfer in-plane + the numba z envelope: within 0.4 pixel + 2% of scipy's exact map."""
    from scipy import ndimage

    from ctui.engine.segment.levelset import _signed_distance

    zz, yy, xx = np.mgrid[:12, :40, :40]
    inside = ((zz - 6) * 2.0) ** 2 + ((yy - 20) * 0.8) ** 2 + ((xx - 18) * 0.8) ** 2 <= 9.0**2
    sp = (2.0, 0.8, 0.8)
    cap = 6.0
    phi = _signed_distance(inside, sp, cap)
    exact = 0.5 * np.minimum(ndimage.distance_transform_edt(inside, sampling=sp), cap) \
        - 0.5 * np.minimum(ndimage.distance_transform_edt(~inside, sampling=sp), cap)
    assert ((phi > 0) == inside).all()
    assert np.abs(phi - exact).max() <= 0.5 * (0.4 * 0.8 + 0.02 * cap) + 1e-4


def test_work_box_and_convergence_stop_change_nothing():
    """The same object in a 3x larger image (the work box crops it back) and with the convergence
    stop off: the same voxels."""
    img, _disc = _disc_with_channel(0)
    img[0] = img[-1] = 40.0  # a disc 3 slices thick, background above and below
    yy, xx = np.mgrid[:64, :64]
    init = np.zeros(img.shape, bool)
    init[1:4] = (yy - 32) ** 2 + (xx - 24) ** 2 <= 11**2
    kw = {"low": 120, "high": 300, "spacing": (3.0, 1.0, 1.0), "curvature": 0.5, "iterations": 30}
    ref = evolve(img, init, patience=0, **kw)
    assert ref[2].sum() > init[2].sum()
    big = np.full((15, 192, 192), 40.0, np.float32)
    big[5:10, 64:128, 64:128] = img
    binit = np.zeros(big.shape, bool)
    binit[5:10, 64:128, 64:128] = init
    got = evolve(big, binit, **kw)
    assert got.sum() == ref.sum() and got[5:10, 64:128, 64:128].sum() == ref.sum()
    np.testing.assert_array_equal(got[5:10, 64:128, 64:128], ref)


def test_convergence_stop_at_rest():
    """A front already on the object's edge in a noiseless image does not move: the evolution stops
    early (fewer steps than asked) with the object as it was."""
    import ctui.engine.segment.levelset as L

    img, disc = _disc_with_channel(0)
    init = np.repeat(disc[None], 5, axis=0)
    calls = []
    step = L._kernel("step")
    L._KERNELS["step"] = lambda *a: (calls.append(1), step(*a))
    try:
        got = evolve(img, init, low=120, high=300, spacing=(3.0, 1.0, 1.0), curvature=0.0, iterations=200)
    finally:
        L._KERNELS["step"] = step
    assert len(calls) < 50
    np.testing.assert_array_equal(got, init)


def test_run_start_seeds_fill_like_every_voxel():
    from ctui.engine.segment.fill3d import fill3d_seeds
    from ctui.engine.segment.grow import run_starts

    rng = np.random.default_rng(3)
    region = rng.random((6, 30, 30)) < 0.55
    init = region & (rng.random(region.shape) < 0.3)
    np.testing.assert_array_equal(fill3d_seeds(region, run_starts(init)), fill3d_seeds(region, np.argwhere(init)))
    assert len(run_starts(init)) < init.sum()
