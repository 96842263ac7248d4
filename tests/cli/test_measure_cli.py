"""`ctui measure`: label files, projects and meshes in; JSON/CSV/PNG out; bad input exits 2."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from ctui.cli import main
from ctui.engine.core.volume import Volume

SP = (0.5, 0.5, 0.5)


def _tube_labels():
    """Object 2: a tube along x (r = 2 mm, 30 mm long) with a parallel neighbour (object 2 too)."""
    shape = (30, 40, 80)
    zz, yy, xx = np.meshgrid(*[np.arange(n) * 0.5 for n in shape], indexing="ij")
    labels = np.zeros(shape, np.uint8)
    labels[((yy - 7.1) ** 2 + (zz - 7.3) ** 2 <= 4.0) & (xx > 5) & (xx < 35)] = 2
    labels[((yy - 14.2) ** 2 + (zz - 7.3) ** 2 <= 2.25) & (xx > 5) & (xx < 35)] = 2
    labels[2:6, 2:6, 2:6] = 1
    origin = (-20.0, 10.0, 5.0)
    return labels, Volume(data=labels, spacing=SP, origin=origin)


def _run(capsys, *argv):
    rc = main(["measure", *map(str, argv)])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


@pytest.fixture()
def label_file(tmp_path):
    from ctui.engine.io.labels import save_labels

    labels, vol = _tube_labels()
    p = tmp_path / "seg.nii.gz"
    save_labels(p, labels, vol)
    return p, labels, vol


def test_measure_label_file_path_between_json(label_file, tmp_path, capsys):
    p, labels, vol = label_file
    # path along the first tube's axis, in patient mm
    o = np.asarray(vol.origin)
    a, b = o + np.array([8.0, 7.1, 7.3]), o + np.array([32.0, 7.1, 7.3])
    path = f"{a[0]},{a[1]},{a[2]};{b[0]},{b[1]},{b[2]}"
    csv, png = tmp_path / "s.csv", tmp_path / "s.png"
    rc, out, err = _run(capsys, p, "--object", 2, f"--path={path}", "--step", 1.0, "--between", "4,16",
                        "--csv", csv, "--plot", png, "--no-mesh", "--json")
    assert rc == 0, err
    doc = json.loads(out)
    for k in ("volume_ml", "area_mm2", "path_length_mm", "sections", "between"):
        assert k in doc
    assert set(doc["volume_ml"]) == {"voxels", "mesh"}
    n2 = int((labels == 2).sum())
    assert doc["volume_ml"]["voxels"] == pytest.approx(n2 * 0.125 / 1000)
    assert doc["path_length_mm"] == pytest.approx(24.0, abs=0.01)
    assert len(doc["sections"]) == 25
    row = doc["sections"][12]
    assert set(row) == {"s_mm", "area_mm2", "eq_diameter_mm", "min_diameter_mm", "max_diameter_mm"}
    assert row["area_mm2"] == pytest.approx(math.pi * 4, rel=0.05)  # the neighbour is not counted
    assert row["eq_diameter_mm"] == pytest.approx(4.0, rel=0.03)
    b = doc["between"]
    assert set(b) == {"volume_ml", "area1_mm2", "area2_mm2"}
    assert b["volume_ml"] == pytest.approx(math.pi * 4 * 12 / 1000, rel=0.05)
    assert csv.read_text().count("\n") == 26 and png.read_bytes()[:4] == b"\x89PNG"


def test_measure_auto_path_text_output(label_file, capsys):
    p, labels, vol = label_file
    rc, out, err = _run(capsys, p, "--object", 1, "--no-mesh")
    assert rc == 0, err
    assert "object 1" in out and "voxel volume 0.008 ml" in out  # 64 voxels of 0.125 mm^3
    labels1 = (labels == 2)
    rc, out, err = _run(capsys, p, "--object", 2, "--path", "auto", "--step", 2, "--no-mesh", "--json")
    assert rc == 0, err
    doc = json.loads(out)
    # the automatic centreline runs along one of the two tubes (largest component = first tube),
    # from end face to end face of its voxels (x 5.25 .. 34.75 mm)
    assert doc["path_length_mm"] == pytest.approx(29.5, abs=0.6)
    # every section reported is a cross-section: the end caps' sections are left out
    a = np.array([r["area_mm2"] for r in doc["sections"]], dtype=float)
    assert len(a) >= 12 and np.all(np.isfinite(a))
    assert np.abs(a / (math.pi * 4) - 1).max() < 0.06, a
    flags = doc["section_flags"]  # what was left out, and where: end caps only (every 2 mm: one or both)
    assert flags["counts"].get("cap", 0) >= 1 and set(flags["counts"]) == {"cap"}
    assert all(r["from_s_mm"] < 2.1 or r["to_s_mm"] > doc["path_length_mm"] - 2.1 for r in flags["ranges"])
    assert labels1.any()


def test_measure_default_step_is_the_measure_package_default():
    import argparse

    from ctui.commands import measure as cmd
    from ctui.engine.actions import defaults
    from ctui.engine.measure import DEFAULT_SECTION_STEP_MM

    ap = argparse.ArgumentParser()
    cmd.register(ap.add_subparsers())
    args = ap.parse_args(["measure", "x.nii.gz"])
    assert args.step == DEFAULT_SECTION_STEP_MM == defaults.SECTION_STEP_MM


def test_measure_project_input(tmp_path, capsys):
    from ctui.engine.io.project import Project, save_project

    labels, vol = _tube_labels()
    proj = Project(source_path=str(tmp_path / "missing_series"), labels=labels,
                   meta={"spacing_zyx_mm": list(SP), "origin_xyz_mm": list(vol.origin)})
    p = tmp_path / "t.ctui"
    save_project(p, proj)
    rc, out, err = _run(capsys, p, "--object", 2, "--no-mesh", "--json")
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["volume_ml"]["voxels"] == pytest.approx((labels == 2).sum() * 0.125 / 1000)
    assert any("not found" in w for w in doc["warnings"])


def test_measure_mesh_input(tmp_path, capsys):
    meshio = pytest.importorskip("ctui.engine.io.meshes", reason="MESH's meshio not available yet")
    import trimesh

    p = tmp_path / "box.stl"
    trimesh.creation.box(extents=(10.0, 20.0, 30.0)).export(p)
    rc, out, err = _run(capsys, p, "--json")
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["volume_ml"]["mesh"] == pytest.approx(6.0, rel=1e-6)
    assert doc["volume_ml"]["voxels"] is None
    assert doc["area_mm2"] == pytest.approx(2 * (200 + 300 + 600), rel=1e-6)
    assert meshio is not None


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["{missing}"], "no such file"),
        (["{bad}"], "bad.nii.gz"),
        (["{labels}", "--object", "9"], "no object 9"),
        (["{labels}", "--path", "1,2;3,4,5"], "path point"),
        (["{labels}", "--between", "1,2"], "need --path"),
        (["{labels}", "--path", "auto", "--between", "1,x"], "--between"),
        (["{labels}", "--step", "0"], "--step"),
        (["{txt}"], "unknown input"),
    ],
)
def test_measure_bad_input_one_line_exit_2(argv, needle, label_file, tmp_path, capsys):
    p, _, _ = label_file
    bad = tmp_path / "bad.nii.gz"
    bad.write_bytes(b"\x1f\x8b not really gzip")
    txt = tmp_path / "notes.txt"
    txt.write_text("hello")
    subs = {"{missing}": tmp_path / "nope.nii.gz", "{bad}": bad, "{labels}": p, "{txt}": txt}
    rc, out, err = _run(capsys, *[subs.get(a, a) for a in argv])
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ctui measure:"), err
    assert needle in lines[0]


@pytest.fixture(scope="module")
def aorta_crop(tmp_path_factory):
    """The shared contrast CT and its aorta mask as NIfTI, cropped to 40 slices (contrast-filled)."""
    from support import shared

    nib = pytest.importorskip("nibabel")
    d = shared("totalseg_example")
    root = tmp_path_factory.mktemp("aorta_nifti")
    for name in ("ct_aorta_1p5mm.nii.gz", "ct_aorta_1p5mm_aorta.nii.gz"):
        img = nib.load(d / name)
        nib.save(img.slicer[:, :, 85:125], root / name)  # NIfTI k = ctui z
    return root / "ct_aorta_1p5mm.nii.gz", root / "ct_aorta_1p5mm_aorta.nii.gz"


def test_labels_over_a_nifti_ct_with_partial_volume_and_path(capsys, aorta_crop, tmp_path):
    """`ctui measure CT.nii.gz --labels aorta.nii.gz --partial-volume`: HU statistics, the
    partial-volume volume and the centreline's points in --json and --path-csv."""
    ct, seg = aorta_crop
    rc, out, err = _run(capsys, ct, "--labels", seg, "--partial-volume", "--path", "auto", "--no-mesh", "--json",
                        "--path-csv", tmp_path / "path.csv")
    assert rc == 0, err
    d = json.loads(out)
    vox, pv = d["volume_ml"]["voxels"], d["volume_ml"]["partial_volume"]
    assert vox > 10 and abs(pv / vox - 1) < 0.1  # sub-voxel volume: close to the voxel count, not equal
    v = d["values"]
    assert v["unit"] == "HU" and v["voxels"] == round(vox * 1000 / 1.5 ** 3)
    assert 150 < v["median"] < 600  # contrast-enhanced blood
    pts = np.array([[p["x_mm"], p["y_mm"], p["z_mm"]] for p in d["path"]])
    assert len(pts) > 10 and abs(d["path"][-1]["s_mm"] - d["path_length_mm"]) < 0.5
    rows = (tmp_path / "path.csv").read_text().splitlines()
    assert rows[0] == "index,s_mm,x_mm,y_mm,z_mm" and len(rows) == len(pts) + 1
    assert np.allclose([float(c) for c in rows[1].split(",")[2:]], pts[0], atol=1e-3)


def test_labels_over_a_volume_that_does_not_match_is_refused(capsys, aorta_crop, tmp_path):
    nib = pytest.importorskip("nibabel")
    ct, seg = aorta_crop
    img = nib.load(seg)
    aff = img.affine.copy()
    aff[:3, 3] += 0.5  # a third of a voxel off
    nib.save(nib.Nifti1Image(np.asarray(img.dataobj), aff), tmp_path / "shifted.nii.gz")
    rc, out, err = _run(capsys, ct, "--labels", tmp_path / "shifted.nii.gz")
    assert rc == 2 and "fraction of a voxel" in err


def test_values_need_the_series(label_file, capsys):
    p, _, _ = label_file
    rc, out, err = _run(capsys, p, "--values")
    assert rc == 2 and "grey-level statistics need the series" in err
