"""Crash-safe file writing.

Every file ctui writes goes through :func:`atomic_write`: the content is written to a
temporary file in the target's folder, flushed, fsynced and renamed over the target,
so a crash (even SIGKILL) leaves either the previous complete file or the new one,
never a half-written file. On failure (disk full, permission denied) the temporary
file is removed and a :class:`~ctui.engine.core.errors.CtuiError` names the target.

Only regular files are written: a target that is a device node, a FIFO, a socket or a
folder (also through a symlink, e.g. ``/dev/null`` or a link to ``/proc/self/fd/1``) is
refused with one line (:func:`regular_target`), never renamed over; a symlink to a
regular file is written through (the file it points to is replaced, the link kept).

Permissions: a new file gets ``0o666 & ~umask`` (what ``open()`` would give; with
umask 077 the user's projects stay private), a replaced file keeps its mode.

:func:`check_output` refuses an output that is one of the command's inputs (the same
file through a symlink or a hard link, or a file inside an input folder): commands
call it before they write anything.
"""

from __future__ import annotations

import contextlib
import os
import re
import stat
import tempfile
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO

from ctui.engine.core.errors import CtuiError, FormatError


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


def current_umask() -> int:
    """The process umask, read without changing it (Linux /proc; else a set-and-restore)."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)  # not thread-safe, hence only the fallback
    os.umask(mask)
    return mask


def target_mode(target: str | os.PathLike) -> int:
    """Permission bits for a file written to ``target``: the mode of the file it
    replaces (followed through a symlink), else ``0o666 & ~umask``."""
    try:
        return stat.S_IMODE(os.stat(target).st_mode)
    except OSError:
        return 0o666 & ~current_umask()


def _lock(fd: int) -> bool:
    try:
        import fcntl  # POSIX only: no lock (and no stale-temp check) where it is missing

        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except (ImportError, OSError):
        return False


def clean_stale_temps(path: str | os.PathLike, *, min_age_s: float = 0.2) -> int:
    """Remove temporary files left beside ``path`` by writers that died mid-save.

    A temp file is one of :func:`atomic_path`'s own names, exactly: ``.NAME.`` + mkstemp's 8
    random characters + ``.tmp`` + an extension (a user's ``.out.stl.keep.tmp`` is not one:
    it was deleted when ``out.stl`` was written). It is stale when no process holds its lock
    (the lock dies with its process) and it is older than ``min_age_s`` (which covers the
    instant between another writer creating and locking it). Returns how many were removed.
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    own = re.compile(re.escape(f".{target.name}.") + r"[a-z0-9_]{8}\.tmp(\.[A-Za-z0-9]{1,8}){0,3}")
    removed = 0
    try:
        names = [n for n in os.listdir(folder) if own.fullmatch(n)]
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


_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISSOCK, "a socket"))


def regular_source(path: str | os.PathLike, *, what: str) -> os.stat_result:
    """``os.stat`` of an input file, checked before opening it (opening a FIFO would block):
    a one-line FormatError when it cannot be read, is a folder (not ``what``) or is not a
    regular file."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise FormatError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        raise FormatError(f"{path}: is a folder, not {what}")
    if not stat.S_ISREG(st.st_mode):
        raise FormatError(f"{path}: not a regular file")
    return st


def regular_target(path: str | os.PathLike) -> Path:
    """The file an output to ``path`` replaces: ``path`` itself, or the regular file a
    symlink at ``path`` points to (the link is kept). Raises a one-line CtuiError when
    ``path`` is (or links to) anything but a regular file, or is a dangling link: renaming
    over ``/dev/null``, a FIFO or a link to a terminal would destroy it."""
    target = Path(path)
    try:
        lst = os.lstat(target)
    except OSError:
        return target  # nothing there yet: a new file
    except ValueError as exc:  # a NUL byte in the name
        raise CtuiError(f"{target!r}: not a valid file name ({exc})") from exc
    if stat.S_ISLNK(lst.st_mode):
        try:
            st = os.stat(target)
        except OSError as exc:
            raise CtuiError(f"{target}: a symbolic link to nothing that can be written ({exc.strerror or exc}); "
                            "remove it or choose another file") from exc
    else:
        st = lst
    if not stat.S_ISREG(st.st_mode):
        what = next((name for test, name in _KINDS if test(st.st_mode)), "not a regular file")
        via = " (through a symbolic link)" if stat.S_ISLNK(lst.st_mode) else ""
        raise CtuiError(f"{target}: is {what}{via}; ctui writes only regular files, choose another output")
    if stat.S_ISLNK(lst.st_mode):
        real = Path(os.path.realpath(target))
        return real if real.is_file() else target
    return target


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

    For writers that insist on a file name (OpenCV, nibabel, trimesh...). The
    temporary name keeps the target's suffix (or ``suffix``) so writers that pick the
    format from the extension still work.
    """
    target = regular_target(path)
    folder = target.parent if str(target.parent) else Path(".")
    if suffix is None:  # (".nii.gz" alone: Path takes ".nii" for a stem; "x.nii.gz"'s suffixes are meant)
        suffix = "".join(Path("x" + target.name).suffixes) or ""
    clean_stale_temps(target)
    mode = target_mode(target)
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
        os.chmod(tmp_path, mode)
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
    with atomic_path(path) as tmp, open(tmp, mode, encoding=encoding) as fh:
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


# --------------------------------------------------------------------- outputs vs inputs
def _ident(path: str | os.PathLike) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return (st.st_dev, st.st_ino)


def _folders_up(path: str) -> Iterator[tuple[str, tuple[int, int]]]:
    """The existing folders containing ``path`` (resolved), nearest first, with their ids."""
    cur = os.path.dirname(os.path.realpath(path))
    while True:
        ident = _ident(cur)
        if ident is not None:
            yield cur, ident
        parent = os.path.dirname(cur)
        if parent == cur:
            return
        cur = parent


def _flat(items: Iterable) -> Iterator[str]:
    for item in items:
        if item is None or item == "":
            continue
        if isinstance(item, (list, tuple, set, frozenset)):
            yield from _flat(item)
        else:
            yield os.fspath(item)


def check_output(out: str | os.PathLike | None, *, inputs: Iterable, label: str = "output") -> None:
    """Refuse to write ``out`` when that would overwrite or pollute an input.

    Raises a one-line :class:`CtuiError` naming both files when ``out`` is the same
    file as an input (also through a symlink or a hard link: same ``(st_dev, st_ino)``)
    or lies inside an input folder (a series folder: a new file there would join the
    series). ``inputs``: paths, possibly nested lists (glob lists), None ignored.
    ``label``: how the message names the output (e.g. "--csv").
    """
    if out is None or out == "":
        return
    out_s = os.fspath(out)
    try:
        st = os.stat(out_s)
    except (OSError, ValueError):
        st = None
    if st is not None and not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
        regular_target(out_s)  # a device, FIFO or socket (or a link to one): refused before any work
    out_id = _ident(out_s)
    up = None
    for inp in _flat(inputs):
        in_id = _ident(inp)
        if in_id is None:
            continue
        if out_id is not None and out_id == in_id:
            what = "the input folder" if os.path.isdir(inp) else "the input"
            raise CtuiError(f"{label} {out_s} is {what} {inp}; refusing to overwrite it, choose another file", path=None)
        if os.path.isdir(inp):
            if up is None:
                up = list(_folders_up(out_s))
            if any(ident == in_id for _, ident in up):
                raise CtuiError(f"{label} {out_s} is inside the input folder {inp}; refusing to write into it, "
                                "choose another folder", path=None)


def check_outputs(outputs: dict, *, inputs: Iterable) -> None:
    """:func:`check_output` for each ``{label: path}`` output, and no two outputs the same file."""
    inputs = list(_flat(inputs))
    seen: dict[str, str] = {}
    for label, out in outputs.items():
        if out is None or out == "":
            continue
        check_output(out, inputs=inputs, label=label)
        key = os.path.realpath(os.fspath(out))
        ident = _ident(key)
        for k in ([key] + ([f"{ident}"] if ident else [])):
            if k in seen:
                raise CtuiError(f"{label} {out} and {seen[k]} are the same file; choose two different files")
        seen[key] = f"{label} {out}"
        if ident:
            seen[f"{ident}"] = f"{label} {out}"
