"""The CLI and the TUI give identical numbers for the same object: both call the actions in
ctui.engine.actions (measure, mesh, export) with the defaults of actions.defaults. Each
case runs `ctui ... --json` on a project and the screens' own code path on the session
rebuilt from that project, and compares the results exactly."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ctui.cli import main
from ctui.engine.core.volume import Volume

SPACING = (1.5, 0.6, 0.6)
ORIGIN = (-20.0, 10.0, 5.0)


def _volume_and_labels():
    """A bent tube (object 1) and a ball (object 3) in a small CT-like volume."""
    nz, ny, nx = 24, 40, 44
    z, y, x = np.mgrid[:nz, :ny, :nx].astype(np.float64)
    zm, ym, xm = z * SPACING[0], y * SPACING[1], x * SPACING[2]
    cy = 10.0 + 0.15 * zm
    tube = (ym - cy) ** 2 + (xm - 8.0) ** 2 <= 2.6**2
    ball = (zm - 18.0) ** 2 + (ym - 12.0) ** 2 + (xm - 18.0) ** 2 <= 5.5**2
    labels = np.zeros((nz, ny, nx), np.uint8)
    labels[tube] = 1
    labels[ball] = 3
    data = np.where(labels > 0, 300, 0).astype(np.int16)
    return Volume(data, spacing=SPACING, origin=ORIGIN, modality="CT", window=(40.0, 400.0)), labels


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    from ctui.engine.actions.project import new_project, save_project
    from ctui.screens.app import session_from_project

    d = tmp_path_factory.mktemp("actions")
    vol, labels = _volume_and_labels()
    proj = new_project(vol, labels=labels, objects=[{"id": 1, "name": "tube", "color": [200, 30, 30]},
                                                    {"id": 3, "name": "ball", "color": [30, 200, 30]}])
    path = d / "p.ctui"
    save_project(path, proj)
    from ctui.engine.io.project import load_project

    session = session_from_project(load_project(path), vol, str(path))
    return d, path, session


def _cli_json(capsys, *argv) -> dict:
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    assert rc == 0, out.err
    return json.loads(out.out)


def test_measure_cli_equals_tui(case, capsys):
    from ctui.engine.actions import defaults
    from ctui.engine.actions.measure import measure_object
    from ctui.engine.core.jsonio import to_jsonable
    from ctui.screens.export import opened_of  # what the screens pass to the actions

    d, path, session = case
    cli = _cli_json(capsys, "measure", path, "--object", 1, "--path", "auto", "--json")
    # the measure screen's call (ctui/screens/measure_screen.py): same action, same defaults
    tui = to_jsonable(measure_object(opened_of(session), object=1, path="auto"))
    tui["input"] = cli["input"]  # the file name the CLI reports; the TUI's session names its project
    notes = cli.pop("warnings")
    assert tui.pop("warnings") == [] and all("geometry from the project" in w for w in notes)  # no series here
    assert cli == tui
    assert len(cli["sections"]) > 10 and cli["path_length_mm"] > 20
    s = [r["s_mm"] for r in cli["sections"]]
    assert np.allclose(np.diff(s), defaults.SECTION_STEP_MM, atol=1e-6)  # one default step for both
    ball = _cli_json(capsys, "measure", path, "--object", 3, "--json")
    assert ball["volume_ml"]["voxels"] == pytest.approx(4 / 3 * np.pi * 5.5**3 / 1000, rel=0.08)


def test_mesh_cli_equals_tui_export_and_3d_view(case, capsys):
    from ctui.engine.io.meshes import load_mesh
    from ctui.engine.mesh.meshtools import mesh_report
    from ctui.screens.export import export_session
    from ctui.screens.view3d import build_meshes

    d, path, session = case
    cli = _cli_json(capsys, "mesh", path, "--out", d / "cli.stl", "--json")
    res = export_session(session, "stl", str(d / "tui.stl"))  # the export menu's "STL: object surfaces"
    tui_mesh = load_mesh(d / "tui.stl")
    assert len(res.objects) == 2 and cli["objects"] == [1, 3]
    a, b = load_mesh(d / "cli.stl"), load_mesh(d / "tui.stl")
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert mesh_report(tui_mesh)["volume_ml"] == pytest.approx(cli["volume_ml"], abs=1e-4)
    # one object, and the 3D view's surfaces
    one = _cli_json(capsys, "mesh", path, "--object", 3, "--out", d / "cli3.ply", "--json")
    session.current = 3
    export_session(session, "ply:current", str(d / "tui3.ply"))  # "PLY: surface of the current object"
    m3 = load_mesh(d / "tui3.ply")
    assert mesh_report(m3)["triangles"] == one["triangles"]
    assert mesh_report(m3)["volume_ml"] == pytest.approx(one["volume_ml"], abs=1e-4)
    view = build_meshes(session, "marching-cubes")
    assert sorted(view) == [1, 3] and np.array_equal(view[3].vertices, m3.vertices)


def test_export_cli_equals_tui(case, capsys):
    from ctui.engine.io.labels import load_labels
    from ctui.screens.export import export_session

    d, path, session = case
    rc = main(["export", str(path), "--format", "nifti", "--out", str(d / "cli.nii.gz")])
    assert rc == 0, capsys.readouterr().err
    export_session(session, "nifti", str(d / "tui.nii.gz"))
    (la, va), (lb, vb) = load_labels(d / "cli.nii.gz"), load_labels(d / "tui.nii.gz")
    assert np.array_equal(la, lb) and np.array_equal(la, session.labels())
    assert np.allclose(va.affine, vb.affine) and np.allclose(va.spacing, SPACING) and np.allclose(va.origin, ORIGIN)
