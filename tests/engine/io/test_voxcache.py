"""The memory-mapped voxel cache (``io/voxcache``, issue 40): a series loaded through the cache
equals the in-memory load bit for bit (DICOM, NIfTI); a second load reuses the entry without
decoding again; a changed source makes a new entry; the memory plan chooses the cache when the
series fits only memory-mapped, and the command's result is the in-memory one."""

from __future__ import annotations

import os

import numpy as np
import pytest

from support import cli_streams
from ctui.engine.core.volume import Volume
from ctui.engine.io import memplan, voxcache
from ctui.engine.io.phantom import write_series
from ctui.engine.io.series import load


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CTUI_CACHE", str(tmp_path / "cache"))


def _phantom(nz: int = 14, ny: int = 48, nx: int = 40) -> np.ndarray:
    """A CT-like int16 volume: an ellipsoid of 400 HU in -1000 with noise (known values)."""
    z, y, x = np.ogrid[:nz, :ny, :nx]
    d = np.where(((z - nz / 2) / (0.4 * nz)) ** 2 + ((y - ny / 2) / (0.35 * ny)) ** 2
                 + ((x - nx / 2) / (0.35 * nx)) ** 2 < 1, 400, -1000).astype(np.int16)
    return d + np.random.default_rng(1).integers(-20, 21, d.shape).astype(np.int16)


@pytest.fixture
def series(tmp_path):
    out = tmp_path / "series"
    write_series(out, Volume(data=_phantom(), spacing=(1.5, 0.7, 0.8), origin=(-10.0, 5.0, 2.0), modality="CT"))
    return out


def _same(a: Volume, b: Volume) -> None:
    assert b.data.dtype == a.data.dtype and b.data.shape == a.data.shape
    assert np.array_equal(np.asarray(b.data), a.data)
    assert b.spacing == a.spacing and np.allclose(b.origin, a.origin) and np.array_equal(b.direction, a.direction)
    assert b.modality == a.modality and b.window == a.window


def test_cached_dicom_equals_the_in_memory_load_and_is_reused(series):
    ref = load(series)
    n0 = voxcache.decoded
    first = load(series, cache=True)
    assert voxcache.decoded == n0 + 1 and isinstance(first.data, np.memmap)
    _same(ref, first)
    entry = voxcache.lookup(series, series=None, spacing=None, shape=None, dtype=None, crop=None, downsample=None,
                            offset=None, resample=True)
    assert entry is not None and first.meta["voxel_cache"] == str(entry)
    assert str(entry).startswith(os.environ["CTUI_CACHE"])
    stamp = (entry / "voxels.npy").stat().st_mtime_ns
    second = load(series, cache=True)
    assert voxcache.decoded == n0 + 1  # no second decode
    assert (entry / "voxels.npy").stat().st_mtime_ns == stamp
    _same(ref, second)
    second.data[0, 0, 0] = 1234  # copy-on-write: an edit never reaches the cache file
    assert load(series, cache=True).data[0, 0, 0] == ref.data[0, 0, 0]
    # another crop is another entry, equal to the in-memory crop
    _same(load(series, crop=(2, 9, None, None, 4, 30)), load(series, crop=(2, 9, None, None, 4, 30), cache=True))
    assert voxcache.decoded == n0 + 2
    assert not [p for p in entry.parent.iterdir() if p.name.startswith(".tmp-")]  # written atomically


def test_a_changed_source_is_decoded_again(series):
    load(series, cache=True)
    n0 = voxcache.decoded
    files = sorted(p for p in series.iterdir() if p.is_file())
    changed = _phantom()
    changed[3] += 7
    write_series(series, Volume(data=changed, spacing=(1.5, 0.7, 0.8), origin=(-10.0, 5.0, 2.0), modality="CT"))
    again = load(series, cache=True)
    assert voxcache.decoded == n0 + 1
    _same(load(series), again)
    assert np.array_equal(np.asarray(again.data)[3], np.maximum(changed[3], -1024))
    # only a modification time changes: decoded again too
    st = files[0].stat()
    os.utime(files[0], ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    load(series, cache=True)
    assert voxcache.decoded == n0 + 2


def test_cached_nifti_equals_the_in_memory_load(tmp_path):
    import nibabel as nib

    d = _phantom(9, 30, 26)
    img = nib.Nifti1Image(np.ascontiguousarray(d.transpose(2, 1, 0)), np.diag([-0.9, -0.9, 2.0, 1.0]))
    nib.save(img, tmp_path / "ct.nii.gz")
    ref = load(tmp_path / "ct.nii.gz")
    _same(ref, load(tmp_path / "ct.nii.gz", cache=True))
    assert np.array_equal(ref.data, d)


def test_overview_is_the_strided_load(series):
    ref = load(series, downsample=(2, 2, 2))  # decoded (no entry yet)
    vol = load(series, cache=True)
    ov = voxcache.overview(vol, 2)
    assert np.array_equal(np.asarray(ov.data), ref.data) and ov.spacing == ref.spacing
    assert (voxcache.lookup(series, series=None, spacing=None, shape=None, dtype=None, crop=None, downsample=None,
                            offset=None, resample=True) / "overview2.npy").is_file()


def test_cache_folder_from_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv("CTUI_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert voxcache.cache_root() == tmp_path / "xdg" / "ctui"


def test_plan_chooses_the_cache_and_the_command_gives_the_in_memory_result(series, tmp_path, monkeypatch):
    shape = (14, 48, 40)
    sb = 14 * 48 * 40 * 2
    need = memplan.estimate("mesh", sb)
    monkeypatch.setenv("CTUI_MEMORY", str(need - sb // 2))  # not in memory; memory-mapped it fits
    plan = memplan.plan("mesh", series)
    assert plan.mode == "cache" and plan.shape == shape and plan.cache == os.environ["CTUI_CACHE"]
    n0 = voxcache.decoded
    rc, out, err = cli_streams(["mesh", str(series), "--iso", "0", "--out", str(tmp_path / "cached.stl")])
    assert rc == 0 and "memory plan: cache" in err, err
    assert voxcache.decoded == n0 + 1
    monkeypatch.delenv("CTUI_MEMORY")
    rc, _, err = cli_streams(["mesh", str(series), "--iso", "0", "--out", str(tmp_path / "free.stl")])
    assert rc == 0 and "memory plan" not in err
    assert (tmp_path / "cached.stl").read_bytes() == (tmp_path / "free.stl").read_bytes()
    monkeypatch.setenv("CTUI_MEMORY", str(need - sb // 2))
    rc, out, _ = cli_streams(["info", str(series)])
    assert rc == 0 and "mesh cache" in out


def test_tui_load_goes_through_the_cache_and_says_so(series, monkeypatch):
    from ctui.screens.session import load_volume

    sb = 14 * 48 * 40 * 2
    ref = load(series)
    assert "memory_plan" not in load_volume(str(series)).meta  # in memory: nothing to say
    monkeypatch.setenv("CTUI_MEMORY", str(memplan.estimate("open", sb) - sb // 2))
    vol = load_volume(str(series))
    assert isinstance(vol.data, np.memmap) and np.array_equal(np.asarray(vol.data), ref.data)
    assert vol.meta["memory_plan"].startswith("memory plan: cache: open needs")


def _series_of(tmp_path, name: str, value: int):
    out = tmp_path / name
    data = _phantom()
    data[0, 0, 0] = value  # another series, another entry
    write_series(out, Volume(data=data, spacing=(1.5, 0.7, 0.8), modality="CT"))
    return out


_LOAD = "import sys; from ctui.engine.io.series import load; v = load(sys.argv[1], cache=True); print(v.meta['voxel_cache'])"


def _load_elsewhere(path) -> str:
    """The series loaded through the cache by another process (which then ends): its entry folder."""
    import subprocess
    import sys

    got = subprocess.run([sys.executable, "-c", _LOAD, str(path)], capture_output=True, text=True, timeout=120,
                         env=dict(os.environ))
    assert got.returncode == 0, got.stderr
    return got.stdout.strip()


def test_cache_max_evicts_the_least_recently_used_entries(tmp_path, monkeypatch):
    a, b, c = (_series_of(tmp_path, n, v) for n, v in (("a", 1), ("b", 2), ("c", 3)))
    ea = _load_elsewhere(a)
    eb = _load_elsewhere(b)
    os.utime(os.path.join(ea, "used"), (1_000_000, 1_000_000))  # a: used long ago, b: later
    os.utime(os.path.join(eb, "used"), (2_000_000, 2_000_000))
    size = sum(os.path.getsize(os.path.join(ea, f)) for f in os.listdir(ea))
    monkeypatch.setenv("CTUI_CACHE_MAX", str(int(2.5 * size)))  # room for two entries
    assert voxcache.max_bytes() == int(2.5 * size)
    ec = _load_elsewhere(c)  # a third entry: the least recently used one (a) goes
    assert not os.path.exists(ea) and os.path.isdir(eb) and os.path.isdir(ec)
    assert not [n for n in os.listdir(os.path.dirname(ea)) if n.startswith(".")]  # nothing left half-removed
    again = load(a, cache=True)  # an evicted series is decoded again, bit for bit
    assert np.array_equal(np.asarray(again.data), load(a).data)
    monkeypatch.setenv("CTUI_CACHE_MAX", "1M")
    assert voxcache.max_bytes() == 1 << 20


def test_eviction_skips_an_entry_another_process_has_open(tmp_path):
    import subprocess
    import sys

    a, b = _series_of(tmp_path, "a", 1), _series_of(tmp_path, "b", 2)
    ea = _load_elsewhere(a)
    hold = ("import sys; from ctui.engine.io.series import load; import numpy as np; v = load(sys.argv[1], cache=True); "
            "print(v.meta['voxel_cache'], flush=True); sys.stdin.readline(); print(int(np.asarray(v.data).sum()))")
    p = subprocess.Popen([sys.executable, "-c", hold, str(b)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                         env=dict(os.environ))
    try:
        eb = p.stdout.readline().strip()  # type: ignore[union-attr]
        assert os.path.isdir(eb)
        removed = voxcache.evict(limit=1)  # everything over the cap: only the entry nobody holds goes
        assert removed == [os.path.basename(ea)] and not os.path.exists(ea) and os.path.isdir(eb)
        out, _ = p.communicate("\n", timeout=60)
    finally:
        p.kill() if p.poll() is None else None
    assert int(out.strip()) == int(load(b).data.sum())  # the holder still read its voxels
    assert voxcache.evict(limit=1) == [os.path.basename(eb)]  # released: now it goes too


@pytest.mark.parametrize("f", [2, 4])
def test_a_downsampled_load_of_a_cached_series_reads_its_overview(series, f):
    """A render from a 2x/4x overview (the memory plan's "overview": ``downsample=(f, f, f)``) of a series
    another command cached reads the entry's overview file: no decode, and no read of the full voxels
    once the overview exists; the same voxels and geometry as the decoded downsampled load."""
    ref = load(series, downsample=(f, f, f))
    load(series, cache=True)
    n0 = voxcache.decoded
    got = load(series, downsample=(f, f, f))
    assert voxcache.decoded == n0 and got.meta["overview"] == f
    _same(ref, got)
    entry = voxcache.lookup(series, series=None, spacing=None, shape=None, dtype=None, crop=None, downsample=None,
                            offset=None, resample=True)
    full = np.load(entry / "voxels.npy", mmap_mode="r+")
    full[:] = 0  # the full-resolution voxels spoiled: a later downsampled load still has the right ones
    full.flush()
    del full
    _same(ref, load(series, downsample=(f, f, f)))
    assert "overview" not in load(series, downsample=(f, f, 1)).meta  # not a uniform overview: decoded as before
