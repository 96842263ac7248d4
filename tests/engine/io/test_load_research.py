"""NIfTI and NRRD volumes: data order, LPS geometry, scaling, detached per-slice data."""

from __future__ import annotations

import numpy as np
import pytest

from support import shared
from ctui.engine.io.series import load, scan


@pytest.fixture
def data():
    return np.arange(4 * 5 * 6, dtype=np.int16).reshape(4, 5, 6) * 7 - 50  # (z, y, x)


@pytest.mark.parametrize("name", ["a.nii", "a.nii.gz"])
def test_nifti_ras_affine_to_lps(tmp_path, data, name):
    import nibabel as nib

    aff = np.diag([-0.5, -0.6, 2.5, 1.0])  # RAS: x and y point left/posterior = +x, +y in LPS
    aff[:3, 3] = [10, 20, 30]
    nib.save(nib.Nifti1Image(data.T.copy(), aff), tmp_path / name)
    vol = load(tmp_path / name)
    np.testing.assert_array_equal(vol.data, data)
    assert vol.data.flags["C_CONTIGUOUS"]
    assert vol.spacing == pytest.approx((2.5, 0.6, 0.5))
    np.testing.assert_allclose(vol.origin, (-10, -20, 30))
    np.testing.assert_allclose(vol.direction, np.eye(3))
    s = scan(tmp_path / name)[0]
    assert s["shape_zyx"] == [4, 5, 6] and s["spacing_zyx_mm"] == pytest.approx([2.5, 0.6, 0.5])
    part = load(tmp_path / name, crop=(1, 3, None, None, 2, None), downsample=(1, 2, 2))
    np.testing.assert_array_equal(part.data, data[1:3, ::2, 2::2])
    np.testing.assert_allclose(part.origin, vol.index_to_mm((1, 0, 2)))


def test_nifti_scaled_to_float(tmp_path, data):
    import nibabel as nib

    img = nib.Nifti1Image(data.T.astype(np.int16), np.eye(4))
    img.header.set_slope_inter(0.5, -3)
    nib.save(img, tmp_path / "s.nii")
    vol = load(tmp_path / "s.nii")
    assert vol.data.dtype == np.float32
    np.testing.assert_allclose(vol.data, data * 0.5 - 3)


@pytest.mark.parametrize("encoding,space", [("raw", "left-posterior-superior"), ("gzip", "right-anterior-superior")])
def test_nrrd(tmp_path, data, encoding, space):
    import nrrd

    hdr = {"encoding": encoding, "space": space, "space directions": np.diag([0.5, 0.6, 2.5]),
           "space origin": np.array([1.0, 2.0, 3.0])}
    nrrd.write(str(tmp_path / "v.nrrd"), data, hdr, index_order="C")
    vol = load(tmp_path / "v.nrrd")
    np.testing.assert_array_equal(vol.data, data)
    sign = 1 if space.startswith("left") else -1
    np.testing.assert_allclose(vol.origin, (sign * 1, sign * 2, 3))
    np.testing.assert_allclose(np.diag(vol.direction), (sign, sign, 1))
    assert vol.spacing == pytest.approx((2.5, 0.6, 0.5))


def test_labelio_geometry_round_trip(tmp_path):
    """Label maps written by FMT's labelio load back with the same geometry."""
    labelio = pytest.importorskip("ctui.engine.io.labels")
    from ctui.engine.core.volume import Volume

    d = np.eye(3)[:, [1, 0, 2]] * [1, -1, 1]  # rotated in-plane
    vol = Volume(data=np.zeros((3, 4, 5), np.int16), spacing=(2.0, 0.7, 0.8), origin=(5.0, -3.0, 12.0), direction=d, modality="CT")
    labels = np.zeros((3, 4, 5), np.uint8)
    labels[1, 2, 3] = 4
    for name in ("m.nii.gz", "m.nrrd"):
        labelio.save_labels(tmp_path / name, labels, vol)
        got = load(tmp_path / name)
        np.testing.assert_array_equal(got.data, labels)
        assert got.spacing == pytest.approx(vol.spacing)
        np.testing.assert_allclose(got.origin, vol.origin, atol=1e-4)
        np.testing.assert_allclose(got.direction, vol.direction, atol=1e-6)


def test_headsq_through_its_nhdr():
    d = shared("headsq_quarter")
    vol = load(d)  # the folder's quarter.nhdr names the 93 per-slice files: no --shape needed
    assert vol.shape == (93, 64, 64) and vol.spacing == pytest.approx((1.5, 3.2, 3.2))
    np.testing.assert_array_equal(vol.data[92], np.fromfile(d / "quarter.93", dtype="<i2").reshape(64, 64))
    assert vol.meta["format"] == "nrrd" and not vol.warnings
