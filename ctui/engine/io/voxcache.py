"""The memory-mapped voxel cache (issue 40): a series that does not fit in memory is decoded
once, slice by slice, straight into a ``.npy`` file in a cache folder and used from there as a
memory map (the pages are file-backed: the kernel drops and re-reads them instead of running
out of memory), together with 2x/4x overviews for navigation, MIP and DVR.

* The cache folder: ``CTUI_CACHE``, else ``$XDG_CACHE_HOME/ctui``, else ``~/.cache/ctui``; the
  voxels of one series in ``voxels/<key>/`` (``voxels.npy``, ``volume.pkl``: the Volume less
  its voxels, ``overview2.npy``, ``overview4.npy``).
* ``<key>``: a SHA-256 of the series' files (path, size, modification time in ns) and the load
  options, so a changed, added or removed file, or another crop, makes another key; an entry
  whose files changed is never found again (stale entries are left for the user to delete).
* Written atomically: into ``voxels/.tmp-<key>-<pid>/``, then renamed to ``voxels/<key>/`` (a
  process that loses the race to another uses the other's entry).
* Bounded: after an entry is written, the least recently used entries are removed until the
  cache holds at most ``CTUI_CACHE_MAX`` (``4G``, ``512M`` or bytes; default 8G; 0: no limit).
  An entry a process has open holds a shared ``flock`` on its ``lock`` file and is never
  removed; one that is free is renamed away first (atomic: another process either opens it
  whole or decodes again) and then deleted. Each open marks an entry used (``used``'s time).
* The voxels are what :func:`ctui.engine.io.series.load` gives (int16 HU for CT), bit for bit;
  the map is copy-on-write (``mmap_mode="c"``): an edit of the array never reaches the file.

:func:`load_cached` is what ``load(..., cache=True)`` runs; :func:`lookup` says whether an entry
exists (``decoded``: how many times this process decoded a series into the cache, for tests).
"""

from __future__ import annotations

import contextlib
import copy
import fcntl
import glob
import hashlib
import os
import pickle
import shutil
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from ctui.engine.core.limits import parse_memory
from ctui.engine.core.volume import Volume
from ctui.engine.io.series._common import ALLOCATOR

FORMAT = 1  # bump when the entry's layout changes
DEFAULT_MAX = 8 << 30  # CTUI_CACHE_MAX when unset: the cache's size cap (bytes)
decoded = 0  # series decoded into the cache by this process (tests count re-decodes)
_SLAB = 16  # slices copied at a time (overviews, a loader that returned another array)


def cache_root() -> Path:
    """The cache folder: ``CTUI_CACHE``, ``$XDG_CACHE_HOME/ctui`` or ``~/.cache/ctui``."""
    env = os.environ.get("CTUI_CACHE", "").strip()
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
    return (Path(xdg).expanduser() if xdg else Path.home() / ".cache") / "ctui"


def disk_free() -> int:
    """Bytes free where the cache folder is (or would be made); 0 when unknown."""
    p = cache_root()
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        return shutil.disk_usage(p).free
    except OSError:
        return 0


def _files(path: Any) -> list[str]:
    """Every file the loader may read for ``path`` (a folder walked, a list, a glob, a file)."""
    paths = [os.fspath(p) for p in path] if isinstance(path, (list, tuple)) else [os.fspath(path)]
    out: list[str] = []
    for p in paths:
        if os.path.isdir(p):
            for root, dirs, names in os.walk(p):
                dirs.sort()
                out.extend(os.path.join(root, n) for n in sorted(names))
        elif os.path.exists(p):
            out.append(p)
        else:  # a glob pattern
            out.extend(sorted(glob.glob(p)))
    return out


def cache_key(path: Any, **load_options: Any) -> str:
    """SHA-256 (hex) of the series' files (absolute path, size, mtime in ns) and the load options
    that change the voxels."""
    h = hashlib.sha256(f"ctui voxels {FORMAT}\n".encode())
    for f in _files(path):
        try:
            st = os.stat(f)
        except OSError:
            continue
        h.update(f"{os.path.abspath(f)}\0{st.st_size}\0{st.st_mtime_ns}\n".encode("utf-8", "surrogateescape"))
    opts = {k: v for k, v in load_options.items() if k not in ("progress", "memory_limit", "cache")}
    h.update(repr(sorted((k, repr(v)) for k, v in opts.items())).encode())
    return h.hexdigest()[:32]


def entry_dir(key: str) -> Path:
    return cache_root() / "voxels" / key


def lookup(path: Any, **load_options: Any) -> Path | None:
    """The cache entry of this series and these options, or None."""
    d = entry_dir(cache_key(path, **load_options))
    return d if (d / "volume.pkl").is_file() and (d / "voxels.npy").is_file() else None


_held: dict[str, int] = {}  # entry folder -> the descriptor holding its shared lock (for this process's life)


def _hold(entry: Path) -> None:
    """A shared lock on the entry while this process may use it (eviction skips it) and its use time."""
    key = str(entry)
    with contextlib.suppress(OSError):  # a read-only cache folder: used unlocked (nothing evicts there either)
        if key not in _held:
            fd = os.open(entry / "lock", os.O_RDWR | os.O_CREAT, 0o600)
            fcntl.flock(fd, fcntl.LOCK_SH)
            _held[key] = fd
        used = entry / "used"
        used.touch()
        os.utime(used)  # touch() leaves the time of an existing file on some systems


def _open(entry: Path) -> Volume:
    _hold(entry)
    with open(entry / "volume.pkl", "rb") as fh:
        vol: Volume = pickle.load(fh)  # written by this module into the user's own cache folder
    vol.data = np.load(entry / "voxels.npy", mmap_mode="c")
    vol.meta["voxel_cache"] = str(entry)
    return vol


def max_bytes() -> int:
    """The cache's size cap: ``CTUI_CACHE_MAX`` (``4G``, ``512M``, bytes; 0: none), else ``DEFAULT_MAX``."""
    text = os.environ.get("CTUI_CACHE_MAX", "").strip()
    if not text:
        return DEFAULT_MAX
    if text == "0":
        return 0
    return parse_memory(text, option="CTUI_CACHE_MAX")


def _size(entry: Path) -> int:
    total = 0
    for f in entry.iterdir():
        with contextlib.suppress(OSError):
            total += f.stat().st_size
    return total


def _last_use(entry: Path) -> float:
    for name in ("used", "volume.pkl"):
        with contextlib.suppress(OSError):
            return (entry / name).stat().st_mtime
    return 0.0


def evict(*, keep: Path | None = None, limit: int | None = None) -> list[str]:
    """Remove the least recently used entries until the cache holds at most ``limit`` bytes
    (default :func:`max_bytes`; 0: no limit), never ``keep`` nor an entry another process holds
    open (its shared lock). Returns the keys removed."""
    limit = max_bytes() if limit is None else int(limit)
    folder = cache_root() / "voxels"
    if limit <= 0 or not folder.is_dir():
        return []
    entries = [e for e in folder.iterdir() if e.is_dir() and not e.name.startswith(".")]
    sizes = {e: _size(e) for e in entries}
    total = sum(sizes.values())
    removed: list[str] = []
    for e in sorted(entries, key=_last_use):
        if total <= limit:
            break
        if keep is not None and e.resolve() == Path(keep).resolve():
            continue
        if str(e) in _held:  # this process uses it
            continue
        try:
            fd = os.open(e / "lock", os.O_RDWR | os.O_CREAT, 0o600)
        except OSError:
            continue
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                continue  # another process has it open
            gone = folder / f".evict-{e.name}-{os.getpid()}"
            try:
                os.rename(e, gone)  # atomic: from now on no process finds it
            except OSError:
                continue
        finally:
            os.close(fd)
        shutil.rmtree(gone, ignore_errors=True)
        total -= sizes[e]
        removed.append(e.name)
    return removed


@contextlib.contextmanager
def _allocating_into(target: Path) -> Iterator[dict]:
    """While active, the series loaders allocate their output as a memory-mapped ``.npy`` at
    ``target`` (``_common.allocate``); yields {"array": the map} once allocated."""
    box: dict[str, Any] = {}

    def alloc(shape: tuple[int, ...], dtype: Any) -> np.ndarray:
        box.pop("array", None)  # a second allocation (a re-decode into int32): the file holds the last
        box["array"] = np.lib.format.open_memmap(target, mode="w+", dtype=np.dtype(dtype), shape=tuple(shape))
        return box["array"]

    token = ALLOCATOR.set(alloc)
    try:
        yield box
    finally:
        ALLOCATOR.reset(token)


def _write_copy(data: np.ndarray, target: Path) -> None:
    """``data`` into a new ``.npy`` at ``target``, slab by slab."""
    mm = np.lib.format.open_memmap(target, mode="w+", dtype=data.dtype, shape=data.shape)
    for z in range(0, data.shape[0], _SLAB):
        mm[z:z + _SLAB] = data[z:z + _SLAB]
    mm.flush()
    del mm


def _decode(path: Any, tmp: Path, loader: Callable[..., Volume], load_options: dict) -> None:
    """Decode the series into ``tmp`` (voxels.npy + volume.pkl) with ``loader``
    (:func:`ctui.engine.io.series.load`)."""
    global decoded
    target = tmp / "voxels.npy"
    opts = dict(load_options, memory_limit=1 << 62)  # the voxels go to the disk, not to memory
    with _allocating_into(target) as box:
        vol = loader(path, **opts)
    decoded += 1
    mm = box.get("array")
    if mm is not None and vol.data is mm:
        mm.flush()
    else:  # the loader made another array (a resampled grid, dropped slices...): copy it over
        box.clear()
        del mm
        _write_copy(np.asarray(vol.data), target)
    vol.data = np.zeros((0, 0, 0), np.int16)
    with open(tmp / "volume.pkl", "wb") as fh:
        pickle.dump(vol, fh, protocol=pickle.HIGHEST_PROTOCOL)
        fh.flush()
        os.fsync(fh.fileno())


def load_cached(path: Any, *, loader: Callable[..., Volume], **load_options: Any) -> Volume:
    """The series at ``path`` as a Volume whose ``data`` is a copy-on-write memory map of its
    cache entry (decoded into the cache first by ``loader``, :func:`ctui.engine.io.series.load`,
    when there is none; see the module docstring); ``meta["voxel_cache"]``: the entry's folder."""
    load_options.pop("cache", None)
    key = cache_key(path, **load_options)
    entry = entry_dir(key)
    if (entry / "volume.pkl").is_file():
        try:
            return _open(entry)
        except (OSError, ValueError, EOFError, pickle.UnpicklingError):
            shutil.rmtree(entry, ignore_errors=True)  # a broken entry: decode again
    entry.parent.mkdir(parents=True, exist_ok=True)
    tmp = entry.parent / f".tmp-{key}-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    try:
        _decode(path, tmp, loader, load_options)
        try:
            os.rename(tmp, entry)
        except OSError:  # another process made the entry meanwhile: use it
            if not (entry / "volume.pkl").is_file():
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    vol = _open(entry)
    evict(keep=entry)
    return vol


def cached_overview(path: Any, factor: int, **load_options: Any) -> Volume | None:
    """``load(path, downsample=(f, f, f), **load_options)`` from the cache when the series has an
    entry (another command decoded it there): its ``factor``-times overview, read from the entry's
    ``overview<f>.npy`` (no decode; made from the map on first use); None without an entry."""
    entry = lookup(path, **dict(load_options, downsample=None))
    if entry is None or int(factor) not in (2, 4):
        return None
    try:
        return overview(_open(entry), factor)
    except (OSError, ValueError, EOFError, pickle.UnpicklingError):
        return None  # removed meanwhile or broken: the caller decodes


def overview(vol: Volume, factor: int) -> Volume:
    """A ``factor``-times coarser copy of a cached Volume (every ``factor``-th voxel along each
    axis: what ``load(..., downsample=(f, f, f))`` gives), itself memory-mapped from the entry's
    ``overview<f>.npy`` (made on first use, slab by slab)."""
    f = int(factor)
    entry = vol.meta.get("voxel_cache")
    sub = vol.data[::f, ::f, ::f]
    out = copy.copy(vol)
    out.meta = dict(vol.meta, overview=f)
    out.spacing = tuple(float(s) * f for s in vol.spacing)
    if vol.slice_positions is not None:
        out.slice_positions = np.asarray(vol.slice_positions)[::f]
    if not entry:
        out.data = np.ascontiguousarray(sub)
        return out
    target = Path(entry) / f"overview{f}.npy"
    if not target.is_file():
        tmp = target.with_name(f".tmp-{target.name}-{os.getpid()}.npy")
        _write_copy(sub, tmp)
        os.replace(tmp, target)
        evict(keep=Path(entry))
    out.data = np.load(target, mmap_mode="c")
    return out
