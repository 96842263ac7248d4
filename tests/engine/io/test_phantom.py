"""The synthetic phantom: analytic truths, partial volume, drift, and the bundled copy."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import ndimage

from ctui.engine.io.phantom import SAMPLE_DIR, load_truth, make_phantom, write_demo


@pytest.fixture(scope="module")
def phantom():
    return make_phantom()


def _grown(vol, obj):
    """Voxels connected to the seed within the object's HU range (a threshold flood fill)."""
    lo, hi = obj["hu_range"]
    m = (vol.data >= lo) & (vol.data < hi)
    lab, _ = ndimage.label(m)
    z, y, x = obj["seed_zyx"]
    assert lab[z, y, x] > 0, f"seed of {obj['name']} is not inside its HU range"
    return lab == lab[z, y, x]


def test_analytic_volumes_match_formulas(phantom):
    _, truth = phantom
    objs = {o["name"]: o for o in truth["objects"]}
    a, b, c = objs["kidney_left"]["semi_axes_xyz_mm"]
    assert objs["kidney_left"]["volume_ml"] == pytest.approx(4 / 3 * np.pi * a * b * c / 1000)
    for k in ("kidney_left", "kidney_right"):
        assert 120 <= objs[k]["volume_ml"] <= 180
    tube = objs["tube"]
    expect = sum(np.pi * s["radius_mm"] ** 2 * s["length_mm"] for s in tube["steps"]) / 1000
    assert tube["volume_ml"] == pytest.approx(expect)
    assert len(tube["steps"]) == 3 and min(s["radius_px"] for s in tube["steps"]) >= 3
    assert [s["start_mm"] for s in tube["steps"]][0] == 0
    labels = [o["label"] for o in truth["objects"]]
    assert labels == sorted(set(labels))


@pytest.mark.parametrize("name,tol", [("kidney_left", 0.01), ("kidney_right", 0.01), ("spine", 0.02), ("tube", 0.05), ("body", 0.01)])
def test_threshold_at_midpoint_reproduces_volume(phantom, name, tol):
    vol, truth = phantom
    obj = next(o for o in truth["objects"] if o["name"] == name)
    got = _grown(vol, obj)
    if name == "body":  # the body includes everything inside its outline
        got = ndimage.binary_fill_holes(vol.data > obj["hu_range"][0], structure=np.ones((1, 3, 3)))
    ml = got.sum() * vol.voxel_volume_mm3() / 1000
    assert ml == pytest.approx(obj["volume_ml"], rel=tol)


def test_objects_are_separated(phantom):
    vol, truth = phantom
    objs = {o["name"]: o for o in truth["objects"]}
    masks = {n: _grown(vol, objs[n]) for n in ("kidney_left", "kidney_right", "spine", "tube")}
    # a threshold range covering kidneys and bone still keeps each kidney apart
    m = vol.data > 110
    lab, _ = ndimage.label(m)
    ids = {n: lab[tuple(objs[n]["seed_zyx"])] for n in masks}
    assert len(set(ids.values())) == 4
    # seeds sit deep inside: the 3x3x3 neighbourhood has the object's HU
    for n, o in objs.items():
        z, y, x = o["seed_zyx"]
        assert abs(vol.data[z - 1 : z + 2, y - 1 : y + 2, x - 1 : x + 2].mean() - o["hu"]) < 15


def test_tube_cross_sections_step(phantom):
    vol, truth = phantom
    tube = next(o for o in truth["objects"] if o["name"] == "tube")
    lo = tube["hu_range"][0]
    px_area = vol.spacing[1] * vol.spacing[2]
    for step in tube["steps"]:
        zmid = step["start_z_mm"] + step["length_mm"] / 2
        k = int(round(vol.mm_to_index((0, 0, zmid))[0]))
        if k in truth["drift"]["slices"]:
            k += 3
        area = (vol.data[k] >= lo).sum() * px_area
        assert area == pytest.approx(step["cross_section_mm2"], rel=0.1)


def test_drift_shifts_whole_slices():
    a, truth = make_phantom(noise_sd=0)
    b, _ = make_phantom(noise_sd=0, drift=False)
    d = truth["drift"]
    assert 3 <= len(d["slices"]) <= 4
    for z, (sy, sx) in zip(d["slices"], d["shifts_px_yx"]):
        assert 1 <= abs(sy) + abs(sx) and max(abs(sy), abs(sx)) <= 4
        np.testing.assert_array_equal(a.data[z, sy:, sx:], b.data[z, : b.shape[1] - sy, : b.shape[2] - sx])
    others = [z for z in range(a.shape[0]) if z not in d["slices"]]
    np.testing.assert_array_equal(a.data[others], b.data[others])


def test_noise_and_storage(phantom):
    vol, truth = phantom
    assert vol.data.dtype == np.int16 and vol.modality == "CT"
    air = vol.data[:, :6, :6].astype(float)
    assert abs(air.mean() + 1000) < 2 and 4 < air.std() < 12
    assert truth["shape_zyx"] == list(vol.shape) and vol.spacing == (2.5, 2.0, 2.0)


def test_deterministic(tmp_path):
    out = write_demo(tmp_path / "demo")
    files = sorted(p.name for p in out.iterdir())
    assert files == sorted(p.name for p in SAMPLE_DIR.iterdir()), "bundled sample out of date: run ctui demo sample_data/phantom"
    for name in files:  # byte-identical to the bundled copy
        assert (out / name).read_bytes() == (SAMPLE_DIR / name).read_bytes(), name


def test_bundled_sample(phantom):
    vol, truth = phantom
    size = sum(p.stat().st_size for p in SAMPLE_DIR.iterdir())
    assert size <= 5 * 1024 * 1024
    t = load_truth()
    assert t["objects"] == json.loads(json.dumps(truth["objects"]))
    names = sorted(p.name for p in SAMPLE_DIR.glob("*.dcm"))
    assert len(names) == vol.shape[0]


def test_sample_round_trip_sorted_despite_shuffled_names(phantom):
    import pydicom

    from ctui.engine.io.series import load

    vol, _ = phantom
    # names are shuffled: name order is not slice order
    by_name = sorted(SAMPLE_DIR.glob("*.dcm"))
    inst = [int(pydicom.dcmread(p, stop_before_pixels=True).InstanceNumber) for p in by_name]
    assert inst != sorted(inst)
    loaded = load(SAMPLE_DIR)
    np.testing.assert_array_equal(loaded.data, vol.data)
    assert loaded.spacing == pytest.approx(vol.spacing)
    np.testing.assert_allclose(loaded.origin, vol.origin)
    np.testing.assert_allclose(loaded.direction, np.eye(3))
    assert loaded.modality == "CT" and loaded.window == (40.0, 400.0)
    assert loaded.warnings == []
    assert [s["file"] for s in loaded.skipped] == ["truth.json"]
