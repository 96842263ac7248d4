"""Every CLI error is ONE line ``ctui CMD: <file>: <fault>`` with a non-zero exit, and
nothing already saved is lost.

Each command is driven with bad input (missing, empty, garbage, truncated files; a
missing or read-only output folder; an output name with an unknown format); the test
checks the exit status (2), that stderr is exactly one line starting with the command
and naming the file, that no traceback appears, and that an output file that existed
before the failed run is byte-identical afterwards (and no temporary file is left).
Read-only folders run in a child with CAP_DAC_OVERRIDE dropped when the tests run as
root (root ignores permission bits), else in-process.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from ctui.cli import main

ROOT = Path(__file__).resolve().parents[2]
SEED = "24,24,8"


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """A small series, its project and mesh, and broken files of each kind."""
    from test_privacy import write_series

    d = tmp_path_factory.mktemp("clierr")
    series = write_series(d / "series", broken=False)
    f = {"series": series, "dir": d}
    assert main(["segment", str(series), "--seed", SEED, "--range", "200:400", "--project", str(d / "p.ctui"),
                 "--mask", str(d / "m.nii.gz")]) == 0
    assert main(["mesh", str(d / "p.ctui"), "--out", str(d / "o.stl")]) == 0
    f.update(project=d / "p.ctui", mask=d / "m.nii.gz", stl=d / "o.stl")
    (d / "empty").mkdir()
    f["empty_dir"] = d / "empty"
    for name, data in {"junk.ctui": os.urandom(3000), "junk.dcm": os.urandom(3000), "empty.stl": b"",
                       "junk.nii.gz": b"\x1f\x8b" + os.urandom(500), "text.csv": b"name,path\nx,/nowhere\n",
                       "junk.mric": os.urandom(200)}.items():
        (d / name).write_bytes(data)
        f[name] = d / name
    stl = f["stl"].read_bytes()
    (d / "cut.stl").write_bytes(stl[: len(stl) // 2])
    f["cut.stl"] = d / "cut.stl"
    pb = f["project"].read_bytes()
    (d / "cut.ctui").write_bytes(pb[: len(pb) // 2])
    f["cut.ctui"] = d / "cut.ctui"
    return f


def _one_line_error(capsys, argv: list, named) -> str:
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    r = capsys.readouterr()
    lines = [ln for ln in r.err.splitlines() if ln.strip()]
    assert rc == 2, (argv, rc, r.err)
    assert len(lines) == 1, (argv, r.err)
    assert lines[0].startswith(f"ctui {argv[0]}: "), lines
    assert "Traceback" not in r.err
    if named is not None:
        assert str(named) in lines[0] or Path(str(named)).name in lines[0], (argv, lines[0])
    return lines[0]


CASES = [  # (command and arguments with {keys} of the files fixture, the file the message must name)
    (["info", "{dir}/missing"], "{dir}/missing"),
    (["info", "{empty_dir}"], "{empty_dir}"),
    (["info", "{junk.dcm}"], "{junk.dcm}"),
    (["info", "{junk.nii.gz}"], "{junk.nii.gz}"),
    (["segment", "{dir}/missing", "--seed", SEED, "--range", "0:1"], "{dir}/missing"),
    (["segment", "{junk.dcm}", "--seed", SEED, "--range", "0:1"], "{junk.dcm}"),
    (["segment", "{series}", "--seed", SEED, "--range", "200:400", "--project", "{dir}/nofolder/p.ctui"],
     "{dir}/nofolder/p.ctui"),
    (["drift", "{dir}/missing.ctui"], "missing.ctui"),
    (["drift", "{junk.ctui}"], "{junk.ctui}"),
    (["drift", "{cut.ctui}"], "{cut.ctui}"),
    (["mesh", "{junk.ctui}", "--out", "{dir}/x.stl"], "{junk.ctui}"),
    (["mesh", "{project}", "--out", "{dir}/x.vtk"], "x.vtk"),
    (["mesh", "{project}", "--out", "{dir}/nofolder/x.stl"], "x.stl"),
    (["mesh", "{junk.mric}", "--out", "{dir}/x.stl"], "{junk.mric}"),
    (["measure", "{dir}/missing.stl"], "missing.stl"),
    (["measure", "{empty.stl}"], "{empty.stl}"),
    (["measure", "{cut.stl}"], "{cut.stl}"),
    (["measure", "{cut.ctui}"], "{cut.ctui}"),
    (["measure", "{junk.nii.gz}"], "{junk.nii.gz}"),
    (["measure", "{project}", "--path", "auto", "--csv", "{dir}/nofolder/s.csv"], "s.csv"),
    (["render", "{dir}/missing.stl", "--out", "{dir}/r.png"], "missing.stl"),
    (["render", "{stl}", "--out", "{dir}/nofolder/r.png"], "r.png"),
    (["render", "{stl}", "--out", "{dir}/r.bmp"], "r.bmp"),
    (["demo", "{junk.dcm}"], "{junk.dcm}"),
    (["export", "{junk.ctui}", "--format", "nifti", "--out", "{dir}/e.nii.gz"], "{junk.ctui}"),
    (["export", "{project}", "--format", "stl", "--out", "{dir}/nofolder/e.stl"], "e.stl"),
    (["batch", "{dir}/missing.csv", "--out", "{dir}/res.csv"], "missing.csv"),
]


def _fill(s: str, f: dict) -> str:
    for k, v in f.items():
        s = s.replace("{" + k + "}", str(v))
    assert "{" not in s, s
    return s


@pytest.mark.parametrize("argv, named", CASES, ids=[" ".join(c[0][:2]).replace("{", "").replace("}", "") + f"-{i}"
                                                     for i, c in enumerate(CASES)])
def test_bad_input_gives_one_line_naming_the_file(capsys, files, argv, named):
    _one_line_error(capsys, [_fill(a, files) for a in argv], _fill(named, files))


def test_failed_runs_keep_what_was_saved(capsys, files, tmp_path):
    """An output that exists keeps its bytes when the run that would replace it fails."""
    keep = {name: tmp_path / name for name in ("p.ctui", "o.stl", "s.csv", "m.nii.gz")}
    for name, p in keep.items():
        shutil.copy(files["project"] if name == "p.ctui" else files["stl"], p)
    before = {n: p.read_bytes() for n, p in keep.items()}
    runs = [
        ["segment", files["junk.dcm"], "--seed", SEED, "--range", "0:1", "--project", keep["p.ctui"], "--mask",
         keep["m.nii.gz"]],
        ["segment", files["series"], "--seed", "999,999,999", "--range", "0:1", "--project", keep["p.ctui"]],
        ["mesh", files["junk.ctui"], "--out", keep["o.stl"]],
        ["measure", files["cut.ctui"], "--path", "auto", "--csv", keep["s.csv"]],
        ["drift", files["cut.ctui"], "--project", keep["p.ctui"]],
    ]
    for argv in runs:
        _one_line_error(capsys, argv, None)
    assert {n: p.read_bytes() for n, p in keep.items()} == before
    assert sorted(os.listdir(tmp_path)) == sorted(keep)  # no temporary file left behind


# --------------------------------------------------------------------- read-only output folder
def _drop_dac_caps() -> None:  # pragma: no cover - runs in the child before exec
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    for cap in (1, 2):  # CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH
        if libc.prctl(24, cap, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


DRIVER = textwrap.dedent(
    """
    import contextlib, io, json, sys
    sys.path[:0] = [sys.argv[1]]
    from ctui.cli import main
    out = []
    for argv in json.loads(sys.argv[2]):
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                rc = main(argv)
            except BaseException as exc:  # a traceback is a failure of the test
                import traceback
                rc = -1
                err.write(traceback.format_exc())
        out.append({"argv": argv, "rc": rc, "err": err.getvalue()})
    print(json.dumps(out))
    """
)


@pytest.mark.slow
def test_read_only_output_folder(files, tmp_path):
    from ctui.engine.render import egl_available

    ro = tmp_path / "ro"
    ro.mkdir()
    (ro / "old.stl").write_bytes(files["stl"].read_bytes())
    f = {k: str(v) for k, v in files.items()}
    runs = [
        ["demo", str(ro / "demo")],
        ["segment", f["series"], "--seed", SEED, "--range", "200:400", "--project", str(ro / "p.ctui")],
        ["segment", f["series"], "--seed", SEED, "--range", "200:400", "--mask", str(ro / "m.nii.gz")],
        ["mesh", f["project"], "--out", str(ro / "old.stl")],
        ["measure", f["project"], "--path", "auto", "--csv", str(ro / "s.csv")],
        ["export", f["project"], "--format", "stl", "--out", str(ro / "e.stl")],
    ]
    if egl_available():
        runs += [["render", f["stl"], "--out", str(ro / "r.png"), "--size", "32x24"],
                 ["render", f["project"], "--flythrough", "auto", "--out", str(ro / "fly"), "--size", "32x24"]]
    before = (ro / "old.stl").read_bytes()
    os.chmod(ro, 0o555)
    try:
        cmd = [sys.executable, "-c", DRIVER, str(ROOT), json.dumps(runs)]
        kw = {"preexec_fn": _drop_dac_caps} if os.geteuid() == 0 else {}
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=ROOT, **kw)
        except (OSError, subprocess.SubprocessError) as exc:
            pytest.skip(f"running as root and cannot drop CAP_DAC_OVERRIDE ({exc})")
    finally:
        os.chmod(ro, 0o755)
    assert r.returncode == 0, r.stderr[-3000:]
    bad = []
    for res in json.loads(r.stdout.strip().splitlines()[-1]):
        lines = [ln for ln in res["err"].splitlines() if ln.strip()]
        ok = res["rc"] == 2 and len(lines) == 1 and str(ro) in lines[0] and "ermission" in lines[0]
        if not ok:
            bad.append(f"ctui {' '.join(res['argv'])} -> {res['rc']}: {res['err'][-400:]}")
    assert not bad, "\n".join(bad)
    assert (ro / "old.stl").read_bytes() == before
    assert sorted(os.listdir(ro)) == ["old.stl"]
