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
    vol = load(series, cache=True)
    ov = voxcache.overview(vol, 2)
    ref = load(series, downsample=(2, 2, 2))
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
