"""Fuzz the ctui commands end to end (engine and rules: tests/fuzz/fuzz_cli.py).

A few hundred mutated inputs (ctui's own projects, NIfTI, NRRD, MRIC, meshes, DICOM,
real files from ../shared/data) go through `ctui info/measure/mesh`, each in a fork
with RLIMIT_AS, 30 s of CPU and a wall-clock alarm: no traceback, no slow run, no
allocation over the cap, no multi-line or unnamed error, no exit-0 wrong result.
``benchmarks/fuzz.py --cases 10000`` is the long run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from fuzz_cli import ROOT, Seed, oracle


def _script_env() -> dict:
    return {**os.environ, "CTUI_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
            "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "CTUI_NO_PROGRESS": "1", "PYTHONHASHSEED": "0"}


@pytest.mark.slow
def test_fuzz_commands(tmp_path):
    """A few hundred mutated inputs through the commands: no traceback, hang, runaway
    allocation, multi-line error or exit-0 wrong result (see the module docstring)."""
    n = int(os.environ.get("CTUI_FUZZ_CLI_CASES", "120"))
    r = subprocess.run([sys.executable, str(Path(__file__).resolve().parent / "fuzz_cli.py"), "--cases", str(n),
                        "--out", str(tmp_path)],
                       capture_output=True, text=True, cwd=ROOT, env=_script_env(), timeout=1800)
    assert r.returncode == 0, r.stderr[-3000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    print(f"fuzz commands: {summary['cases']} cases in {summary['seconds']} s, counts {summary['counts']}")
    assert summary["cases"] == n
    assert summary["counts"]["ok"] + summary["counts"]["error"] == n, summary["findings"][:8]


@pytest.mark.slow
def test_fuzz_round_four_families(tmp_path):
    """Issue 41's families alone (deflate bombs, JPEG-LS frames, enhanced geometry, FIFO sources,
    C1 folder names, resource limits, closed streams, temp races): every seed once unmutated,
    then mutated cases; no finding."""
    n = int(os.environ.get("CTUI_FUZZ_FOUR_CASES", "60"))
    r = subprocess.run([sys.executable, str(Path(__file__).resolve().parent / "fuzz_cli.py"), "--cases", str(n),
                        "--out", str(tmp_path), "--seed", "3"],
                       capture_output=True, text=True, cwd=ROOT, env={**_script_env(), "CTUI_FUZZ_FAMILIES": "four",
                                                                       "CTUI_FUZZ_WALL_S": "60"}, timeout=1800)
    assert r.returncode == 0, r.stderr[-3000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["cases"] == n and len(summary["seeds"]) >= 15
    assert summary["counts"]["ok"] + summary["counts"]["error"] == n, summary["findings"][:8]


def test_oracle_catches_wrong_results(tmp_path):
    """The oracle itself: a shape that contradicts the header, NaN spacing, negative volume."""
    seed = Seed("nrrd", "nrrd", "m.nrrd", {}, ["info", "{dir}/m.nrrd", "--json"])
    (tmp_path / "m.nrrd").write_bytes(b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 5 4 3\nencoding: raw\n\n" + bytes(60))
    ok = {"shape_zyx": [3, 4, 5], "spacing_zyx_mm": [1.0, 1.0, 1.0]}
    assert oracle(seed, tmp_path, json.dumps(ok)) is None
    assert "declares" in oracle(seed, tmp_path, json.dumps({**ok, "shape_zyx": [3, 4, 6]}))
    assert "spacing" in oracle(seed, tmp_path, json.dumps({**ok, "spacing_zyx_mm": [1.0, 0.0, 1.0]}))
    assert "non-finite" in oracle(seed, tmp_path, json.dumps({**ok, "spacing_zyx_mm": [1.0, float("nan"), 1.0]}))
    m = Seed("stl", "stl", "b.stl", {}, ["measure", "{dir}/b.stl", "--json"])
    assert "negative" in oracle(m, tmp_path, json.dumps({"volume_ml": -3.0}))




# --------------------------------------------------------------------- the rules themselves
def _tb(argv):
    raise KeyError("a bug")


def _greedy(argv):
    import numpy as np

    return int(np.ones(6 * 2**30, np.uint8)[-1])  # 6 GiB: over the address-space cap


def _spin(argv):
    while True:
        pass


def _two_lines(argv):
    print("ctui info: x.nrrd: first\nsecond line", file=sys.stderr)
    return 2


def _unnamed(argv):
    print("ctui info: something is wrong", file=sys.stderr)
    return 2


def _polite(argv):
    print(f"ctui info: {argv[1]}: not a label map", file=sys.stderr)
    return 2


@pytest.mark.slow
def test_rules_catch_every_kind_of_failure(tmp_path):
    """run_case classifies a traceback, an allocation over the cap, a CPU hog, a multi-line
    and an unnamed error as findings, and a one-line error naming the file as clean."""
    from fuzz_cli import run_case

    seed = Seed("nrrd", "nrrd", "x.nrrd", {"x.nrrd": b"x"}, ["info", "{dir}/x.nrrd", "--json"])
    kinds = {f.__name__: run_case(seed, b"x", tmp_path / f.__name__, target=f, cpu_s=2).kind
             for f in (_tb, _greedy, _spin, _two_lines, _unnamed, _polite)}
    assert kinds == {"_tb": "traceback", "_greedy": "alloc", "_spin": "slow", "_two_lines": "message",
                     "_unnamed": "message", "_polite": "error"}
