"""Key-to-paint latency of a slice change in the TUI, ctui vs textual-image, in one run
(and of a brush stroke step in ctui).

ctui: the real app (WorkspaceScreen, half-block renderer forced, overlay view with one
object, side panel updated) on a 512x512-pixel CT-like series at a 160x50 terminal; each PageUp/PageDown is timed from the key press
until the frame holding the new slice has been composed AND turned into terminal
escape codes (the headless driver skips that step, so the benchmark does it itself in
App._display with a truecolor console, as a real terminal session would).

Peer: textual-image's own half-block widget (HalfcellImage) in a minimal app of the
same size, given the same windowed 512x512 slice as a PIL image on each key press
(what an app without ctui's renderer would do), timed the same way.

Prints medians and p90 of the wall time and of the process's CPU time (every thread, key to
frame: comparable on a loaded machine), the ratio and memory. Goal (issues 6, 40): a slice
step and a brush step <= 50 ms median, at 24 and at 2,000 slices.

    python3 benchmarks/tui.py [--n 60] [--size 160x50]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("TEXTUAL_COLOR_SYSTEM", "truecolor")  # before textual is imported
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402


def make_volume(nz: int = 24, n: int = 512, *, cache_dir: str | None = None):
    """A 512x512 CT-like series: body ellipse, organs, noise (HU). With ``cache_dir`` its voxels
    are written there as ``voxels.npy`` and memory-mapped copy-on-write, as the voxel cache
    (``engine/io/voxcache``) holds a series too big for memory: the TUI then reads every
    slice from the file's pages."""
    from ctui.engine.core.volume import Volume

    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32)
    target = None if cache_dir is None else os.path.join(cache_dir, "voxels.npy")
    data = np.lib.format.open_memmap(target, mode="w+", dtype=np.int16, shape=(nz, n, n)) if target else np.empty((nz, n, n), np.int16)
    for z in range(nz):
        body = ((xx - n / 2) / (0.45 * n)) ** 2 + ((yy - n / 2) / (0.33 * n)) ** 2 <= 1
        k1 = ((xx - 0.32 * n - z) / (0.06 * n)) ** 2 + ((yy - 0.6 * n) / (0.09 * n)) ** 2 <= 1
        k2 = ((xx - 0.68 * n + z) / (0.06 * n)) ** 2 + ((yy - 0.6 * n) / (0.09 * n)) ** 2 <= 1
        sp = (xx - n / 2) ** 2 + (yy - 0.72 * n) ** 2 <= (0.05 * n) ** 2
        sl = np.where(body, 40, -1000).astype(np.float32)
        sl[k1 | k2] = 200
        sl[sp] = 700
        sl += rng.normal(0, 12, (n, n)).astype(np.float32)
        data[z] = sl.astype(np.int16)
    meta = {}
    if target:
        data.flush()
        del data
        data = np.load(target, mmap_mode="c")  # what voxcache._open gives
        meta["voxel_cache"] = cache_dir
    vol = Volume(data, spacing=(2.5, 0.7, 0.7), modality="CT", window=(40.0, 400.0))
    vol.meta.update(meta)
    return vol


def _hook_display(app, stamps: list):
    """Wrap App._display: also turn the update into escape codes and stamp the time."""
    from textual._compositor import CompositorUpdate

    orig = app._display

    def display(screen, renderable):
        orig(screen, renderable)
        if renderable is not None and isinstance(renderable, CompositorUpdate):
            renderable.render_segments(app.console)
            stamps.append((time.perf_counter(), time.process_time()))

    app._display = display


async def _wait_frame(pilot, stamps: list, t0: float, ready, timeout: float = 5.0, cpu0: float | None = None):
    """Seconds from ``t0`` to the last frame painted once ``ready()``; with ``cpu0`` (the
    process CPU time at ``t0``) also the CPU seconds of every thread until that frame: the
    figure that still means something on a loaded machine."""
    end = time.perf_counter() + timeout
    while time.perf_counter() < end:
        if ready():
            after = [t for t in stamps if t[0] > t0]
            if after:
                return after[-1][0] - t0 if cpu0 is None else (after[-1][0] - t0, after[-1][1] - cpu0)
        await asyncio.sleep(0.0005)
    raise TimeoutError("frame not painted")


async def bench_ctui(vol, size, n: int) -> list[tuple[float, float]]:
    from ctui.screens import graphics

    graphics._chosen = "halfblock"
    from ctui.screens.app import CtuiApp
    from ctui.screens.session import Session

    sess = Session(vol, source_path="bench")
    sess.view = "overlay"  # the default view, with an object coloured over the slice
    sess.seg.add_object()
    yy, xx = np.mgrid[0:vol.shape[1], 0:vol.shape[2]]
    disk = (xx - 0.32 * vol.shape[2]) ** 2 + (yy - 0.6 * vol.shape[1]) ** 2 <= (0.05 * vol.shape[1]) ** 2
    sess.seg.labels[:, disk] = 1
    app = CtuiApp(session=sess)
    times: list[tuple[float, float]] = []  # (wall, CPU) seconds per key
    async with app.run_test(size=size) as pilot:
        await pilot.pause(0.2)
        stamps: list[float] = []
        _hook_display(app, stamps)
        mv = app.workspace.main_view
        for i in range(n + 3):
            key = "pageup" if (i // 10) % 2 == 0 else "pagedown"
            z_before = sess.z
            t0, c0 = time.perf_counter(), time.process_time()
            await pilot.press(key)
            zt = sess.z
            assert zt != z_before, "slice did not change"
            dt = await _wait_frame(pilot, stamps, t0, lambda: mv.painted[0] is not None and mv.painted[0][0] == zt and mv.painted[1] > t0,
                                   cpu0=c0)
            if i >= 3:  # warm-up
                times.append(dt)
            await pilot.pause(0.01)
    return times


async def bench_brush(vol, size, n: int) -> list[tuple[float, float]]:
    """Brush stroke: brush down (b), then each cursor step (l/h) paints a 3-px-radius dab;
    timed from the key to the painted frame showing it (issue 14 goal: <= 30 ms)."""
    from ctui.screens import graphics

    graphics._chosen = "halfblock"
    from ctui.screens.app import CtuiApp
    from ctui.screens.session import Session

    sess = Session(vol, source_path="bench")
    app = CtuiApp(session=sess, autosave_s=1e9)
    times: list[tuple[float, float]] = []  # (wall, CPU) seconds per key
    async with app.run_test(size=size) as pilot:
        await pilot.pause(0.2)
        stamps: list[float] = []
        _hook_display(app, stamps)
        ws = app.workspace
        mv = ws.main_view
        await pilot.press("b")
        for i in range(n + 3):
            key = "l"  # always onto new pixels (a step back over the stroke paints nothing: no new frame)
            version = ws.volumes.version
            t0, c0 = time.perf_counter(), time.process_time()
            await pilot.press(key)
            dt = await _wait_frame(pilot, stamps, t0, lambda: ws.volumes.version > version and mv.painted[1] > t0, cpu0=c0)
            if i >= 3:
                times.append(dt)
            await pilot.pause(0.01)
    return times


async def bench_textual_image(vol, size, n: int) -> list[tuple[float, float]]:
    from PIL import Image as PILImage
    from textual.app import App
    from textual.binding import Binding
    from textual_image.widget import HalfcellImage

    from ctui.engine.core.windows import apply_window

    class Peer(App):
        CSS = "HalfcellImage { width: 1fr; height: 1fr; }"
        BINDINGS = [Binding("pageup", "step(1)"), Binding("pagedown", "step(-1)")]

        def __init__(self) -> None:
            super().__init__()
            self.z = vol.shape[0] // 2
            self.rendered_z = None

        def compose(self):
            yield HalfcellImage(id="img")

        def on_mount(self) -> None:
            self.show()

        def show(self) -> None:
            img = apply_window(vol.data[self.z], (40.0, 400.0))
            self.query_one(HalfcellImage).image = PILImage.fromarray(img)
            self.rendered_z = self.z

        def action_step(self, d: int) -> None:
            self.z = int(np.clip(self.z + d, 0, vol.shape[0] - 1))
            self.show()

    app = Peer()
    times: list[tuple[float, float]] = []  # (wall, CPU) seconds per key
    async with app.run_test(size=size) as pilot:
        await pilot.pause(0.3)
        stamps: list[float] = []
        _hook_display(app, stamps)
        for i in range(n + 3):
            key = "pageup" if (i // 10) % 2 == 0 else "pagedown"
            t0, c0 = time.perf_counter(), time.process_time()
            await pilot.press(key)
            # the new image is painted on the next frame after the press was handled
            dt = await _wait_frame(pilot, stamps, t0, lambda: True, cpu0=c0)
            if i >= 3:
                times.append(dt)
            await pilot.pause(0.01)
    return times


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=60, help="slice changes timed per renderer")
    ap.add_argument("--size", default="160x50", help="terminal size COLSxROWS")
    ap.add_argument("--slices", type=int, default=24, help="slices of the series (e.g. 2000: a big series)")
    ap.add_argument("--memmap", choices=("auto", "yes", "no"), default="auto",
                    help="the voxels memory-mapped from a .npy as the voxel cache holds them (auto: from 1,000 slices)")
    ap.add_argument("--profile", nargs="?", const="step", choices=("step", "brush"),
                    help="print where ctui's slice steps (or brush steps) spend the main thread's CPU time")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.lower().split("x"))
    import psutil

    proc = psutil.Process()
    memmap = args.memmap == "yes" or (args.memmap == "auto" and args.slices >= 1000)
    tmp = tempfile.TemporaryDirectory(prefix="ctui-bench-tui-") if memmap else None
    vol = make_volume(args.slices, cache_dir=tmp.name if tmp else None)
    rss0 = proc.memory_info().rss
    if args.profile:
        import cProfile
        import pstats

        prof = cProfile.Profile(time.thread_time)  # the main thread's CPU: meaningful on a loaded machine
        prof.enable()
        asyncio.run((bench_brush if args.profile == "brush" else bench_ctui)(vol, (w, h), args.n))
        prof.disable()
        pstats.Stats(prof).sort_stats("cumulative").print_stats(50)
        return 0
    print(f"series {vol.shape} int16{' memory-mapped (voxel cache)' if memmap else ''}, terminal {w}x{h}, half-block, {args.n} slice changes each")
    ct = asyncio.run(bench_ctui(vol, (w, h), args.n))
    rss_ctui = proc.memory_info().rss
    ti = asyncio.run(bench_textual_image(vol, (w, h), max(args.n // 3, 10)))
    rss_peer = proc.memory_info().rss
    br = asyncio.run(bench_brush(vol, (w, h), max(args.n // 2, 10)))

    def line(name: str, ts: list[tuple[float, float]], goal: float | None = None) -> float:
        wall = [t[0] * 1000 for t in ts]
        cpu = [t[1] * 1000 for t in ts]
        med = statistics.median(wall)
        verdict = "" if goal is None else f"   goal <= {goal:g} ms: {'met' if med <= goal else 'NOT met'}"
        print(f"{name:<24}median {med:7.1f} ms  p90 {np.percentile(wall, 90):7.1f} ms   "
              f"CPU median {statistics.median(cpu):6.1f} ms  p90 {np.percentile(cpu, 90):6.1f} ms  (n={len(ts)}){verdict}")
        return med

    mc = line("ctui slice step", ct, 50)
    mt = line("textual-image Halfcell", ti)
    mb = line("ctui brush stroke step", br, 50)
    print(f"ratio textual-image / ctui (slice step): {mt / mc:.1f}x; brush / peer's slice step {mb / mt:.2f}x")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores: CPU ms (all threads, key to frame) "
          f"compare on a loaded machine, wall ms do not")
    print(f"RSS: after volume {rss0 / 2**20:.0f} MiB, after ctui {rss_ctui / 2**20:.0f} MiB, after peer {rss_peer / 2**20:.0f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
