"""The memory plan (``io/memplan``): each command's estimated peak against the memory it may
use (``--memory``, ``CTUI_MEMORY``, RLIMIT_AS); in memory, from an overview (volume
renders), or refused in one line naming what would fit. A 600-slice series opens, segments
and meshes in a process whose address space is limited, with the same results as without."""

from __future__ import annotations

import gzip
import os
import resource
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from ctui.engine.actions.options import load_options
from ctui.engine.core.errors import CtuiError
from ctui.engine.io import memplan

ROOT = Path(__file__).resolve().parents[3]
MB = 1 << 20


@pytest.mark.parametrize("text,want", [("4G", 4 << 30), ("512M", 512 << 20), ("1.5GB", int(1.5 * (1 << 30))),
                                       ("2GiB", 2 << 30), ("1000", 1000)])
def test_parse_memory(text, want):
    assert memplan.parse_memory(text) == want
    assert load_options(memory=text) == {"memory_limit": want}


@pytest.mark.parametrize("text", ["", "four", "-1G", "0", "1e30T"])
def test_bad_memory_is_one_line_naming_the_option(text):
    with pytest.raises(CtuiError) as exc:
        memplan.parse_memory(text)
    assert exc.value.option == "memory" and "\n" not in str(exc.value)


def test_decide_memory_overview_refuse():
    shape = (2000, 512, 512)  # 1 GB as int16
    sb = 2000 * 512 * 512 * 2
    roomy = memplan.decide("segment", shape, limit=64 << 30)
    assert roomy.mode == "memory" and roomy.need_bytes == memplan.estimate("segment", sb) < 64 << 30
    # fits only with the voxels memory-mapped from the cache (not under an address-space limit)
    cached = memplan.decide("segment", shape, limit=2 << 30, source="memory option")
    assert cached.mode == "cache" and cached.need_bytes == memplan.estimate("segment", sb) - sb <= 2 << 30
    assert cached.cache and "memory-mapped from the cache" in cached.reason
    assert memplan.decide("segment", shape, limit=2 << 30,
                          source="the address-space limit (RLIMIT_AS, less 700 MB the libraries reserve)").mode == "refuse"
    tight = memplan.decide("segment", shape, limit=int(1.2 * (1 << 30)), source="memory option")
    assert tight.mode == "refuse" and tight.need_bytes > 1.2 * (1 << 30)
    assert "downsample=(2, 2, 2)" in tight.reason and "--crop 0," in tight.reason
    zmax = int(tight.fits[-1].split("at most ")[1].split()[0])
    lim = int(1.2 * (1 << 30))
    assert memplan.estimate("segment", zmax * 512 * 512 * 2) <= lim < memplan.estimate("segment", (zmax + 1) * 512 * 512 * 2)
    # a volume render may use an overview; a surface render of the same series may not
    ov = memplan.decide("render", shape, limit=2 << 30, overview=True)
    assert ov.mode == "overview" and ov.downsample == 2 and ov.need_bytes <= 2 << 30
    assert memplan.decide("render", shape, limit=2 << 30).mode == "refuse"


def test_limit_from_env_and_option(monkeypatch):
    monkeypatch.setenv("CTUI_MEMORY", "3G")
    assert memplan.memory_limit() == (3 << 30, "CTUI_MEMORY")
    assert memplan.memory_limit("1G") == (1 << 30, "memory option")


# --------------------------------------------------------------------- whole commands
def _write_nifti(path: Path, nz: int, ny: int, nx: int) -> None:
    """A CT-like int16 series (body, spine column through every slice), streamed slice by slice."""
    import nibabel as nib

    hdr = nib.Nifti1Header()
    hdr.set_data_shape((nx, ny, nz))
    hdr.set_data_dtype(np.int16)
    hdr.set_sform(np.diag([-0.7, -0.7, 1.0, 1.0]), 1)
    hdr["vox_offset"] = 352
    y, x = np.ogrid[:ny, :nx]
    rng = np.random.default_rng(0)
    body = np.where(((x - nx / 2) / (0.42 * nx)) ** 2 + ((y - ny / 2) / (0.33 * ny)) ** 2 <= 1, 40, -1000)
    with (gzip.open(path, "wb", compresslevel=1) if str(path).endswith(".gz") else open(path, "wb")) as fh:
        fh.write(hdr.binaryblock + b"\0" * 4)
        for z in range(nz):
            r = np.hypot(x - nx / 2, y - 0.7 * ny)
            s = np.where(r < 0.05 * nx * (0.8 + 0.1 * np.cos(z / 4.0)), 700, body)
            fh.write((s + rng.integers(-15, 16, size=s.shape)).astype(np.int16).tobytes())


def _ctui(args: list, *, as_limit: int | None = None, env: dict | None = None) -> subprocess.CompletedProcess:
    def limit() -> None:
        if as_limit:
            resource.setrlimit(resource.RLIMIT_AS, (as_limit, as_limit))

    e = {k: v for k, v in os.environ.items() if k != "CTUI_MEMORY"}
    e.update(PYTHONPATH=str(ROOT), CTUI_NO_PROGRESS="1", **(env or {}))
    return subprocess.run([sys.executable, "-m", "ctui.cli", *map(str, args)], cwd=ROOT, env=e, capture_output=True,
                          text=True, preexec_fn=limit, timeout=600, check=False)


@pytest.fixture(scope="module")
def tall(tmp_path_factory):
    d = tmp_path_factory.mktemp("tall")
    _write_nifti(d / "ct.nii.gz", 600, 256, 256)
    yield d / "ct.nii.gz"
    (d / "ct.nii.gz").unlink()


def _labels(project: Path) -> np.ndarray:
    import io

    with zipfile.ZipFile(project) as z:
        return np.load(io.BytesIO(z.read("labels.npy")))


@pytest.mark.slow
def test_tall_series_segments_and_meshes_under_an_address_space_limit(tall, tmp_path):
    seed = ["--seed", "128,179,300", "--range", "200:3000", "--mode", "3d"]
    free = _ctui(["segment", tall, *seed, "--project", tmp_path / "free.ctui"])
    assert free.returncode == 0, free.stderr
    capped = _ctui(["segment", tall, *seed, "--project", tmp_path / "capped.ctui"], as_limit=1600 * MB)
    assert capped.returncode == 0, capped.stderr
    a, b = _labels(tmp_path / "free.ctui"), _labels(tmp_path / "capped.ctui")
    assert a.shape == (600, 256, 256) and a.any() and np.array_equal(a, b)  # bit for bit
    assert np.nonzero(a.any(axis=(1, 2)))[0].tolist() == list(range(600))  # the column: every slice
    for name, lim in (("free", None), ("capped", 1600 * MB)):
        r = _ctui(["mesh", tall, "--iso", "300", "--out", tmp_path / f"{name}.stl"], as_limit=lim)
        assert r.returncode == 0, r.stderr
    assert (tmp_path / "free.stl").read_bytes() == (tmp_path / "capped.stl").read_bytes()


@pytest.mark.slow
def test_too_little_memory_is_refused_in_one_line_naming_what_fits(tall, tmp_path):
    r = _ctui(["segment", tall, "--seed", "128,179,300", "--range", "200:3000", "--mode", "3d", "--memory", "450M",
               "--project", tmp_path / "x.ctui"])  # (500M: it fits with the voxels memory-mapped from the cache)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "450.0 MB is allowed by the memory option" in r.stderr and "--crop 0," in r.stderr
    assert not (tmp_path / "x.ctui").exists()
    r = _ctui(["render", tall, "--mode", "mip", "--out", tmp_path / "m.png"], env={"CTUI_MEMORY": "600M"})
    if r.returncode == 0:  # EGL present: the render ran from an overview and said so
        assert "memory plan: overview" in r.stderr and (tmp_path / "m.png").exists()
    else:
        assert "EGL" in r.stderr or "OpenGL" in r.stderr or "context" in r.stderr, r.stderr


def test_info_json_gives_each_commands_plan(tall):
    import json

    r = _ctui(["info", tall, "--json", "--memory", "300M"])
    assert r.returncode == 0, r.stderr
    plan = json.loads(r.stdout)["memory_plan"]
    assert plan["limit_bytes"] == 300 * MB and plan["limit_source"] == "memory option"
    assert plan["segment"]["mode"] == "refuse" and plan["mesh"]["mode"] in ("memory", "refuse")
    assert plan["segment"]["need_bytes"] == memplan.estimate("segment", 600 * 256 * 256 * 2)


_OPEN = """
import asyncio, sys
from ctui.screens.app import CtuiApp
from ctui.screens.testing import wait_for, wait_workspace

async def main():
    app = CtuiApp(path=sys.argv[1], autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app, timeout=900)
        mv = app.workspace.main_view
        z = app.session.z
        await pilot.press("pageup")
        await wait_for(pilot, lambda: mv.painted[0] is not None and mv.painted[0][0] == z + 1, timeout=60, what="the next slice")
        print(app.session.shape, z, app.session.volume.meta.get("memory_plan", "memory plan: memory"), flush=True)

asyncio.run(main())
"""


@pytest.mark.slow
def test_2000_slices_open_segment_and_mesh_under_4g(tmp_path):
    """Issue 40: a 2,000 x 512 x 512 series (1 GB of int16, written here, removed after) opens in the TUI
    (a slice step painted), segments through every slice and meshes, each in a process under a 4 GB
    address-space limit. (Bit for bit against the in-memory path: the 600-slice test above and test_voxcache.)"""
    ct = tmp_path / "ct2000.nii"
    _write_nifti(ct, 2000, 512, 512)
    env = {"CTUI_CACHE": str(tmp_path / "cache")}
    try:
        opened = subprocess.run([sys.executable, "-c", _OPEN, str(ct)], cwd=ROOT, capture_output=True, text=True,
                                timeout=900, check=False, env=dict(os.environ, PYTHONPATH=str(ROOT), CTUI_NO_PROGRESS="1", **env),
                                preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30)))
        assert opened.returncode == 0, opened.stderr[-2000:]
        assert opened.stdout.startswith("(2000, 512, 512)"), opened.stdout
        seed = ["--seed", "256,358,1000", "--range", "200:3000", "--mode", "3d"]
        seg = _ctui(["segment", ct, *seed, "--project", tmp_path / "big.ctui"], as_limit=4 << 30, env=env)
        assert seg.returncode == 0, seg.stderr
        lab = _labels(tmp_path / "big.ctui")
        assert lab.shape == (2000, 512, 512)
        assert np.nonzero(lab.any(axis=(1, 2)))[0].tolist() == list(range(2000))  # the spine column: every slice
        del lab
        mesh = _ctui(["mesh", ct, "--iso", "300", "--out", tmp_path / "big.stl"], as_limit=4 << 30, env=env)
        assert mesh.returncode == 0, mesh.stderr
        assert (tmp_path / "big.stl").stat().st_size > 10_000
    finally:
        ct.unlink(missing_ok=True)
        shutil.rmtree(tmp_path / "cache", ignore_errors=True)
