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


# ----------------------------------------------------------------- DICOM-SEG made on another series
@pytest.fixture(scope="module")
def two_series(tmp_path_factory):
    import numpy as np

    from ctui.engine.io.dicomseg import source_datasets, write_seg
    from ctui.engine.io.phantom import make_phantom, write_series
    from ctui.engine.io.series import load

    root = tmp_path_factory.mktemp("seg41")
    vol, _ = make_phantom(shape=(6, 32, 32), spacing=(4.0, 10.0, 10.0), noise_sd=0, drift=False)
    write_series(root / "a", vol, seed=1)
    write_series(root / "b", vol, seed=2)  # same grid, other UIDs: another series (another study's)
    va = load(root / "a")
    labels = np.zeros(va.shape, np.uint8)
    labels[1:5, 8:20, 8:20] = 1
    write_seg(root / "seg.dcm", labels, source_datasets(root / "a", va), objects=[{"id": 1, "name": "box"}])
    return root


def test_seg_of_another_series_is_said(two_series):
    from ctui.engine.actions.opened import open_input

    own = open_input(two_series / "a", labels=two_series / "seg.dcm")
    assert not any("another series" in n or "Frame of Reference" in n for n in own.notes), own.notes
    other = open_input(two_series / "b", labels=two_series / "seg.dcm")
    assert any("references 6 of its 6 source images outside this series" in n for n in other.notes), other.notes
    assert int(other.labels.sum()) == 4 * 12 * 12  # still placed (same grid), but not in silence


def test_seg_in_another_frame_of_reference_is_said(two_series):
    import pydicom

    from ctui.engine.actions.opened import open_input

    ds = pydicom.dcmread(two_series / "seg.dcm")
    ds.FrameOfReferenceUID = "1.2.3.4.5"
    ds.save_as(two_series / "seg-for.dcm")
    opened = open_input(two_series / "a", labels=two_series / "seg-for.dcm")
    assert any("Frame of Reference mismatch" in n and "1.2.3.4.5" in n for n in opened.notes), opened.notes


# ----------------------------------------------------------------- a 255-segment DICOM-SEG: one decode, not 255
@pytest.mark.slow
def test_255_segment_seg_is_decoded_in_one_call_and_exactly(two_series, monkeypatch):
    import highdicom as hd
    import numpy as np

    from ctui.engine.io import dicomseg
    from ctui.engine.io.series import load

    va = load(two_series / "a")
    labels = np.zeros(va.shape, np.uint8)
    flat = labels.reshape(-1)
    flat[np.arange(255) * 23 + 5] = np.arange(1, 256)  # 255 one-voxel objects spread over the 6 slices
    path = two_series / "seg255.dcm"
    dicomseg.write_seg(path, labels, dicomseg.source_datasets(two_series / "a", va),
                       objects=[{"id": i, "name": f"o{i}"} for i in range(1, 256)])
    calls = []
    real = hd.seg.Segmentation.get_volume

    def counted(self, *a, **k):
        calls.append((len(k.get("segment_numbers") or []), k.get("combine_segments")))
        return real(self, *a, **k)

    monkeypatch.setattr(hd.seg.Segmentation, "get_volume", counted)
    c = dicomseg.read_seg(path)
    assert calls == [(255, True)]  # was 255 full-volume decodes, one a segment (a minute on a real series)
    assert [s.number for s in c.segments] == list(range(1, 256)) and c.voxel_counts() == [1] * 255
    # (overlapping segments are still read one by one, kept apart: test_dicomseg's overlap cases)
    from ctui.engine.io.imports import read_label_file

    imp = read_label_file(path, grid=va)
    assert np.array_equal(imp.labels, labels)  # every segment where it was written
