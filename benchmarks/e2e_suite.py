"""``benchmarks/end_to_end.py --suite``: every command a user meets, fresh processes, wall and
CPU seconds, optionally beside an older tree (``--base``) in the same run. See that file's
docstring for what each row is."""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "benchmarks" / "_cache"
DATA = ROOT.parent / "shared" / "data" / "totalseg_example"
if not DATA.exists():
    DATA = Path("/work/shared/data/totalseg_example")
KIDNEY_RANGE = "-33:39"  # HU: what today's automatic range finds at the seed (older trees need one given)


def make_kidney() -> tuple[Path, str]:
    """The TotalSegmentator abdomen (30 x 101 x 122, 3 mm) written as a DICOM series (cached)
    and a seed "X,Y,Z" at the right kidney's (label 2) deepest voxel on the series' grid."""
    import numpy as np
    from scipy import ndimage

    from ctui.engine.actions.opened import open_input
    from ctui.engine.io.phantom import write_series
    from ctui.engine.io.series import load

    out = CACHE / "kidney_abdomen_3mm"
    seed_file = out / ".seed"
    if seed_file.exists():
        return out, seed_file.read_text().strip()
    vol = load(DATA / "ct_abdomen_3mm.nii.gz")
    labels = open_input(DATA / "ct_abdomen_3mm_labels.nii.gz").labels
    if out.exists():
        shutil.rmtree(out)
    write_series(out, vol, description="ctui benchmark abdomen")
    back = load(out)
    if back.shape != vol.shape or not np.array_equal(back.data, np.maximum(vol.data, -1024)):  # stored from -1024
        raise SystemExit("the abdomen written as DICOM does not read back on the same grid")
    depth = ndimage.distance_transform_edt(labels == 2, sampling=vol.spacing)
    z, y, x = np.unravel_index(int(np.argmax(depth)), depth.shape)
    seed = f"{x},{y},{z}"
    seed_file.write_text(seed + "\n")
    return out, seed


def _run(cmd: list[str], env: dict, cwd: Path) -> tuple[float, float, str, float]:
    """(wall s, CPU s of the process and its children, last stdout line, peak resident MB) of one
    fresh process."""
    t = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=err, cwd=cwd)
        _, status, usage = os.wait4(proc.pid, 0)
        dt = time.perf_counter() - t
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(errors="replace"), err.read().decode(errors="replace")
    code = os.waitstatus_to_exitcode(status)
    if code != 0 and not (code == 2 and "--help" in cmd):
        raise SystemExit(f"failed ({cwd}): {' '.join(cmd)}\n{stderr[-2000:]}")
    lines = stdout.strip().splitlines()
    return dt, usage.ru_utime + usage.ru_stime, lines[-1] if lines else "", usage.ru_maxrss / 1024


def tui_paint(path: Path, env: dict, cwd: Path, *, timeout: float = 60.0) -> tuple[float | None, float | None]:
    """Seconds from starting ``python -m ctui PATH`` in a private tmux (100 x 30) to the
    series' first slice on screen (the loading screen's preview, or the workspace when no
    preview was shown: small series, older trees) and to a painted workspace (the status
    line's "Slice"), read with capture-pane every 50 ms."""
    if shutil.which("tmux") is None:
        return None, None
    sock = ["tmux", "-L", f"ctui-e2e-{uuid.uuid4().hex[:6]}"]
    env = {k: v for k, v in env.items() if k not in ("TMUX", "TMUX_PANE")}
    work = tempfile.mkdtemp()
    pp = env.get("PYTHONPATH", "")
    cmd = (f"cd {cwd} && PYTHONPATH={pp} CTUI_AUTOSAVE_DIR={work}/as COLORTERM=truecolor {sys.executable} -m ctui "
           f"--graphics halfblock {path}; sleep 30")
    t0 = time.monotonic()
    subprocess.run(sock + ["new-session", "-d", "-s", "e2e", "-x", "100", "-y", "30", cmd], check=True, env=env)
    first = None
    try:
        while time.monotonic() - t0 < timeout:
            out = subprocess.run(sock + ["capture-pane", "-p", "-t", "e2e"], capture_output=True, text=True,
                                 env=env).stdout
            t = time.monotonic() - t0
            if first is None and "preview:" in out:
                first = t
            if "Slice" in out:
                return (first if first is not None else t), t
            time.sleep(0.05)
        return first, None
    finally:
        subprocess.run(sock + ["kill-server"], capture_output=True, env=env)
        shutil.rmtree(work, ignore_errors=True)


class Tree:
    """One source tree of ctui: how to run it and its private empty numba cache (cold runs)."""

    def __init__(self, name: str, root: Path, tmp: Path):
        self.name, self.root = name, root
        self.cold_dir = tmp / f"numba-cold-{name}"
        self.env = dict(os.environ, CTUI_NO_PROGRESS="1", CTUI_NO_BACKGROUND_COMPILE="1", PYTHONPATH=str(root))
        self.env.pop("CTUI_KERNELS", None)
        self.env.pop("NUMBA_CACHE_DIR", None)
        # as installed by pip: bytecode cached (PYTHONDONTWRITEBYTECODE=1, as on some build machines,
        # would compile every ctui module in every process: 0.1-0.2 s more per command)
        self.env.pop("PYTHONDONTWRITEBYTECODE", None)
        self.cold_env = dict(self.env, NUMBA_CACHE_DIR=str(self.cold_dir))

    def warm(self) -> None:
        subprocess.run([sys.executable, "-m", "compileall", "-q", "ctui"], env=self.env, check=True, cwd=self.root)
        if (self.root / "ctui/engine/mesh/warm.py").exists():
            subprocess.run([sys.executable, "-m", "ctui.engine.mesh.warm"], env=self.env, check=True, cwd=self.root)

    def run(self, args: list[str], *, cold: bool = False) -> tuple[float, float, str]:
        if cold:
            shutil.rmtree(self.cold_dir, ignore_errors=True)
            self.cold_dir.mkdir(parents=True)
        return _run([sys.executable, "-m", "ctui.cli", *args], self.cold_env if cold else self.env, self.root)


def _median(runs: list[tuple[float, float, str, float]]) -> tuple[float, float, str, float]:
    return (statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs), runs[-1][2],
            max(r[3] for r in runs))


def run_suite(args, *, make_series, peer_source: str) -> None:
    shape = tuple(int(v) for v in args.shape.split(","))
    tmp = Path(tempfile.mkdtemp(prefix="ctui-e2e-suite-"))
    trees = [Tree("now", ROOT, tmp)]
    if args.base:
        trees.insert(0, Tree("base", Path(args.base).resolve(), tmp))
    for t in trees:
        t.warm()
    series = make_series(shape)
    kidney, seed = make_kidney()
    proj = {t.name: tmp / f"kidney-{t.name}.ctui" for t in trees}
    for t in trees:  # the kidney project each tree measures and exports (made by that tree)
        t.run(["segment", str(kidney), "--seed", seed, f"--range={KIDNEY_RANGE}", "--project", str(proj[t.name])])
    out = tmp / "out"
    out.mkdir()
    big = f"big series {shape[0]}x{shape[1]}x{shape[2]}"
    rows: list[tuple[str, list[str] | None, bool]] = [
        ("ctui --help", ["--help"], False),
        (f"ctui info ({big})", ["info", str(series)], False),
        (f"ctui mesh --iso {args.level:g}, warm cache ({big})",
         ["mesh", str(series), "--iso", str(args.level), "--out", str(out / "big.stl")], False),
        (f"ctui mesh --iso {args.level:g}, cold cache ({big})",
         ["mesh", str(series), "--iso", str(args.level), "--out", str(out / "big.stl")], True),
        ("ctui segment kidney (abdomen 30x101x122)",
         ["segment", str(kidney), "--seed", seed, f"--range={KIDNEY_RANGE}", "--project", str(out / "k.ctui")], False),
        ("ctui mesh kidney project", ["mesh", "{proj}", "--out", str(out / "k.stl")], False),
        ("ctui measure kidney project", ["measure", "{proj}"], False),
        ("ctui measure kidney project --path auto", ["measure", "{proj}", "--path", "auto"], False),
        ("ctui export --format dicom-seg", ["export", "{proj}", "--format", "dicom-seg",
                                            "--out", str(out / "k-seg.dcm")], False),
    ]
    peer_py = tmp / "peer.py"
    peer_py.write_text(peer_source)
    peer_cmd = [sys.executable, str(peer_py), str(series), str(args.level), str(out / "peer.stl")]
    results: dict[tuple[str, str], tuple[float, float, str]] = {}
    peer_runs = []
    for name, argv, cold in rows:
        for t in trees:
            a = [str(proj[t.name]) if x == "{proj}" else x for x in argv]
            results[(name, t.name)] = _median([t.run(a, cold=cold) for _ in range(args.repeat)])
        if "warm cache" in name:  # the peer right beside ctui's big mesh
            peer_runs = [_run(peer_cmd, trees[-1].env, ROOT) for _ in range(args.repeat)]
    tui: dict[tuple[str, str], tuple[float | None, float | None]] = {}
    if not args.no_tui:
        big_proj = {t.name: tmp / f"big-{t.name}.ctui" for t in trees}
        for t in trees:  # a project of the big series (its body, grown from the centre: a large object)
            t.run(["segment", str(series), "--seed", f"{shape[2] // 2},{shape[1] // 2},{shape[0] // 2}",
                   "--range=-200:200", "--project", str(big_proj[t.name])])
        for what in ("series", "project", "big project"):
            for t in trees:
                p = {"series": series, "project": proj[t.name], "big project": big_proj[t.name]}[what]
                runs = [tui_paint(p, t.env, t.root) for _ in range(args.repeat)]
                med = [statistics.median(ok) if ok else None
                       for ok in ([r[i] for r in runs if r[i] is not None] for i in (0, 1))]
                tui[(what, t.name)] = (med[0], med[1])
    _print(rows, trees, results, _median(peer_runs), tui)
    shutil.rmtree(tmp, ignore_errors=True)


def _print(rows, trees, results, peer, tui) -> None:
    head = f"{'command (fresh process; median; peak MB: max)':56s}" + "".join(
        f" {t.name + ' wall':>10s} {t.name + ' cpu':>9s} {t.name + ' MB':>8s}" for t in trees)
    print(head)
    for name, _, _ in rows:
        print(f"{name:56s}" + "".join(f" {results[(name, t.name)][0]:10.2f} {results[(name, t.name)][1]:9.2f}"
                                      f" {results[(name, t.name)][3]:8.0f}" for t in trees))
    print(f"{'peer: SimpleITK + VTK flying edges + STL + mass props':56s} {peer[0]:10.2f} {peer[1]:9.2f} "
          f"{peer[3]:8.0f}")
    for t in trees:
        for name, _, _ in rows:
            if name.startswith("ctui mesh --iso"):
                w, c, line, _ = results[(name, t.name)]
                print(f"  {t.name}: {name.split(',')[1].strip():10s} ctui/peer wall {w / peer[0]:.2f}, "
                      f"cpu {c / peer[1]:.2f}  ({line[:80]})")
    print(f"  peer: {peer[2][:90]}")
    if tui:
        fmt = lambda v: "never" if v is None else f"{v:.2f} s"  # noqa: E731
        for what in ("series", "project", "big project"):
            cells = "".join(f"  {t.name}: first slice {fmt(tui[(what, t.name)][0])}, workspace "
                            f"{fmt(tui[(what, t.name)][1])}" for t in trees)
            label = {"series": "the big series", "project": "the kidney project",
                     "big project": "a project of the big series"}[what]
            print(f"TUI, {label:28s}{cells}")
