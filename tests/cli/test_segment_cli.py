"""`ctui segment` and `ctui drift` on the bundled phantom series."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ctui.cli import main


@pytest.fixture(scope="module")
def truth():
    pytest.importorskip("ctui.engine.io.series")
    from ctui.engine.io.phantom import load_truth

    return load_truth()


@pytest.fixture(scope="module")
def sample():
    from ctui.engine.io.phantom import SAMPLE_DIR

    return str(SAMPLE_DIR)


def _kidneys(truth):
    return [o for o in truth["objects"] if o["name"].startswith("kidney")]


def _run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_segment_two_kidneys_json(capsys, truth, sample):
    args = ["segment", sample]
    for k in _kidneys(truth):
        z, y, x = k["seed_zyx"]
        args += ["--seed", f"{x},{y},{z}", "--range", "{}:{}".format(*k["hu_range"])]
    rc, out, err = _run(capsys, *args, "--filter", "median:size=3,stage=2", "--json")
    assert rc == 0, err
    rep = json.loads(out)
    objs = rep["objects"]
    assert [o["id"] for o in objs] == [1, 2]
    for o, k in zip(objs, _kidneys(truth)):
        assert set(o) >= {"id", "voxels", "volume_ml", "slices", "warnings"}
        assert o["volume_ml"] == pytest.approx(k["volume_ml"], rel=0.02)
        assert o["slices"][0] < k["seed_zyx"][0] < o["slices"][1]
        assert o["warnings"] == []
    assert rep["pipeline"]["domain"] == "hu" and rep["pipeline"]["steps"][0]["name"] == "median"


def test_segment_writes_project_mask_mric(capsys, truth, sample, tmp_path):
    k = _kidneys(truth)[0]
    z, y, x = k["seed_zyx"]
    proj, mask, mric = tmp_path / "k.ctui", tmp_path / "k.nii.gz", tmp_path / "k.mric"
    rc, out, err = _run(capsys, "segment", sample, "--seed", f"{x},{y},{z}", "--tolerance", "80",
                        "--filter", "opening:size=3,shape=ellipse", "--project", proj, "--mask", mask, "--mric", mric)
    assert rc == 0, err
    assert "object 1:" in out and "ml" in out
    from ctui.engine.io.labels import load_labels
    from ctui.engine.io.mric import read_mric
    from ctui.engine.io.project import load_project

    p = load_project(proj)
    labels, geom = load_labels(mask)
    np.testing.assert_array_equal(p.labels, labels)
    assert p.pipeline["steps"][0]["params"]["shape"] == "ellipse"
    assert p.objects[0]["seeds"] == [[x, y, z]] and p.propagation["direction"] == "both"
    first, last = np.flatnonzero(labels.any(axis=(1, 2)))[[0, -1]]
    m = read_mric(mric)
    assert len(m.slices) == labels.shape[0] and (m.width, m.height) == labels.shape[:0:-1]
    assert len(m.slices[z]) == 1 and len(m.slices[first - 1]) == 0 and len(m.slices[last]) == 1


@pytest.mark.slow
def test_drift_from_project_and_seeds(capsys, truth, sample, tmp_path):
    k = _kidneys(truth)[1]
    z, y, x = k["seed_zyx"]
    proj = tmp_path / "d.ctui"
    rc, out, err = _run(capsys, "segment", sample, "--seed", f"{x},{y},{z}", "--range", "{}:{}".format(*k["hu_range"]),
                        "--project", proj)
    assert rc == 0, err
    png = tmp_path / "drift.png"
    rc, out, err = _run(capsys, "drift", proj, "--json", "--plot", png)
    assert rc == 0, err
    rep = json.loads(out)
    assert rep["flagged"] == truth["drift"]["slices"]
    assert [c["slice"] for c in rep["corrections"]] == truth["drift"]["slices"]
    assert png.stat().st_size > 1000
    assert any(c["flagged"] for c in rep["centroids"]) and all(len(c["centroid_mm"]) == 3 for c in rep["centroids"])
    # seeds directly, corrections recorded in a new project
    out_proj = tmp_path / "corr.ctui"
    rc, out, err = _run(capsys, "drift", sample, "--seed", f"{x},{y},{z}", "--range", "{}:{}".format(*k["hu_range"]),
                        "--project", out_proj)
    assert rc == 0, err
    assert "flagged slices" in out
    from ctui.engine.io.project import load_project

    assert [c["slice"] for c in load_project(out_proj).drift["corrections"]] == truth["drift"]["slices"]


@pytest.mark.parametrize("extra, message", [
    (["--seed", "500,10,10", "--range", "0:100"], "outside the volume"),
    (["--seed", "10,10", "--range", "0:100"], "expected X,Y,Z"),
    (["--seed", "10,10,10", "--range", "100:0"], "LO is above HI"),
    (["--seed", "10,10,10", "--range", "a:b"], "expected LO:HI"),
    (["--seed", "10,10,10", "--range", "0:100", "--filter", "blur"], "unknown filter"),
    (["--seed", "10,10,10", "--seed", "20,20,20", "--range", "0:1", "--range", "0:1", "--range", "0:1"], "one per seed"),
    (["--seed", "10,10,10", "--range", "auto", "--box", "1,2,3"], "--box"),
    (["--seed", "10,10,40", "--range", "115:445"], "outside the range"),
])
def test_segment_bad_arguments_exit_2(capsys, truth, sample, extra, message):
    rc, out, err = _run(capsys, "segment", sample, *extra)
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ctui segment:") and message in lines[0]


def test_help_documents_filter_syntax(capsys):
    with pytest.raises(SystemExit):
        main(["segment", "--help"])
    out = capsys.readouterr().out
    assert "opening:size=3" in out and "stage=1|2" in out


@pytest.mark.parametrize("extra, part", [(["--mode", "3d"], "all"), (["--direction", "forward"], "upper"),
                                         (["--direction", "backward", "--connectivity", "4"], "lower")])
def test_segment_modes_and_directions(capsys, truth, sample, extra, part):
    k = _kidneys(truth)[0]
    z, y, x = k["seed_zyx"]
    rc, out, err = _run(capsys, "segment", sample, "--seed", f"{x},{y},{z}", "--range", "{}:{}".format(*k["hu_range"]),
                        "--json", *extra)
    assert rc == 0, err
    (o,) = json.loads(out)["objects"]
    if part == "all":
        assert o["volume_ml"] == pytest.approx(k["volume_ml"], rel=0.02)
    elif part == "upper":
        assert o["slices"][0] == z and o["slices"][1] > z + 10
        assert 0.3 < o["volume_ml"] / k["volume_ml"] < 0.7
    else:
        assert o["slices"][1] == z and o["slices"][0] < z - 10
        assert 0.3 < o["volume_ml"] / k["volume_ml"] < 0.7
