"""The pydicom-only DICOM-SEG writer (``io.segwriter``) writes what highdicom writes for ctui's
call: the same frames (order, plane positions, source references, dimension index values),
segments, references, shared groups and packed pixels, for one segment, several, and
overlapping ones; highdicom reads each back voxel for voxel."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.io.dicomseg import _objects_in, _prepared, _segment_description, source_datasets
from ctui.engine.io.phantom import write_series
from ctui.engine.io.segwriter import build_seg, rgb_to_cielab
from ctui.engine.io.series import load
from ctui.engine.core.volume import Volume

hd = pytest.importorskip("highdicom")


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    root = tmp_path_factory.mktemp("segw")
    rng = np.random.default_rng(3)
    data = rng.integers(-100, 100, size=(9, 20, 24)).astype(np.int16)
    vol = Volume(data=data, spacing=(2.5, 0.8, 0.7), origin=(-10.0, 5.0, 30.0), modality="CT",
                 direction=np.array([[-1.0, 0, 0], [0, -1.0, 0], [0, 0, 1.0]]))
    write_series(root / "s", vol)
    v = load(root / "s")
    return v, source_datasets(root / "s", v)


def _highdicom(seg_array, sources, objs):
    from ctui import __version__

    descs = [_segment_description(n, o) for n, o in enumerate(objs, start=1)]
    return hd.seg.Segmentation(
        source_images=_prepared(sources, False), pixel_array=seg_array,
        segmentation_type=hd.seg.SegmentationTypeValues.BINARY, segment_descriptions=descs,
        series_instance_uid=hd.UID(), series_number=1, sop_instance_uid=hd.UID(), instance_number=1,
        manufacturer="ctui", manufacturer_model_name="ctui", software_versions=__version__, device_serial_number="0",
        series_description="x", content_label="CTUI", content_description="ctui segmentation", omit_empty_frames=True)


def _plain(ds):
    """The dataset as pydicom reads it from its bytes (highdicom's items compare only with their own kind)."""
    import io

    import pydicom

    buf = io.BytesIO()
    ds.save_as(buf, enforce_file_format=True)
    buf.seek(0)
    return pydicom.dcmread(buf)


def _labels(shape, n_objects: int) -> np.ndarray:
    lab = np.zeros(shape, np.uint8)
    lab[2:5, 3:9, 4:12] = 1
    if n_objects > 1:
        lab[4:8, 10:16, 10:20] = 2
        lab[6, 0:2, 0:3] = 3
    return lab


@pytest.mark.parametrize("n_objects", [1, 3])
def test_same_object_as_highdicom(series, n_objects):
    from ctui import __version__

    v, sources = series
    lab = _labels(v.shape, n_objects)
    objs = _objects_in(lab, [{"id": 1, "name": "a", "color": [230, 60, 60]}])
    ours = _plain(build_seg(lab, sources, objs, series_description="x", version=__version__))
    ref = _plain(_highdicom(lab, sources, objs))
    assert ours.PixelData == ref.PixelData and int(ours.NumberOfFrames) == int(ref.NumberOfFrames)
    assert ours.PerFrameFunctionalGroupsSequence == ref.PerFrameFunctionalGroupsSequence
    assert ours.SegmentSequence == ref.SegmentSequence
    for kw in ("ReferencedSeriesSequence", "SourceImageSequence", "DimensionIndexSequence"):
        a, b = ours[kw].value, ref[kw].value
        if kw == "DimensionIndexSequence":  # its UID is new in each
            a = [(i.DimensionIndexPointer, i.FunctionalGroupPointer, i.DimensionDescriptionLabel) for i in a]
            b = [(i.DimensionIndexPointer, i.FunctionalGroupPointer, i.DimensionDescriptionLabel) for i in b]
        assert a == b, kw
    sa, sb = ours.SharedFunctionalGroupsSequence[0], ref.SharedFunctionalGroupsSequence[0]
    assert sa.PlaneOrientationSequence == sb.PlaneOrientationSequence
    assert sa.get("SegmentIdentificationSequence") == sb.get("SegmentIdentificationSequence")
    ma, mb = sa.PixelMeasuresSequence[0], sb.PixelMeasuresSequence[0]
    assert list(ma.PixelSpacing) == list(mb.PixelSpacing)
    assert float(ma.SpacingBetweenSlices) == pytest.approx(float(mb.SpacingBetweenSlices))
    for kw in ("StudyInstanceUID", "FrameOfReferenceUID", "SegmentationType", "SegmentsOverlap", "Rows", "Columns",
               "BitsAllocated", "ImageType", "Modality", "SOPClassUID"):
        assert ours[kw].value == ref[kw].value, kw


def test_overlapping_segments_and_read_back(series, tmp_path):
    from ctui import __version__

    v, sources = series
    a = np.zeros(v.shape, bool)
    a[1:6, 2:10, 2:10] = True
    b = np.zeros(v.shape, bool)
    b[4:9, 6:14, 6:16] = True
    stack = np.stack([a, b], axis=-1)
    objs = [{"id": 1, "name": "a", "color": (255, 0, 0)}, {"id": 2, "name": "b", "color": (0, 0, 255)}]
    ours = _plain(build_seg(stack, sources, objs, series_description="x", version=__version__))
    ref = _plain(_highdicom(stack, sources, objs))
    assert ours.SegmentsOverlap == ref.SegmentsOverlap == "YES"
    assert ours.PixelData == ref.PixelData
    assert ours.PerFrameFunctionalGroupsSequence == ref.PerFrameFunctionalGroupsSequence
    ours.save_as(tmp_path / "o.dcm", enforce_file_format=True)
    back = hd.seg.segread(str(tmp_path / "o.dcm"))
    px = back.get_pixels_by_source_instance([d.SOPInstanceUID for d in sources], combine_segments=False)
    assert np.array_equal(px[..., 0].astype(bool), a) and np.array_equal(px[..., 1].astype(bool), b)


def test_cielab_as_highdicom():
    for rgb in ((230, 60, 60), (0, 0, 0), (255, 255, 255), (60, 180, 75), (12, 200, 255)):
        assert rgb_to_cielab(rgb) == list(hd.color.CIELabColor.from_rgb(*rgb).value)


def test_pydicom_imported_without_requests_leaves_requests_importable():
    import subprocess
    import sys

    code = ("import sys\nfrom ctui.engine.io.dicomseg import import_pydicom\npd = import_pydicom()\n"
            "print('requests' in sys.modules, hasattr(pd, 'dcmread'))\n"
            "try:\n    import requests\n    print(True)\nexcept ImportError:\n    print('absent')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120).stdout.split()
    assert out[:2] == ["False", "True"]
    assert out[2] in ("True", "absent")  # importable again (or not installed at all)
