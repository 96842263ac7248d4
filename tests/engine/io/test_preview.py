"""The preview slice (``actions.series.preview``, shown by the TUI before the rest of a series
is read) is the full volume's slice voxel for voxel, on real data: same values, in-plane
spacing, direction and the origin of that slice; loading stops when its progress cancels."""

from __future__ import annotations

import numpy as np
import pytest

from support import shared
from ctui.engine.actions.series import load, preview
from ctui.engine.core.progress import Cancelled


def _same_slice(path, **options):
    pv = preview(path, **options)
    assert pv is not None, path
    full = load(path, **options)
    assert pv.depth == full.shape[0] and pv.z == full.shape[0] // 2
    assert pv.volume.shape == (1, *full.shape[1:])
    assert np.array_equal(pv.volume.data[0], full.data[pv.z])  # voxel for voxel
    assert np.allclose(pv.volume.origin, full.index_to_mm((pv.z, 0, 0)), atol=1e-4)
    assert np.allclose(pv.volume.direction, full.direction)
    assert np.allclose(pv.volume.spacing[1:], full.spacing[1:])
    assert pv.volume.modality == full.modality
    return pv, full


def test_dicom_folder_preview_is_the_middle_slice():
    pv, full = _same_slice(shared("ct_head_phantom_philips"))
    assert tuple(pv.volume.window) == tuple(full.window)  # the header's window


def test_oblique_mr_dicom_preview():
    pv, full = _same_slice(shared("mr_sagittal_oblique"))
    assert tuple(pv.volume.window) == tuple(full.window)


def test_nifti_preview_is_the_middle_slice():
    pv, full = _same_slice(shared("totalseg_example") / "ct_abdomen_3mm.nii.gz")
    assert pv.volume.modality == "CT" and tuple(pv.volume.window) == tuple(full.window)


def test_metaimage_preview():
    _same_slice(shared("misc_mr") / "HeadMRVolume.mhd")


def test_no_preview_when_options_change_the_grid_or_the_volume_is_small():
    p = shared("ct_head_phantom_philips")
    assert preview(p, crop=(0, 4, None, None, None, None)) is None
    assert preview(p, downsample=2) is None
    assert preview(p, min_voxels=10**9) is None  # loads about as fast as its preview
    assert preview(p / "no such folder") is None  # the full read reports it


def test_cancelled_progress_stops_the_load():
    p = shared("ct_head_phantom_philips")
    seen = []

    def progress(done, total):
        seen.append(done)
        if len(seen) == 3:
            raise Cancelled()

    with pytest.raises(Cancelled):
        load(p, progress=progress)
    assert len(seen) == 3


def test_load_after_preview_reads_each_header_once(monkeypatch):
    from ctui.engine.io.series import dicom_headers

    p = shared("ct_head_phantom_philips")
    calls = []
    real = dicom_headers.read_header
    monkeypatch.setattr(dicom_headers, "read_header", lambda f, **kw: calls.append(f) or real(f, **kw))
    pv = preview(p)
    n = len(calls)
    full = load(p)
    assert len(calls) == n >= full.shape[0]  # the load used the preview's headers
    assert np.array_equal(pv.volume.data[0], full.data[pv.z])
    load(p)  # used once only: the next load reads them again
    assert len(calls) == 2 * n


def test_compressed_file_preview_stays_near_the_start(monkeypatch):
    """A large .nii.gz is not inflated to its middle twice: the preview slice lies within the
    first COMPRESSED_REACH bytes, and is still the full volume's slice at its index."""
    from ctui.engine.io.series import preview as pmod

    p = shared("totalseg_example") / "ct_abdomen_3mm.nii.gz"
    monkeypatch.setattr(pmod, "COMPRESSED_REACH", 5 * 101 * 122 * 2)  # five slices of int16
    pv = preview(p)
    full = load(p)
    assert pv.z == 4 < full.shape[0] // 2
    assert np.array_equal(pv.volume.data[0], full.data[pv.z])
    assert np.allclose(pv.volume.origin, full.index_to_mm((pv.z, 0, 0)), atol=1e-4)
