"""RTSTRUCT export over the phantom series: read back with pydicom, rasterised back exactly."""

from __future__ import annotations

import numpy as np
import pydicom
import pytest
from scipy import ndimage

from ctui.engine.actions.export import export
from ctui.engine.actions.project import new_project, save_project
from ctui.engine.io.dicomseg import source_datasets
from ctui.engine.io.imports import read_label_file
from ctui.engine.io.phantom import make_phantom, write_series
from ctui.engine.io.rtstruct import fill_contours, slice_contours
from ctui.engine.io.series import load


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("rt")
    vol, truth = make_phantom(shape=(24, 52, 52), spacing=(8.0, 5.0, 5.0), noise_sd=0, drift=False, supersample=2)
    series = root / "series"
    write_series(series, vol)
    v = load(series)
    labels = np.zeros(v.shape, np.uint8)
    comp, _ = ndimage.label((v.data > 115) & (v.data < 445))
    seed = next(o["seed_zyx"] for o in truth["objects"] if o["name"] == "kidney_left")
    labels[comp == comp[tuple(seed)]] = 1
    labels[v.data > 1000] = 2  # the stepped tube
    labels[5, 10:20, 10:20] = 3  # a square with a hole: holes must come back
    labels[5, 13:17, 13:17] = 0
    objects = [{"id": 1, "name": "kidney_left"}, {"id": 2, "name": "tube"}, {"id": 3, "name": "ring"}]
    save_project(root / "p.ctui", new_project(v, source_path=series, labels=labels, objects=objects))
    out = root / "out" / "rt.dcm"
    out.parent.mkdir()
    export(root / "p.ctui", format="rtstruct", out=out)
    return {"series": series, "volume": v, "labels": labels, "rt": out, "project": root / "p.ctui"}


def test_rtstruct_rois_and_references(case):
    ds = pydicom.dcmread(case["rt"])
    srcs = source_datasets(case["series"], case["volume"])
    by_uid = {d.SOPInstanceUID: d for d in srcs}
    assert ds.Modality == "RTSTRUCT" and ds.SOPClassUID == "1.2.840.10008.5.1.4.1.1.481.3"
    assert [r.ROIName for r in ds.StructureSetROISequence] == ["kidney_left", "tube", "ring"]
    assert len(ds.ROIContourSequence) == 3
    ref_series = ds.ReferencedFrameOfReferenceSequence[0].RTReferencedStudySequence[0].RTReferencedSeriesSequence[0]
    assert ref_series.SeriesInstanceUID == srcs[0].SeriesInstanceUID
    assert {i.ReferencedSOPInstanceUID for i in ref_series.ContourImageSequence} == set(by_uid)
    assert ds.FrameOfReferenceUID == srcs[0].FrameOfReferenceUID
    assert ds.StudyInstanceUID == srcs[0].StudyInstanceUID
    for roi in ds.ROIContourSequence:
        for c in roi.ContourSequence:
            assert c.ContourGeometricType == "CLOSED_PLANAR"
            pts = np.asarray(c.ContourData, dtype=float).reshape(-1, 3)
            assert len(pts) == c.NumberOfContourPoints
            img = by_uid[c.ContourImageSequence[0].ReferencedSOPInstanceUID]
            # every point lies in its image's plane
            assert np.allclose(pts[:, 2], float(img.ImagePositionPatient[2]), atol=1e-4)
    assert str(ds.PatientName) == "" and ds.PatientID == "" and ds.PatientBirthDate == ""


def test_rtstruct_reads_back_voxel_exact(case):
    imp = read_label_file(case["rt"], grid=case["volume"])
    assert [o["name"] for o in imp.objects] == ["kidney_left", "tube", "ring"]
    np.testing.assert_array_equal(imp.labels, case["labels"])


def test_rtstruct_needs_its_series(case):
    from ctui.engine.core.errors import CtuiError

    with pytest.raises(CtuiError, match="series"):
        read_label_file(case["rt"])


def test_contours_fill_back_exactly():
    rng = np.random.default_rng(3)
    m = ndimage.binary_opening(rng.random((40, 50)) > 0.45)
    back = fill_contours(slice_contours(m), m.shape)
    np.testing.assert_array_equal(back, m)


def test_rtstruct_on_an_oblique_real_series(tmp_path):
    """Siemens oblique sagittal MR: contours in patient mm on the tilted planes come back voxel for voxel."""
    from support import shared

    from ctui.engine.core.geometry import Geometry
    from ctui.engine.io.rtstruct import write_rtstruct

    d = shared("mr_sagittal_oblique")
    v = load(d)
    labels = np.zeros(v.shape, np.uint8)
    z, y, x = np.ogrid[: v.shape[0], : v.shape[1], : v.shape[2]]
    r2 = ((z - 20) / 12.0) ** 2 + ((y - 120) / 50.0) ** 2 + ((x - 130) / 40.0) ** 2
    labels[(r2 < 1) & (r2 > 0.3)] = 1  # a shell: rings with holes on most slices
    labels[15:25, 30:60, 30:70] = 2
    write_rtstruct(tmp_path / "rt.dcm", labels, Geometry.of(v), source_datasets(d, v))
    back = read_label_file(tmp_path / "rt.dcm", grid=v)
    np.testing.assert_array_equal(back.labels, labels)
