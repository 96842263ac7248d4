"""``ctui auto --engine totalsegmentator`` with a stand-in ``TotalSegmentator`` on PATH that takes the
real CLI's flags (``-i``, ``-o``, ``--ml``, ``--task``, ``--roi_subset``, ``--fast``, ``--device``) and
writes what the real one writes: one label map with its class map in the NIfTI header extension
(``--ml``; CaretExtension XML as TotalSegmentator's ``add_label_map_to_nifti`` writes it), or one
``<class>.nii.gz`` per class. Its output is flipped along x (an equivalent NIfTI) so ctui must place
it on the series' grid. Objects are named, on the grid, merged by policy; missing pieces are one line."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

nib = pytest.importorskip("nibabel")

from ctui.engine.actions.auto import merge_classes  # noqa: E402
from ctui.engine.io import totalseg  # noqa: E402

SHAPE = (12, 30, 40)  # (nz, ny, nx)

STAND_IN = r'''#!{python}
"""A stand-in for TotalSegmentator's CLI: liver (5) = body voxels with x < 20, spleen (1) = x >= 20,
kidney_left (3) = slices 0..3 of the body; --roi_subset keeps the named classes."""
import argparse, json, sys
from pathlib import Path
import nibabel as nib
import numpy as np

p = argparse.ArgumentParser()
p.add_argument("-i", dest="input"); p.add_argument("-o", dest="output")
p.add_argument("-ml", "--ml", action="store_true"); p.add_argument("-ta", "--task", default="total")
p.add_argument("-rs", "--roi_subset", nargs="+"); p.add_argument("-f", "--fast", action="store_true")
p.add_argument("-d", "--device", default="gpu")
a = p.parse_args()
Path(sys.argv[0] + ".args.json").write_text(json.dumps(sys.argv[1:]))
if {fail}:
    print("ERROR: CUDA out of memory while predicting", flush=True); sys.exit(1)
img = nib.load(a.input)
data = np.asanyarray(img.dataobj)  # (x, y, z)
names = {{1: "spleen", 3: "kidney_left", 5: "liver"}}
lab = np.zeros(data.shape, np.uint8)
body = data > 0
xs = np.arange(data.shape[0])[:, None, None]
lab[body & (xs < 20)] = 5
lab[body & (xs >= 20)] = 1
lab[body & (np.arange(data.shape[2])[None, None, :] < 4)] = 3
if a.roi_subset:
    keep = [k for k, v in names.items() if v in a.roi_subset]
    lab[~np.isin(lab, keep)] = 0
    names = {{k: v for k, v in names.items() if k in keep}}
for i in (1, 2):
    print(f"Predicting part {{i}} of 2 ...", flush=True)
flip = np.diag([-1.0, 1, 1, 1]); flip[0, 3] = data.shape[0] - 1  # index x -> nx-1-x
aff = img.affine @ flip
colors = [[255,0,0],[0,255,0],[0,0,255],[255,255,0],[255,0,255],[0,255,255],[255,128,0],[255,0,128],[128,255,128],[0,128,255],[128,128,128],[185,170,155]]
def save(arr, path, label_map):
    out = nib.Nifti1Image(np.ascontiguousarray(arr[::-1]), aff)
    if label_map is not None:
        body = ""
        for k, v in label_map.items():
            rgb = colors[k % len(colors)]
            body += f'<Label Key="{{k}}" Red="{{rgb[0]/255}}" Green="{{rgb[1]/255}}" Blue="{{rgb[2]/255}}" Alpha="1"><![CDATA[{{v}}]]></Label>\n'
        xml = ('<?xml version="1.0" encoding="UTF-8"?> <CaretExtension>  <VolumeInformation Index="0">   <LabelTable>'
               + "\n" + body + "\n" + '  </LabelTable> <VolumeType><![CDATA[Label]]></VolumeType>   </VolumeInformation></CaretExtension>')
        out.header.extensions.append(nib.nifti1.Nifti1Extension(0, bytes(xml, "utf-8")))
    nib.save(out, path)
if a.ml:
    save(lab, a.output, names)
else:
    Path(a.output).mkdir(parents=True, exist_ok=True)
    for k, v in names.items():
        save((lab == k).astype(np.uint8), str(Path(a.output) / f"{{v}}.nii.gz"), None)
'''


def data() -> np.ndarray:
    d = np.full(SHAPE, -1000, np.int16)
    d[2:10, 5:25, 4:36] = 50  # the body
    return d


def truth() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The stand-in's classes on the series' grid (z, y, x)."""
    body = data() > 0
    xs = np.arange(SHAPE[2])[None, None, :]
    liver, spleen = body & (xs < 20), body & (xs >= 20)
    kidney = body & (np.arange(SHAPE[0])[:, None, None] < 4)
    return body, {"liver": liver & ~kidney, "spleen": spleen & ~kidney, "kidney_left": kidney}


@pytest.fixture
def env(tmp_path, monkeypatch):
    """The series, the stand-in on PATH, weights where TotalSegmentator looks (TOTALSEG_HOME_DIR)."""
    series = tmp_path / "ct.nii.gz"
    aff = np.diag([-0.9, -0.9, 3.0, 1.0])
    aff[:3, 3] = [100.0, 80.0, -40.0]
    nib.save(nib.Nifti1Image(np.ascontiguousarray(data().transpose(2, 1, 0)), aff), str(series))
    home = tmp_path / "tshome"
    (home / "nnunet" / "results" / "Dataset291_TotalSegmentator_part1_organs_1559subj").mkdir(parents=True)
    monkeypatch.setenv("TOTALSEG_HOME_DIR", str(home))
    monkeypatch.delenv("TOTALSEG_WEIGHTS_PATH", raising=False)
    bindir = tmp_path / "bin"
    bindir.mkdir()
    install(bindir)
    monkeypatch.setenv("PATH", f"{bindir}{os.pathsep}{os.environ.get('PATH', '')}")
    monkeypatch.chdir(tmp_path)  # the default output, <stem>-auto.ctui, goes to the working folder
    return series, home, bindir


def install(bindir: Path, *, fail: bool = False) -> Path:
    exe = bindir / "TotalSegmentator"
    exe.write_text(STAND_IN.format(python=sys.executable, fail=fail))
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    return exe


def project(path: Path) -> tuple[np.ndarray, list[dict]]:
    z = zipfile.ZipFile(path)
    meta = json.loads(z.read("project.json"))
    import io

    return np.load(io.BytesIO(z.read("labels.npy"))), meta["objects"]


def run(args, capsys):
    """``ctui ARGS`` in a child process (the environment, PATH and working folder the fixtures set): exit
    status, stdout, stderr. In this process, the CLI's one error line was once caught neither by capsys nor
    by a redirection of sys.stderr in the full suite (another test's thread had put back its own streams)."""
    proc = subprocess.run([sys.executable, "-m", "ctui.cli", *args], capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=300)
    return proc.returncode, proc.stdout, proc.stderr


@pytest.mark.slow
def test_classes_named_on_the_grid(env, tmp_path, capsys):
    series, _, bindir = env
    out = tmp_path / "auto.ctui"
    rc, text, err = run(["auto", str(series), "--engine", "totalsegmentator", "--roi-subset", "liver,spleen",
                         "--fast", "--project", str(out), "--json"], capsys)
    assert rc == 0, err
    args = json.loads((bindir / "TotalSegmentator.args.json").read_text())
    assert args[args.index("--task") + 1] == "total" and "--ml" in args and "--fast" in args
    assert args[args.index("--roi_subset") + 1:args.index("--roi_subset") + 3] == ["liver", "spleen"]
    assert args[args.index("--device") + 1] == "cpu"
    labels, objects = project(out)
    _, want = truth()
    by_name = {o["name"]: o for o in objects}
    assert set(by_name) == {"liver", "spleen"}
    assert by_name["liver"]["id"] == 5 and by_name["spleen"]["id"] == 1  # TotalSegmentator's numbers when free
    assert by_name["liver"]["color"] == [0, 255, 255] and by_name["spleen"]["color"] == [0, 255, 0]  # its class map
    body = data() > 0
    kidney = np.arange(SHAPE[0])[:, None, None] < 4
    assert np.array_equal(labels == 5, body & ~kidney & (np.arange(SHAPE[2]) < 20))  # placed back (flipped x)
    assert np.array_equal(labels == 1, body & ~kidney & (np.arange(SHAPE[2]) >= 20))
    rep = json.loads(text)
    assert {o["name"] for o in rep["objects"]} == {"liver", "spleen"}


@pytest.mark.parametrize("merge", ["add", "replace", "keep"])
@pytest.mark.slow
def test_merge_policy(env, tmp_path, capsys, merge):
    series, _, _ = env
    base = tmp_path / "base.ctui"
    assert run(["auto", str(series), "--roi-subset", "liver", "--project", str(base)], capsys)[0] == 0
    labels, objects = project(base)  # the user's object "liver" (id 5); now draw an own object over part of it
    from ctui.engine.actions.project import load_project, save_project

    proj = load_project(str(base))
    mine = np.zeros(SHAPE, bool)
    mine[5:8, 10:20, 10:30] = True  # across liver and spleen
    proj.labels = np.where(mine, 2, proj.labels).astype(np.uint8)
    proj.objects = [*proj.objects, {"id": 2, "name": "tumour", "color": [9, 9, 9]}]
    save_project(str(base), proj)
    before = proj.labels.copy()
    out = tmp_path / f"{merge}.ctui"
    rc, _, err = run(["auto", str(base), "--merge", merge, "--project", str(out)], capsys)
    assert rc == 0, err
    labels, objects = project(out)
    names = [o["name"] for o in objects]
    _, want = truth()
    if merge == "keep":  # the existing liver stays as it was; spleen and kidney are added around the user's voxels
        assert names.count("liver") == 1 and np.array_equal(labels == 5, before == 5)
    if merge == "add":  # a second liver object beside the first
        assert names.count("liver") == 2
    if merge == "replace":  # the class replaces the object of that name and wins over the user's voxels
        assert names.count("liver") == 1 and np.array_equal(labels == 5, want["liver"])
        assert np.array_equal(labels == 2, mine & ~want["liver"] & ~want["spleen"] & ~want["kidney_left"])
    else:
        assert np.array_equal(labels == 2, mine)  # the user's object is untouched
        spleen = next(o["id"] for o in objects if o["name"] == "spleen")
        assert np.array_equal(labels == spleen, want["spleen"] & ~mine)


@pytest.mark.slow
def test_missing_weights(env, tmp_path, capsys, monkeypatch):
    series = env[0]
    monkeypatch.setenv("TOTALSEG_HOME_DIR", str(tmp_path / "empty"))
    rc, _, err = run(["auto", str(series), "--task", "total"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert "has no weights in" in err and "totalseg_download_weights -t total" in err


@pytest.mark.slow
def test_licensed_task(env, capsys):
    series, home, _ = env
    rc, _, err = run(["auto", str(series), "--task", "tissue_types"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert "'tissue_types' is a licensed task" in err and "totalseg_set_license" in err
    (home / "config.json").write_text(json.dumps({"license_number": "aca_TEST"}))
    rc, out, err = run(["auto", str(series), "--task", "tissue_types", "--roi-subset", "liver"], capsys)
    assert rc == 0, err
    assert "licensed TotalSegmentator task" in out
    assert project(Path("ct-auto.ctui"))[1][0]["name"] == "liver"  # the default output name


@pytest.mark.slow
def test_not_installed(env, capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path / "nothing"))
    rc, _, err = run(["auto", str(env[0])], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "pip install TotalSegmentator" in err


@pytest.mark.slow
def test_failure_is_one_line(env, capsys):
    install(env[2], fail=True)
    rc, _, err = run(["auto", str(env[0]), "--roi-subset", "liver"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert "TotalSegmentator failed (exit 1): ERROR: CUDA out of memory" in err


@pytest.mark.slow
def test_folder_layout(env, tmp_path):
    """Without --ml TotalSegmentator writes one NIfTI per class: read as classes named by their files."""
    series, _, bindir = env
    outdir = tmp_path / "segs"
    import subprocess

    subprocess.run([str(bindir / "TotalSegmentator"), "-i", str(series), "-o", str(outdir)], check=True,
                   capture_output=True)
    got = totalseg.read_output(outdir)
    assert sorted(got.names.values()) == ["kidney_left", "liver", "spleen"]
    _, want = truth()
    from ctui.engine.core.geometry import Geometry
    from ctui.engine.io.imports import place_on_grid
    from ctui.engine.io.series import load

    placed = place_on_grid(got.labels, Geometry.of(got.volume), Geometry.of(load(str(series))))
    for k, name in got.names.items():
        assert np.array_equal(placed == k, want[name])


def test_merge_ids_when_taken():
    classes = np.zeros((2, 3, 3), np.uint8)
    classes[0, 0, 0], classes[1, 1, 1] = 5, 7
    labels = np.zeros_like(classes)
    labels[0, 2, 2] = 5
    res = merge_classes(classes, {5: "liver", 7: "aorta"}, {}, labels=labels, objects=[{"id": 5, "name": "mine"}])
    ids = {o["name"]: o["id"] for o in res.objects}
    assert ids == {"mine": 5, "liver": 1, "aorta": 7}
    assert res.labels[0, 0, 0] == 1 and res.labels[1, 1, 1] == 7 and res.labels[0, 2, 2] == 5
