"""Bone isosurface of a 512x512x300 int16 CT-like volume: ctui vs VTK flying edges vs scikit-image.

Run: ``python3 benchmarks/isosurface.py [--shape 300,512,512] [--repeat 5] [--level 300]``

The volume (soft-tissue body in air, spine, ribs, pelvis-like shells, a skull-like
cap, 15 HU noise) is written once to a temporary .npy; each method then runs in its own
fresh process that loads it (memory-mapped pages read into RAM first) so that peak
memory is measured the same way for all three: after one warm-up call, the peak-RSS
counter is reset (/proc/self/clear_refs) and the peak over the timed calls minus the
RSS with the volume loaded is reported; the first call's peak (which includes loading
numba's cached machine code or VTK's libraries) is printed too. Times are medians over ``--repeat``
runs after one warm-up run (numba's cached compile and VTK's first-call set-up are
excluded, as a user's second call would see). VTK runs with
``VTK_SMP_BACKEND_IN_USE=STDThread`` (threads on), normals on, scalars off, like ctui.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# measure the compiled kernels, never the first-use fallback (ctui.engine.mesh.jit)
os.environ.setdefault("CTUI_KERNELS", "compiled")

ROOT = Path(__file__).resolve().parents[1]


def make_ct(shape=(300, 512, 512), seed=0) -> np.ndarray:
    """CT-like int16 volume (HU), spacing 0.7 x 0.7 x 1.0 mm (x, y, z)."""
    nz, ny, nx = shape
    rng = np.random.default_rng(seed)
    vol = np.empty(shape, np.int16)
    y, x = np.mgrid[:ny, :nx].astype(np.float32)
    cy, cx = ny / 2, nx / 2
    body = ((x - cx) / (0.42 * nx)) ** 2 + ((y - cy) / (0.33 * ny)) ** 2 <= 1.0
    for z in range(nz):
        zf = z / max(nz - 1, 1)
        s = np.where(body, 40.0, -1000.0).astype(np.float32)
        # spine: vertebral body with a cortical shell, along z, segmented
        r = np.hypot(x - cx, y - (cy + 0.2 * ny))
        seg = 0.5 + 0.5 * np.cos(2 * np.pi * z / 25.0)
        s = np.where(r < 0.05 * nx * (0.8 + 0.2 * seg), 250.0 + 500.0 * (r > 0.04 * nx), s)
        # ribs: elliptic rings in the upper 60 %, every 20 slices, 6 slices thick
        if zf > 0.4 and (z % 20) < 6:
            e = np.hypot((x - cx) / (0.38 * nx), (y - cy) / (0.29 * ny))
            s = np.where(np.abs(e - 1.0) < 0.025, 800.0, s)
        # pelvis-like shells in the lower 30 %
        if zf < 0.3:
            for sx in (-1, 1):
                e = np.hypot((x - cx - sx * 0.22 * nx) / (0.12 * nx), (y - cy) / (0.18 * ny))
                s = np.where(np.abs(e - 1.0) < 0.06 * (1.0 - zf), 900.0, s)
        # skull-like cap in the top 10 %
        if zf > 0.9:
            e = np.hypot((x - cx) / (0.3 * nx), (y - cy) / (0.25 * ny))
            s = np.where(np.abs(e - 0.8) < 0.05, 1200.0, s)
        s += rng.normal(0.0, 15.0, size=s.shape).astype(np.float32)
        vol[z] = np.clip(s, -1024, 3071).astype(np.int16)
    return vol


CHILD = r"""
import os, sys, json, time, resource
os.environ.setdefault("VTK_SMP_BACKEND_IN_USE", "STDThread")
import numpy as np
method, path, level, repeat = sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4])
spacing = (1.0, 0.7, 0.7)  # (dz, dy, dx)
if method == "vtk":
    import vtk
    from vtk.util import numpy_support
elif method == "skimage":
    from skimage.measure import marching_cubes as smc
else:
    try:
        from ctui.engine.mesh.surface import isosurface
    except ImportError:  # a tree from before the engine's stage packages (--base)
        from ctui.engine.surface import isosurface
vol = np.load(path)
vol = np.ascontiguousarray(vol)
def rss():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
def current():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
base = current()
def run():
    if method == "vtk":
        img = vtk.vtkImageData()
        img.SetDimensions(vol.shape[2], vol.shape[1], vol.shape[0])
        img.SetSpacing(spacing[2], spacing[1], spacing[0])
        arr = numpy_support.numpy_to_vtk(vol.ravel(), deep=False)
        img.GetPointData().SetScalars(arr)
        fe = vtk.vtkFlyingEdges3D()
        fe.SetInputData(img)
        fe.SetValue(0, level)
        fe.ComputeNormalsOn()
        fe.ComputeScalarsOff()
        fe.ComputeGradientsOff()
        fe.Update()
        out = fe.GetOutput()
        return out.GetNumberOfPoints(), out.GetNumberOfCells(), out
    if method == "skimage":
        v, f, n, _ = smc(vol, level, spacing=spacing)
        return len(v), len(f), (v, f, n)
    m = isosurface(vol, level, spacing=spacing)
    return m.n_vertices, m.n_faces, m
nv, nf, keep = run()   # warm-up (numba cache load, VTK set-up)
first_peak = rss()
del keep
import gc; gc.collect()
base2 = current()
def hwm():
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
try:
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")  # reset the peak-RSS counter (Linux >= 4.0)
    reset = True
except OSError:
    reset = False
times, cpu = [], []
for _ in range(repeat):
    t, c = time.perf_counter(), time.process_time()
    nv, nf, keep = run()
    times.append(time.perf_counter() - t); cpu.append(time.process_time() - c); del keep
peak = hwm() if reset else rss()
print(json.dumps({"method": method, "times": times, "cpu": cpu, "vertices": nv, "triangles": nf,
                  "peak_over_volume_mb": (peak - base2) / 2**20, "first_call_peak_mb": (first_peak - base) / 2**20,
                  "volume_mb": vol.nbytes / 2**20}))
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", default="300,512,512", help="z,y,x")
    ap.add_argument("--level", type=float, default=300.0, help="bone threshold (HU)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--methods", default="ctui,vtk,skimage")
    ap.add_argument("--base", default=None, help="an older ctui tree (git worktree add /tmp/ctui-base REV): its "
                    "kernel and this tree's, alternately in fresh processes, --rounds times (wall and CPU)")
    ap.add_argument("--rounds", type=int, default=4)
    args = ap.parse_args()
    if args.base:
        return compare_trees(Path(args.base).resolve(), tuple(int(s) for s in args.shape.split(",")), args)
    shape = tuple(int(s) for s in args.shape.split(","))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "ct.npy"
        t = time.perf_counter()
        np.save(path, make_ct(shape))
        print(f"volume {shape} int16 built in {time.perf_counter() - t:.1f} s; level {args.level} HU; "
              f"{os.cpu_count()} CPUs")
        results = {}
        env = dict(os.environ, VTK_SMP_BACKEND_IN_USE="STDThread", PYTHONPATH=str(ROOT))
        for method in args.methods.split(","):
            rep = args.repeat if method != "skimage" else max(1, min(args.repeat, 3))
            out = subprocess.run([sys.executable, "-c", CHILD, method, str(path), str(args.level), str(rep)],
                                 capture_output=True, text=True, env=env)
            if out.returncode != 0:
                print(f"{method}: failed\n{out.stderr[-2000:]}")
                continue
            r = json.loads(out.stdout.strip().splitlines()[-1])
            r["median"] = float(np.median(r["times"]))
            results[method] = r
            print(f"{method:8s} median {r['median']:.3f} s  (runs {', '.join(f'{t:.3f}' for t in r['times'])})  "
                  f"{r['vertices']} vertices {r['triangles']} triangles  "
                  f"peak memory over the loaded volume {r['peak_over_volume_mb']:.0f} MB "
                  f"(first call incl. one-time set-up {r['first_call_peak_mb']:.0f} MB; volume {r['volume_mb']:.0f} MB)")
        if "ctui" in results:
            c = results["ctui"]["median"]
            for peer in ("vtk", "skimage"):
                if peer in results:
                    p = results[peer]
                    print(f"ratio {peer}/ctui time: {p['median'] / c:.2f}x   "
                          f"memory ctui/{peer}: {results['ctui']['peak_over_volume_mb'] / max(p['peak_over_volume_mb'], 1e-9):.2f}")
    return 0


def compare_trees(base: Path, shape: tuple[int, int, int], args) -> int:
    """This tree's ctui kernel against ``base``'s: fresh processes, alternating order per round,
    ``--repeat`` timed calls each after a warm-up; minimum and median wall and CPU seconds."""
    trees = {"base": base, "now": ROOT}
    got: dict[str, dict[str, list[float]]] = {k: {"times": [], "cpu": []} for k in trees}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "ct.npy"
        np.save(path, make_ct(shape))
        for r in range(args.rounds):
            for name in (list(trees) if r % 2 == 0 else list(trees)[::-1]):
                env = dict(os.environ, PYTHONPATH=str(trees[name]))
                out = subprocess.run([sys.executable, "-c", CHILD, "ctui", str(path), str(args.level), str(args.repeat)],
                                     capture_output=True, text=True, env=env, cwd=trees[name])
                if out.returncode != 0:
                    print(f"{name}: failed\n{out.stderr[-2000:]}")
                    return 1
                res = json.loads(out.stdout.strip().splitlines()[-1])
                for k in ("times", "cpu"):
                    got[name][k] += res.get(k, [])
    print(f"isosurface kernel {shape} at {args.level:g} HU, {args.rounds} rounds x {args.repeat} calls")
    for name, d in got.items():
        print(f"{name:5s} wall min {min(d['times']):.3f} median {np.median(d['times']):.3f} s   "
              f"cpu min {min(d['cpu']):.3f} median {np.median(d['cpu']):.3f} s   ({trees[name]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
