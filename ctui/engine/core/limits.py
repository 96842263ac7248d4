"""Memory the process may use: the smallest of free RAM, RLIMIT_AS and the cgroup limit.

Every large allocation (a loaded series, a resampled grid, an image, label or distance
volume) is checked with :func:`check_allocation` before it is made, so a too-big input
stops with a one-line message instead of a MemoryError, a SIGSEGV or the OOM killer.
``CTUI_MEMORY_LIMIT`` (bytes) overrides, for tests.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ctui.engine.core.errors import CtuiError

_UNLIMITED = 1 << 62

#: the smallest and largest voxel size (mm) any input may declare: 1 micrometre (micro-CT)
#: to 100 m. Beyond, volumes round to 0 mL or products overflow; loaders replace such a
#: size by 1 mm with a warning, projects and options are refused.
MIN_SPACING_MM = 1e-3
MAX_SPACING_MM = 1e5


def fmt_bytes(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if abs(n) < 1024 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024.0
    return f"{n:.1f} TB"  # pragma: no cover


def parse_memory(text: Any, option: str = "memory") -> int:
    """``"4G"``, ``"512M"``, ``"1.5GB"`` or a number of bytes -> bytes; one-line error otherwise."""
    key = "memory" if option == "memory" else None  # CTUI_MEMORY is no option of an action
    t = str(text).strip().upper().removesuffix("B").removesuffix("I")
    mult = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}.get(t[-1:], 1)
    try:
        val = float(t[:-1] if t[-1:] in "KMGT" else t)
    except (ValueError, IndexError):
        raise CtuiError(f"{option} {text!r}: expected a size such as 4G, 512M or bytes", option=key) from None
    if not (val > 0 and val * mult < 1 << 60):
        raise CtuiError(f"{option} {text!r}: expected a positive size such as 4G", option=key)
    return int(val * mult)


def _cgroup_limit() -> int:
    """memory.max - memory.current of this process's cgroup (v2), or v1's limit."""
    try:
        rel = ""
        for line in Path("/proc/self/cgroup").read_text().splitlines():
            parts = line.split(":", 2)
            if len(parts) == 3 and parts[0] == "0":
                rel = parts[2]
        base = Path("/sys/fs/cgroup") / rel.lstrip("/")
        for folder in (base, *base.parents):
            mx = folder / "memory.max"
            if mx.exists():
                txt = mx.read_text().strip()
                if txt != "max":
                    cur = folder / "memory.current"
                    used = int(cur.read_text()) if cur.exists() else 0
                    return max(0, int(txt) - used)
            if folder == Path("/sys/fs/cgroup"):
                break
        v1 = Path("/sys/fs/cgroup/memory/memory.limit_in_bytes")
        if v1.exists():
            lim = int(v1.read_text())
            if lim < _UNLIMITED:
                used_f = Path("/sys/fs/cgroup/memory/memory.usage_in_bytes")
                used = int(used_f.read_text()) if used_f.exists() else 0
                return max(0, lim - used)
    except (OSError, ValueError):
        pass
    return _UNLIMITED


def _rlimit_as() -> int:
    """RLIMIT_AS minus the address space already mapped (VmSize)."""
    try:
        import resource  # POSIX only: no address-space limit where it is missing

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft == resource.RLIM_INFINITY or soft <= 0:
            return _UNLIMITED
        vm = 0
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                vm = int(line.split()[1]) * 1024
        return max(0, int(soft) - vm)
    except (OSError, ValueError, ImportError):
        return _UNLIMITED


def _free_ram() -> int:
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except Exception:  # pragma: no cover
        return _UNLIMITED


def available_memory() -> int:
    """Bytes this process may still allocate: min(free RAM, RLIMIT_AS headroom, cgroup headroom)."""
    env = os.environ.get("CTUI_MEMORY_LIMIT")
    if env:
        try:
            return int(float(env))
        except ValueError:
            pass
    return min(_free_ram(), _rlimit_as(), _cgroup_limit())


def check_allocation(nbytes: float, *, what: str, path: Any = None, fraction: float = 0.9, hint: str = "") -> None:
    """Raise CtuiError (naming ``path`` and ``what``) when ``nbytes`` will not fit.

    ``fraction``: the part of the available memory one allocation may take.
    """
    avail = available_memory()
    if nbytes > avail * fraction:
        msg = f"{what} needs {fmt_bytes(nbytes)} but only {fmt_bytes(avail)} of memory is available to ctui"
        if hint:
            msg += f"; {hint}"
        raise CtuiError(msg, path=path)


# ---------------------------------------------------------------- address-space limit (ulimit -v)
#: The address space (MB) each command's libraries map on a small input under :func:`fit_address_space`'s
#: settings (its VmPeak, measured on the bundled sample and a project of it, plus 15%). Below it a library's
#: loader can fail in native code instead of raising: OpenCV's BLAS segfaults, scipy's BLAS retries its buffer
#: forever. The command is refused first, in one line. Commands not listed: :data:`AS_FLOOR_OTHER_MB`.
AS_FLOOR_MB = {"info": 210, "demo": 510, "drift": 340, "segment": 680, "edit": 640, "mesh": 640, "measure": 690,
               "export": 640, "report": 830, "render": 990, "vessel": 1050}
AS_FLOOR_OTHER_MB = 1000  # the TUI (open, web), batch (Dask), auto (TotalSegmentator)
_M_ARENA_MAX = -8  # glibc's mallopt parameter


def address_space_limit() -> int | None:
    """RLIMIT_AS in bytes (``ulimit -v``), None when unlimited or unknown."""
    try:
        import resource  # POSIX only

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, OSError, ValueError):
        return None
    return None if soft == resource.RLIM_INFINITY or soft <= 0 else int(soft)


def fit_address_space() -> int | None:
    """Under an address-space limit, map less before the libraries load (call it before numpy is imported):
    BLAS single-threaded (``OPENBLAS_NUM_THREADS=1`` unless set: three BLAS copies load, numpy's, scipy's and
    OpenCV's, and each thread of each maps a 32-64 MB buffer) and at most two malloc arenas (each thread's
    arena reserves 64 MB). Results do not change: ctui's kernels use no BLAS threads. Returns the limit (bytes)
    or None (then nothing is changed)."""
    limit = address_space_limit()
    if limit is None:
        return None
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    try:
        import ctypes  # glibc's mallopt; elsewhere nothing to do

        ctypes.CDLL(None).mallopt(_M_ARENA_MAX, 2)
    except (OSError, AttributeError):
        pass
    return limit


def check_address_space(command: str) -> None:
    """CtuiError (one line, what is needed) when ``ulimit -v`` is below what ``command``'s libraries map."""
    limit = address_space_limit()
    floor = AS_FLOOR_MB.get(command, AS_FLOOR_OTHER_MB) * 1024 * 1024
    if limit is not None and limit < floor:
        raise CtuiError(f"the address-space limit (ulimit -v {limit // 1024}) is below the {fmt_bytes(floor)} "
                        f"that ctui {command}'s libraries map (numpy, OpenCV, scipy, numba, VTK/EGL): raise it "
                        f"to at least ulimit -v {floor // 1024}")
