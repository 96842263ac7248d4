"""Disk full, file too large, permission denied and read-only folders: every writer
must raise one clear CtuiError naming the file, leave the previous file intact and no
partial/temporary file behind, and leave the in-memory data unchanged.

Disk full uses a 256 KiB tmpfs (needs root to mount; skipped with the reason
otherwise) and, everywhere, RLIMIT_FSIZE in a subprocess (EFBIG). Permission denied
runs the writers on a 0o555 folder, in a subprocess (root ignores
permission bits) with CAP_DAC_OVERRIDE dropped when running as root, else in-process
on a 0o555 folder. Read-only uses a tmpfs remounted
read-only (root) or is skipped.
"""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from ctui.engine.core.errors import CtuiError

ROOT = Path(__file__).resolve().parents[3]


def _writers():
    """name -> (file name, save(path, big: bool, data), load(path) -> marker, data factory)."""
    from ctui.engine.core.atomic import write_text
    from ctui.engine.io.labels import load_labels, save_labels
    from ctui.engine.io.mric import read_mric, write_mric
    from ctui.engine.io.project import Project, load_project, save_project
    from ctui.engine.core.volume import Volume

    rng = np.random.default_rng(0)

    def labels(big):
        shape = (40, 128, 128) if big else (2, 4, 4)
        return rng.integers(0, 11, shape).astype(np.uint8)  # random: does not compress

    w = {}

    def proj_data(big):
        return Project(source_path="s", labels=labels(big), meta={"big": big}, objects=[{"id": 1, "seeds": [[1, 2, 3]]}])

    w["project"] = ("p.ctui", lambda p, d: save_project(p, d), lambda p: load_project(p).meta["big"], proj_data)

    def mric_data(big):
        n = 400 if big else 1
        return {"slices": [[[rng.integers(0, 100, (200, 2))]] for _ in range(n)], "big": big}

    w["mric"] = (
        "c.mric",
        lambda p, d: write_mric(p, d["slices"], width=100, height=100, axis=(int(d["big"]), 0)),
        lambda p: bool(read_mric(p).axis[0]),
        mric_data,
    )
    for ext in ("nii.gz", "nrrd", "seg.nrrd"):
        w[ext] = (
            f"l.{ext}",
            lambda p, d: save_labels(p, d, Volume(data=d, window=(1, 1))),
            lambda p: load_labels(p)[0].size > 32,
            labels,
        )
    w["json"] = ("r.json", lambda p, d: write_text(p, json.dumps(d)), lambda p: json.loads(Path(p).read_text())["big"], lambda big: {"big": big, "x": list(range(200000 if big else 1))})
    try:
        from ctui.engine.render.outputs import save_png

        def png_load(p):
            from PIL import Image

            with Image.open(p) as im:
                return im.size[0] > 10

        w["png"] = ("i.png", lambda p, d: save_png(p, d), png_load, lambda big: rng.integers(0, 256, (600, 600, 3) if big else (4, 4, 3)).astype(np.uint8))
    except ImportError:
        pass
    try:
        from ctui.engine.core.meshdata import Mesh
        from ctui.engine.io.meshes import load_mesh, save_mesh

        def mesh(big):
            import trimesh

            s = trimesh.creation.icosphere(subdivisions=5 if big else 1)
            return Mesh(vertices=np.asarray(s.vertices, float), faces=np.asarray(s.faces))

        for ext in ("stl", "ply", "obj"):
            w["mesh." + ext] = (f"m.{ext}", lambda p, d: save_mesh(p, d), lambda p: len(load_mesh(p).faces) > 100, mesh)
    except ImportError:
        pass
    return w


def _equal(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b)
    if hasattr(a, "vertices") and hasattr(a, "faces"):
        return np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b))
    return a == b


def _check_failure(folder: Path, name: str, writer, *, expect_previous: bool) -> str:
    fname, save, load, make = writer
    target = folder / fname
    big = make(True)
    keep = copy.deepcopy(big)
    with pytest.raises(CtuiError) as err:
        save(target, big)
    msg = str(err.value)
    assert "\n" not in msg and fname in msg, (name, msg)
    assert _equal(big, keep), f"{name}: in-memory data changed by a failed save"
    if expect_previous:
        assert load(target) is False, f"{name}: previous version not intact"
    else:
        assert not target.exists()
    leftovers = [f for f in os.listdir(folder) if f.startswith(f".{fname}.")]
    assert leftovers == [], (name, leftovers)
    return msg


def _mount_tmpfs(path: Path, size: str) -> bool:
    if os.geteuid() != 0:
        return False
    path.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True)
    return r.returncode == 0


def _umount(path: Path) -> None:
    subprocess.run(["umount", "-l", str(path)], capture_output=True)


@pytest.fixture
def small_fs(tmp_path):
    mnt = tmp_path / "small"
    if not _mount_tmpfs(mnt, "1m"):
        pytest.skip("cannot mount a size-limited tmpfs (needs root and mount permission); the RLIMIT_FSIZE test covers disk-full")
    yield mnt
    _umount(mnt)


def _fill(folder: Path) -> None:
    """Fill the file system, leaving about 16 KiB."""
    st = os.statvfs(folder)
    free = st.f_bavail * st.f_frsize
    with open(folder / "filler", "wb") as fh:
        try:
            fh.write(b"\0" * max(free - 16 * 1024, 0))
        except OSError:
            pass


@pytest.mark.slow
def test_disk_full_tmpfs(small_fs):
    writers = _writers()
    for name, w in writers.items():
        fname, save, load, make = w
        save(small_fs / fname, make(False))  # a small previous version
        assert load(small_fs / fname) is False
    _fill(small_fs)
    msgs = {name: _check_failure(small_fs, name, w, expect_previous=True) for name, w in writers.items()}
    assert all("space" in m.lower() or "cannot write" in m for m in msgs.values()), msgs


@pytest.mark.slow
def test_file_too_large_rlimit(tmp_path):
    """RLIMIT_FSIZE (EFBIG) in a subprocess: works without root."""
    script = textwrap.dedent(
        f"""
        import json, os, resource, sys
        sys.path[:0] = {[str(Path(__file__).resolve().parent), str(ROOT / 'tests')]!r}; sys.path.insert(0, {str(ROOT)!r})
        import test_disk_errors as t
        from pathlib import Path
        folder = Path(sys.argv[1])
        ws = t._writers()
        for name, w in ws.items():
            w[1](folder / w[0], w[3](False))
        resource.setrlimit(resource.RLIMIT_FSIZE, (64 * 1024, 64 * 1024))
        out = {{}}
        for name, w in ws.items():
            try:
                out[name] = t._check_failure(folder, name, w, expect_previous=True)
            except BaseException as exc:
                out[name] = "FAILED: " + type(exc).__name__ + ": " + str(exc)
        print(json.dumps(out))
        """
    )
    r = subprocess.run([sys.executable, "-c", script, str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    bad = {k: v for k, v in out.items() if v.startswith("FAILED")}
    assert not bad, bad
    assert {"project", "mric", "nii.gz", "nrrd", "seg.nrrd", "json"} <= set(out)


def _drop_dac_caps() -> None:  # pragma: no cover - runs in the child before exec
    """Drop CAP_DAC_OVERRIDE / CAP_DAC_READ_SEARCH from the bounding set, so root
    obeys permission bits after exec (prctl PR_CAPBSET_DROP)."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    for cap in (1, 2):
        if libc.prctl(24, cap, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


def _as_unprivileged(script: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", script, *args],
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=_drop_dac_caps,
    )


def _permission_script() -> str:
    return textwrap.dedent(
        f"""
        import json, sys
        sys.path[:0] = {[str(Path(__file__).resolve().parent), str(ROOT / 'tests')]!r}; sys.path.insert(0, {str(ROOT)!r})
        import test_disk_errors as t
        from pathlib import Path
        folder = Path(sys.argv[1]); expect_previous = sys.argv[2] == "1"
        out = {{}}
        for name, w in t._writers().items():
            try:
                out[name] = t._check_failure(folder, name, w, expect_previous=expect_previous)
            except BaseException as exc:
                out[name] = "FAILED: " + type(exc).__name__ + ": " + str(exc)
        print(json.dumps(out))
        """
    )


@pytest.mark.slow
def test_permission_denied(tmp_path):
    folder = tmp_path / "locked"
    folder.mkdir()
    writers = _writers()
    for name, (fname, save, load, make) in writers.items():
        save(folder / fname, make(False))
    os.chmod(folder, 0o555)
    try:
        if os.geteuid() == 0:
            try:
                r = _as_unprivileged(_permission_script(), str(folder), "1")
            except (OSError, subprocess.SubprocessError) as exc:
                pytest.skip(f"running as root and cannot drop CAP_DAC_OVERRIDE ({exc}): root ignores permission bits")
            assert r.returncode == 0, r.stderr[-3000:]
            out = json.loads(r.stdout.strip().splitlines()[-1])
        else:
            out = {name: _check_failure(folder, name, w, expect_previous=True) for name, w in writers.items()}
    finally:
        os.chmod(folder, 0o755)
    bad = {k: v for k, v in out.items() if v.startswith("FAILED")}
    assert not bad, bad
    assert all("ermission" in v for v in out.values()), out


def test_read_only_folder(tmp_path):
    mnt = tmp_path / "ro"
    if not _mount_tmpfs(mnt, "4m"):
        pytest.skip("cannot mount a tmpfs to remount read-only (needs root and mount permission)")
    try:
        writers = _writers()
        for name, (fname, save, load, make) in writers.items():
            save(mnt / fname, make(False))
        r = subprocess.run(["mount", "-o", "remount,ro", str(mnt)], capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot remount read-only: {r.stderr.strip()}")
        msgs = {name: _check_failure(mnt, name, w, expect_previous=True) for name, w in writers.items()}
        assert all("read-only" in m.lower() for m in msgs.values()), msgs
    finally:
        _umount(mnt)
