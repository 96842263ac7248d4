"""Hostile files and options, round three (issue 26): one regression case per defect the
outside campaign found. Each drives the command (or the reader) with the hostile input
and checks the real outcome: a one-line error naming the file, or the right result,
and never a renamed device, a hang, a runaway allocation or a control character on the
terminal."""

from __future__ import annotations

import gzip
import json
import os
import stat
from pathlib import Path

import numpy as np
import pytest

from ctui.cli import main

SEED = "24,24,8"


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    from test_privacy import write_series

    d = tmp_path_factory.mktemp("hostile3")
    series = write_series(d / "series", broken=False, description="evil\x1b]52;c;ZXZpbA==\x07\x1b[2J desc")
    assert main(["segment", str(series), "--seed", SEED, "--range", "200:400", "--project", str(d / "p.ctui")]) == 0
    return {"dir": d, "series": series, "project": d / "p.ctui"}


def _err(capsys, argv: list) -> str:
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and lines[0].startswith(f"ctui {argv[0]}: "), (rc, err, out)
    return lines[0]


# ----------------------------------------------------------------- 1: non-regular outputs
def test_outputs_never_replace_devices_fifos_or_links_to_them(files, capsys, tmp_path):
    """`--plot /dev/null`, a FIFO, a symlink to a device: refused in one line, the
    node left as it was; a symlink to a regular file is written through (link kept)."""
    fifo = tmp_path / "fifo.png"
    os.mkfifo(fifo)
    link = tmp_path / "null.csv"  # (a link to /proc/self/fd/1 is a link to whatever fd 1 is under pytest)
    link.symlink_to("/dev/null")
    assert "character device" in _err(capsys, ["drift", files["project"], "--plot", "/dev/null"])
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    assert "FIFO" in _err(capsys, ["drift", files["project"], "--plot", fifo])
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert "symbolic link" in _err(capsys, ["measure", files["project"], "--path", "auto", "--csv", link])
    assert link.is_symlink()
    real = tmp_path / "real.csv"
    real.write_text("old")
    (tmp_path / "via.csv").symlink_to(real)
    assert main(["measure", str(files["project"]), "--path", "auto", "--csv", str(tmp_path / "via.csv")]) == 0
    assert (tmp_path / "via.csv").is_symlink() and real.read_text() != "old" and "," in real.read_text()


# ----------------------------------------------------------------- 2: NRRD detached / inflating data
NRRD_HDR = ("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 10 8 12\nspace: left-posterior-superior\n"
            "space directions: (1,0,0) (0,1,0) (0,0,2)\n")


@pytest.mark.parametrize("case", ["dev-zero", "fifo", "bomb", "line-skip"])
def test_nrrd_data_is_read_with_bounds(case, capsys, tmp_path):
    """/dev/zero or a FIFO as the data file, a gzip stream inflating past the declared 960
    voxels, line skip 99999999: one line each, no hang, no runaway allocation."""
    if case == "dev-zero":
        p = tmp_path / "z.nhdr"
        p.write_text(NRRD_HDR + "encoding: gzip\ndata file: /dev/zero\n\n")
    elif case == "fifo":
        os.mkfifo(tmp_path / "pipe")
        p = tmp_path / "f.nhdr"
        p.write_text(NRRD_HDR + "encoding: raw\nline skip: 1\ndata file: pipe\n\n")
    elif case == "bomb":
        p = tmp_path / "b.nrrd"
        p.write_bytes((NRRD_HDR + "encoding: gzip\n\n").encode() + gzip.compress(bytes(20_000_000)))
    else:
        p = tmp_path / "s.nrrd"
        p.write_bytes((NRRD_HDR + "encoding: raw\nline skip: 99999999\n\n").encode() + bytes(1000))
    line = _err(capsys, ["info", p, "--json"])
    assert p.name in line


def test_nrrd_gzip_ascii_and_line_skip_still_read(tmp_path):
    """The bounded reader gives pynrrd's voxels for gzip, ascii and line-skip files."""
    import nrrd

    from ctui.engine.io.series import load

    vals = (np.arange(960) * 7 % 256).astype(np.uint8)
    cases = {"g.nrrd": (NRRD_HDR + "encoding: gzip\n\n").encode() + gzip.compress(vals.tobytes()),
             "a.nrrd": (NRRD_HDR + "encoding: ascii\n\n").encode() + " ".join(map(str, vals)).encode(),
             "l.nrrd": (NRRD_HDR + "encoding: raw\nline skip: 2\n\n").encode() + b"x\ny\n" + vals.tobytes()}
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        ref, _ = nrrd.read(str(tmp_path / name), index_order="C")
        got = load(tmp_path / name)
        assert got.shape == (12, 8, 10) and np.array_equal(got.data, ref), name


# ----------------------------------------------------------------- 3, 18: DICOM-SEG frame counts
@pytest.mark.parametrize("frames", [2**31 - 1, 1])
def test_seg_number_of_frames_checked_before_highdicom(frames, capsys, tmp_path):
    """NumberOfFrames 2**31-1 (or 1 for 3 frames) in the dcmqi liver SEG: refused in one line."""
    from conftest import shared
    import pydicom

    src = shared("dcmqi_seg/liver.dcm")
    ds = pydicom.dcmread(str(src))
    ds.NumberOfFrames = frames
    p = tmp_path / "seg.dcm"
    ds.save_as(str(p))
    line = _err(capsys, ["measure", p, "--json", "--no-mesh"])
    assert "NumberOfFrames" in line and "seg.dcm" in line


# ----------------------------------------------------------------- 4: terminal escapes
def test_text_from_files_cannot_drive_the_terminal(files, capsys):
    """A SeriesDescription holding OSC 52 and ESC[2J is printed escaped by `ctui info`."""
    capsys.readouterr()
    assert main(["info", str(files["series"])]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\x07" not in out
    assert "evil\\x1b]52;c;ZXZpbA==\\x07\\x1b[2J desc" in out


def test_printable_and_csv_cell():
    from ctui.engine.core.safetext import csv_cell, printable

    assert printable("a\x1b[2Jb\x9b\u202e\n") == "a\\x1b[2Jb\\x9b\\u202e\\x0a"
    assert printable("l1\nl2\tx", keep_newlines=True) == "l1\nl2\tx"
    assert [csv_cell(v) for v in ("=HYPERLINK(1)", "@SUM(A1)", "+1+2", "-x", "-1.5", "kidney", 3.0)] == \
        ["'=HYPERLINK(1)", "'@SUM(A1)", "'+1+2", "'-x", "-1.5", "kidney", 3.0]


# ----------------------------------------------------------------- 5, 13: numeric options
@pytest.mark.parametrize("spec", ["clahe:tiles=0", "clahe:tiles=100000", "gaussian:sigma=nan", "gaussian:sigma=1e308",
                                  "erode:iterations=100000", "opening:size=1e21"])
def test_filter_parameters_are_bounded(spec, files, capsys):
    """`--filter clahe:tiles=0` killed the process with SIGFPE inside OpenCV; the others
    raised or ran for minutes: all refused in one line naming the parameter."""
    line = _err(capsys, ["segment", files["series"], "--seed", SEED, "--range", "200:400", "--filter", spec])
    assert spec.split(":")[1].split("=")[0] in line
