"""A project stands on its own: copy the sample series, segment it into a project, move the
series away: `ctui measure`, `ctui mesh` and `ctui render` of the project give the same
volume as before the move. A series whose voxels changed is refused; an empty source path
never loads the current folder; projects written before the schema had a version open."""

from __future__ import annotations

import io
import json
import shutil
import zipfile

import numpy as np
import pytest

from ctui.cli import main


def _cli(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    """(folder, series path, project path): the sample phantom's left kidney segmented."""
    from ctui.engine.io.phantom import load_truth, sample_path

    d = tmp_path_factory.mktemp("standalone")
    series = d / "series"
    shutil.copytree(sample_path(), series)
    kidney = next(o for o in load_truth(series)["objects"] if o["name"] == "kidney_left")
    z, y, x = kidney["seed_zyx"]
    lo, hi = kidney["hu_range"]
    proj = d / "kidney.ctui"
    rc = main(["segment", str(series), "--seed", f"{x},{y},{z}", "--range", f"{lo:g}:{hi:g}", "--project", str(proj)])
    assert rc == 0
    return d, series, proj


def _numbers(capsys, d, proj, tag: str) -> dict:
    rc, out, err = _cli(capsys, "measure", proj, "--json")
    assert rc == 0, err
    m = json.loads(out)
    rc, out, err = _cli(capsys, "mesh", proj, "--out", d / f"k_{tag}.stl", "--json")
    assert rc == 0, err
    return {"voxels": m["volume_ml"]["voxels"], "mesh": m["volume_ml"]["mesh"], "area": m["area_mm2"],
            "stl": json.loads(out)["volume_ml"], "warnings": m["warnings"]}


@pytest.mark.slow
def test_measure_mesh_render_without_the_series(project, capsys):
    from ctui.engine.io.project import load_project
    from ctui.engine.io.series import load

    d, series, proj = project
    p = load_project(proj)
    vol = load(series)
    assert p.version == 2 and p.geometry is not None and p.geometry.same_grid(p.geometry.of(vol))
    assert p.modality == "CT" and p.voxel_hash and p.voxel_hash.startswith("blake2b-128:")
    before = _numbers(capsys, d, proj, "before")
    assert before["voxels"] == pytest.approx(143.07, rel=0.02)  # the phantom's analytic kidney
    moved = d / "moved"
    series.rename(moved)
    try:
        after = _numbers(capsys, d, proj, "after")
        for key in ("voxels", "mesh", "area", "stl"):
            assert after[key] == before[key], key
        assert any("not found" in w for w in after["warnings"])
        rc, out, err = _cli(capsys, "drift", proj, "--json")
        assert rc == 0, err
        assert json.loads(out)["centroids"]
        rc, out, err = _cli(capsys, "export", proj, "--format", "nifti", "--out", d / "k.nii.gz")
        assert rc == 0, err
        from ctui.engine.io.labels import load_labels

        lab, lvol = load_labels(d / "k.nii.gz")
        assert np.array_equal(lab, p.labels) and lvol.geometry.same_grid(p.geometry)
        from ctui.engine.render import egl_available

        if egl_available():
            rc, out, err = _cli(capsys, "render", proj, "--out", d / "k.png", "--size", "160x120")
            assert rc == 0, err
            from PIL import Image

            img = np.asarray(Image.open(d / "k.png").convert("RGB"))
            assert img.shape == (120, 160, 3) and img.std() > 5  # something was drawn
        # grey levels are needed: a one-line error, not a traceback
        rc, out, err = _cli(capsys, "measure", proj, "--partial-volume")
        assert rc == 2 and "missing" in err and len(err.strip().splitlines()) == 1
    finally:
        moved.rename(series)


def test_changed_series_refused(project, tmp_path, capsys):
    from ctui.engine.actions.opened import open_input
    from ctui.engine.core.errors import CtuiError
    from ctui.engine.io.project import load_project, save_project

    d, series, proj = project
    other = tmp_path / "other"
    assert main(["demo", str(other), "--seed", "7"]) == 0
    capsys.readouterr()
    p = load_project(proj)
    p.source_path = str(other)  # same grid, other voxels
    q = tmp_path / "q.ctui"
    save_project(q, p)
    with pytest.raises(CtuiError, match="no longer matches"):
        open_input(q, with_series=True)
    rc, out, err = _cli(capsys, "measure", q, "--partial-volume")
    assert rc == 2 and "no longer matches" in err and len(err.strip().splitlines()) == 1
    # measure from the project's own geometry still works (the voxels are not used)
    rc, out, err = _cli(capsys, "measure", q, "--no-mesh", "--json")
    assert rc == 0, err


def test_empty_source_path_never_loads_the_current_folder(project, tmp_path, monkeypatch, capsys):
    from ctui.engine.actions.opened import open_input
    from ctui.engine.io.project import load_project, save_project

    d, series, proj = project
    p = load_project(proj)
    p.source_path = ""
    q = tmp_path / "empty.ctui"
    save_project(q, p)
    monkeypatch.chdir(series)  # a loadable series in the current folder must not be picked up
    opened = open_input(q)
    assert opened.volume is None and opened.geometry is not None
    assert any("not found" in n for n in opened.notes)
    p.geometry = None
    save_project(q, p)
    rc, out, err = _cli(capsys, "mesh", q, "--out", tmp_path / "x.stl")
    assert rc == 2 and "records no geometry" in err


def test_unversioned_v1_project_still_opens(tmp_path):
    """A project.json written before versions (and v1 with the geometry in meta) opens."""
    from ctui.engine.actions.opened import open_input
    from ctui.engine.io.project import load_project

    labels = np.zeros((4, 5, 6), np.uint8)
    labels[1:3, 1:4, 2:5] = 3
    npy = io.BytesIO()
    np.lib.format.write_array(npy, labels, allow_pickle=False)
    doc = {"format": "ctui-project", "source_path": str(tmp_path / "gone"), "source_options": {}, "pipeline": {},
           "objects": [{"id": 3, "name": "x", "color": [1, 2, 3]}], "propagation": {}, "drift": {},
           "window": [40, 400], "meta": {"spacing_zyx_mm": [2.0, 0.5, 0.5], "origin_xyz_mm": [1, 2, 3]},
           "labels": {"member": "labels.npy", "shape": [4, 5, 6], "dtype": "uint8"}}
    f = tmp_path / "old.ctui"
    with zipfile.ZipFile(f, "w") as zf:
        zf.writestr("project.json", json.dumps(doc))
        zf.writestr("labels.npy", npy.getvalue())
    p = load_project(f)
    assert p.version == 1 and p.geometry.spacing == (2.0, 0.5, 0.5) and p.geometry.origin == (1.0, 2.0, 3.0)
    opened = open_input(f)
    assert opened.object_ids == [3] and opened.geometry.voxel_volume_mm3 == 0.5


def test_labels_only_stand_in_series(project):
    """What the TUI opens when the series is gone and the user picks "labels only"."""
    from ctui.engine.actions.opened import labels_only_volume
    from ctui.engine.io.project import load_project

    d, series, proj = project
    p = load_project(proj)
    vol = labels_only_volume(p)
    assert vol.shape == p.labels.shape and vol.geometry.same_grid(p.geometry) and not vol.data.any()
    assert vol.meta["labels_only"] and vol.modality == "CT" and vol.window == p.window


async def test_tui_opens_a_project_without_its_series_labels_only(project, tmp_path):
    """The TUI opens a project whose series moved away: its objects on the recorded grid
    (no grey levels, said in a warning); saving it keeps the series' identity, so the
    project still opens over the series once it is back."""
    from ctui.engine.actions.opened import open_project
    from ctui.engine.io.project import load_project
    from ctui.screens.app import CtuiApp
    from ctui.screens.testing import wait_workspace

    d, series, proj = project
    before = load_project(proj)
    away = d / "series-away"
    series.rename(away)
    try:
        app = CtuiApp(project=str(proj))
        async with app.run_test(size=(120, 40)) as pilot:
            await wait_workspace(pilot, app)
            s = app.session
            assert s.volume.meta.get("labels_only") and not s.volume.data.any()
            assert np.array_equal(s.labels(), before.labels)
            assert any("labels only" in w for w in s.volume.warnings)
            out = tmp_path / "copy.ctui"
            app._save_to(str(out))
            assert not app.internal_errors
        saved = load_project(out)
        assert saved.voxel_hash == before.voxel_hash and saved.geometry.same_grid(before.geometry)
        assert np.array_equal(saved.labels, before.labels)
    finally:
        away.rename(series)
    assert open_project(str(out), with_series=True).volume is not None  # the series is back: it opens over it
