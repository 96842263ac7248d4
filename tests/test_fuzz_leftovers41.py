"""Leftovers of issue 41's outside fuzz campaign: each case reproduces one finding at its cause."""

from __future__ import annotations

import logging

import pytest


# ----------------------------------------------------------------- batch: a row writing into another row's series
def test_batch_row_writing_into_another_rows_series_is_refused(tmp_path):
    from ctui.engine.actions.batch import read_manifest, refuse_cross_writes, run_job

    for name in ("a", "b", "c"):
        (tmp_path / name).mkdir()
    (tmp_path / "jobs.csv").write_text('series,seed,outdir,name\n'
                                       'a,"1,1,1",b/out,intruder\n'      # outdir inside row 2's series folder
                                       'b,"1,1,1",results,fine\n'
                                       'c,"1,1,1",b,direct\n'           # outdir IS row 2's series folder
                                       'b,"2,2,2",results,same\n')      # same series as row 2: not "another"
    jobs = read_manifest(tmp_path / "jobs.csv")
    assert refuse_cross_writes(jobs) == 2
    by = {j.name: j for j in jobs}
    assert "inside row 2's series" in by["intruder"].error and "inside row 2's series" in by["direct"].error
    assert by["fine"].error == "" and by["same"].error == ""
    row = run_job(by["intruder"])  # the row is a one-line failure, nothing written
    assert row["status"] == "failed" and "\n" not in row["error"] and "another series" in row["error"]
    assert not (tmp_path / "b" / "out").exists()


# ----------------------------------------------------------------- batch: a killed Dask worker, one line
def test_killed_worker_noise_silenced_and_one_line_row(capsys):
    pytest.importorskip("distributed")
    from distributed.scheduler import KilledWorker

    from ctui.engine.actions.batch import Job, _failed_row, _quiet_dask

    seen = []

    class Catch(logging.Handler):
        def emit(self, record):
            seen.append(record.getMessage())

    h = Catch()
    root = logging.getLogger()
    root.addHandler(h)
    try:
        with _quiet_dask():
            for name in ("distributed.scheduler", "distributed.nanny", "distributed.client", "distributed.core"):
                logging.getLogger(name).error("Worker process 123 was killed by signal 9\nTraceback ...")
        logging.getLogger("distributed.scheduler").critical("after")  # levels restored afterwards
    finally:
        root.removeHandler(h)
    assert seen == ["after"]
    exc = KilledWorker("ctui-job-x-1", "tcp://127.0.0.1:1", allowed_failures=3)
    row = _failed_row(Job(1, "s", (0, 0, 0), None, name="s"), exc)
    assert row["status"] == "failed" and "worker process running it died" in row["error"]
    assert "\n" not in row["error"] and len(row["error"]) < 120
