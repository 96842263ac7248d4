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
