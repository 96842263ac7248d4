"""The memory plan: before a command loads a series, its peak is estimated from the series'
headers and compared with the memory it may use; the command then runs in memory, renders
from an overview (a 2x or 4x downsampled copy, where the image cannot show more detail), or
is refused in one line naming what would fit (``downsample``, ``crop``).

Estimates are ``fixed + factor x series`` (series: its voxels as int16, nz x ny x nx x 2 bytes),
from ``benchmarks/scale.py`` (peak RSS of each command on synthetic 512 x 512 CT series of 300
and 1,000 slices, rounded up). The limit: ``memory`` (bytes, the ``--memory 4G`` loader option),
else ``CTUI_MEMORY``, else what :func:`ctui.engine.core.limits.available_memory` gives (free RAM,
RLIMIT_AS and cgroup headroom).
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ctui.engine.core import limits
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.limits import fmt_bytes, parse_memory
from ctui.engine.io.series import scan
from ctui.engine.io.series._common import make_plan
from ctui.engine.io.voxcache import cache_root, disk_free

MB = 1 << 20

#: command -> (fixed bytes: interpreter, libraries, kernels; factor: x the series as int16)
PEAKS: dict[str, tuple[int, float]] = {
    "info": (60 * MB, 0.05),
    "load": (60 * MB, 1.1),
    "open": (300 * MB, 2.0),  # the TUI: the series, labels, slice views
    "segment": (420 * MB, 2.0),  # 300 slices: 652 MB, 1,000: 1,201 MB (one blob through every slice)
    "auto": (420 * MB, 2.0),
    "drift": (420 * MB, 2.0),
    "mesh": (80 * MB, 2.2),  # 300: 375 MB, 1,000: 1,069 MB
    "render": (500 * MB, 2.6),  # MIP 300: 577 MB, 1,000: 1,285 MB; a DVR adds its gradients (<= 2 x 320 MB)
}
#: address space the libraries map without using it (numba/LLVM, thread stacks): counted
#: against RLIMIT_AS only
#: the commands `info` reports a plan for (text and --json), in this order
REPORTED = ("open", "segment", "mesh", "render")
AS_OVERHEAD = 700 * MB
#: commands that may work from an overview (``downsample``) without changing their result's meaning
OVERVIEW_OK = {"render"}
#: commands that may read the voxels from the memory-mapped cache (``io/voxcache``): their peak
#: less the series, whose pages are then the file's (not under RLIMIT_AS: a map takes address space)
CACHE_OK = {"load", "open", "segment", "auto", "drift", "mesh", "render"}
#: compressed inputs may hold this many times their file size in voxels (a quick upper bound)
_COMPRESSION = 4.0


@dataclass
class MemoryPlan:
    """How a command will hold a series.

    mode : "memory" (load whole), "overview" (load downsampled by ``downsample`` per axis),
        "cache" (the voxels memory-mapped from the cache file in ``cache``: ``io/voxcache``), "refuse" (``reason`` says what would fit) or "unknown" (no estimate: not a series).
    need_bytes : the estimated peak; limit_bytes : what the command may use; limit_source :
        "memory option", "CTUI_MEMORY" or "available"; series_bytes : nz x ny x nx x 2.
    shape : (nz, ny, nx) of the series or None; fits : other ways that fit (text).
    """

    command: str
    mode: str
    reason: str
    need_bytes: int = 0
    limit_bytes: int = 0
    limit_source: str = "available"
    series_bytes: int = 0
    shape: tuple[int, int, int] | None = None
    downsample: int = 1
    fits: list[str] = field(default_factory=list)
    cache: str = ""

    def to_dict(self) -> dict:
        return asdict(self)

    def summary(self) -> str:
        return f"memory plan: {self.mode}: {self.reason}"


def _address_space() -> int | None:
    """RLIMIT_AS less what is mapped now and what the libraries will map (numba/LLVM and
    thread stacks reserve address space they never touch), or None without a limit."""
    try:
        import resource  # POSIX only

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, OSError, ValueError):
        return None
    if soft == resource.RLIM_INFINITY or soft <= 0:
        return None
    vm = 0
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                vm = int(line.split()[1]) * 1024
    except (OSError, ValueError):
        pass
    return max(0, int(soft) - vm - AS_OVERHEAD)


def memory_limit(memory: Any = None) -> tuple[int, str]:
    """(bytes, where from): the ``memory`` option, ``CTUI_MEMORY``, or what is available; an
    address-space limit (RLIMIT_AS) smaller than that wins."""
    if memory not in (None, ""):
        limit, source = (memory if isinstance(memory, int) else parse_memory(memory)), "memory option"
    elif os.environ.get("CTUI_MEMORY", "").strip():
        limit, source = parse_memory(os.environ["CTUI_MEMORY"], "CTUI_MEMORY"), "CTUI_MEMORY"
    else:
        limit, source = limits.available_memory(), "available"
    space = _address_space()
    if space is not None and space < limit:
        return space, "the address-space limit (RLIMIT_AS, less 700 MB the libraries reserve)"
    return limit, source


def _file_bytes(path: Path) -> tuple[int, bool]:
    """(bytes of the files at ``path``, any compressed), from directory entries only."""
    if path.is_file():
        return path.stat().st_size, path.name.lower().endswith((".gz", ".nrrd", ".nhdr", ".zip", ".mha"))
    total = 0
    for root, _, names in os.walk(path):
        for n in names:
            try:
                total += os.stat(os.path.join(root, n)).st_size
            except OSError:
                pass
    return total, True  # DICOM may be JPEG-compressed


def series_shape(path: Any, **load_options: Any) -> tuple[int, int, int] | None:
    """(nz, ny, nx) of the series a loader would load (headers only; None when unknown),
    after ``crop`` and ``downsample``."""
    try:
        found = scan(path, shape=load_options.get("shape"), dtype=load_options.get("dtype"))
    except Exception:  # noqa: BLE001 - no estimate; the loader reports what is wrong
        return None
    if not found:
        return None
    pick = load_options.get("series")
    if isinstance(pick, int) and 0 <= pick < len(found):
        entry = found[pick]
    else:
        entry = max(found, key=lambda s: _voxels(s.get("shape_zyx")))  # the largest: an upper bound
    full = tuple(int(v) for v in entry.get("shape_zyx") or ())
    if len(full) != 3 or min(full) < 1:
        return None
    try:
        return make_plan(full, crop=load_options.get("crop"), downsample=load_options.get("downsample")).out_shape(full)
    except CtuiError:
        return None


def _voxels(shape: Any) -> int:
    try:
        n = 1
        for v in shape:
            n *= int(v)
        return n
    except (TypeError, ValueError):
        return 0


def estimate(command: str, series_bytes: int) -> int:
    fixed, factor = PEAKS.get(command, PEAKS["segment"])
    return int(fixed + factor * series_bytes)


def plan(command: str, path: Any, *, memory: Any = None, overview: bool = False, **load_options: Any) -> MemoryPlan:
    """The :class:`MemoryPlan` of ``command`` on the series at ``path`` (headers only);
    ``overview``: the command may work from a downsampled copy (volume rendering)."""
    limit, source = memory_limit(memory)
    try:
        p = Path(os.fspath(path[0] if isinstance(path, (list, tuple)) and path else path))
        if command not in PEAKS or not p.exists():
            raise ValueError
        nbytes, compressed = _file_bytes(p)
    except (OSError, ValueError, TypeError):  # a glob pattern, a name with NUL...: the loader says what is wrong
        return MemoryPlan(command, "unknown", "no estimate for this input", limit_bytes=limit, limit_source=source)
    bound = nbytes * (_COMPRESSION if compressed else 1.0)
    if estimate(command, int(bound)) <= limit:  # quick: the files alone show that it fits
        return MemoryPlan(command, "memory", f"{command} needs at most {fmt_bytes(estimate(command, int(bound)))} "
                          f"for these files, {_allowed(limit, source)}: in memory", estimate(command, int(bound)),
                          limit, source, int(bound))
    shape = series_shape(p, **load_options)
    if shape is None:
        return MemoryPlan(command, "unknown", "the series' size is unknown before loading", limit_bytes=limit,
                          limit_source=source)
    return decide(command, shape, limit=limit, source=source, overview=overview)


def _allowed(limit: int, source: str) -> str:
    if source == "available":
        return f"{fmt_bytes(limit)} is available"
    return f"{fmt_bytes(limit)} is allowed by {'the memory option' if source == 'memory option' else source}"


def _cached(command: str, need: int, limit: int, source: str, shape: tuple[int, int, int],
            overview: bool) -> MemoryPlan | None:
    """The "cache" plan when the command fits with the voxels memory-mapped (its peak less the
    series), unless a volume render fits from an overview (coarser, and no cache to write)."""
    if command not in CACHE_OK or source.startswith("the address-space") or need > limit:
        return None
    if overview and command in OVERVIEW_OK:
        return None  # the 2x/4x overview comes first for volume renders (see decide)
    sb = shape[0] * shape[1] * shape[2] * 2
    if disk_free() < 1.2 * sb:  # the voxels and their overviews (1/8 + 1/64)
        return None
    size = f"{shape[0]}x{shape[1]}x{shape[2]} ({fmt_bytes(sb)})"
    return MemoryPlan(command, "cache", f"{command} needs about {fmt_bytes(need + sb)} for {size} in memory, "
                      f"{_allowed(limit, source)}: the voxels memory-mapped from the cache in {cache_root()} "
                      f"(about {fmt_bytes(need)} in memory)",
                      need, limit, source, sb, shape, 1, [], str(cache_root()))


def decide(command: str, shape: tuple[int, int, int], *, limit: int, source: str = "available",
           overview: bool = False) -> MemoryPlan:
    """The plan for a series of ``shape`` (nz, ny, nx) against ``limit`` bytes."""
    nz, ny, nx = shape
    sb = nz * ny * nx * 2
    need = estimate(command, sb)
    size = f"{nz}x{ny}x{nx} ({fmt_bytes(sb)})"
    if need <= limit:
        return MemoryPlan(command, "memory", f"{command} needs about {fmt_bytes(need)} for {size}, "
                          f"{_allowed(limit, source)}: in memory", need, limit, source, sb, shape)
    fits = []
    cached = _cached(command, need - sb, limit, source, shape, overview)
    if cached is not None:
        return cached
    for d in (2, 4):
        sub = -(-nz // d) * -(-ny // d) * -(-nx // d) * 2
        if estimate(command, sub) <= limit:
            if overview and command in OVERVIEW_OK:
                return MemoryPlan(command, "overview", f"{command} needs about {fmt_bytes(need)} for {size}, "
                                  f"{_allowed(limit, source)}: from a {d}x overview "
                                  f"(about {fmt_bytes(estimate(command, sub))})", estimate(command, sub), limit,
                                  source, sb, shape, d)
            fits.append(f"downsample=({d}, {d}, {d}) (--downsample {d},{d},{d}; about {fmt_bytes(estimate(command, sub))})")
            break
    fixed, factor = PEAKS.get(command, PEAKS["segment"])
    zmax = int((limit - fixed) / (factor * ny * nx * 2)) if limit > fixed else 0
    if zmax >= 1:
        fits.append(f"a crop of at most {zmax} slices (--crop 0,{zmax},,,,)")
    what = (f"it would fit with {' or '.join(fits)}" if fits else
            f"nothing smaller fits: the command alone takes about {fmt_bytes(fixed)}")
    return MemoryPlan(command, "refuse", f"{command} needs about {fmt_bytes(need)} for {size} but "
                      f"{_allowed(limit, source)}; {what}", need, limit, source, sb, shape, 1, fits)
