"""Hostile files, options and environments, round four (issue 41): one regression case per
defect of the outside campaign that ``test_fuzz_codestreams`` and ``test_loader_assumptions``
do not cover. Each drives the command (or the function) and checks the real outcome."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ctui.cli import main
from support import ROOT

SEED, RANGE = "24,24,8", "200:400"


def _one_line(capsys, argv) -> str:
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and "Traceback" not in err, (rc, err)
    return lines[0]


@pytest.fixture(scope="module")
def proj(tmp_path_factory) -> dict:
    from test_privacy import write_series

    d = tmp_path_factory.mktemp("hostile4")
    s = write_series(d / "series", broken=False)
    assert main(["segment", str(s), "--seed", SEED, "--range", RANGE, "--project", str(d / "p.ctui")]) == 0
    return {"dir": d, "series": s, "project": d / "p.ctui"}


@pytest.mark.parametrize("iop", [[1, 0, 0, 0.2, 1, 0], [2, 0, 0, 0, 2, 0], [0, 0, 0, 0, 0, 0]])
@pytest.mark.parametrize("fmt", ["dicom-seg", "rtstruct"])
def test_invalid_orientation_is_said_and_never_written_into_seg_or_rtstruct(tmp_path, capsys, iop, fmt):
    """Zero, non-unit, non-orthogonal ImageOrientationPatient: loaded with an orientation
    assumption (the non-unit one was silent), and a SEG/RTSTRUCT refused in one line (they were
    written with the raw orientation, exit 0, and could not be read back)."""
    from test_loader_assumptions import _mutate
    from test_privacy import write_series

    s = _mutate(write_series(tmp_path / "s", broken=False), lambda ds: setattr(ds, "ImageOrientationPatient", iop))
    p = tmp_path / "p.ctui"
    capsys.readouterr()
    assert main(["segment", str(s), "--seed", SEED, "--range", RANGE, "--project", str(p)]) == 0
    assert "assumed (orientation)" in capsys.readouterr().out
    out = tmp_path / "x.dcm"
    line = _one_line(capsys, ["export", p, "--format", fmt, "--out", out])
    assert "ImageOrientationPatient" in line and not out.exists()


@pytest.mark.parametrize("case", ["nan", "two values"])
def test_enhanced_ct_with_a_bad_frame_position_exports_in_one_line(tmp_path, capsys, case):
    import pydicom
    from test_load_synthetic import _enhanced

    from ctui.engine.core.volume import Volume

    data = np.full((9, 32, 32), -1000, np.int16)
    data[2:7, 8:24, 8:24] = 300
    f = _enhanced(tmp_path, Volume(data=data, spacing=(2.0, 1.0, 1.0), modality="CT", window=(40, 400)),
                  list(range(9)))
    ds = pydicom.dcmread(f)
    ds.StudyInstanceUID, ds.FrameOfReferenceUID = pydicom.uid.generate_uid(), pydicom.uid.generate_uid()
    pos = ds.PerFrameFunctionalGroupsSequence[4].PlanePositionSequence[0]
    pos.ImagePositionPatient = [0.0, float("nan"), 8.0] if case == "nan" else [0.0, 8.0]
    series = tmp_path / "mf"
    series.mkdir()
    ds.save_as(series / "mf.dcm", enforce_file_format=True)
    f.unlink()
    p = tmp_path / "p.ctui"
    assert main(["segment", str(series), "--seed", "16,16,4", "--range", "200:400", "--project", str(p)]) == 0
    assert "frame 5" in _one_line(capsys, ["export", p, "--format", "dicom-seg", "--out", tmp_path / "x.dcm"])


def test_stale_temp_cleaner_keeps_the_users_own_files(proj, tmp_path, capsys):
    """Writing out.stl deleted the user's .out.stl.keep.tmp (data loss); ctui's own dead temp goes."""
    from ctui.engine.core.atomic import clean_stale_temps

    keep = tmp_path / ".out.stl.keep.tmp"
    keep.write_text("mine")
    dead = tmp_path / ".out.stl.ab12cd_9.tmp.stl"
    dead.write_text("left by a killed writer")
    os.utime(dead, (1, 1))
    os.utime(keep, (1, 1))
    assert main(["mesh", str(proj["project"]), "--out", str(tmp_path / "out.stl")]) == 0
    assert keep.read_text() == "mine" and not dead.exists()
    assert clean_stale_temps(tmp_path / "out.stl") == 0


def test_output_named_only_an_extension(proj, tmp_path, capsys, monkeypatch):
    """`--out .nii.gz` ended in nibabel's traceback: it is written (a hidden file, as asked)."""
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main(["export", str(proj["project"]), "--format", "nifti", "--out", ".nii.gz"]) == 0
    import nibabel as nib

    assert np.asarray(nib.load(tmp_path / ".nii.gz").dataobj).any()


def test_render_slice_outside_the_series_is_refused(proj, tmp_path, capsys):
    line = _one_line(capsys, ["render", proj["series"], "--out", tmp_path / "r.png", "--slice", "z:1000",
                              "--size", "32x32"])
    assert "outside the series (0..15" in line and not (tmp_path / "r.png").exists()


def test_mesh_refuses_the_projects_own_series_folder(proj, capsys):
    out = proj["series"] / "m.stl"
    assert "inside the input folder" in _one_line(capsys, ["mesh", proj["project"], "--out", out])
    assert not out.exists()


def test_project_whose_source_is_a_fifo_never_blocks(proj, tmp_path, capsys):
    import json
    import zipfile

    fifo = tmp_path / "fifo.dcm"
    os.mkfifo(fifo)
    with zipfile.ZipFile(proj["project"]) as zi:
        members = {n: zi.read(n) for n in zi.namelist()}
    meta = json.loads(members["project.json"])
    meta["source_path"] = str(fifo)
    members["project.json"] = json.dumps(meta).encode()
    p = tmp_path / "fifo.ctui"
    with zipfile.ZipFile(p, "w") as zo:
        for n, b in members.items():
            zo.writestr(n, b)
    for argv in (["export", p, "--format", "dicom-seg", "--out", tmp_path / "x.dcm"],
                 ["measure", p, "--values"]):
        _one_line(capsys, argv)  # (a blocking read would hang the test)


def test_warm_lock_never_follows_a_symlink(tmp_path, monkeypatch):
    from ctui.engine.mesh import jit

    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    lock = tmp_path / "lock"
    lock.symlink_to(victim)
    monkeypatch.setattr(jit, "_LOCK", lock)
    assert jit._take_lock() is False
    assert victim.read_text() == "precious"
    lock.unlink()
    assert jit._take_lock() is True and lock.is_file() and not lock.is_symlink()
    assert jit._take_lock() is False  # fresh: once per 10 minutes


def test_info_never_wraps_unsigned_ct(tmp_path, capsys):
    """Unsigned CT up to 58976 HU: `info` said -5536..0 (the int16 guess wrapped)."""
    import json

    from test_loader_assumptions import _mutate
    from test_privacy import write_series

    def big(ds):
        a = np.zeros((48, 48), np.uint16)
        a[:, :24] = 60000
        ds.PixelRepresentation, ds.PixelData, ds.RescaleIntercept = 0, a.tobytes(), -1024

    s = _mutate(write_series(tmp_path / "u", broken=False), big)
    capsys.readouterr()
    assert main(["info", str(s), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["value_range"] == [-1024, 58976]


def test_dicom_write_error_is_one_line_without_traceback_text(proj, tmp_path, capsys, monkeypatch):
    import pydicom

    def failing(*a, **k):
        raise ValueError("With tag (0010,0010) got exception: bad value\nTraceback (most recent call last):\n  File x")

    monkeypatch.setattr(pydicom, "dcmwrite", failing)
    line = _one_line(capsys, ["export", proj["project"], "--format", "rtstruct", "--out", tmp_path / "x.dcm"])
    assert "With tag (0010,0010) got exception: bad value" in line and "Traceback" not in line


def test_open_with_stdin_closed_is_one_line(proj):
    r = subprocess.run([sys.executable, "-m", "ctui.cli", "open", str(proj["project"])], cwd=ROOT,
                       stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120,
                       env=dict(os.environ, PYTHONPATH=str(ROOT)), preexec_fn=lambda: os.close(0))
    assert r.returncode == 2 and "Traceback" not in r.stderr and "standard input" in r.stderr, r.stderr


def test_library_that_cannot_be_mapped_is_one_line():
    from ctui.cli import error_line

    msg, code = error_line(ImportError("libscipy_openblas.so: failed to map segment from shared object"))
    assert code == 2 and "ulimit" in msg
    assert error_line(ImportError("No module named 'x'")) is None  # a bug stays a traceback


def test_undecodable_file_name_bytes_are_escaped():
    from ctui.engine.core.safetext import printable

    name = b"ser\x9b2J\x1b]0;x\x07".decode("utf-8", "surrogateescape")
    assert printable(name) == "ser\\x9b2J\\x1b]0;x\\x07"


def test_seg_frame_pointing_at_a_missing_segment_is_said(tmp_path):
    """A frame of the dcmqi liver SEG re-pointed at segment 9 (absent) was left out without a word."""
    import pydicom

    from support import shared
    from ctui.engine.io.imports import read_label_file

    src = shared("dcmqi_seg") / "liver.dcm"
    ds = pydicom.dcmread(src)
    ds.PerFrameFunctionalGroupsSequence[1].SegmentIdentificationSequence[0].ReferencedSegmentNumber = 9
    ds.save_as(tmp_path / "liver9.dcm")
    whole, cut = read_label_file(src), read_label_file(tmp_path / "liver9.dcm")
    assert whole.warnings == [] and cut.labels.sum() < whole.labels.sum()
    assert cut.warnings == ["1 frames point at a segment the file does not describe: left out"]
