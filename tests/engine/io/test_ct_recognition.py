"""CT without a DICOM header is recognised by its values (air near -1000 HU, soft tissue
near 0) or by its header's text (NIfTI descrip, NRRD content): modality CT, HU shown and
the CT window presets offered. Label maps, MR and plain images stay as they are."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.windows import CT_PRESETS, ct_hint, looks_like_ct
from ctui.engine.io.series import load
from ctui.screens.session import Session
from support import shared


def test_real_ct_nifti_is_ct_and_its_labels_are_not():
    d = shared("totalseg_example")
    ct = load(d / "ct_abdomen_3mm.nii.gz")
    assert ct.modality == "CT" and ct.meta["modality_from"] == "values"
    assert ct.window == CT_PRESETS["abdomen"]
    names = [n for n, _w in Session(ct, source_path="x").window_presets()]
    assert "abdomen" in names and "lung" in names and "bone" in names
    labels = load(d / "ct_abdomen_3mm_labels.nii.gz")
    assert labels.modality == "OT"
    assert not looks_like_ct(load(shared("mr_sagittal_oblique")).data)


def _head(n=24) -> np.ndarray:
    """A CT-like phantom: air, a water-like body, a bone ring (HU)."""
    zz, yy, xx = np.mgrid[:n, :n, :n]
    r = np.hypot(yy - n / 2, xx - n / 2)
    data = np.full((n, n, n), -1000, np.int16)
    data[r < n * 0.4] = 30
    data[(r >= n * 0.3) & (r < n * 0.4)] = 900
    return data


def test_values_and_header_hints(tmp_path):
    nib = pytest.importorskip("nibabel")
    data = _head()
    assert looks_like_ct(data)
    assert not looks_like_ct(data + 1024)  # stored without the rescale: not HU
    assert not looks_like_ct((data > 0).astype(np.uint8))
    # a NIfTI whose values alone look like CT
    p = tmp_path / "head.nii"
    nib.save(nib.Nifti1Image(np.ascontiguousarray(data.T), np.eye(4)), str(p))
    assert load(p).modality == "CT"
    # a mostly-bone crop (little air) is recognised from its descrip
    crop = np.full((8, 8, 8), 900, np.int16)
    crop[0, 0, :] = -800
    img = nib.Nifti1Image(np.ascontiguousarray(crop.T), np.eye(4))
    img.header["descrip"] = b"CT chest, HU"
    p2 = tmp_path / "crop.nii.gz"
    nib.save(img, str(p2))
    vol = load(p2)
    assert vol.modality == "CT" and vol.meta["modality_from"] == "header"
    assert ct_hint("Computed Tomography") and ct_hint("ct") and not ct_hint("T1 MPRAGE") and not ct_hint("act")


def test_nrrd_content_hint(tmp_path):
    nrrd = pytest.importorskip("nrrd")
    crop = np.full((6, 6, 6), 700, np.int16)
    crop[0] = -700
    p = tmp_path / "bone.nrrd"
    nrrd.write(str(p), np.ascontiguousarray(crop.T), {"content": "CT bone crop", "space": "left-posterior-superior"})
    vol = load(p)
    assert vol.modality == "CT" and vol.meta["modality_from"] == "header"
