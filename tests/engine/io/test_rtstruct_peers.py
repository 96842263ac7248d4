"""RTSTRUCT across tools: ctui's contours read by rt-utils, rt-utils' contours read by ctui,
on real organs (TotalSegmentator's reference labels of the shared abdominal CT).

rt-utils writes the polygon through the boundary pixels' centres and fills with
cv2.fillPoly; ctui writes a quarter pixel outside those centres and fills by centre inside
or on the outline (ctui/engine/io/rtstruct.py). Before, each lost or gained a boundary ring
(ctui -> rt-utils +7.0 to +24.5%, rt-utils -> ctui -6.1 to -16.5% on these organs).
"""

from __future__ import annotations

import numpy as np
import pytest

from support import shared

ORGANS = {1: "spleen", 2: "kidney_right", 3: "kidney_left", 5: "liver"}


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    pydicom = pytest.importorskip("pydicom")
    d = shared("totalseg_example")
    from ctui.engine.core.geometry import Geometry
    from ctui.engine.core.volume import Volume
    from ctui.engine.io.imports import place_on_grid
    from ctui.engine.io.labels import load_labels
    from ctui.engine.io.phantom import write_series
    from ctui.engine.io.series import load

    ct = load(d / "ct_abdomen_3mm.nii.gz")
    lab, lv = load_labels(d / "ct_abdomen_3mm_labels.nii.gz")
    lab = place_on_grid(lab, Geometry.of(lv), Geometry.of(ct))
    # rt-utils assumes square images (its masks are Columns x Rows): a 101 x 101 crop
    origin = Geometry.of(ct).index_to_mm(np.array([[0.0, 0.0, 10.0]]))[0]
    sq = Volume(np.ascontiguousarray(ct.data[:, :, 10:111]), spacing=ct.spacing, origin=tuple(origin),
                direction=ct.direction, modality="CT")
    root = tmp_path_factory.mktemp("rtpeers")
    write_series(root / "series", sq)
    for f in (root / "series").iterdir():  # rt-utils copies StudyID, which the demo series lacks
        ds = pydicom.dcmread(f)
        ds.StudyID = "1"
        ds.save_as(f)
    v = load(root / "series")
    labels = place_on_grid(lab[:, :, 10:111], Geometry.of(sq), Geometry.of(v))
    labels = np.where(np.isin(labels, list(ORGANS)), labels, 0).astype(np.uint8)
    return {"root": root, "series": root / "series", "volume": v, "labels": labels}


def test_rt_utils_reads_ctui_rtstruct(case):
    rt_utils = pytest.importorskip("rt_utils")
    from ctui.engine.core.geometry import Geometry
    from ctui.engine.io.dicomseg import source_datasets
    from ctui.engine.io.rtstruct import write_rtstruct

    out = case["root"] / "ctui_rt.dcm"
    write_rtstruct(out, case["labels"], Geometry.of(case["volume"]), source_datasets(case["series"], case["volume"]),
                   objects=[{"id": i, "name": n} for i, n in ORGANS.items()])
    rt = rt_utils.RTStructBuilder.create_from(str(case["series"]), str(out))
    for i, name in ORGANS.items():
        theirs = np.transpose(rt.get_roi_mask_by_name(name), (2, 0, 1))  # rows, cols, slices -> z, y, x
        ours = case["labels"] == i
        assert abs(theirs.sum() / ours.sum() - 1) < 0.02, name
        assert np.count_nonzero(theirs != ours) <= 0.02 * ours.sum(), name


def test_ctui_reads_rt_utils_rtstruct(case):
    rt_utils = pytest.importorskip("rt_utils")
    from ctui.engine.io.imports import read_label_file

    rt = rt_utils.RTStructBuilder.create_new(str(case["series"]))
    for i, name in ORGANS.items():
        rt.add_roi(mask=np.transpose(case["labels"] == i, (1, 2, 0)), name=name)
    out = case["root"] / "rtutils_rt.dcm"
    rt.save(str(out))
    imp = read_label_file(out, grid=case["volume"])
    assert not imp.warnings
    by_name = {o["name"]: o["id"] for o in imp.objects}
    for i, name in ORGANS.items():
        theirs = imp.mask(by_name[name])
        ours = case["labels"] == i
        assert abs(theirs.sum() / ours.sum() - 1) < 0.02, name
        assert np.count_nonzero(theirs != ours) <= 0.02 * ours.sum(), name
