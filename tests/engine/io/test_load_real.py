"""Loaders on real public data in ../shared/data (skipped when absent)."""

from __future__ import annotations

import numpy as np
import pytest

from support import shared
from ctui.engine.io.series import load, scan

pytestmark = pytest.mark.shared_data


def _normal_pos(ds):
    iop = np.array([float(v) for v in ds.ImageOrientationPatient])
    n = np.cross(iop[:3], iop[3:])
    return float(n @ np.array([float(v) for v in ds.ImagePositionPatient]))


def test_head_phantom_ct():
    import pydicom

    d = shared("ct_head_phantom_philips")
    vol = load(d)
    assert vol.shape == (28, 512, 512) and vol.modality == "CT"
    assert vol.spacing[0] == pytest.approx(5.0, abs=1e-3)
    assert vol.spacing[1] == pytest.approx(0.451171875)
    # ordered along the normal: positions strictly increasing, 5 mm apart
    assert np.allclose(np.diff(vol.slice_positions), 5.0, atol=1e-3)
    # each slice is the file at that position, rescaled to HU
    files = sorted(d.glob("I*.dcm"), key=lambda p: _normal_pos(pydicom.dcmread(p, stop_before_pixels=True)))
    for k in (0, 1, 9, 27):
        ds = pydicom.dcmread(files[k])
        hu = ds.pixel_array.astype(np.int32) * float(ds.RescaleSlope) + float(ds.RescaleIntercept)
        np.testing.assert_array_equal(vol.data[k], hu)
    # HU plausible: air about -1000, a water-like phantom body about 0
    assert vol.data.dtype == np.int16
    assert abs(np.median(vol.data[:, :20, :20]) + 1000) < 30
    water = ((vol.data > -100) & (vol.data < 100)).mean()
    assert water > 0.01
    assert vol.data.max() < 3100 and vol.data.min() >= -1100
    assert {s["file"] for s in vol.skipped} == {"LICENSE_repo_BSD2.txt", "README_dcm_qa_ct.md"}
    assert vol.window == (40.0, 80.0)  # the header's window


def test_oblique_sagittal_mr_sorted_along_normal():
    import pydicom

    d = shared("mr_sagittal_oblique")
    vol = load(d)
    assert vol.shape == (40, 256, 256) and vol.modality == "MR"
    pos = vol.slice_positions
    assert np.all(np.diff(pos) > 0)
    assert vol.spacing[0] == pytest.approx(0.9, abs=1e-3)
    dsets = [pydicom.dcmread(p) for p in d.glob("*.dcm")]
    dsets.sort(key=_normal_pos)
    np.testing.assert_allclose(pos, [_normal_pos(ds) for ds in dsets], atol=1e-4)
    for k in (0, 13, 39):
        np.testing.assert_array_equal(vol.data[k], dsets[k].pixel_array)
    # direction: row/col from IOP, normal = their cross product; oblique (not axis-aligned)
    iop = np.array([float(v) for v in dsets[0].ImageOrientationPatient])
    np.testing.assert_allclose(vol.direction[:, 0], iop[:3] / np.linalg.norm(iop[:3]), atol=1e-6)
    assert np.max(np.abs(vol.direction[:, 2])) < 0.9995
    # origin is the first sorted slice's position
    np.testing.assert_allclose(vol.origin, [float(v) for v in dsets[0].ImagePositionPatient], atol=1e-4)
    assert not any("tilt" in w for w in vol.warnings)


def test_ball_phantom_instance_number_order():
    import pydicom

    d = shared("ball_phantom_no_geometry")
    vol = load(d)
    assert vol.shape == (129, 128, 129)
    assert any("InstanceNumber" in w for w in vol.warnings)
    by_inst = {int(pydicom.dcmread(p, stop_before_pixels=True).InstanceNumber): p for p in d.glob("*.dcm")}
    for k in (0, 1, 64, 128):
        np.testing.assert_array_equal(vol.data[k], pydicom.dcmread(by_inst[k + 1]).pixel_array)
    # the ball: inside values ~114-139, outside 0-14; its sections grow then shrink
    area = (vol.data > 60).sum(axis=(1, 2))
    top = int(np.argmax(area))
    assert 40 < top < 90 and np.all(np.diff(area[top - 30 : top + 1]) >= 0) and np.all(np.diff(area[top : top + 30]) <= 0)


def test_multiframe_mr():
    import pydicom

    f = shared("mr_multiframe/emri_small.dcm")
    vol = load(f)
    assert vol.shape == (10, 64, 64)
    np.testing.assert_array_equal(vol.data, pydicom.dcmread(f).pixel_array)
    assert vol.spacing[0] == pytest.approx(1.2)  # SpacingBetweenSlices: no per-frame positions in this file
    assert any("ImagePositionPatient" in w for w in vol.warnings)
    assert scan(f)[0]["kind"] == "dicom-multiframe"


def test_mr_without_file_meta():
    f = shared("misc_mr/mr.001")
    raw = f.read_bytes()
    assert raw[128:132] != b"DICM"
    vol = load(f)
    assert vol.shape == (1, 256, 256) and vol.modality == "MR"
    assert 0 < vol.data.max() < 5000 and vol.data.std() > 10
    assert vol.spacing[1] == pytest.approx(0.78125, abs=1e-4)


def test_cthead_raw_slices_numeric_order():
    d = shared("cthead_unc")
    vol = load(d, shape=(256, 256), dtype=">u2", spacing=(2.0, 1.0, 1.0))
    assert vol.shape == (113, 256, 256) and vol.data.dtype == np.uint16
    for k in (0, 1, 8, 9, 10, 99, 112):  # numeric: CThead.2 right after CThead.1, CThead.10 tenth
        ref = np.fromfile(d / f"CThead.{k + 1}", dtype=">u2").reshape(256, 256)
        np.testing.assert_array_equal(vol.data[k], ref)
    # slice 1 is at the vertex: a small cap of skull; the middle slices are full head sections
    area = (vol.data > 1000).sum(axis=(1, 2))
    assert area[0] < 0.05 * area[56]
    assert [s["file"] for s in vol.skipped] == ["desc.txt.orig"]
    assert vol.spacing == (2.0, 1.0, 1.0) and not any("default spacing" in w for w in vol.warnings)


def test_cthead_glob_pattern():
    d = shared("cthead_unc")
    vol = load(str(d / "CThead.1*"), shape=(256, 256), dtype=">u2")
    # CThead.1, .10-.19, .100-.113: 25 files, in numeric order
    assert vol.shape[0] == 25
    np.testing.assert_array_equal(vol.data[1], np.fromfile(d / "CThead.10", dtype=">u2").reshape(256, 256))
    assert any("default spacing" in w for w in vol.warnings)


def test_multipage_tiff():
    from PIL import Image, ImageSequence

    f = shared("cthead_tiff_stack/brain.tiff")
    vol = load(f)
    assert vol.shape == (10, 256, 256)
    with Image.open(f) as im:
        pages = [np.asarray(p) for p in ImageSequence.Iterator(im)]
    np.testing.assert_array_equal(vol.data, np.stack(pages))
    assert any("default spacing" in w for w in vol.warnings)
    assert vol.spacing == (1.0, 1.0, 1.0)


def test_headsq_quarter():
    d = shared("headsq_quarter")
    vol = load(d, shape=(64, 64), dtype="<i2", spacing=(1.5, 3.2, 3.2))
    assert vol.shape == (93, 64, 64) and vol.data.dtype == np.int16
    np.testing.assert_array_equal(vol.data[92], np.fromfile(d / "quarter.93", dtype="<i2").reshape(64, 64))
    np.testing.assert_array_equal(vol.data[9], np.fromfile(d / "quarter.10", dtype="<i2").reshape(64, 64))
    assert all("size" in s["reason"] for s in vol.skipped)


def test_metaimage():
    f = shared("misc_mr/HeadMRVolume.mhd")
    vol = load(f)
    assert vol.shape == (42, 62, 48) and vol.data.dtype == np.uint8
    assert vol.spacing == (4.0, 4.0, 4.0)
    ref = np.fromfile(f.with_suffix(".raw"), dtype=np.uint8).reshape(42, 62, 48)
    np.testing.assert_array_equal(vol.data, ref)
    assert not vol.warnings


def test_raw_volume_and_crop():
    f = shared("lobster/lobster_301x324x56_uint8.raw")
    full = load(f, shape=(56, 324, 301), dtype="u1", spacing=(1.4, 1, 1))
    ref = np.fromfile(f, dtype=np.uint8).reshape(56, 324, 301)
    np.testing.assert_array_equal(full.data, ref)
    part = load(f, shape=(56, 324, 301), dtype="u1", spacing=(1.4, 1, 1), crop=(10, 40, 20, None, None, 200), downsample=(2, 3, 3))
    np.testing.assert_array_equal(part.data, ref[10:40:2, 20::3, :200:3])
    assert part.spacing == pytest.approx((2.8, 3.0, 3.0))
    np.testing.assert_allclose(part.origin, full.index_to_mm((10, 20, 0)))
    # shape (y, x) only: z from the file size
    assert load(f, shape=(324, 301), dtype="u1").shape == (56, 324, 301)
    with pytest.raises(Exception, match="bytes"):
        load(f, shape=(57, 324, 301), dtype="u1")


def test_scan_lists_series_cheaply():
    s = scan(shared("ct_head_phantom_philips"))
    assert len(s) == 1
    e = s[0]
    assert set(e) == {"uid", "description", "modality", "files", "shape_zyx", "spacing_zyx_mm", "kind"}
    assert e["shape_zyx"] == [28, 512, 512] and e["files"] == 28 and e["kind"] == "dicom"
    assert e["spacing_zyx_mm"][0] == pytest.approx(5.0)
