"""Hostile RTSTRUCT contours (issue 26, item 9): each is said, none silently changes a volume.

Contours partly off the image, POINT / OPEN_PLANAR contours, non-finite points and a
Frame of Reference that is not the series' each give a warning naming the ROI, and
the parts that cannot be areas on the image are left out (never filled as closed).
"""

from __future__ import annotations

import numpy as np
import pydicom
import pytest

from ctui.engine.core.geometry import Geometry
from ctui.engine.io.dicomseg import source_datasets
from ctui.engine.io.imports import read_label_file
from ctui.engine.io.phantom import make_phantom, write_series
from ctui.engine.io.rtstruct import write_rtstruct
from ctui.engine.io.series import load


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    root = tmp_path_factory.mktemp("rtfuzz")
    vol, _ = make_phantom(shape=(6, 32, 32), spacing=(4.0, 10.0, 10.0), noise_sd=0, drift=False)
    write_series(root / "series", vol)
    v = load(root / "series")
    labels = np.zeros(v.shape, np.uint8)
    labels[1:5, 8:20, 8:20] = 1  # a box, 144 px a slice
    labels[2:4, 24:28, 24:28] = 2
    rt = root / "rt.dcm"
    write_rtstruct(rt, labels, Geometry.of(v), source_datasets(root / "series", v),
                   objects=[{"id": 1, "name": "box"}, {"id": 2, "name": "small"}])
    return {"root": root, "series": root / "series", "volume": v, "labels": labels, "rt": rt}


def _mutated(base, name, change):
    ds = pydicom.dcmread(base["rt"])
    change(ds)
    out = base["root"] / f"{name}.dcm"
    ds.save_as(out, enforce_file_format=True)
    return out


def _box_contours(ds):
    return ds.ROIContourSequence[0].ContourSequence


def test_untouched_file_reads_back_without_warnings(base):
    imp = read_label_file(base["rt"], grid=base["volume"])
    assert imp.warnings == []
    np.testing.assert_array_equal(imp.labels, base["labels"])


def test_contour_partly_off_the_image_is_said_with_the_voxels_lost(base):
    g = Geometry.of(base["volume"])
    dx = g.spacing[2]

    def shift(ds):  # the box's contour on its first slice moves 14 px towards -x: 6 of its 12 columns leave
        c = _box_contours(ds)[0]
        pts = np.asarray(c.ContourData, dtype=float).reshape(-1, 3)
        step = g.index_to_mm(np.array([[0, 0, -14.0]]))[0] - g.index_to_mm(np.array([[0, 0, 0.0]]))[0]
        c.ContourData = [f"{v:.4f}" for v in (pts + step).ravel()]
        assert abs(np.linalg.norm(step) - 14 * dx) < 1e-6

    imp = read_label_file(_mutated(base, "off", shift), grid=base["volume"])
    w = " ".join(imp.warnings)
    assert "ROI box" in w and "beyond the image on 1 slices" in w and "72 voxels" in w, imp.warnings
    assert np.count_nonzero(imp.mask(1)[1]) == 72  # what is on the image is kept


def test_point_and_open_contours_are_not_filled(base):
    def retype(ds):
        cs = _box_contours(ds)
        cs[0].ContourGeometricType = "POINT"
        cs[1].ContourGeometricType = "OPEN_PLANAR"

    imp = read_label_file(_mutated(base, "types", retype), grid=base["volume"])
    w = " ".join(imp.warnings)
    assert "1 POINT contours" in w and "1 OPEN_PLANAR contours" in w, imp.warnings
    m = imp.mask(1)
    assert not m[1].any() and not m[2].any() and m[3].sum() == 144


def test_non_finite_points_drop_the_contour_with_a_warning(base):
    def nan(ds):
        c = _box_contours(ds)[0]
        vals = [str(v) for v in c.ContourData]
        vals[4] = "NaN"
        c[0x30060050] = pydicom.DataElement(0x30060050, "DS", "\\".join(vals))

    pydicom.config.settings.writing_validation_mode = pydicom.config.IGNORE
    try:
        path = _mutated(base, "nan", nan)
    finally:
        pydicom.config.settings.writing_validation_mode = pydicom.config.WARN
    imp = read_label_file(path, grid=base["volume"])
    assert any("ROI box" in w and "non-finite" in w for w in imp.warnings), imp.warnings
    assert not imp.mask(1)[1].any() and imp.mask(1)[2].sum() == 144


def test_frame_of_reference_mismatch_is_said(base):
    from ctui.engine.actions.opened import open_input

    def other_frame(ds):
        ds.FrameOfReferenceUID = "1.2.3.4.5"
        for r in ds.StructureSetROISequence:
            r.ReferencedFrameOfReferenceUID = "1.2.3.4.5"

    path = _mutated(base, "for", other_frame)
    opened = open_input(base["series"], labels=path)
    assert any("Frame of Reference mismatch" in n and "1.2.3.4.5" in n for n in opened.notes), opened.notes
    same = open_input(base["series"], labels=base["rt"])
    assert not any("Frame of Reference" in n for n in same.notes)


@pytest.mark.parametrize("value, said", [("abc", "coordinates that are not numbers"),
                                         ("1e308", "points beyond 1e+06 mm")])
def test_text_or_huge_coordinate_drops_the_contour_with_a_warning(base, value, said):
    """A text coordinate and a 1e308 point were dropped (or clipped) without a word (issue 41).
    The coordinate is written into the file's bytes (pydicom refuses to build such a DS)."""
    ds = pydicom.dcmread(base["rt"])
    text = "\\".join(str(v) for v in _box_contours(ds)[0].ContourData).encode()
    vals = text.split(b"\\")
    k = next(i for i, v in enumerate(vals) if len(v) >= len(value))  # same element length: the file stays valid
    vals[k] = value.encode().ljust(len(vals[k]))
    new = b"\\".join(vals)
    raw = base["rt"].read_bytes()
    assert raw.count(text) == 1 and len(new) == len(text)
    path = base["root"] / f"bad-{value}.dcm"
    path.write_bytes(raw.replace(text, new))
    imp = read_label_file(path, grid=base["volume"])
    assert any("ROI box" in w and said in w for w in imp.warnings), imp.warnings
    assert not imp.mask(1)[1].any() and imp.mask(1)[2].sum() == 144
