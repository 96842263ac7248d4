"""`ctui export` in every format from one project: each file read back against the project."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from ctui.cli import main
from ctui.engine.actions.export import FORMATS, export
from ctui.engine.actions.project import new_project, save_project
from ctui.engine.core.errors import CtuiError
from ctui.engine.io.imports import read_label_file
from ctui.engine.io.phantom import make_phantom, write_series
from ctui.engine.io.series import load


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("export")
    vol, _ = make_phantom(shape=(24, 52, 52), spacing=(8.0, 5.0, 5.0), noise_sd=0, drift=False, supersample=2)
    write_series(root / "series", vol)
    v = load(root / "series")
    labels = np.zeros(v.shape, np.uint8)
    labels[4:12, 10:20, 12:24] = 1  # a box: 8 x 10 x 12 voxels
    labels[14:20, 30:36, 30:34] = 2
    objects = [{"id": 1, "name": "box", "color": [230, 60, 60]}, {"id": 2, "name": "small box", "color": [60, 180, 75]}]
    save_project(root / "p.ctui", new_project(v, source_path=root / "series", labels=labels, objects=objects))
    (root / "out").mkdir()
    return {"root": root, "volume": v, "labels": labels, "project": root / "p.ctui", "out": root / "out"}


@pytest.mark.parametrize("fmt", ["nifti", "nrrd", "dicom-seg", "rtstruct"])
def test_label_formats_read_back_equal(case, fmt):
    out = case["out"] / f"labels{FORMATS[fmt].suffix}" if fmt not in ("rtstruct",) else case["out"] / "rt.dcm"
    res = export(case["project"], format=fmt, out=out)
    assert [o["name"] for o in res.objects] == ["box", "small box"]
    back = read_label_file(out, grid=case["volume"])
    np.testing.assert_array_equal(back.labels, case["labels"])
    if fmt != "nifti":  # NIfTI stores no names
        assert [o["name"] for o in back.objects] == ["box", "small box"]


@pytest.mark.parametrize("fmt", ["stl", "ply", "obj"])
def test_mesh_formats(case, fmt):
    from ctui.engine.io.meshes import load_mesh

    out = case["out"] / f"m.{fmt}"
    export(case["project"], format=fmt, out=out, objects=[1])
    mesh = load_mesh(out)
    box_ml = 8 * 10 * 12 * 8 * 5 * 5 / 1000.0
    assert abs(mesh.volume_mm3()) / 1000.0 == pytest.approx(box_ml, rel=0.05)
    lo, hi = mesh.bounds()
    centre = case["volume"].index_to_mm((7.5, 14.5, 17.5))
    assert np.allclose((lo + hi) / 2, centre, atol=1.0)  # in patient mm where the series puts the box


def test_csv_rows(case):
    out = case["out"] / "objects.csv"
    res = export(case["project"], format="csv", out=out)
    rows = list(csv.DictReader(out.open()))
    assert [r["name"] for r in rows] == ["box", "small box"]
    assert int(rows[0]["voxels"]) == 960 and float(rows[0]["volume_voxels_ml"]) == pytest.approx(192.0)
    assert float(rows[1]["volume_voxels_ml"]) == pytest.approx(6 * 6 * 4 * 0.2)
    assert res.rows[0]["volume_mesh_ml"] == pytest.approx(192.0, rel=0.02)


def test_mric_export(case):
    from ctui.engine.io.mric import read_mric

    out = case["out"] / "c.mric"
    export(case["project"], format="mric", out=out)
    data = read_mric(out)
    assert len(data.slices) == case["labels"].shape[0]
    assert sum(len(s) for s in data.slices) == 8 + 6  # one object list per slice the objects are on


def test_cli_export_and_errors(case, capsys):
    out = case["out"] / "cli-seg.dcm"
    assert main(["export", str(case["project"]), "--format", "dicom-seg", "--out", str(out), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["format"] == "dicom-seg" and [o["id"] for o in rep["objects"]] == [1, 2]
    # into the series folder: refused (the file would join the series)
    assert main(["export", str(case["project"]), "--format", "rtstruct", "--out",
                 str(case["root"] / "series" / "rt.dcm")]) == 2
    assert "input folder" in capsys.readouterr().err
    # a SEG has no series of its own: RTSTRUCT from it needs the series (the engine names the
    # keyword, the CLI its flag)
    with pytest.raises(CtuiError, match="needs the DICOM series") as err:
        export(out, format="rtstruct", out=case["out"] / "x.dcm")
    assert err.value.option == "series" and "--" not in str(err.value)
    assert main(["export", str(out), "--format", "rtstruct", "--out", str(case["out"] / "x.dcm")]) == 2
    assert "(see --series)" in capsys.readouterr().err
    res = export(out, format="rtstruct", out=case["out"] / "x.dcm", series=case["root"] / "series")
    assert len(res.objects) == 2
    with pytest.raises(CtuiError, match="no object 7"):
        export(case["project"], format="csv", out=case["out"] / "y.csv", objects=[7])
    with pytest.raises(CtuiError, match=r"\.nii"):
        export(case["project"], format="nifti", out=case["out"] / "y.nrrd")


def test_dicom_export_from_a_project_without_series_uid(case):
    """A project that recorded no series UID (older ctui): the series is found in its folder."""
    from ctui.engine.io.project import load_project
    from ctui.engine.io.project import save_project as save_raw

    proj = load_project(case["project"])
    proj.series_uid = None
    save_raw(case["root"] / "old.ctui", proj)
    out = case["out"] / "old-seg.dcm"
    export(case["root"] / "old.ctui", format="dicom-seg", out=out)
    np.testing.assert_array_equal(read_label_file(out, grid=case["volume"]).labels, case["labels"])
