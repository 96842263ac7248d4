"""Time from starting ``ctui`` (bundled sample or PATH, in a private tmux server at 100x30) to
the first text on screen, the loading screen, the series' middle slice shown before the rest
is read (the loading screen's preview, large series only) and the workspace, read with
capture-pane every 50 ms. Issue 23: something on screen within 1 s of the command; issue 27:
the first slice within 1 s.

    python3 benchmarks/first_paint.py [--runs 3] [PATH]

The big series of ``benchmarks/end_to_end.py`` is ``benchmarks/_cache/ct_300x512x512``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
import uuid


def one_run(path: str = "") -> tuple[float | None, float | None, float | None, float | None]:
    sock = ["tmux", "-L", f"ctui-fp-{uuid.uuid4().hex[:6]}"]
    env = {k: v for k, v in os.environ.items() if k not in ("TMUX", "TMUX_PANE")}
    work = tempfile.mkdtemp()
    cmd = (f"cd {work} && CTUI_AUTOSAVE_DIR={work}/as COLORTERM=truecolor {sys.executable} -m ctui "
           f"--graphics halfblock {path}; sleep 30")
    t0 = time.monotonic()
    subprocess.run(sock + ["new-session", "-d", "-s", "fp", "-x", "100", "-y", "30", cmd], check=True, env=env)
    first = loading = preview = ready = None
    try:
        while time.monotonic() - t0 < 60:
            out = subprocess.run(sock + ["capture-pane", "-p", "-t", "fp"], capture_output=True, text=True,
                                 env=env).stdout
            t = time.monotonic() - t0
            if first is None and out.strip():
                first = t
            if loading is None and "Loading" in out:
                loading = t
            if preview is None and "preview:" in out:
                preview = t
            if "Slice" in out:
                ready = t
                break
            time.sleep(0.05)
    finally:
        subprocess.run(sock + ["kill-server"], capture_output=True, env=env)
        shutil.rmtree(work, ignore_errors=True)
    return first, loading, preview, ready


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("path", nargs="?", default="", help="a series or project (default: the bundled sample)")
    args = ap.parse_args()
    if shutil.which("tmux") is None:
        print("tmux is not installed", file=sys.stderr)
        return 2
    for i in range(args.runs):
        first, loading, preview, ready = one_run(os.path.abspath(args.path) if args.path else "")
        fmt = lambda v: "never" if v is None else f"{v:.2f} s"  # noqa: E731
        print(f"run {i + 1}: first text {fmt(first)}, loading screen {fmt(loading)}, first slice (preview) "
              f"{fmt(preview)}, workspace {fmt(ready)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
