"""A 1000 x 512 x 512 series under a 2 GB address-space limit (RLIMIT_AS, as on a small
machine): ``ctui mesh`` either works or stops with one clear line (exit 2), never a
traceback, a MemoryError or a crash by signal.

The raw series is a sparse file (500 MB that take almost no disk): a spheroid in the
middle (a normal surface: must work), or a block of noise (a surface of ~100 M
triangles: must be refused before it is allocated), with the compiled and the
vectorised marching cubes.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from support import ROOT

resource = pytest.importorskip("resource")

SHAPE = (1000, 512, 512)
LIMIT = 2 * 1024 ** 3


def _raw(path, fill) -> str:
    with open(path, "wb") as f:
        f.truncate(int(np.prod(SHAPE)) * 2)
    m = np.memmap(path, dtype=np.int16, mode="r+", shape=SHAPE)
    fill(m)
    m.flush()
    del m
    return str(path)


def _spheroid(m) -> None:
    z, y, x = np.ogrid[-20:20, -60:60, -60:60]
    m[480:520, 196:316, 196:316] = np.where(z ** 2 / 400 + (y ** 2 + x ** 2) / 3600 < 1, 1000, 0).astype(np.int16)


def _noise(m) -> None:
    rng = np.random.default_rng(0)
    for z0 in range(400, 520, 20):
        m[z0: z0 + 20] = rng.integers(0, 600, (20,) + SHAPE[1:]).astype(np.int16)


def _limited_mesh(raw, out, kernels) -> subprocess.CompletedProcess:
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))

    env = dict(os.environ, CTUI_KERNELS=kernels, CTUI_NO_BACKGROUND_COMPILE="1", CTUI_NO_PROGRESS="1")
    env.pop("CTUI_MEMORY_LIMIT", None)
    return subprocess.run([sys.executable, "-m", "ctui.cli", "mesh", raw, "--shape", ",".join(map(str, SHAPE)),
                           "--dtype", "int16", "--iso", "300", "--out", str(out), "--json"],
                          preexec_fn=limit, env=env, cwd=ROOT, capture_output=True, text=True, timeout=600)


def _works_or_says_why(res) -> bool:
    """True when it worked; otherwise asserts a clean one-line refusal."""
    assert res.returncode in (0, 2), (res.returncode, res.stderr[-2000:])  # no signal, no crash
    assert "Traceback" not in res.stderr and "MemoryError" not in res.stderr, res.stderr[-2000:]
    if res.returncode == 2:
        lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("ctui mesh:"), res.stderr
        assert "memory" in lines[0] or "needs" in lines[0], lines[0]
        return False
    return True


@pytest.mark.slow
def test_normal_surface_under_2gb(tmp_path):
    raw = _raw(tmp_path / "big.raw", _spheroid)
    res = _limited_mesh(raw, tmp_path / "s.stl", "auto")
    if _works_or_says_why(res):
        import json

        rep = json.loads(res.stdout)
        assert rep["watertight"]
        analytic_ml = 4 / 3 * np.pi * 20 * 60 * 60 / 1000  # 1 mm voxels
        assert abs(rep["volume_ml"] / analytic_ml - 1) < 0.03


@pytest.mark.slow
@pytest.mark.parametrize("kernels", ["compiled", "numpy"])
def test_huge_surface_refused_before_allocating(tmp_path, kernels):
    raw = _raw(tmp_path / "noise.raw", _noise)
    res = _limited_mesh(raw, tmp_path / "n.stl", kernels)
    assert not _works_or_says_why(res)  # ~100 M triangles cannot fit in 2 GB
    assert not (tmp_path / "n.stl").exists()
