"""The numba threshold level set: regrows an object to its in-range boundary; the curvature term keeps
the front out of a narrow channel that a plain threshold front floods."""

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
