"""Slice filters against references (scipy.ndimage) and known shapes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from ctui.engine.segment import filters as F


def _scene() -> np.ndarray:
    img = np.zeros((64, 64), np.float32)
    img[10:30, 10:30] = 100.0  # a 20x20 square
    img[40, 40] = 500.0  # a one-pixel spike
    img[50, 5:60] = 80.0  # a one-pixel-wide line
    return img


def test_opening_removes_small_details_and_keeps_square():
    img = _scene()
    out = F.opening(img, shape="rect", size=3)
    assert out.dtype == np.float32 and out.shape == img.shape
    expected = np.zeros_like(img)
    expected[10:30, 10:30] = 100.0
    np.testing.assert_array_equal(out, expected)


def test_closing_fills_small_hole():
    img = np.full((40, 40), 100.0, np.float32)
    img[20, 20] = 0.0
    img[5:7, 5:7] = 0.0
    out = F.closing(img, shape="rect", size=3)
    assert out[20, 20] == 100.0 and (out[5:7, 5:7] == 100.0).all()
    # a large hole survives
    img[25:35, 25:35] = 0.0
    out = F.closing(img, shape="rect", size=3)
    assert (out[27:33, 27:33] == 0.0).all()


@pytest.mark.parametrize("shape", ["rect", "ellipse", "cross"])
@pytest.mark.parametrize("size", [3, 5])
def test_erode_dilate_match_scipy(shape, size):
    rng = np.random.default_rng(1)
    img = rng.normal(0, 100, (48, 52)).astype(np.float32)
    k = F.make_kernel(shape=shape, size=size).astype(bool)
    r = size // 2
    inner = (slice(r, -r), slice(r, -r))
    np.testing.assert_array_equal(F.erode(img, shape=shape, size=size)[inner],
                                  ndimage.grey_erosion(img, footprint=k)[inner])
    np.testing.assert_array_equal(F.dilate(img, shape=shape, size=size)[inner],
                                  ndimage.grey_dilation(img, footprint=k)[inner])


def test_iterations_equal_repeated_erosion():
    rng = np.random.default_rng(2)
    img = rng.normal(0, 1, (40, 40)).astype(np.float32)
    once = F.erode(F.erode(img, size=3), size=3)
    twice = F.erode(img, size=3, iterations=2)
    np.testing.assert_array_equal(once[4:-4, 4:-4], twice[4:-4, 4:-4])


def test_custom_kernel_equals_cross():
    rng = np.random.default_rng(3)
    img = rng.normal(0, 1, (30, 30)).astype(np.float32)
    custom = F.dilate(img, shape="custom", kernel=[[0, 1, 0], [1, 1, 1], [0, 1, 0]])
    np.testing.assert_array_equal(custom, F.dilate(img, shape="cross", size=3))
    with pytest.raises(ValueError):
        F.make_kernel(shape="custom", kernel=[[1, 1], [1, 1]])  # even sides


def test_conservative_smoothing_clamps_spike_keeps_edge():
    img = np.zeros((20, 20), np.float32)
    img[:, 10:] = 100.0  # a step edge
    img[5, 4] = 1000.0  # spike in the dark half
    img[15, 15] = -500.0  # pit in the bright half
    out = F.conservative(img, size=3)
    assert out[5, 4] == 0.0 and out[15, 15] == 100.0
    clean = np.zeros((20, 20), np.float32)
    clean[:, 10:] = 100.0
    np.testing.assert_array_equal(out, clean)


@pytest.mark.parametrize("size", [3, 5, 7])
def test_median_matches_scipy(size):
    rng = np.random.default_rng(4)
    img = rng.normal(0, 50, (40, 44)).astype(np.float32)
    r = size // 2
    np.testing.assert_allclose(F.median(img, size=size)[r:-r, r:-r],
                               ndimage.median_filter(img, size=size)[r:-r, r:-r])


@pytest.mark.parametrize("size", [7, 11])
def test_large_median_on_whole_hu_values_matches_scipy(size):
    """Whole HU values take the sliding-histogram path; exact, edges included."""
    rng = np.random.default_rng(8)
    img = rng.integers(-1024, 2000, (50, 61)).astype(np.float32)
    img[10:30, 10:40] = 40.0
    np.testing.assert_array_equal(F.median(img, size=size), ndimage.median_filter(img, size=size, mode="nearest"))


def test_gaussian_matches_scipy_and_preserves_mean():
    rng = np.random.default_rng(5)
    img = rng.normal(0, 50, (64, 64)).astype(np.float32)
    out = F.gaussian(img, sigma=1.5)
    ref = ndimage.gaussian_filter(img, 1.5, truncate=4.0)
    np.testing.assert_allclose(out[8:-8, 8:-8], ref[8:-8, 8:-8], atol=0.05 * img.std())


def test_sharpen_overshoots_edges_keeps_flat():
    img = np.zeros((20, 40), np.float32)
    img[:, 20:] = 100.0
    out = F.sharpen(img, sigma=1.0, amount=1.0)
    assert out[:, 20].max() > 100.0 and out[:, 19].min() < 0.0
    np.testing.assert_allclose(out[:, :10], 0.0, atol=1e-4)
    np.testing.assert_allclose(out[:, 30:], 100.0, atol=1e-3)


def test_invert_and_equalize_in_hu_and_uint8():
    img = np.linspace(-100, 300, 64 * 64, dtype=np.float32).reshape(64, 64)
    np.testing.assert_allclose(F.invert(img, window=(100.0, 400.0)), 200.0 - img)
    u8 = (np.arange(64 * 64) % 256).astype(np.uint8).reshape(64, 64)
    np.testing.assert_array_equal(F.invert(u8), 255 - u8)
    eq = F.equalize(img ** 2 / 300.0, window=(100.0, 400.0))
    assert eq.dtype == np.float32 and eq.min() >= -100.0 - 1e-3 and eq.max() <= 300.0 + 1e-3
    # equalization is monotone
    src = (img ** 2 / 300.0).ravel()
    order = np.argsort(src, kind="stable")
    assert np.all(np.diff(eq.ravel()[order]) >= -1e-3)
    cl = F.clahe(u8, clip_limit=2.0, tiles=4)
    assert cl.shape == u8.shape and cl.dtype == np.uint8


def test_check_params_rejects_bad_input():
    with pytest.raises(ValueError, match="unknown filter"):
        F.check_params("blur9", {})
    with pytest.raises(ValueError, match="unknown parameter"):
        F.check_params("opening", {"radius": 3})
    with pytest.raises(ValueError):
        F.check_params("median", {"size": 4})
    with pytest.raises(ValueError):
        F.check_params("gaussian", {"sigma": 0})


def test_filter_reach_is_enough_for_crops():
    rng = np.random.default_rng(6)
    img = rng.normal(0, 100, (120, 120)).astype(np.float32)
    for name, params in [("opening", {"size": 5, "shape": "ellipse"}), ("closing", {"size": 3, "iterations": 2}),
                         ("median", {"size": 5}), ("gaussian", {"sigma": 2.0}), ("sharpen", {"sigma": 1.5}),
                         ("conservative", {"size": 3}), ("erode", {"size": 7, "shape": "cross"})]:
        r = F.filter_reach(name, params)
        full = F.apply_filter(img, name, params)
        crop = F.apply_filter(img[30 - r:90 + r, 30 - r:90 + r], name, params)
        np.testing.assert_allclose(crop[r:-r or None, r:-r or None], full[30:90, 30:90], rtol=1e-5, atol=1e-3, err_msg=name)
    assert F.filter_reach("equalize", {}) is None and F.filter_reach("clahe", {}) is None
