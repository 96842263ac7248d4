"""Outputs never destroy inputs, and output streams fail cleanly.

- :func:`check_output` refuses an output that is an input: the same path, a symlink
  to it, a hard link to it, or a file inside an input folder (a series folder).
- Every writing command calls it first: ``ctui measure P.ctui --csv P.ctui`` and
  friends exit 2 with one line naming both files, and the input is byte-identical.
- ``ctui info ... --json | head`` (stdout closed early) exits quietly: no traceback.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from ctui.cli import main
from ctui.engine.core.atomic import check_output, check_outputs
from ctui.engine.core.errors import CtuiError

ROOT = Path(__file__).resolve().parents[2]
SEED = "24,24,8"  # x,y,z of the ball in test_privacy.write_series


# --------------------------------------------------------------------- check_output
def test_same_file_symlink_hardlink_and_folder_are_refused(tmp_path):
    src = tmp_path / "in.ctui"
    src.write_bytes(b"project")
    (tmp_path / "sym.ctui").symlink_to(src)
    os.link(src, tmp_path / "hard.ctui")
    series = tmp_path / "series"
    (series / "sub").mkdir(parents=True)
    (tmp_path / "serieslink").symlink_to(series)
    for out in (src, tmp_path / "sym.ctui", tmp_path / "hard.ctui", tmp_path / "." / "in.ctui"):
        with pytest.raises(CtuiError) as err:
            check_output(out, inputs=[src], label="--csv")
        msg = str(err.value)
        assert "\n" not in msg and str(out) in msg and str(src) in msg and "--csv" in msg
    for out in (series / "new.nii.gz", series / "sub" / "x.png", tmp_path / "serieslink" / "m.stl", series):
        with pytest.raises(CtuiError, match="input folder"):
            check_output(out, inputs=[series])
    # the symlinked folder given as the input, the real folder as the output
    with pytest.raises(CtuiError, match="inside the input folder"):
        check_output(series / "x.nrrd", inputs=[tmp_path / "serieslink"])


def test_other_outputs_are_accepted(tmp_path):
    src = tmp_path / "in.ctui"
    src.write_bytes(b"project")
    series = tmp_path / "series"
    series.mkdir()
    check_output(tmp_path / "out.csv", inputs=[src, series, None, [tmp_path / "missing"]])
    check_output(tmp_path / "in.ctui.csv", inputs=[src])
    check_output(tmp_path / "seriesX" / "a.png", inputs=[series])  # a name prefix is not a folder
    check_output(None, inputs=[src])
    check_outputs({"--mask": tmp_path / "m.nii.gz", "--project": tmp_path / "p.ctui"}, inputs=[series])


def test_two_outputs_onto_one_file_are_refused(tmp_path):
    with pytest.raises(CtuiError, match="same file"):
        check_outputs({"--project": tmp_path / "x.ctui", "--mask": tmp_path / "." / "x.ctui"}, inputs=[])


# --------------------------------------------------------------------- the commands
@pytest.fixture(scope="module")
def series(tmp_path_factory) -> Path:
    from test_privacy import write_series

    return write_series(tmp_path_factory.mktemp("outputs") / "series", broken=False)


@pytest.fixture(scope="module")
def project(series, tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("proj") / "p.ctui"
    assert main(["segment", str(series), "--seed", SEED, "--range", "200:400", "--project", str(p)]) == 0
    return p


def _refused(capsys, argv, *names):
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2, (argv, rc, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for n in names:
        assert str(n) in lines[0], (n, lines[0])
    return lines[0]


def test_commands_refuse_to_overwrite_their_input(capsys, series, project, tmp_path):
    before = project.read_bytes()
    series_files = sorted(os.listdir(series))
    link = tmp_path / "link.ctui"
    link.symlink_to(project)
    hard = tmp_path / "hard.ctui"
    os.link(project, hard)
    stl = tmp_path / "p.stl"  # a mesh name that is a symlink to the project
    stl.symlink_to(project)
    cases = [
        (["measure", project, "--path", "auto", "--csv", project], project),
        (["measure", project, "--path", "auto", "--plot", hard], hard),
        (["measure", link, "--path", "auto", "--csv", project], project),
        (["drift", project, "--plot", link], link),
        (["drift", project, "--project", hard], hard),
        (["mesh", project, "--out", stl], stl),
        (["segment", series, "--seed", SEED, "--range", "200:400", "--mask", series / "m.nii.gz"], series / "m.nii.gz"),
        (["segment", series, "--seed", SEED, "--range", "200:400", "--project", series / "p.ctui"], series / "p.ctui"),
        (["segment", series, "--seed", SEED, "--range", "200:400", "--project", series / "slice000.dcm"], series),
        (["drift", series, "--seed", SEED, "--range", "200:400", "--plot", series / "d.png"], series),
        (["render", series, "--mode", "mip", "--out", series / "mip.png"], series),
    ]
    for argv, named in cases:
        _refused(capsys, argv, named)
    assert project.read_bytes() == before
    assert sorted(os.listdir(series)) == series_files
    _refused(capsys, ["segment", series, "--seed", SEED, "--range", "200:400", "--project", tmp_path / "x.ctui",
                      "--mask", tmp_path / "x.ctui"], "same file")
    assert not (tmp_path / "x.ctui").exists()


def test_closed_stdout_pipe_exits_quietly(series):
    """`ctui info --json | head`: the reader is gone before ctui writes (EPIPE)."""
    r, w = os.pipe()
    os.close(r)
    try:
        proc = subprocess.run([sys.executable, "-m", "ctui", "info", str(series), "--json"], stdout=w,
                              stderr=subprocess.PIPE, text=True, cwd=ROOT, timeout=120)
    finally:
        os.close(w)
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr, proc.stderr
    assert proc.returncode == 141, (proc.returncode, proc.stderr)
