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

Prints medians, the ratio and peak memory. Goal (issue 6): ctui median <= 50 ms.

    python3 benchmarks/tui.py [--n 60] [--size 160x50]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("TEXTUAL_COLOR_SYSTEM", "truecolor")  # before textual is imported
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402


def make_volume(nz: int = 24, n: int = 512):
    """A 512x512 CT-like series: body ellipse, organs, noise (HU)."""
    from ctui.engine.core.volume import Volume

    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32)
    data = np.full((nz, n, n), -1000, np.int16)
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
    return Volume(data, spacing=(2.5, 0.7, 0.7), modality="CT", window=(40.0, 400.0))


def _hook_display(app, stamps: list):
    """Wrap App._display: also turn the update into escape codes and stamp the time."""
    from textual._compositor import CompositorUpdate

    orig = app._display

    def display(screen, renderable):
        orig(screen, renderable)
        if renderable is not None and isinstance(renderable, CompositorUpdate):
            renderable.render_segments(app.console)
            stamps.append(time.perf_counter())

    app._display = display


async def _wait_frame(pilot, stamps: list, t0: float, ready, timeout: float = 5.0) -> float:
    end = time.perf_counter() + timeout
    while time.perf_counter() < end:
        if ready():
            after = [t for t in stamps if t > t0]
            if after:
                return after[-1] - t0
        await asyncio.sleep(0.0005)
    raise TimeoutError("frame not painted")


async def bench_ctui(vol, size, n: int) -> list[float]:
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
    times: list[float] = []
    async with app.run_test(size=size) as pilot:
        await pilot.pause(0.2)
        stamps: list[float] = []
        _hook_display(app, stamps)
        mv = app.workspace.main_view
        for i in range(n + 3):
            key = "pageup" if (i // 10) % 2 == 0 else "pagedown"
            z_before = sess.z
            t0 = time.perf_counter()
            await pilot.press(key)
            zt = sess.z
            assert zt != z_before, "slice did not change"
            dt = await _wait_frame(pilot, stamps, t0, lambda: mv.painted[0] is not None and mv.painted[0][0] == zt and mv.painted[1] > t0)
            if i >= 3:  # warm-up
                times.append(dt)
            await pilot.pause(0.01)
    return times


async def bench_brush(vol, size, n: int) -> list[float]:
    """Brush stroke: brush down (b), then each cursor step (l/h) paints a 3-px-radius dab;
    timed from the key to the painted frame showing it (issue 14 goal: <= 30 ms)."""
    from ctui.screens import graphics

    graphics._chosen = "halfblock"
    from ctui.screens.app import CtuiApp
    from ctui.screens.session import Session

    sess = Session(vol, source_path="bench")
    app = CtuiApp(session=sess, autosave_s=1e9)
    times: list[float] = []
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
            t0 = time.perf_counter()
            await pilot.press(key)
            dt = await _wait_frame(pilot, stamps, t0, lambda: ws.volumes.version > version and mv.painted[1] > t0)
            if i >= 3:
                times.append(dt)
            await pilot.pause(0.01)
    return times


async def bench_textual_image(vol, size, n: int) -> list[float]:
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
    times: list[float] = []
    async with app.run_test(size=size) as pilot:
        await pilot.pause(0.3)
        stamps: list[float] = []
        _hook_display(app, stamps)
        for i in range(n + 3):
            key = "pageup" if (i // 10) % 2 == 0 else "pagedown"
            t0 = time.perf_counter()
            await pilot.press(key)
            # the new image is painted on the next frame after the press was handled
            dt = await _wait_frame(pilot, stamps, t0, lambda: True)
            if i >= 3:
                times.append(dt)
            await pilot.pause(0.01)
    return times


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=60, help="slice changes timed per renderer")
    ap.add_argument("--size", default="160x50", help="terminal size COLSxROWS")
    ap.add_argument("--slices", type=int, default=24, help="slices of the series (e.g. 2000: a big series)")
    ap.add_argument("--profile", action="store_true", help="print where ctui's slice steps spend their time")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.lower().split("x"))
    import psutil

    proc = psutil.Process()
    vol = make_volume(args.slices)
    rss0 = proc.memory_info().rss
    if args.profile:
        import cProfile
        import pstats

        prof = cProfile.Profile()
        prof.enable()
        asyncio.run(bench_ctui(vol, (w, h), args.n))
        prof.disable()
        pstats.Stats(prof).sort_stats("cumulative").print_stats(40)
        return 0
    print(f"series {vol.shape} int16, terminal {w}x{h}, half-block, {args.n} slice changes each")
    ct = asyncio.run(bench_ctui(vol, (w, h), args.n))
    rss_ctui = proc.memory_info().rss
    ti = asyncio.run(bench_textual_image(vol, (w, h), max(args.n // 3, 10)))
    rss_peer = proc.memory_info().rss
    br = asyncio.run(bench_brush(vol, (w, h), max(args.n // 2, 10)))
    mc, mt = statistics.median(ct) * 1000, statistics.median(ti) * 1000
    print(f"ctui half-block         median {mc:7.1f} ms  p90 {np.percentile(ct, 90) * 1000:7.1f} ms  (n={len(ct)})")
    print(f"textual-image Halfcell  median {mt:7.1f} ms  p90 {np.percentile(ti, 90) * 1000:7.1f} ms  (n={len(ti)})")
    print(f"ratio textual-image / ctui: {mt / mc:.1f}x   goal ctui <= 50 ms: {'met' if mc <= 50 else 'NOT met'}")
    mb = statistics.median(br) * 1000
    print(f"ctui brush stroke step  median {mb:7.1f} ms  p90 {np.percentile(br, 90) * 1000:7.1f} ms  (n={len(br)})"
          f"   goal <= 30 ms: {'met' if mb <= 30 else 'NOT met'}")
    print(f"RSS: after volume {rss0 / 2**20:.0f} MiB, after ctui {rss_ctui / 2**20:.0f} MiB, after peer {rss_peer / 2**20:.0f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
