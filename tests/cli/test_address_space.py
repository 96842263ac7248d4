"""``ulimit -v`` between 450 and 800 MB (issue 41): every command on the small sample either works or ends in one
line (non-zero exit), never in native code (a segfault or abort in a library's loader, OpenBLAS retrying its
buffer forever, a MemoryError traceback).

Before: ``ctui demo`` and ``ctui measure/export/mesh PROJECT`` died by SIGSEGV at 450-650 MB (OpenCV's BLAS
loading), hung at 550-700 MB (scipy's BLAS retrying a 32 MB buffer) or printed OpenBLAS's own error. Now the CLI
maps less under a limit (:func:`ctui.engine.core.limits.fit_address_space`) and refuses a command whose libraries
need more (:data:`ctui.engine.core.limits.AS_FLOOR_MB`), saying what ``ulimit -v`` it needs.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from support import ROOT, SAMPLE_DATA

resource = pytest.importorskip("resource")


def _limited(args: list[str], limit_kb: int, cwd) -> subprocess.CompletedProcess:
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit_kb * 1024, limit_kb * 1024))

    env = dict(os.environ, CTUI_NO_BACKGROUND_COMPILE="1", CTUI_NO_PROGRESS="1", PYTHONPATH=str(ROOT))
    for k in ("CTUI_MEMORY_LIMIT", "OPENBLAS_NUM_THREADS", "MALLOC_ARENA_MAX"):
        env.pop(k, None)
    return subprocess.run([sys.executable, "-m", "ctui.cli", *args], preexec_fn=limit, env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=180)


def _works_or_one_line(res: subprocess.CompletedProcess, what: str) -> None:
    assert res.returncode >= 0, f"{what}: killed by {signal.Signals(-res.returncode).name}"
    assert res.returncode not in (128 + signal.SIGSEGV, 128 + signal.SIGABRT), f"{what}: {res.returncode}"
    if res.returncode == 0:
        return
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ctui "), f"{what}: rc {res.returncode}\n{res.stderr[-1500:]}"
    assert "Traceback" not in res.stderr and "OpenBLAS" not in res.stderr


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    d = tmp_path_factory.mktemp("as")
    res = subprocess.run([sys.executable, "-m", "ctui.cli", "segment", str(SAMPLE_DATA / "phantom"), "--seed", "94,81,30",
                          "--project", str(d / "p.ctui")], cwd=ROOT, capture_output=True, text=True, timeout=300,
                         env=dict(os.environ, CTUI_NO_PROGRESS="1", PYTHONPATH=str(ROOT)))
    assert res.returncode == 0, res.stderr
    return d / "p.ctui"


@pytest.mark.slow
@pytest.mark.parametrize("limit_kb", [450_000, 550_000, 650_000, 800_000])
def test_commands_under_an_address_space_limit(limit_kb, project, tmp_path):
    series = str(SAMPLE_DATA / "phantom")
    runs = {
        "info": ["info", series],
        "segment": ["segment", series, "--seed", "94,81,30"],
        "mesh": ["mesh", series, "--iso", "300", "--out", str(tmp_path / "m.stl")],
        "render": ["render", series, "--out", str(tmp_path / "r.png")],
        "measure project": ["measure", str(project)],
        "mesh project": ["mesh", str(project), "--out", str(tmp_path / "p.stl")],
        "export project": ["export", str(project), "--format", "stl", "--out", str(tmp_path / "e.stl")],
        "demo": ["demo", str(tmp_path / "demo")],
    }
    for what, args in runs.items():
        _works_or_one_line(_limited(args, limit_kb, tmp_path), f"{what} at ulimit -v {limit_kb}")


def test_a_too_small_limit_says_what_is_needed(project, tmp_path):
    from ctui.engine.core.limits import AS_FLOOR_MB

    res = _limited(["measure", str(project)], 400_000, tmp_path)
    assert res.returncode == 2
    line = res.stderr.strip()
    assert len(line.splitlines()) == 1 and f"ulimit -v {AS_FLOOR_MB['measure'] * 1024}" in line, line
