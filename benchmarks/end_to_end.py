"""Whole commands, start to exit, as a user meets them: ctui vs a SimpleITK + VTK script.

Run: ``python3 benchmarks/end_to_end.py [--shape 300,512,512] [--repeat 3] [--level 300]``

* A CT-like series (``benchmarks/isosurface.py``'s volume: body, spine, ribs, pelvis,
  skull cap, noise; 0.7 x 0.7 x 1.0 mm) is written once as DICOM with ctui's own writer
  (:func:`ctui.engine.io.phantom.write_series`) into ``benchmarks/_cache/`` (git-ignored).
* Every figure is the wall time of a fresh process (``subprocess``, start to exit),
  median of ``--repeat`` runs:

  - ``ctui mesh SERIES --iso L --out x.stl`` with a warm numba cache and with a cold one
    (an empty ``NUMBA_CACHE_DIR``: a fresh install; no background compilation);
  - the peer: a Python script doing SimpleITK series read + VTK flying edges (normals
    on) + binary STL write + vtkMassProperties (volume, area): what ``ctui mesh`` does;
  - ``ctui info SERIES`` (the goal is <= 1 s on 300 slices);
  - the bundled sample (``sample_data/phantom``): ``ctui mesh --iso 300`` and
    ``--method contours``, cold and warm cache (the goal: <= 3 s cold).

Ratios printed: ctui / peer (goal <= 1.2), cold / warm.

``--peers`` (issue 40) runs every whole command beside the script a user would write instead
(render of a big STL, measure, segment, info, mesh --iso, MIP, DVR, SEG export, DICOM load),
alternating, warm and cold: see ``benchmarks/e2e_peers.py``::

    nice -n 10 python3 benchmarks/end_to_end.py --peers --repeat 3 [--only render,info]

``--suite`` (issue 27) prints instead, in one run, the wall and CPU seconds (user + system of
the process and its children, ``os.wait4``: what a loaded machine inflates least) of fresh
processes for every command a user meets: ``ctui --help``, ``ctui info``, ``ctui mesh --iso``
on the big series (warm and cold numba cache) beside the SimpleITK + VTK script, ``ctui
segment`` + ``ctui mesh`` of a kidney (the TotalSegmentator abdomen of ``/work/shared/data``
written as DICOM, seeded at the right kidney's deepest voxel), ``ctui measure`` without and
with sections (``--path auto``), ``ctui export --format dicom-seg``, and the TUI's time to a
painted workspace and to the first slice on screen (the loading screen's preview) for the
series, the kidney project and a project of the big series (tmux, wall only). With ``--base TREE`` (an older
checkout: ``git worktree add /tmp/ctui-base fa2b183``) every row also runs that tree
(``PYTHONPATH``), interleaved run by run, for before/after figures from the same run::

    python3 benchmarks/end_to_end.py --suite --base /tmp/ctui-base --repeat 3
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
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "benchmarks" / "_cache"
SAMPLE = ROOT / "sample_data" / "phantom"

#: a peer script's reading of the DICOM series into a vtkImageData (SimpleITK then VTK, no copy)
SERIES_AS_VTK = """\
reader = sitk.ImageSeriesReader()
reader.SetFileNames(reader.GetGDCMSeriesFileNames(series))
img = reader.Execute()
arr = sitk.GetArrayViewFromImage(img)
vimg = vtk.vtkImageData()
vimg.SetDimensions(arr.shape[2], arr.shape[1], arr.shape[0])
vimg.SetSpacing(*img.GetSpacing())
"""

PEER = r"""
import sys, os
os.environ.setdefault("VTK_SMP_BACKEND_IN_USE", "STDThread")
import SimpleITK as sitk
import vtk
from vtk.util import numpy_support
series, level, out = sys.argv[1], float(sys.argv[2]), sys.argv[3]
""" + SERIES_AS_VTK + r"""vimg.SetOrigin(*img.GetOrigin())
vimg.GetPointData().SetScalars(numpy_support.numpy_to_vtk(arr.ravel(), deep=False))
fe = vtk.vtkFlyingEdges3D()
fe.SetInputData(vimg)
fe.SetValue(0, level)
fe.ComputeNormalsOn()
fe.ComputeScalarsOff()
fe.Update()
w = vtk.vtkSTLWriter()
w.SetFileTypeToBinary()
w.SetFileName(out)
w.SetInputConnection(fe.GetOutputPort())
w.Write()
mp = vtk.vtkMassProperties()
mp.SetInputConnection(fe.GetOutputPort())
mp.Update()
print(f"{fe.GetOutput().GetNumberOfCells()} triangles, volume {mp.GetVolume() / 1000:.2f} ml, area {mp.GetSurfaceArea():.0f} mm2")
"""


def make_series(shape: tuple[int, int, int]) -> Path:
    """The DICOM series (cached): benchmarks/_cache/ct_<z>x<y>x<x>/."""
    out = CACHE / f"ct_{shape[0]}x{shape[1]}x{shape[2]}"
    if (out / ".done").exists():
        return out
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from isosurface import make_ct

    from ctui.engine.core.volume import Volume
    from ctui.engine.io.phantom import write_series

    data = make_ct(shape)
    vol = Volume(data=data, spacing=(1.0, 0.7, 0.7), origin=(-180.0, -180.0, -150.0), modality="CT")
    if out.exists():
        shutil.rmtree(out)
    write_series(out, vol, description="ctui benchmark CT")
    (out / ".done").write_text("ok\n")
    return out


TREE = ROOT  # where ``python -m ctui.cli`` imports ctui from (--tree: an older checkout, for before/after)


CPU_TIMES: dict[str, float] = {}  # command line -> median CPU seconds (user + system) of its last median_run


def timed(cmd: list[str], env: dict | None = None, *, setup=None) -> tuple[float, str, float]:
    """(wall seconds, last stdout line, CPU seconds: user + system of the process and its children)."""
    if setup:
        setup()
    t = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=err, cwd=TREE)
        _, status, usage = os.wait4(proc.pid, 0)
        dt = time.perf_counter() - t
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(), err.read().decode()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}\n{stderr[-2000:]}")
    return dt, stdout.strip().splitlines()[-1] if stdout.strip() else "", usage.ru_utime + usage.ru_stime


def median_run(cmd, env=None, *, repeat: int, setup=None) -> tuple[float, str]:
    """Median wall time and the last output line; the median CPU time goes to CPU_TIMES (a
    loaded machine inflates wall times, CPU times much less)."""
    runs = [timed(cmd, env, setup=setup) for _ in range(repeat)]
    CPU_TIMES[" ".join(cmd)] = statistics.median(r[2] for r in runs)
    return statistics.median(r[0] for r in runs), runs[-1][1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", default="300,512,512")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--level", type=float, default=300.0)
    ap.add_argument("--skip-big", action="store_true", help="only the sample's cold/warm figures")
    ap.add_argument("--tree", default=None, help="run the ctui of this source tree (e.g. an older release unpacked "
                    "with git archive) for a before/after comparison")
    ap.add_argument("--suite", action="store_true", help="every command, wall and CPU seconds (issue 27)")
    ap.add_argument("--base", default=None, help="with --suite: an older tree run beside this one (before/after)")
    ap.add_argument("--no-tui", action="store_true", help="with --suite: skip the TUI rows")
    ap.add_argument("--peers", action="store_true", help="every command beside its peer script, warm and cold "
                    "(issue 40; benchmarks/e2e_peers.py)")
    ap.add_argument("--only", default="", help="with --peers: rows whose name contains one of these (comma list)")
    ap.add_argument("--verbose", action="store_true", help="with --peers: each side's last output line")
    args = ap.parse_args()
    if args.peers:
        from e2e_peers import run_peers
        from e2e_suite import make_kidney

        run_peers(args, make_series=make_series, make_kidney=make_kidney, peer_mesh=PEER)
        return
    if args.suite:
        from e2e_suite import run_suite

        run_suite(args, make_series=make_series, peer_source=PEER)
        return
    global TREE
    if args.tree:
        TREE = Path(args.tree).resolve()
    shape = tuple(int(v) for v in args.shape.split(","))
    tmp = Path(tempfile.mkdtemp(prefix="ctui-e2e-"))
    cold_dir = tmp / "numba-cold"
    base = dict(os.environ, CTUI_NO_PROGRESS="1", CTUI_NO_BACKGROUND_COMPILE="1")
    base.pop("CTUI_KERNELS", None)
    cold_env = dict(base, NUMBA_CACHE_DIR=str(cold_dir))

    def fresh_cache() -> None:
        shutil.rmtree(cold_dir, ignore_errors=True)
        cold_dir.mkdir()

    ctui = [sys.executable, "-m", "ctui.cli"]
    # warm the default cache (compile everything once) so "warm" means warm
    warm_mod = "ctui.engine.mesh.warm" if (TREE / "ctui/engine/mesh/warm.py").exists() else None
    if warm_mod:
        subprocess.run([sys.executable, "-m", warm_mod], env=base, check=True, cwd=TREE)
    else:  # an older tree: one run of each command compiles its kernels
        for method in ("marching-cubes", "contours"):
            subprocess.run(ctui + ["mesh", str(SAMPLE), "--iso", "300", "--method", method, "--out",
                                   str(tmp / "w.stl")], env=base, cwd=TREE, capture_output=True)
    rows = []
    for method in ("marching-cubes", "contours"):
        cmd = ctui + ["mesh", str(SAMPLE), "--iso", "300", "--method", method, "--out", str(tmp / "s.stl")]
        cold, _ = median_run(cmd, cold_env, repeat=args.repeat, setup=fresh_cache)
        cold_cpu = CPU_TIMES[" ".join(cmd)]
        warm, line = median_run(cmd, base, repeat=args.repeat)
        rows.append((f"sample mesh --method {method}", cold, warm, cold_cpu, CPU_TIMES[" ".join(cmd)]))
    print(f"{'command':40s} {'cold s':>8s} {'warm s':>8s} {'cold/warm':>9s}   {'cold cpu s':>10s} {'warm cpu s':>10s}")
    for name, cold, warm, ccpu, wcpu in rows:
        print(f"{name:40s} {cold:8.2f} {warm:8.2f} {cold / warm:9.2f}   {ccpu:10.2f} {wcpu:10.2f}")
    if args.skip_big:
        return
    t0 = time.perf_counter()
    series = make_series(shape)
    print(f"\nseries {series} ({shape[0]}x{shape[1]}x{shape[2]}; made or found in {time.perf_counter() - t0:.1f} s)")
    peer_py = tmp / "peer.py"
    peer_py.write_text(PEER)
    out = tmp / "big.stl"
    mesh_cmd = ctui + ["mesh", str(series), "--iso", str(args.level), "--out", str(out)]
    figures = {}
    figures["peer"] = median_run([sys.executable, str(peer_py), str(series), str(args.level), str(tmp / "peer.stl")],
                                 base, repeat=args.repeat) + (CPU_TIMES.popitem()[1],)
    figures["warm"] = median_run(mesh_cmd, base, repeat=args.repeat) + (CPU_TIMES.popitem()[1],)
    figures["cold"] = median_run(mesh_cmd, cold_env, repeat=args.repeat, setup=fresh_cache) + (CPU_TIMES.popitem()[1],)
    figures["info"] = median_run(ctui + ["info", str(series)], base, repeat=args.repeat) + (CPU_TIMES.popitem()[1],)
    names = {"peer": "peer (SimpleITK + VTK flying edges + STL + mass properties)",
             "warm": "ctui mesh --iso, warm cache", "cold": "ctui mesh --iso, cold cache (fresh install)",
             "info": "ctui info"}
    print(f"{'':62s} {'wall s':>7s} {'cpu s':>7s}")
    for k, (wall, line, cpu) in figures.items():
        print(f"{names[k]:62s} {wall:7.2f} {cpu:7.2f}   {line[:90] if k in ('peer', 'warm') else ''}")
    pw, pc = figures["peer"][0], figures["peer"][2]
    print(f"ratio ctui/peer: warm {figures['warm'][0] / pw:.2f} (cpu {figures['warm'][2] / pc:.2f}), "
          f"cold {figures['cold'][0] / pw:.2f} (cpu {figures['cold'][2] / pc:.2f})  (goal <= 1.2)")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
