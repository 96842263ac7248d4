"""Time from starting ``ctui`` (bundled sample or PATH, in a private tmux server at 100x30) to
the first text on screen, the loading screen, the series' middle slice shown before the rest
is read (the loading screen's preview, large series only) and the workspace, read with
capture-pane every 50 ms. Issue 23: something on screen within 1 s of the command; issue 27:
the first slice within 1 s.

    python3 benchmarks/first_paint.py [--runs 3] [--base TREE] [PATH]

The big series of ``benchmarks/end_to_end.py`` is ``benchmarks/_cache/ct_300x512x512``. With
``--base`` (an older checkout: ``git worktree add /tmp/ctui-base REV``) each run starts that
tree and this one in turn, and the medians of both are printed (wall seconds, and the ctui
process's CPU seconds at the first slice and at the workspace).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import uuid


def _cpu_of_ctui(sock: list[str], env: dict) -> float | None:
    """CPU seconds (user + system, all threads) the ctui process has used so far: the pane's
    shell's child, read from /proc (Linux); None elsewhere."""
    try:
        shell = subprocess.run(sock + ["list-panes", "-t", "fp", "-F", "#{pane_pid}"], capture_output=True,
                               text=True, env=env).stdout.split()[0]
        with open(f"/proc/{shell}/task/{shell}/children") as fh:
            kids = fh.read().split()
        for pid in kids:
            with open(f"/proc/{pid}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
            if fields:
                return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime
    except (OSError, IndexError, ValueError):
        return None
    return None


def one_run(path: str = "", tree: str | None = None) -> tuple[float | None, ...]:
    """(first text, loading screen, preview, workspace) seconds of wall time, then the ctui
    process's CPU seconds at the preview and at the workspace; ``tree``: the ctui source tree
    to run (PYTHONPATH), else the installed one."""
    sock = ["tmux", "-L", f"ctui-fp-{uuid.uuid4().hex[:6]}"]
    env = {k: v for k, v in os.environ.items() if k not in ("TMUX", "TMUX_PANE")}
    if tree:
        env["PYTHONPATH"] = tree
    work = tempfile.mkdtemp()
    cmd = (f"cd {work} && CTUI_AUTOSAVE_DIR={work}/as COLORTERM=truecolor {sys.executable} -m ctui "
           f"--graphics halfblock {path}; sleep 30")
    t0 = time.monotonic()
    subprocess.run(sock + ["new-session", "-d", "-s", "fp", "-x", "100", "-y", "30", cmd], check=True, env=env)
    first = loading = preview = ready = cpu_preview = cpu_ready = None
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
                cpu_preview = _cpu_of_ctui(sock, env)
            if "Slice" in out:
                ready = t
                cpu_ready = _cpu_of_ctui(sock, env)
                break
            time.sleep(0.05)
    finally:
        subprocess.run(sock + ["kill-server"], capture_output=True, env=env)
        shutil.rmtree(work, ignore_errors=True)
    return first, loading, preview, ready, cpu_preview, cpu_ready


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--base", default=None, help="an older tree started in turn with this one (medians of both)")
    ap.add_argument("path", nargs="?", default="", help="a series or project (default: the bundled sample)")
    args = ap.parse_args()
    if shutil.which("tmux") is None:
        print("tmux is not installed", file=sys.stderr)
        return 2
    path = os.path.abspath(args.path) if args.path else ""
    trees = {"base": os.path.abspath(args.base), "now": os.path.dirname(os.path.dirname(os.path.abspath(__file__)))} \
        if args.base else {"": None}
    runs: dict[str, list] = {k: [] for k in trees}
    fmt = lambda v: "never" if v is None else f"{v:.2f} s"  # noqa: E731
    for i in range(args.runs):
        for name, tree in trees.items():
            first, loading, preview, ready, cpu_pv, cpu_ws = r = one_run(path, tree)
            runs[name].append(r)
            print(f"run {i + 1}{' ' + name if name else ''}: first text {fmt(first)}, loading screen {fmt(loading)}, "
                  f"first slice (preview) {fmt(preview)} (cpu {fmt(cpu_pv)}), workspace {fmt(ready)} (cpu {fmt(cpu_ws)})")
    if args.base:
        for name, rs in runs.items():
            med = [statistics.median(v) if v else None for v in ([r[j] for r in rs if r[j] is not None] for j in range(6))]
            print(f"{name} median of {len(rs)}: loading screen {fmt(med[1])}, first slice {fmt(med[2])} (cpu "
                  f"{fmt(med[4])}), workspace {fmt(med[3])} (cpu {fmt(med[5])})  ({trees[name]})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
