"""NIfTI read slice by slice into the output (no full-size or float copy): the same voxels
as nibabel's whole-array read (the path before), bit for bit."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from ctui.engine.core.errors import LoadError
from ctui.engine.io.series import load


def _reference(path, idx=(slice(None),) * 3) -> np.ndarray:
    """What the loader gave before: nibabel's scaled array, transposed to (z, y, x), as float32
    when scaled or floating, else the stored integer type."""
    import nibabel as nib

    img = nib.load(str(path))
    arr = np.asanyarray(img.dataobj[idx + (0,) * (len(img.shape) - 3)])
    scaled = (img.dataobj.slope, img.dataobj.inter) != (1.0, 0.0)
    dt = np.float32 if scaled or arr.dtype.kind == "f" else arr.dtype.newbyteorder("=")
    return np.ascontiguousarray(arr.T, dtype=dt)


def _save(path, data_zyx, *, dtype, slope=None, inter=None, extra=()):
    import nibabel as nib

    arr = data_zyx.T.astype(dtype)
    if extra:
        arr = np.stack([arr] + [arr + k for k in extra], axis=-1)
    img = nib.Nifti1Image(arr, np.diag([-0.7, -0.7, 1.5, 1.0]))
    img.header.set_data_dtype(dtype)
    if slope is not None:
        img.header.set_slope_inter(slope, inter)
    nib.save(img, path)
    return path


@pytest.fixture
def ct():
    rng = np.random.default_rng(3)
    return rng.integers(-1024, 3000, size=(9, 11, 13)).astype(np.int32)


@pytest.mark.parametrize("name,dtype,slope,inter,out", [
    ("a.nii.gz", np.int16, None, None, np.int16),          # plain compressed CT
    ("b.nii.gz", np.uint16, 1.0, -1024.0, np.int16),       # dcm2niix-style: integral scaling stays int16
    ("c.nii", np.int16, 0.5, -3.0, np.float32),           # fractional slope: float32 as nibabel computes it
    ("d.nii.gz", ">i2", 1.0, 7.0, np.int16),              # big-endian
    ("e.nii.gz", np.float64, None, None, np.float32),
    ("f.nii.gz", np.uint8, None, None, np.uint8),
])
def test_streamed_equals_whole_read(tmp_path, ct, name, dtype, slope, inter, out):
    data = ct + 1024 if np.dtype(dtype).kind == "u" else ct
    if np.dtype(dtype) == np.uint8:
        data = data % 256
    path = _save(tmp_path / name, data, dtype=dtype, slope=slope, inter=inter)
    vol = load(path)
    ref = _reference(path)
    assert vol.data.dtype == out
    assert vol.data.flags["C_CONTIGUOUS"]
    np.testing.assert_array_equal(vol.data, ref)  # the same values ...
    assert np.array_equal(vol.data.astype(ref.dtype), ref)  # ... bit for bit in the old type
    part = load(path, crop=(2, 7, 1, None, None, 10), downsample=(2, 2, 3))
    np.testing.assert_array_equal(part.data, ref[2:7:2, 1::2, :10:3])


def test_integral_scaling_beyond_int16_becomes_float32(tmp_path, ct):
    path = _save(tmp_path / "big.nii.gz", ct, dtype=np.int16, slope=20.0, inter=0.0)  # up to 60,000
    vol = load(path)
    assert vol.data.dtype == np.float32
    np.testing.assert_array_equal(vol.data, _reference(path))


def test_first_of_several_volumes(tmp_path, ct):
    path = _save(tmp_path / "t.nii.gz", ct, dtype=np.int16, extra=(5, 9))
    vol = load(path)
    np.testing.assert_array_equal(vol.data, ct)
    assert any("volumes" in w for w in vol.warnings)


def test_truncated_stream_is_one_line(tmp_path, ct):
    path = _save(tmp_path / "t.nii.gz", ct, dtype=np.int16)
    raw = gzip.decompress(path.read_bytes())
    path.write_bytes(gzip.compress(raw[: len(raw) - 13 * 11 * 2 * 3]))
    with pytest.raises(LoadError, match="ends in slice"):
        load(path)
