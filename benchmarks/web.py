"""Time to the first slice and slice-step latency: `ctui web` in headless Chromium vs `ctui open`
in a terminal (a pty), the same CT, sixel images both ways, in one run.

Browser: from Page.navigate to the first image in xterm.js's image layer (page load, websocket,
the TUI's start, the series' load, sixel encode, transfer, decode, draw), and from a PageUp key
event to the image layer changing (checked in the page at every animation frame).
Terminal: `ctui open CT --graphics sixel` on a pty of the same cells (140x38, 9x17-pixel cells
reported by TIOCSWINSZ): from the spawn to the end of the first sixel sequence written, and from
writing PageUp to the end of the next one (the terminal's own decode and draw not included).

    python3 benchmarks/web.py [--ct PATH] [--steps 15]

Needs the web extra and Debian's chromium; the default CT is ../shared/data's TotalSegmentator abdomen.
"""

from __future__ import annotations

import argparse
import asyncio
import fcntl
import os
import pty
import select
import signal
import statistics
import struct
import sys
import termios
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "tui"))

COLS, ROWS, CELL = 140, 38, (9, 17)
#: a cheap signature of the image layer (sampled pixels), and a wait for it to change, in the page
SIG_JS = """window.__ctuiSig = () => {
  const c = document.querySelector('canvas.xterm-image-layer');
  if (!c || !c.width) return 0;
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  let s = 0;
  for (let i = 0; i < d.length; i += 4 * 97) s = (s * 31 + d[i] + d[i + 1] * 3 + d[i + 3]) % 1000000007;
  return s;
};
window.__ctuiChange = async (before, limit) => {
  const t0 = performance.now();
  while (performance.now() - t0 < limit) {
    const s = window.__ctuiSig();
    if (s && s !== before) return s;
    await new Promise(r => requestAnimationFrame(r));
  }
  return -1;
};"""


async def browser_run(ct: str, steps: int, profile: Path) -> dict:
    from web_browser import Browser, CtuiWeb, chromium

    exe = chromium()
    if exe is None:
        raise SystemExit("chromium is not installed (apt-get install chromium)")
    web = CtuiWeb(ct)
    try:
        async with Browser(exe, profile, width=COLS * CELL[0] + 20, height=ROWS * CELL[1] + 30) as b:
            await b.call("Page.addScriptToEvaluateOnNewDocument", source=SIG_JS)
            t0 = time.perf_counter()
            await b.open(web.url)
            sig = 0
            while not sig and time.perf_counter() - t0 < 180:
                sig = await b.evaluate("window.__ctuiSig ? window.__ctuiSig() : 0") or 0
                await asyncio.sleep(0.01)
            first = time.perf_counter() - t0
            await asyncio.sleep(2.0)  # the side panel settles
            sig = await b.evaluate("window.__ctuiSig()")
            lat = []
            for k in range(steps):
                key = ("PageUp", 33) if k % 2 == 0 else ("PageDown", 34)
                t = time.perf_counter()
                await b.press(key[0], key[0], key[1])
                new = await b.evaluate(f"window.__ctuiChange({sig}, 10000)")
                if new == -1:
                    raise RuntimeError("the slice did not change in the page")
                lat.append(time.perf_counter() - t)
                sig = new
                await asyncio.sleep(0.3)
            cells = await b.evaluate("(() => { const r = document.querySelector('.xterm-screen')"
                                     ".getBoundingClientRect(); return [r.width, r.height]; })()")
    finally:
        web.stop()
    return {"first_s": first, "step_s": lat, "screen_px": cells}


def _read_until(fd: int, buf: bytearray, marker_from: int, timeout: float) -> int | None:
    """Read the pty until a complete sixel sequence (ESC P ... q ... ESC \\) starts at or after
    ``marker_from`` in ``buf``; the index after it, or None on timeout."""
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < timeout:
        start = buf.find(b"\x1bP", marker_from)
        if start >= 0:
            end = buf.find(b"\x1b\\", start)
            if end >= 0 and b"q" in buf[start:end][:40]:
                return end + 2
            if end >= 0:
                marker_from = end + 2
                continue
        r, _, _ = select.select([fd], [], [], 0.05)
        if r:
            try:
                buf += os.read(fd, 1 << 20)
            except OSError:
                return None
    return None


def terminal_run(ct: str, steps: int) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "TERM": "xterm-256color", "COLORTERM": "truecolor",
           "CTUI_GRAPHICS": "sixel"}
    env.pop("CTUI_WEB", None)
    t0 = time.perf_counter()
    pid, fd = pty.fork()
    if pid == 0:  # the child: the pty's size in cells and pixels, then ctui
        fcntl.ioctl(0, termios.TIOCSWINSZ, struct.pack("HHHH", ROWS, COLS, COLS * CELL[0], ROWS * CELL[1]))
        os.execve(sys.executable, [sys.executable, "-m", "ctui.cli", "open", ct, "--graphics", "sixel"], env)
    buf = bytearray()
    try:
        end = _read_until(fd, buf, 0, 180)
        if end is None:
            raise RuntimeError("no sixel image from ctui in the terminal")
        first = time.perf_counter() - t0
        settle = time.perf_counter() + 2.0
        while time.perf_counter() < settle:  # drain the side panel's updates
            if select.select([fd], [], [], 0.05)[0]:
                buf += os.read(fd, 1 << 20)
        lat = []
        for k in range(steps):
            mark = len(buf)
            t = time.perf_counter()
            os.write(fd, b"\x1b[5~" if k % 2 == 0 else b"\x1b[6~")
            if _read_until(fd, buf, mark, 10) is None:
                raise RuntimeError("no new sixel image after the key")
            lat.append(time.perf_counter() - t)
            settle = time.perf_counter() + 0.3
            while time.perf_counter() < settle:
                if select.select([fd], [], [], 0.05)[0]:
                    buf += os.read(fd, 1 << 20)
        return {"first_s": first, "step_s": lat, "bytes": len(buf)}
    finally:
        os.kill(pid, signal.SIGTERM)
        os.waitpid(pid, 0)
        os.close(fd)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ct", default=str(ROOT.parent / "shared" / "data" / "totalseg_example" / "ct_abdomen_3mm.nii.gz"))
    ap.add_argument("--steps", type=int, default=15)
    args = ap.parse_args()
    import tempfile

    term = terminal_run(args.ct, args.steps)
    with tempfile.TemporaryDirectory() as tmp:
        web = asyncio.run(browser_run(args.ct, args.steps, Path(tmp) / "profile"))
    print(f"CT {Path(args.ct).name}, {COLS}x{ROWS} cells, sixel, {args.steps} slice steps (PageUp/PageDown)")
    print(f"{'':24}{'first slice s':>15}{'step median ms':>16}{'step p90 ms':>13}")
    for name, r in (("terminal (pty)", term), ("browser (ctui web)", web)):
        s = sorted(r["step_s"])
        p90 = s[min(len(s) - 1, int(round(0.9 * (len(s) - 1))))]
        print(f"{name:24}{r['first_s']:15.2f}{1000 * statistics.median(s):16.0f}{1000 * p90:13.0f}")
    print(f"browser / terminal step: {statistics.median(web['step_s']) / statistics.median(term['step_s']):.2f}x; "
          f"page's terminal {web['screen_px'][0]:.0f}x{web['screen_px'][1]:.0f} CSS px")
    return 0


if __name__ == "__main__":
    sys.exit(main())
