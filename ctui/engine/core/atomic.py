"""Crash-safe file writing.

Every file ctui writes goes through :func:`atomic_write`: the content is written to a
temporary file in the target's folder, flushed, fsynced and renamed over the target,
so a crash (even SIGKILL) leaves either the previous complete file or the new one,
never a half-written file. On failure (disk full, permission denied) the temporary
file is removed and a :class:`~ctui.engine.core.errors.CtuiError` names the target.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from pathlib import Path
from typing import IO, Iterator

from ctui.engine.core.errors import CtuiError


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _lock(fd: int) -> bool:
    try:
        import fcntl

        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except (ImportError, OSError):
        return False


def clean_stale_temps(path: str | os.PathLike, *, min_age_s: float = 0.2) -> int:
    """Remove temporary files left beside ``path`` by writers that died mid-save.

    A temp file ``.NAME.*.tmp*`` is stale when no process holds its lock (the lock
    dies with its process) and it is older than ``min_age_s`` (which covers the instant
    between another writer creating and locking it). Returns how many were removed.
    """
    import time

    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    prefix = f".{target.name}."
    removed = 0
    try:
        names = [n for n in os.listdir(folder) if n.startswith(prefix) and ".tmp" in n[len(prefix):]]
    except OSError:
        return 0
    now = time.time()
    for name in names:
        p = folder / name
        try:
            st = os.lstat(p)
            if not stat.S_ISREG(st.st_mode) or now - st.st_mtime < min_age_s:
                continue
            fd = os.open(p, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
        except OSError:
            continue
        try:
            if _lock(fd):
                os.unlink(p)
                removed += 1
        except OSError:
            pass
        finally:
            os.close(fd)
    return removed


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

    For writers that insist on a file name (OpenCV, nibabel, trimesh...). The
    temporary name keeps the target's suffix (or ``suffix``) so writers that pick the
    format from the extension still work.
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if suffix is None:
        suffix = "".join(target.suffixes) or ""
    clean_stale_temps(target)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f".tmp{suffix}", dir=folder)
    except OSError as exc:
        raise CtuiError(f"{target}: cannot write ({exc.strerror or exc})") from exc
    # Hold an exclusive lock on the temp file while it is in flight: the kernel drops
    # it when this process dies (even SIGKILL), which tells clean_stale_temps that a
    # leftover is stale.
    _lock(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp_path, 0o644)
        os.replace(tmp_path, target)
        _fsync_dir(folder)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise CtuiError(f"{target}: cannot write ({exc.strerror or exc})") from exc
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb", *, encoding: str | None = None) -> Iterator[IO]:
    """Open a temporary file beside ``path`` for writing; rename it onto ``path`` on success.

    >>> with atomic_write("out.json", "w") as fh:
    ...     fh.write("{}")
    """
    if "w" not in mode:
        raise ValueError("atomic_write is for writing ('w' or 'wb')")
    if "b" not in mode and encoding is None:
        encoding = "utf-8"
    with atomic_path(path) as tmp:
        with open(tmp, mode, encoding=encoding) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_write(path, "wb") as fh:
        fh.write(data)


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_write(path, "w") as fh:
        fh.write(text)
