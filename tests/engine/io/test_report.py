"""`ctui report`: a DICOM SR (TID 1500) read back by highdicom (and dcmqi's tid1500reader when
installed) with every number equal to `ctui measure --json`, its references resolving to the
SEG's segments and the source images, and no patient identifiers unless asked."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess

import numpy as np
import pytest

from ctui.cli import main
from ctui.engine.actions.project import new_project, save_project
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.privacy import find_strings
from ctui.engine.io.phantom import make_phantom, write_series
from ctui.engine.io.series import load

NAMES = {1: "left kidney", 2: "aorta"}
PATIENT = ("PHANTOM^SYNTHETIC", "SYNTHETIC-0000")  # what io.phantom.write_series puts in every header


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    vol, _ = make_phantom(shape=(24, 52, 52), spacing=(8.0, 5.0, 5.0), noise_sd=0, drift=False, supersample=2)
    write_series(root / "series", vol)
    v = load(root / "series")
    labels = np.zeros(v.shape, np.uint8)
    labels[4:12, 10:20, 12:24] = 1  # a box
    z, y, x = np.mgrid[:24, :52, :52]
    labels[(z >= 2) & (z < 22) & ((y - 36) ** 2 + (x - 34) ** 2 <= 16)] = 2  # a tube along z: sections
    objects = [{"id": i, "name": n, "color": [200, 60 * i, 60]} for i, n in NAMES.items()]
    save_project(root / "p.ctui", new_project(v, source_path=root / "series", labels=labels, objects=objects))
    (root / "out").mkdir()
    sr = root / "out" / "r.dcm"
    assert main(["report", str(root / "p.ctui"), "--out", str(sr), "--path", "auto"]) == 0
    return {"root": root, "labels": labels, "project": root / "p.ctui", "sr": sr, "seg": root / "out" / "r-seg.dcm",
            "series": root / "series", "out": root / "out"}


def _measure_json(capsys, *args) -> dict:
    capsys.readouterr()
    assert main(["measure", *map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _expected(m: dict) -> dict:
    """What the SR must hold for one `ctui measure --json --values --path auto` result."""
    exp = {"volume_voxels_ml": m["volume_ml"]["voxels"], "volume_mesh_ml": m["volume_ml"]["mesh"],
           "area_mm2": m["area_mm2"], "mean": m["values"]["mean"], "sd": m["values"]["sd"],
           "path_length_mm": m["path_length_mm"]}
    exp.update({f"axis_{k}_mm": a for k, a in enumerate(m["principal_axes_mm"], start=1)})
    secs = m["sections"]
    if secs:
        for key, col, pick in (("max_diameter", "max_diameter_mm", max), ("min_diameter", "min_diameter_mm", min),
                               ("max_area", "area_mm2", max), ("min_area", "area_mm2", min)):
            best = pick(secs, key=lambda r: r[col])
            exp[f"{key}_{col.rsplit('_', 1)[1]}"], exp[f"{key}_s_mm"] = best[col], best["s_mm"]
    return exp


def _groups_by_highdicom(path):
    import highdicom as hd

    sr = hd.sr.srread(path)
    return sr, sr.content.get_volumetric_roi_measurement_groups(), sr.content.get_planar_roi_measurement_groups()


@pytest.mark.slow
def test_sr_numbers_equal_ctui_measure_json(case, capsys):
    from ctui.engine.actions.report import read_report

    groups = {g["name"]: g for g in read_report(case["sr"]).groups if g["kind"] == "object"}
    assert set(groups) == set(NAMES.values())
    _, volumetric, planar = _groups_by_highdicom(case["sr"])
    assert len(volumetric) == 2
    for oid, name in NAMES.items():
        m = _measure_json(capsys, case["project"], "--object", oid, "--values", "--path", "auto")
        exp = _expected(m)
        got = groups[name]["values"]
        assert set(got) == {k for k, v in exp.items() if v is not None}, name
        for k, v in exp.items():
            assert got[k] == pytest.approx(v, rel=1e-9, abs=1e-6), (name, k)
    tube = _measure_json(capsys, case["project"], "--object", 2, "--values", "--path", "auto")
    assert len(tube["sections"]) > 100  # the tube has sections; the SR carries its extremes as planar groups
    rows = {r["s_mm"]: r for r in tube["sections"]}
    assert 1 <= len(planar) <= 4
    for g in planar:  # each extreme section: its numbers and its contour in patient mm
        vals = {m.name.meaning + (f" {m.derivation.meaning}" if m.derivation else ""): float(m.value)
                for m in g.get_measurements()}
        row = rows[vals["Arc length along the path"]]
        assert vals["Area"] == pytest.approx(row["area_mm2"], abs=1e-6)
        assert vals["Diameter Maximum"] == pytest.approx(row["max_diameter_mm"], abs=1e-6)
        assert vals["Diameter Minimum"] == pytest.approx(row["min_diameter_mm"], abs=1e-6)
        contour = np.asarray(g.roi.value, float)
        assert contour.shape[1] == 3 and np.allclose(contour[0], contour[-1])  # closed polygon
        radius = np.sqrt(row["area_mm2"] / np.pi)
        centre = contour.mean(axis=0)
        assert np.abs(np.linalg.norm(contour - centre, axis=1) - radius).max() < 6.0  # around the tube's axis


def test_references_resolve_to_the_seg_segments_and_source_images(case):
    import pydicom

    from ctui.engine.actions.report import read_report
    from ctui.engine.io.imports import read_label_file

    seg = pydicom.dcmread(case["seg"])
    series = {}
    for f in sorted(case["series"].iterdir()):
        ds = pydicom.dcmread(f, stop_before_pixels=True)
        series[str(ds.SOPInstanceUID)] = ds
    by_z = {round(float(ds.ImagePositionPatient[2]), 3): uid for uid, ds in series.items()}
    zs = sorted(by_z)  # the phantom's slices go up in z with the index (write_series)
    imp = read_label_file(case["seg"], grid=load(case["series"]))
    doc = read_report(case["sr"])
    assert set(doc.evidence) == set(series) | {str(seg.SOPInstanceUID)}
    labels = {int(s.SegmentNumber): s.SegmentLabel for s in seg.SegmentSequence}
    for g in (g for g in doc.groups if g["kind"] == "object"):
        ref = g["segment"]
        assert ref["sop_instance_uid"] == str(seg.SOPInstanceUID)
        assert labels[ref["segment_number"]] == g["name"]
        oid = next(i for i, n in NAMES.items() if n == g["name"])
        obj = next(o for o in imp.objects if o["source_number"] == ref["segment_number"])
        assert np.array_equal(imp.mask(obj["id"]), case["labels"] == oid)  # the segment is the object's voxels
        slices = np.flatnonzero((case["labels"] == oid).any(axis=(1, 2)))
        assert set(ref["source_images"]) == {by_z[zs[k]] for k in slices}  # the images the segment lies on


def test_deidentified_unless_asked(case):
    import pydicom

    for path in (case["sr"], case["seg"]):
        assert find_strings([path], ["SYNTHETIC", PATIENT[1]]) == [], path  # ("PHANTOM" stays: a common word)
        ds = pydicom.dcmread(path)
        assert not str(ds.get("PatientName", "")) and not ds.get("PatientID") and not ds.get("PatientBirthDate")
    kept = case["out"] / "kept.dcm"
    assert main(["report", str(case["project"]), "--out", str(kept), "--keep-identifiers", "--object", "1"]) == 0
    assert str(pydicom.dcmread(kept).PatientName) == PATIENT[0]
    assert str(pydicom.dcmread(case["out"] / "kept-seg.dcm").PatientID) == PATIENT[1]


def test_measure_lists_the_report(case, capsys):
    capsys.readouterr()
    assert main(["measure", str(case["sr"])]) == 0
    out = capsys.readouterr().out
    assert "left kidney [Kidney, Left]" in out and "aorta [Aorta]" in out
    assert "Volume (Sum of segmented voxel method for volume): 192 ml" in out  # 8 x 10 x 12 voxels of 200 mm3
    doc = _measure_json(capsys, case["sr"])
    assert doc["kind"] == "dicom-sr" and len([g for g in doc["groups"] if g["kind"] == "object"]) == 2


@pytest.mark.slow
def test_given_seg_and_seg_input(case, capsys):
    from ctui.engine.actions.report import read_report, write_report

    seg_uid = read_report(case["sr"]).groups[0]["segment"]["sop_instance_uid"]
    again = case["out"] / "again.dcm"
    res = write_report(case["project"], out=again, seg=case["seg"])
    assert not res.seg_written and not (case["out"] / "again-seg.dcm").exists()
    assert {g["segment"]["sop_instance_uid"] for g in read_report(again).groups} == {seg_uid}
    from_seg = case["out"] / "from-seg.dcm"  # a DICOM-SEG input over its series is its own reference
    assert main(["report", str(case["seg"]), "--series", str(case["series"]), "--out", str(from_seg)]) == 0
    groups = read_report(from_seg).groups
    assert {g["segment"]["sop_instance_uid"] for g in groups} == {seg_uid}
    m = _measure_json(capsys, case["series"], "--labels", case["seg"], "--object", 1)
    assert groups[0]["values"]["volume_mesh_ml"] == pytest.approx(m["volume_ml"]["mesh"], abs=1e-6)
    other = case["out"] / "other-seg.dcm"  # a SEG holding only object 1: object 2 has no segment there
    assert main(["export", str(case["project"]), "--format", "dicom-seg", "--object", "1", "--out", str(other)]) == 0
    with pytest.raises(CtuiError, match="no segment of the DICOM-SEG matches object 2"):
        write_report(case["project"], out=case["out"] / "bad.dcm", seg=other)
    with pytest.raises(CtuiError, match="needs the series"):
        write_report(case["seg"], out=case["out"] / "bad.dcm")


def test_csv_and_json_formats(case, capsys):
    out_csv, out_json = case["out"] / "r.csv", case["out"] / "r.json"
    assert main(["report", str(case["project"]), "--format", "csv", "--out", str(out_csv)]) == 0
    assert main(["report", str(case["project"]), "--format", "json", "--out", str(out_json)]) == 0
    rows = list(csv.DictReader(out_csv.open()))
    doc = json.loads(out_json.read_text())
    for row, m in zip(rows, doc["measurements"]):
        assert float(row["volume_mesh_ml"]) == pytest.approx(m["volume_ml"]["mesh"], abs=1e-6)
        assert float(row["mean"]) == pytest.approx(m["values"]["mean"], abs=1e-6)
    assert [r["name"] for r in rows] == list(NAMES.values())
    assert not (case["out"] / "r.csv-seg.dcm").exists()


def test_sr_export_format(case):
    from ctui.engine.actions.export import export
    from ctui.engine.actions.report import read_report

    out = case["out"] / "e-sr.dcm"
    res = export(case["project"], format="sr", out=out, objects=[2])
    assert [r["name"] for r in res.rows] == ["aorta"] and (case["out"] / "e-sr-seg.dcm").is_file()
    (g,) = read_report(out).groups
    assert g["values"]["volume_voxels_ml"] == pytest.approx(res.rows[0]["volume_voxels_ml"])


def _tid1500reader() -> str | None:
    exe = shutil.which("tid1500reader")
    if exe:
        return exe
    try:
        import dcmqi
    except ImportError:
        return None
    try:
        return str(dcmqi._lookup("tid1500reader"))  # noqa: SLF001 - the wheel's own executable
    except (AttributeError, FileNotFoundError):
        return None


def test_dcmqi_reads_the_same_numbers(case):
    from ctui.engine.actions.report import read_report

    exe = _tid1500reader()
    if exe is None:
        pytest.skip("dcmqi's tid1500reader is not installed (pip install dcmqi: Linux x86-64 wheels)")
    meta = case["out"] / "dcmqi.json"
    run = subprocess.run([exe, "--inputDICOM", str(case["sr"]), "--outputMetadata", str(meta)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-500:]
    theirs = {g["TrackingIdentifier"]: g for g in json.loads(meta.read_text())["Measurements"]}
    ours = [g for g in read_report(case["sr"]).groups if g["kind"] == "object"]
    assert {g["name"] for g in ours} <= set(theirs)
    for g in ours:
        t = theirs[g["name"]]
        assert t["segmentationSOPInstanceUID"] == g["segment"]["sop_instance_uid"]
        assert int(t["ReferencedSegment"]) == g["segment"]["segment_number"]
        assert [float(i["value"]) for i in t["measurementItems"]] == pytest.approx(
            [m["value"] for m in g["measurements"]], rel=1e-12)
        assert [i["quantity"]["CodeValue"] for i in t["measurementItems"]][:3] == ["118565006", "118565006", "42798000"]


def test_report_over_a_dcmqi_seg(tmp_path, capsys):
    """dcmqi's liver SEG over its real CT: referenced as it is, numbers those of `ctui measure --labels`."""
    from support import shared

    from ctui.engine.actions.report import read_report

    data = shared("dcmqi_seg")
    seg, ct = data / "liver.dcm", data / "ct-3slice"
    out = tmp_path / "liver-sr.dcm"
    assert main(["report", str(seg), "--series", str(ct), "--out", str(out)]) == 0
    m = _measure_json(capsys, ct, "--labels", seg, "--object", 1)
    (g,) = read_report(out).groups
    import pydicom

    assert g["segment"]["sop_instance_uid"] == str(pydicom.dcmread(seg, stop_before_pixels=True).SOPInstanceUID)
    assert g["site"] == "Liver" and g["name"] == "Liver"
    exp = _expected(m)
    assert {k: g["values"][k] for k in exp if exp[k] is not None} == pytest.approx(
        {k: v for k, v in exp.items() if v is not None}, abs=1e-6)
    assert not list(tmp_path.glob("*-seg.dcm"))


@pytest.mark.slow
def test_all_sections(case, capsys):
    """--sections all: every section of `ctui measure --json` is a planar group with its numbers."""
    out = case["out"] / "all.dcm"
    assert main(["report", str(case["project"]), "--object", "2", "--path", "auto", "--step", "4",
                 "--sections", "all", "--seg", str(case["seg"]), "--out", str(out)]) == 0
    m = _measure_json(capsys, case["project"], "--object", 2, "--path", "auto", "--step", 4)
    _, volumetric, planar = _groups_by_highdicom(out)
    assert len(volumetric) == 1 and len(planar) == len(m["sections"]) > 10
    got = sorted((float(next(x.value for x in g.get_measurements() if x.name.meaning == "Arc length along the path")),
                  float(next(x.value for x in g.get_measurements() if x.name.meaning == "Area"))) for g in planar)
    assert got == pytest.approx([(r["s_mm"], r["area_mm2"]) for r in m["sections"]], abs=1e-6)
