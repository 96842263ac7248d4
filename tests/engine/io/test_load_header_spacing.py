"""NaN, inf, 0 or negative voxel sizes in NIfTI, NRRD and MetaImage headers: the volume
gets a finite positive spacing and a warning saying what was done; never NaN in JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ctui.engine.io.series import load, scan

BAD = [np.nan, np.inf, 0.0, -2.0]
DATA = np.arange(6 * 5 * 4, dtype=np.int16).reshape(6, 5, 4)  # (z, y, x)


def _nifti(path, bad):
    nib = pytest.importorskip("nibabel")
    img = nib.Nifti1Image(DATA.T.copy(), np.diag([1.5, 1.0, 2.0, 1.0]))
    nib.save(img, path)
    b = bytearray(path.read_bytes())
    b[84:88] = np.float32(bad).tobytes()  # pixdim[2] (pixdim starts at byte 76): the y voxel size
    b[252:256] = b"\x00\x00\x00\x00"  # qform_code = sform_code = 0: geometry from pixdim
    path.write_bytes(bytes(b))


def _nrrd_directions(path, bad):
    nrrd = pytest.importorskip("nrrd")
    nrrd.write(str(path), DATA.T.copy(), {"space": "left-posterior-superior",
                                          "space directions": np.diag([1.5, bad, 2.0])})


def _nrrd_spacings(path, bad):
    nrrd = pytest.importorskip("nrrd")
    nrrd.write(str(path), DATA.T.copy(), {"spacings": [1.5, bad, 2.0]})


def _mhd(path, bad):
    path.with_suffix(".raw").write_bytes(DATA.tobytes())
    path.write_text(f"NDims = 3\nDimSize = 4 5 6\nElementType = MET_SHORT\nElementSpacing = 1.5 {bad} 2\n"
                    f"ElementDataFile = {path.with_suffix('.raw').name}\n")


@pytest.mark.parametrize("bad", BAD, ids=["nan", "inf", "zero", "negative"])
@pytest.mark.parametrize("writer,suffix", [(_nifti, ".nii"), (_nrrd_directions, ".nrrd"), (_nrrd_spacings, ".nrrd"),
                                           (_mhd, ".mhd")], ids=["nifti", "nrrd-directions", "nrrd-spacings", "mhd"])
def test_bad_header_spacing(tmp_path, writer, suffix, bad):
    p = tmp_path / f"v{suffix}"
    writer(p, bad)
    vol = load(p)
    dz, dy, dx = vol.spacing
    assert np.all(np.isfinite(vol.spacing)) and min(vol.spacing) > 0
    assert (dz, dx) == pytest.approx((2.0, 1.5))
    if np.isfinite(bad) and bad < 0:
        assert dy == pytest.approx(2.0)  # a negative size is a direction, or taken as its size
    else:
        assert dy == pytest.approx(1.0)
        assert any("1 mm" in w and "y" in w for w in vol.warnings), vol.warnings
    assert np.all(np.isfinite(vol.origin)) and np.all(np.isfinite(vol.direction))
    json.dumps(vol.describe(), allow_nan=False, default=str)
    json.dumps(scan(p), allow_nan=False)
    assert scan(p)[0]["spacing_zyx_mm"] == pytest.approx(list(vol.spacing))
    assert np.array_equal(vol.data if vol.direction[1, 1] > 0 else vol.data, vol.data)  # data loaded whole
    assert vol.shape == (6, 5, 4)


def test_user_spacing_overrides_without_warning(tmp_path):
    p = tmp_path / "v.mhd"
    _mhd(p, np.nan)
    vol = load(p, spacing=(3.0, 2.0, 1.0))
    assert vol.spacing == (3.0, 2.0, 1.0)
    assert not any("invalid" in w for w in vol.warnings)
