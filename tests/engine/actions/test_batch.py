"""`ctui batch` on a dask.distributed LocalCluster: three phantom series and one missing path."""

from __future__ import annotations

import csv

import pytest

from ctui.engine.io.phantom import make_phantom, write_series

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def manifest(tmp_path_factory):
    root = tmp_path_factory.mktemp("batch")
    rows = ["series,seed,range,outdir,name,method,mode,background"]
    how = ["fill,slice,", "grow,slice,{bg}", "fill,3d,"]  # the segment action's methods, one each
    truths = {}
    for i in range(3):
        vol, truth = make_phantom(shape=(24, 52, 52), spacing=(8.0, 5.0, 5.0), noise_sd=4.0, seed=i, drift=False,
                                  supersample=2)
        write_series(root / f"s{i}", vol, seed=i)
        k = next(o for o in truth["objects"] if o["name"] == "kidney_left")
        z, y, x = k["seed_zyx"]
        bz, by, bx = next(o for o in truth["objects"] if o["name"] == "spine")["seed_zyx"]
        rows.append(f's{i},"{x},{y},{z}",115:445,out,case{i},' + how[i].format(bg=f'"{bx},{by},{bz}"'))
        truths[f"case{i}"] = k["volume_ml"]
    rows.append('missing,"1,2,3",115:445,out,gone,,,')
    (root / "jobs.csv").write_text("\n".join(rows) + "\n")
    return root, truths


def _rows(path):
    return {r["name"]: r for r in csv.DictReader(open(path))}


@pytest.mark.slow
def test_batch_three_right_rows_one_failed_then_skips(manifest):
    from ctui.engine.actions.batch import run_batch

    root, truths = manifest
    out = root / "results.csv"
    res = run_batch(root / "jobs.csv", out=out, workers=2, processes=False)
    assert (res.ran, res.failed, res.skipped) == (4, 1, 0)
    rows = _rows(out)
    assert set(rows) == {"case0", "case1", "case2", "gone"}
    for name, truth_ml in truths.items():
        r = rows[name]
        assert r["status"] == "ok", r["error"]
        assert r["method"] == ["fill/slice", "grow/slice", "fill/3d"][int(name[-1])]
        assert float(r["volume_voxels_ml"]) == pytest.approx(truth_ml, rel=0.03)
        assert float(r["volume_mesh_ml"]) == pytest.approx(truth_ml, rel=0.03)
        assert float(r["area_mm2"]) > 0
        assert (root / "out").joinpath(r["project"]).exists() and (root / "out").joinpath(r["mesh"]).exists()
    assert rows["gone"]["status"] == "failed" and "no such series" in rows["gone"]["error"]
    # a second run skips the three done jobs and tries the failed one again
    again = run_batch(root / "jobs.csv", out=out, workers=1, processes=False)
    assert (again.ran, again.skipped, again.failed) == (1, 3, 1)
    assert _rows(out)["case1"]["volume_voxels_ml"] == rows["case1"]["volume_voxels_ml"]


def test_bad_manifest_rows_fail_alone(tmp_path):
    from ctui.engine.actions.batch import read_manifest, run_job

    (tmp_path / "m.csv").write_text('series,seed,range\nx,"1,2",1:2\ny,"1,2,3",5:1\n')
    jobs = read_manifest(tmp_path / "m.csv")
    assert "X,Y,Z" in run_job(jobs[0])["error"] and "LO is above HI" in run_job(jobs[1])["error"]
    (tmp_path / "n.csv").write_text("series,range\nx,1:2\n")
    from ctui.engine.core.errors import CtuiError

    with pytest.raises(CtuiError, match="seed"):
        read_manifest(tmp_path / "n.csv")


def test_batch_on_a_running_scheduler(manifest):
    """--scheduler tcp://HOST:PORT: the jobs go to that cluster's workers."""
    from distributed import LocalCluster

    from ctui.engine.actions.batch import run_batch

    root, truths = manifest
    lines = (root / "jobs.csv").read_text().splitlines()
    (root / "one.csv").write_text("\n".join([lines[0], lines[1]]) + "\n")
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        res = run_batch(root / "one.csv", out=root / "one-results.csv", scheduler=cluster.scheduler_address)
    assert (res.ran, res.failed) == (1, 0)
    assert float(res.rows[0]["volume_voxels_ml"]) == pytest.approx(truths["case0"], rel=0.03)


def test_batch_cli(manifest, capsys):
    import json

    from ctui.cli import main

    root, _ = manifest
    lines = (root / "jobs.csv").read_text().splitlines()
    (root / "cli.csv").write_text("\n".join([lines[0], lines[1], lines[-1]]) + "\n")
    rc = main(["batch", str(root / "cli.csv"), "--out", str(root / "cli-results.csv"), "--threads", "--workers", "1",
               "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert rc == 1 and rep["failed"] == 1 and rep["jobs"] == 2  # a failed job: exit status 1, the rest written
    assert [r["status"] for r in rep["rows"]] == ["ok", "failed"]


def test_outputs_never_go_into_a_series_folder(manifest, tmp_path):
    from ctui.engine.actions.batch import read_manifest, run_batch, run_job
    from ctui.engine.core.errors import CtuiError

    root, _ = manifest
    lines = (root / "jobs.csv").read_text().splitlines()
    (root / "inside.csv").write_text(lines[0] + "\n" + lines[1].replace(",out,", ",s0,") + "\n")
    row = run_job(read_manifest(root / "inside.csv")[0])
    assert row["status"] == "failed" and "input folder" in row["error"]
    with pytest.raises(CtuiError, match="input folder"):
        run_batch(root / "jobs.csv", out=root / "s1" / "results.csv", processes=False)
