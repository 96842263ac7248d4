"""Helpers shared by the loaders: file listing, natural order, crop/downsample plans,
the memory check, privacy scrubbing and the parallel slice decoder."""

from __future__ import annotations

import contextvars
import os
import re
import stat
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from ctui.engine.core.assumptions import Assumption
from ctui.engine.core import limits as _limits
from ctui.engine.core.limits import MAX_SPACING_MM, MIN_SPACING_MM
from ctui.engine.core.errors import CtuiError, LoadError
from ctui.engine.core.privacy import scrub_text, scrub_text_obj
from ctui.engine.core.limits import fmt_bytes

IMAGE_SUFFIXES = {".png", ".bmp", ".tif", ".tiff", ".jpg", ".jpeg"}
_NATURAL = re.compile(r"(\d+)")
MAX_FILES = 200_000  # bound on a folder walk (symlink loops, huge trees)
#: how the loaders allocate their output array: None = ``np.empty``; the voxel cache
#: (``io/voxcache``) sets a function (shape, dtype) -> a memory-mapped ``.npy``
ALLOCATOR: contextvars.ContextVar[Callable[[tuple, Any], np.ndarray] | None] = contextvars.ContextVar(
    "ctui_allocator", default=None)


def allocate(shape: Sequence[int], dtype: Any) -> np.ndarray:
    """The loaders' output array (uninitialised): ``np.empty``, or the voxel cache's file."""
    alloc = ALLOCATOR.get()
    return np.empty(tuple(shape), dtype=dtype) if alloc is None else alloc(tuple(int(v) for v in shape), dtype)


def natural_key(s: str) -> tuple:
    """Sort key putting "2" before "10" (slice0, slice1, ..., slice10; CThead.2 < CThead.10)."""
    parts = _NATURAL.split(str(s))
    return tuple((0, int(p), p) if p.isdigit() else (1, 0, p.lower()) for p in parts)


def list_files(path: Path, *, recursive: bool = True, skipped: list[dict[str, str]] | None = None) -> list[Path]:
    """Regular files under ``path`` (recursive; hidden entries ignored).

    Symbolic links to files are followed; links to folders are not (no loops, no
    escaping the series folder). Broken links, FIFOs, devices and linked folders are
    reported in ``skipped`` (when given) with a reason.
    """
    out: list[Path] = []
    seen: set[tuple[int, int]] = set()

    def note(p: str, reason: str) -> None:
        if skipped is not None:
            skipped.append({"file": rel(p, path), "reason": reason})

    def walk(folder: Path) -> list[Path]:
        """Files of one folder into ``out``; returns its sub-folders (iterative walk:
        no recursion limit on deep trees)."""
        subs: list[Path] = []
        try:
            st = folder.stat()
        except OSError:
            return subs
        key = (st.st_dev, st.st_ino)
        if key in seen:
            return subs
        seen.add(key)
        try:
            entries = sorted(os.scandir(folder), key=lambda e: natural_key(e.name))
        except OSError as exc:
            note(str(folder), f"cannot list folder ({exc.strerror or exc})")
            return subs
        for e in entries:
            if e.name.startswith("."):
                continue
            try:
                if e.is_symlink():
                    try:
                        target = os.stat(e.path)
                    except OSError:
                        note(e.path, "broken or looping symbolic link")
                        continue
                    if stat.S_ISDIR(target.st_mode):
                        note(e.path, "symbolic link to a folder (not followed)")
                        continue
                    mode = target.st_mode
                elif e.is_dir(follow_symlinks=False):
                    if recursive:
                        subs.append(Path(e.path))
                    continue
                else:
                    mode = e.stat(follow_symlinks=False).st_mode
                if not stat.S_ISREG(mode):
                    note(e.path, "not a regular file (FIFO, device or socket)")
                    continue
                out.append(Path(e.path))
                if len(out) > MAX_FILES:
                    raise LoadError(f"more than {MAX_FILES} files; point ctui at one series folder", path=path)
            except OSError as exc:
                note(e.path, f"cannot read ({exc.strerror or exc})")
        return subs

    stack = [path]
    while stack:
        # depth-first, in natural name order
        stack.extend(reversed(walk(stack.pop())))
    return out


def rel(p: Path | str, base: Path | None) -> str:
    """``p`` relative to ``base`` for messages (just the name when outside it)."""
    p = Path(p)
    if base is not None:
        try:
            return str(p.relative_to(base)) or p.name
        except ValueError:
            pass
    return str(p)


# --------------------------------------------------------------------- crop / stride
@dataclass
class Plan:
    """Which part of a (nz, ny, nx) source grid to load: python slices per axis."""

    z: slice
    y: slice
    x: slice

    def out_len(self, axis: int, n: int) -> int:
        return len(range(*(self.z, self.y, self.x)[axis].indices(n)))

    def out_shape(self, shape: Sequence[int]) -> tuple[int, int, int]:
        return tuple(self.out_len(a, int(n)) for a, n in enumerate(shape))  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction

    def starts(self, shape: Sequence[int]) -> tuple[int, int, int]:
        return tuple((self.z, self.y, self.x)[a].indices(int(n))[0] for a, n in enumerate(shape))  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction

    def steps(self) -> tuple[int, int, int]:
        return tuple(s.step or 1 for s in (self.z, self.y, self.x))  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction

    def is_full(self, shape: Sequence[int]) -> bool:
        """True when the plan loads the whole (nz, ny, nx) grid."""
        return self.steps() == (1, 1, 1) and self.out_shape(shape) == tuple(int(n) for n in shape)


def make_plan(shape: Sequence[int], *, crop: Any = None, downsample: Any = None, path: Any = None) -> Plan:
    """Validate ``crop`` and ``downsample`` against a (nz, ny, nx) grid.

    crop : (z0, z1, y0, y1, x0, x1) voxel index ranges (end exclusive, None = to the
        edge), as in python slicing of the full volume.
    downsample : int N (stride N in y and x, slices kept) or (sz, sy, sx) strides.
    """
    nz, ny, nx = (int(n) for n in shape)
    if downsample is None:
        steps = (1, 1, 1)
    elif isinstance(downsample, (int, np.integer)):
        steps = (1, int(downsample), int(downsample))
    else:
        steps = tuple(int(s) for s in downsample)
        if len(steps) == 2:
            steps = (1, *steps)
    if len(steps) != 3 or min(steps) < 1:
        raise CtuiError(f"downsample must be a positive integer or three (z, y, x) strides, got {downsample!r}", path=path)
    bounds: list[tuple[int | None, int | None]] = [(None, None)] * 3
    if crop is not None:
        c = list(crop)
        if len(c) != 6:
            raise CtuiError(f"crop must be (z0, z1, y0, y1, x0, x1), got {crop!r}", path=path)
        bounds = [(c[0], c[1]), (c[2], c[3]), (c[4], c[5])]
    slices = []
    for axis, ((a, b), n, st) in enumerate(zip(bounds, (nz, ny, nx), steps)):
        a = 0 if a is None else int(a)
        b = n if b is None else int(b)
        if a < 0:
            a += n
        if b < 0:
            b += n
        a, b = max(0, a), min(n, b)
        if b <= a:
            raise CtuiError(f"crop leaves nothing along {'zyx'[axis]} (0..{n} available)", path=path)
        slices.append(slice(a, b, st))
    return Plan(*slices)


# --------------------------------------------------------------------- memory
def available_memory() -> int:
    """Bytes this process may still allocate (:func:`ctui.engine.core.limits.available_memory`:
    the smallest of free RAM, RLIMIT_AS headroom and the cgroup's memory.max headroom)."""
    return _limits.available_memory()


def check_memory(nbytes: int, *, shape: Sequence[int], path: Any, limit: int | None = None, what: str = "") -> None:
    """Raise a CtuiError offering crop/downsample when ``nbytes`` will not fit in memory.

    ``limit``: bytes allowed (default: 90% of what :func:`available_memory` gives, which
    respects RLIMIT_AS and the cgroup limit, not only free RAM).
    """
    nz, ny, nx = (int(s) for s in shape)
    hint = ("load a part with crop=(z0,z1,y0,y1,x0,x1) (--crop) or fewer voxels with "
            "downsample=N (--downsample N, or z,y,x strides)")
    what = what or f"{nz}x{ny}x{nx} voxels"
    if limit is None:
        _limits.check_allocation(nbytes, what=what, path=path, hint=hint)
        return
    if nbytes > int(limit):
        raise CtuiError(f"{what} needs {fmt_bytes(nbytes)} but only {fmt_bytes(int(limit))} of memory is "
                        f"allowed (memory_limit); {hint}", path=path)


# --------------------------------------------------------------------- privacy
def scrub(text: str, identifiers: Iterable[str]) -> str:
    """``text`` without the whole-word tokens of the headers' own patient identifiers
    (name, ID, birth date...): :func:`ctui.engine.core.privacy.scrub_text` (common words
    such as HEAD or CHEST in a name are left alone)."""
    return scrub_text(text, identifiers)


def scrub_obj(obj: Any, identifiers: Iterable[str]) -> Any:
    """:func:`scrub` applied to every string in ``obj`` (dicts' values, lists, tuples)."""
    return scrub_text_obj(obj, list(identifiers))


# --------------------------------------------------------------------- parallel decode
def n_threads() -> int:
    env = os.environ.get("CTUI_THREADS")
    if env and env.isdigit() and int(env) > 0:
        return int(env)
    return max(1, min(8, os.cpu_count() or 1))


def run_parallel(
    tasks: Sequence[Any],
    work: Callable[[int, Any], str | None],
    *,
    progress: Callable[[int, int], Any] | None = None,
) -> list[tuple[int, str]]:
    """Run ``work(k, task)`` for every task on a thread pool.

    ``work`` returns None on success or a reason string (the task is skipped).
    Returns [(k, reason)] of failures. ``progress(done, total)`` is called from the
    calling thread.
    """
    failures: list[tuple[int, str]] = []
    total = len(tasks)
    nt = n_threads()
    if nt == 1 or total <= 2:
        for k, t in enumerate(tasks):
            r = _safe(work, k, t)
            if r:
                failures.append((k, r))
            if progress:
                progress(k + 1, total)
        return failures
    with ThreadPoolExecutor(max_workers=nt, thread_name_prefix="ctui-load") as pool:
        futs = {pool.submit(_safe, work, k, t): k for k, t in enumerate(tasks)}
        try:
            for done, fut in enumerate(as_completed(futs), start=1):
                r = fut.result()
                if r:
                    failures.append((futs[fut], r))
                if progress:
                    progress(done, total)
        except BaseException:  # progress raised Cancelled (or Ctrl+C): the slices not started are dropped
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    failures.sort()
    return failures


def _safe(work: Callable[[int, Any], str | None], k: int, t: Any) -> str | None:
    try:
        return work(k, t)
    except MemoryError:
        return "out of memory while decoding"
    except CtuiError as exc:
        return str(exc)
    except Exception as exc:  # a broken file must not stop the others
        msg = " ".join(str(exc).split())[:200]
        return f"cannot decode ({type(exc).__name__}: {msg})" if msg else f"cannot decode ({type(exc).__name__})"


def to_grey(arr: np.ndarray, *, channels_last: bool = True) -> np.ndarray:
    """Colour (…, 3|4) -> luminance (ITU-R 601: 0.299 R + 0.587 G + 0.114 B), input dtype kept."""
    if arr.ndim < 3:
        return arr
    rgb = arr[..., :3].astype(np.float32)
    g = rgb[..., 0] * 0.299 + rgb[..., 1] * 0.587 + rgb[..., 2] * 0.114
    if np.issubdtype(arr.dtype, np.integer):
        return np.rint(g).astype(arr.dtype)
    return g.astype(arr.dtype)


# --------------------------------------------------------------------- header geometry
def orthonormal(direction: Any, *, what: str) -> tuple[np.ndarray, list[str]]:
    """``direction`` (3, 3; columns = index axes) with unit columns at right angles.

    A voxel grid cannot be sheared: a header whose axes are not at right angles (NIfTI
    sform with off-diagonal shear, MetaImage ``TransformMatrix 1 5 0 ...``) gets the
    nearest rotation (polar decomposition; handedness kept) and a warning giving the
    largest change of an axis in degrees. Slight shears (under 0.06 degrees) are kept.
    Returns (direction, warnings); a degenerate matrix gives the identity (and a warning).
    """
    d = np.array(direction, dtype=np.float64).reshape(3, 3)
    with np.errstate(all="ignore"):
        norms = np.sqrt((d * d).sum(axis=0))
    if not (np.all(np.isfinite(d)) and np.all(norms > 1e-9)) or abs(np.linalg.det(d / norms[None, :])) < 1e-6:
        return np.eye(3), [Assumption(f"{what} gives degenerate axis directions: axis-aligned directions used",
                                      "orientation")]
    d = d / norms[None, :]
    if np.abs(d.T @ d - np.eye(3)).max() < 1e-3:
        return d, []
    u, _, vt = np.linalg.svd(d)
    r = u @ vt
    cos = np.clip((d * r).sum(axis=0), -1.0, 1.0)
    worst = float(np.degrees(np.arccos(cos)).max())
    return r, [Assumption(f"{what} gives axes that are not at right angles (a shear): the nearest orthonormal "
                          f"directions are used (an axis moves by up to {worst:.1f} degrees)", "orientation")]


def checked_axes(m: Any, origin: Any, *, what: str, spacing_given: bool = False
                 ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Validate a header's index-axis matrix and origin (NIfTI, NRRD, MetaImage).

    ``m`` (3, 3): columns = steps in mm of the x, y, z index axes (spacing x direction);
    ``origin`` (3,) mm. An axis whose step is NaN, infinite, 0 or beyond 100 m becomes
    a 1 mm step along its own index axis; collinear axes become axis-aligned; a
    non-finite origin becomes 0. Each correction is said in the returned warnings
    (``spacing_given``: the user's spacing replaces the voxel size, so that part is not
    warned about). Returns (m, origin, warnings); never NaN or inf.
    """
    m = np.array(m, dtype=np.float64).reshape(3, 3)
    warnings: list[str] = []
    with np.errstate(all="ignore"):
        norms = np.sqrt((m * m).sum(axis=0))
    bad = [a for a in range(3) if not (np.all(np.isfinite(m[:, a])) and MIN_SPACING_MM <= norms[a] <= MAX_SPACING_MM)]
    for a in bad:
        m[:, a] = np.eye(3)[:, a]
    if bad and not spacing_given:
        vals = ", ".join(f"{'xyz'[a]} ({'NaN' if not np.isfinite(norms[a]) and np.isnan(norms[a]) else f'{norms[a]:g}'})"
                         for a in bad)
        warnings.append(Assumption(f"{what} gives an invalid voxel size along {vals}: 1 mm used instead; give "
                                   f"spacing=(dz, dy, dx) (--spacing dz,dy,dx) for true measurements", "spacing"))
    norms = np.sqrt((m * m).sum(axis=0))
    if abs(np.linalg.det(m / norms[None, :])) < 1e-6:
        m = np.diag(norms)
        warnings.append(Assumption(f"{what} gives collinear axis directions: axis-aligned directions used",
                                   "orientation"))
    else:
        d, sheared = orthonormal(m / norms[None, :], what=what)
        m = d * norms[None, :]
        warnings += sheared
    o = np.zeros(3)
    try:
        given = np.array(origin, dtype=np.float64).reshape(-1)[:3]
        o[: len(given)] = given
    except (TypeError, ValueError):
        o[:] = np.nan
    if not np.all(np.isfinite(o)) or np.abs(o).max() > 1e7:
        o = np.zeros(3)
        warnings.append(Assumption(f"{what} gives an invalid origin: (0, 0, 0) used", "origin"))
    return m, o, warnings
