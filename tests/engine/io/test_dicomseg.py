"""DICOM-SEG export over the phantom series: read back with highdicom and pydicom."""

from __future__ import annotations

import numpy as np
import pydicom
import pytest
from scipy import ndimage

from ctui.engine.actions.export import export
from ctui.engine.actions.project import new_project, save_project
from ctui.engine.io.dicomseg import read_seg, source_datasets
from ctui.engine.io.phantom import make_phantom, write_series
from ctui.engine.io.series import load

hd = pytest.importorskip("highdicom")


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """A small phantom series, a project with both kidneys (ids 1, 2), and its SEG."""
    root = tmp_path_factory.mktemp("seg")
    vol, truth = make_phantom(shape=(24, 52, 52), spacing=(8.0, 5.0, 5.0), noise_sd=0, drift=False, supersample=2)
    series = root / "series"
    write_series(series, vol)
    v = load(series)
    comp, _ = ndimage.label((v.data > 115) & (v.data < 445))
    labels = np.zeros(v.shape, np.uint8)
    objects = []
    for oid, name in ((1, "kidney_left"), (2, "kidney_right")):
        seed = next(o["seed_zyx"] for o in truth["objects"] if o["name"] == name)
        labels[comp == comp[tuple(seed)]] = oid
        objects.append({"id": oid, "name": name, "color": [230, 60, 60] if oid == 1 else [60, 180, 75]})
    proj = new_project(v, source_path=series, labels=labels, objects=objects)
    save_project(root / "p.ctui", proj)
    seg = root / "out" / "kidneys-seg.dcm"
    seg.parent.mkdir()
    export(root / "p.ctui", format="dicom-seg", out=seg)
    return {"root": root, "series": series, "volume": v, "labels": labels, "project": root / "p.ctui", "seg": seg}


def test_seg_references_the_series_and_holds_the_projects_voxels(case):
    seg = hd.seg.segread(str(case["seg"]))
    srcs = source_datasets(case["series"], case["volume"])
    assert seg.SegmentationType == "BINARY"
    assert seg.number_of_segments == 2
    assert [seg.get_segment_description(n).SegmentLabel for n in (1, 2)] == ["kidney_left", "kidney_right"]
    refs = seg.get_source_image_uids()
    assert {r[1] for r in refs} == {srcs[0].SeriesInstanceUID}
    assert {r[2] for r in refs} == {d.SOPInstanceUID for d in srcs}
    assert seg.StudyInstanceUID == srcs[0].StudyInstanceUID
    assert seg.FrameOfReferenceUID == srcs[0].FrameOfReferenceUID
    # frames only where an object is
    lab = case["labels"]
    expected_frames = sum(int((lab == k).any(axis=(1, 2)).sum()) for k in (1, 2))
    assert int(seg.NumberOfFrames) == expected_frames < 2 * lab.shape[0]
    # voxels per source instance equal the project's, slice by slice
    uids = [d.SOPInstanceUID for d in srcs]
    px = seg.get_pixels_by_source_instance(uids, combine_segments=False)
    for k in (1, 2):
        np.testing.assert_array_equal(px[..., k - 1].astype(bool), lab == k)


def test_segment_descriptions_algorithm_colour(case):
    seg = pydicom.dcmread(case["seg"])
    for item, rgb in zip(seg.SegmentSequence, ((230, 60, 60), (60, 180, 75))):
        assert item.SegmentAlgorithmType == "SEMIAUTOMATIC"
        assert item.SegmentationAlgorithmIdentificationSequence[0].AlgorithmName == "ctui"
        back = hd.color.CIELabColor.from_dicom_value(list(item.RecommendedDisplayCIELabValue)).to_rgb(clip=True)
        assert np.abs(np.subtract(back, rgb)).max() <= 2


def test_seg_geometry_matches_the_series(case):
    c = read_seg(case["seg"])
    v = case["volume"]
    # the SEG's grid spans the slices with objects; each of its slices is a series slice
    z = v.mm_to_index(np.asarray(c.geometry.origin))
    assert np.allclose(z, np.round(z), atol=1e-3) and np.allclose(z[1:], 0, atol=1e-3)
    assert np.allclose(c.geometry.spacing, v.spacing, atol=1e-4)
    assert np.allclose(c.geometry.direction, v.direction, atol=1e-6)


def test_no_patient_identifiers_unless_kept(case, tmp_path):
    seg = pydicom.dcmread(case["seg"])
    assert str(seg.PatientName) == "" and seg.PatientID == "" and seg.PatientBirthDate == ""
    raw = case["seg"].read_bytes()
    assert b"PHANTOM" not in raw and b"SYNTHETIC-0000" not in raw
    kept = tmp_path / "kept.dcm"
    export(case["project"], format="dicom-seg", out=kept, keep_identifiers=True)
    assert str(pydicom.dcmread(kept).PatientName) == "PHANTOM^SYNTHETIC"


def test_seg_round_trip_measures_the_same_volume(case):
    from ctui.engine.actions.measure import measure_object

    for oid in (1, 2):
        a = measure_object(case["project"], object=oid, mesh=False)
        b = measure_object(case["seg"], object=oid, mesh=False)
        assert b.volume_ml["voxels"] == pytest.approx(a.volume_ml["voxels"], rel=1e-12)
        assert a.volume_ml["voxels"] == pytest.approx((case["labels"] == oid).sum() * 8 * 5 * 5 / 1000.0)


def test_seg_export_refuses_a_resampled_grid(case, tmp_path):
    from ctui.engine.core.errors import CtuiError
    from ctui.engine.io.dicomseg import write_seg

    v = load(case["series"], downsample=2)
    with pytest.raises(CtuiError, match="own grid"):
        write_seg(tmp_path / "x.dcm", case["labels"][::2, ::2, ::2], source_datasets(case["series"], v))
