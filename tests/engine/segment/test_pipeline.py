"""Pipeline as data: JSON round trip, views, caching, crops, the CLI filter syntax."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ctui.engine.core.colors import OBJECT_COLORS
from ctui.engine.segment.pipeline import Pipeline, Step, overlay, parse_filter_spec
from ctui.engine.core.volume import Volume


def _volume(nz: int = 6, n: int = 96) -> Volume:
    rng = np.random.default_rng(0)
    data = rng.normal(40, 30, (nz, n, n)).astype(np.int16)
    data[:, 30:60, 30:60] += 200
    return Volume(data, spacing=(2.0, 0.8, 0.8), modality="CT")


def _pipeline() -> Pipeline:
    p = Pipeline(domain="hu")
    p.add("opening", size=3, shape="ellipse")
    p.add("median", size=5, stage=2)
    p.add("dilate", shape="custom", kernel=[[0, 1, 0], [1, 1, 1], [0, 1, 0]], stage=2, enabled=False)
    return p


def test_json_round_trip_gives_identical_pipeline_and_results():
    p = _pipeline()
    text = json.dumps(p.to_dict())
    q = Pipeline.from_dict(json.loads(text))
    assert q == p and q.key() == p.key()
    assert q.to_dict()["domain"] == "hu" and q.to_dict()["steps"][2]["enabled"] is False
    vol = _volume()
    np.testing.assert_array_equal(p.run_slice(vol, 2).final, q.run_slice(vol, 2).final)


def test_stages_give_intermediate_and_final_views():
    vol = _volume()
    p = _pipeline()
    v = p.run_slice(vol, 1)
    from ctui.engine.segment import filters as F

    orig = vol.data[1].astype(np.float32)
    np.testing.assert_array_equal(v.original, orig)
    np.testing.assert_array_equal(v.intermediate, F.opening(orig, size=3, shape="ellipse"))
    np.testing.assert_array_equal(v.final, F.median(v.intermediate, size=5))
    assert v.display("final").dtype == np.uint8


def test_stage_order_runs_stage1_first():
    p = Pipeline()
    p.add("invert", stage=2)
    p.add("erode", size=3, stage=1)
    assert [s.name for s in p.active_steps()] == ["erode", "invert"]


def test_cache_hit_and_invalidation():
    vol = _volume()
    p = _pipeline()
    a = p.run_slice(vol, 3)
    assert p.run_slice(vol, 3) is a  # cached
    key = p.key()
    p.set_params(0, size=5)
    assert p.key() != key
    b = p.run_slice(vol, 3)
    assert b is not a and not np.array_equal(a.intermediate, b.intermediate)


def test_cache_is_bounded():
    vol = _volume(nz=10)
    p = Pipeline(cache_bytes=3 * 3 * 96 * 96 * 4)  # room for 3 slices of 3 float32 views
    for z in range(10):
        p.run_slice(vol, z)
    assert p.cached_slices() == 3


def test_final_region_equals_full_slice():
    vol = _volume()
    for p in (_pipeline(), Pipeline([Step("gaussian", 1, {"sigma": 1.5}), Step("closing", 2, {"size": 5, "iterations": 2})])):
        full = p.run_image(p.prepare(vol.data[4], p.window_for(vol)), window=p.window_for(vol))[1]
        region = p.final_region(vol, 4, 20, 70, 25, 80)
        np.testing.assert_allclose(region, full[20:70, 25:80], rtol=1e-5, atol=1e-3)


def test_window8_domain_works_on_uint8():
    vol = _volume()
    p = Pipeline([Step("clahe", 1, {"clip_limit": 2.0})], domain="window8", window=(40.0, 400.0))
    v = p.run_slice(vol, 0)
    assert v.original.dtype == np.uint8 and v.final.dtype == np.uint8
    assert p.reach() is None  # global step: no cropping
    assert Pipeline.from_dict(p.to_dict()).to_dict() == {"version": 1, "domain": "window8", "window": [40.0, 400.0],
                                                         "steps": [{"name": "clahe", "stage": 1, "params": {"clip_limit": 2.0}, "enabled": True}]}


def test_overlay_colours_objects():
    gray = np.full((8, 8), 100, np.uint8)
    lab = np.zeros((8, 8), np.uint8)
    lab[2, 3] = 1
    lab[5, 5] = 3
    rgb = overlay(gray, lab, alpha=1.0)
    assert rgb.shape == (8, 8, 3) and rgb.dtype == np.uint8
    assert tuple(rgb[2, 3]) == OBJECT_COLORS[0] and tuple(rgb[5, 5]) == OBJECT_COLORS[2]
    assert tuple(rgb[0, 0]) == (100, 100, 100)


def test_parse_filter_spec():
    s = parse_filter_spec("opening:size=3,shape=ellipse,stage=2")
    assert (s.name, s.stage, s.params) == ("opening", 2, {"size": 3, "shape": "ellipse"})
    s = parse_filter_spec("dilate:kernel=010/111/010")
    assert s.params["shape"] == "custom" and s.params["kernel"] == [[0, 1, 0], [1, 1, 1], [0, 1, 0]]
    s = parse_filter_spec("gaussian:sigma=1.5")
    assert s.params == {"sigma": 1.5} and s.stage == 1
    for bad in ("blur", "opening:size", "opening:size=x", "opening:stage=3", "median:size=4", "dilate:kernel=012",
                "opening:radius=2"):
        with pytest.raises(ValueError):
            parse_filter_spec(bad)
