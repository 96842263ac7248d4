"""Display windows: CT presets, the DICOM header's window, percentile windows."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.windows import (
    CT_PRESETS,
    apply_window,
    auto_window,
    header_window,
    percentile_window,
    preset,
    window_from_range,
    window_range,
)


def test_presets_have_usual_values():
    for name in ("brain", "subdural", "stroke", "bone", "lung", "abdomen", "soft_tissue", "liver", "mediastinum"):
        assert name in CT_PRESETS
    assert CT_PRESETS["brain"] == (40, 80)
    assert CT_PRESETS["lung"] == (-600, 1500)
    assert CT_PRESETS["bone"][1] >= 1500
    assert preset("Soft tissue") == CT_PRESETS["soft_tissue"]
    assert preset("ABDOMEN") == (40, 400)
    with pytest.raises(KeyError, match="known"):
        preset("kidney")
    # brain window: grey matter ~40 HU mid-grey, bone white, air black
    img = apply_window(np.array([-1000, 0, 40, 80, 1000]), preset("brain"))
    assert list(img) == [0, 0, 127, 255, 255]


def test_header_window_parsing():
    assert header_window(40, 400) == (40.0, 400.0)
    assert header_window("40\\80", "400\\200") == (40.0, 400.0)
    assert header_window([300, 50], [649, 100]) == (300.0, 649.0)
    assert header_window(None, 400) is None
    assert header_window(40, 0) is None
    assert header_window("x", "y") is None
    assert auto_window(np.zeros((2, 2, 2)), modality="MR", header=(10, 20)) == (10.0, 20.0)


def test_percentile_window_for_mr_and_plain():
    rng = np.random.default_rng(0)
    data = rng.uniform(100, 300, size=(20, 50, 50))
    data[0, 0, :10] = 1e6  # a few outliers do not stretch the window
    c, w = auto_window(data, modality="MR")
    assert c == pytest.approx(200, abs=3) and w == pytest.approx(198, abs=4)
    big = rng.uniform(0, 1000, size=(64, 256, 256)).astype(np.float32)
    c, w = percentile_window(big)
    assert c == pytest.approx(500, abs=10) and w == pytest.approx(990, abs=15)
    assert auto_window(data, modality="CT") == (40.0, 400.0)
    assert percentile_window(np.array([np.nan, 1.0, 3.0])) == pytest.approx((2.0, 1.98), abs=0.01)
    lo, hi = window_range((40, 400))
    assert (lo, hi) == (-160, 240) and window_from_range(lo, hi) == (40, 400)


def test_loaded_windows():
    from support import shared
    from ctui.engine.io.series import load
    from ctui.engine.io.phantom import SAMPLE_DIR

    assert load(SAMPLE_DIR).window == (40.0, 400.0)  # the header's window
    vol = load(shared("cthead_tiff_stack/brain.tiff"))
    lo, hi = window_range(vol.window)
    assert np.mean((vol.data >= lo) & (vol.data <= hi)) > 0.98
