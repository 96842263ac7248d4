"""Exports over a series that cannot be referenced (issue 25, item 2): a DICOM-SEG and an
RTSTRUCT point at the source images by UID; over a series whose UIDs or Frame of Reference
are missing both are refused, naming the missing attribute, and nothing is invented."""

from __future__ import annotations

import numpy as np
import pydicom
import pytest

from ctui.engine.actions.export import export
from ctui.engine.actions.project import new_project, save_project
from ctui.engine.core.errors import CtuiError
from ctui.engine.io.phantom import make_phantom, write_series
from ctui.engine.io.series import load


def _series(root, blank):
    vol, _ = make_phantom(shape=(4, 26, 26), spacing=(5.0, 10.0, 10.0), noise_sd=0, drift=False)
    write_series(root / "series", vol)
    for f in sorted((root / "series").iterdir()):
        ds = pydicom.dcmread(f)
        for kw in blank:
            setattr(ds, kw, "") if kw != "FrameOfReferenceUID" else delattr(ds, kw)
        ds.save_as(f)
    v = load(root / "series")
    labels = np.zeros(v.shape, np.uint8)
    labels[1:3, 8:16, 8:16] = 1
    save_project(root / "p.ctui", new_project(v, source_path=root / "series", labels=labels,
                                              objects=[{"id": 1, "name": "box"}]))
    return root / "p.ctui"


@pytest.mark.parametrize("fmt", ["dicom-seg", "rtstruct"])
@pytest.mark.parametrize("blank,named", [
    (("SOPInstanceUID", "SeriesInstanceUID", "StudyInstanceUID"), "SOPInstanceUID (0008,0018) missing or empty"),
    (("FrameOfReferenceUID",), "FrameOfReferenceUID (0020,0052) missing or empty"),
])
def test_unreferenceable_series_is_refused(tmp_path, fmt, blank, named):
    project = _series(tmp_path, blank)
    out = tmp_path / "out.dcm"
    for keep in (False, True):  # --keep-identifiers never invents identity either
        with pytest.raises(CtuiError, match="cannot write (a DICOM-SEG|an RTSTRUCT) over this series") as err:
            export(project, format=fmt, out=out, keep_identifiers=keep)
        assert named in str(err.value)
        if "SeriesInstanceUID" in blank:
            assert "SeriesInstanceUID (0020,000E)" in str(err.value)
        assert not out.exists()


def test_whole_series_exports(tmp_path):
    project = _series(tmp_path, ())
    for fmt in ("dicom-seg", "rtstruct"):
        out = tmp_path / f"{fmt}.dcm"
        export(project, format=fmt, out=out)
        assert pydicom.dcmread(out).FrameOfReferenceUID
