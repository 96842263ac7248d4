"""`ctui mesh`: series, project and MRIC inputs, JSON report, one-line errors with exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ctui.cli import main
from ctui.engine.io.meshes import load_mesh
from ctui.engine.mesh.meshtools import mesh_report

KEYS = {"triangles", "vertices", "watertight", "volume_ml", "area_mm2"}


@pytest.fixture(scope="module")
def sample():
    from ctui.engine.io.series import load
    from ctui.engine.io.phantom import load_truth, sample_path

    path = sample_path()
    return path, load(path), load_truth(path)


def run(capsys, *argv):
    rc = main(["mesh", *map(str, argv)])
    out = capsys.readouterr()
    return rc, out.out, out.err


def kidney_labels(volume, truth):
    from scipy.ndimage import label

    lab = np.zeros(volume.data.shape, np.uint8)
    for name in ("kidney_left", "kidney_right"):
        obj = next(o for o in truth["objects"] if o["name"] == name)
        lo, hi = obj["hu_range"]
        comp, _ = label((volume.data >= lo) & (volume.data <= hi))
        lab[comp == comp[tuple(obj["seed_zyx"])]] = obj["label"]
    return lab


def test_series_iso_json(tmp_path, capsys, sample):
    path, _, _ = sample
    out = tmp_path / "bone.stl"
    rc, so, se = run(capsys, path, "--iso", 300, "--out", out, "--json")
    assert rc == 0, se
    rep = json.loads(so)
    assert KEYS <= set(rep)
    assert rep["watertight"] is True and rep["triangles"] > 1000
    back = mesh_report(load_mesh(out))
    assert back["triangles"] == rep["triangles"] and back["watertight"]
    assert back["volume_ml"] == pytest.approx(rep["volume_ml"], rel=1e-3)


def test_project_objects_both_methods(tmp_path, capsys, sample):
    from ctui.engine.io.project import Project, save_project

    path, volume, truth = sample
    proj = tmp_path / "kidneys.ctui"
    save_project(proj, Project(source_path=str(path), labels=kidney_labels(volume, truth)))
    analytic = next(o for o in truth["objects"] if o["name"] == "kidney_left")["volume_ml"]
    vols = {}
    for method in ("marching-cubes", "contours"):
        out = tmp_path / f"k_{method}.ply"
        rc, so, se = run(capsys, proj, "--object", 2, "--method", method, "--out", out, "--json")
        assert rc == 0, se
        rep = json.loads(so)
        assert rep["watertight"] is True
        vols[method] = rep["volume_ml"]
        assert abs(rep["volume_ml"] / analytic - 1) < 0.03
    assert abs(vols["marching-cubes"] / vols["contours"] - 1) < 0.03
    # all objects, smoothed and decimated, OBJ
    out = tmp_path / "all.obj"
    rc, so, se = run(capsys, proj, "--smooth", 5, "--decimate", 3000, "--out", out, "--json")
    assert rc == 0, se
    rep = json.loads(so)
    assert rep["triangles"] <= 3000 and rep["components"] == 2 and rep["watertight"]
    rc, so, se = run(capsys, proj, "--object", 9, "--out", out)
    assert rc == 2 and "no object 9" in se


@pytest.mark.slow
def test_project_terraced_all_objects_in_one_pass(tmp_path, capsys, sample):
    """--terraced: the label map's plain marching cubes, both kidneys from one pass;
    each closed, volumes near the voxel volumes (terraced surfaces cut the corners)."""
    from ctui.engine.mesh.meshtools import components
    from ctui.engine.io.project import Project, save_project

    path, volume, truth = sample
    lab = kidney_labels(volume, truth)
    proj = tmp_path / "kidneys.ctui"
    save_project(proj, Project(source_path=str(path), labels=lab))
    out = tmp_path / "terraced.stl"
    rc, so, se = run(capsys, proj, "--terraced", "--out", out, "--json")
    assert rc == 0, se
    rep = json.loads(so)
    assert rep["watertight"] and rep["components"] == 2
    vox_ml = np.count_nonzero(lab) * np.prod(volume.spacing) / 1000.0
    assert rep["volume_ml"] == pytest.approx(vox_ml, rel=0.02)
    assert len(components(load_mesh(out))) == 2
    rc, so, se = run(capsys, proj, "--terraced", "--method", "contours", "--out", out)
    assert rc == 2 and "--terraced" in se


def test_mric_input(tmp_path, capsys):
    from ctui.engine.core.borders import borders_for_mric
    from ctui.engine.io.mric import write_mric

    z, y, x = np.mgrid[:20, :60, :60]
    m = ((x - 30) ** 2 + (y - 29) ** 2) * 1.0 + ((z - 10) * 2.5) ** 2 <= 22**2
    f = tmp_path / "ball.mric"
    write_mric(f, borders_for_mric(m.astype(np.uint8)), width=60, height=60)
    out = tmp_path / "ball.stl"
    rc, so, se = run(capsys, f, "--out", out, "--spacing", "2.5,1,1", "--json")
    assert rc == 0, se
    rep = json.loads(so)
    assert rep["watertight"] is True
    assert rep["volume_ml"] == pytest.approx(m.sum() * 2.5 / 1000, rel=0.01)
    rc, so, se = run(capsys, f, "--out", out, "--method", "marching-cubes")
    assert rc == 2


def test_bad_inputs_one_line_exit_2(tmp_path, capsys, sample):
    path, _, _ = sample
    junk = tmp_path / "junk.mric"
    junk.write_bytes(b"VAJIRA-MRICUBE-V8" + b"\xff" * 30)
    cases = [
        (tmp_path / "missing", "--iso", 1, "--out", tmp_path / "a.stl"),
        (path, "--out", tmp_path / "a.stl"),  # series without --iso
        (path, "--iso", 300, "--out", tmp_path / "a.vtk"),  # unknown format
        (path, "--iso", 99999, "--out", tmp_path / "a.stl"),  # no surface
        (junk, "--out", tmp_path / "a.stl"),
        (path, "--iso", 300, "--out", tmp_path / "nodir" / "a.stl"),
    ]
    for argv in cases:
        rc, so, se = run(capsys, *argv)
        assert rc == 2, argv
        lines = se.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("ctui mesh: "), se
    assert not (tmp_path / "a.stl").exists()
