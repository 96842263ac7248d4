"""Surfaces of every object of a multi-label label map: one pass vs one pass per label.

Run: ``python3 benchmarks/multilabel.py [--shape 300,512,512] [--objects 10] [--repeat 3]``

A uint8 label map with ``--objects`` ellipsoids (two of them touching, one touching the
volume border) is built once; then, in one run:

* ctui one pass: :func:`ctui.engine.mesh.multilabel.multilabel_marching_cubes` (every object
  from one scan of the label map);
* ctui per label: plain (terraced) marching cubes of each object's mask inside its
  bounding box (what ``label_surfaces(smooth=False)`` did before the one-pass kernel);
* VTK ``vtkDiscreteFlyingEdges3D`` with all labels (threads on), the peer;
* scikit-image ``marching_cubes`` of each object's mask over the whole volume (the
  naive one pass per label).

All four must give the same triangle count per object (VTK's and scikit-image's
tables differ from ctui's on ambiguous faces, so their counts may differ slightly).
Times are medians after one warm-up call (numba's cached compile excluded).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

# measure the compiled kernels, never the first-use fallback (ctui.engine.mesh.jit)
os.environ.setdefault("CTUI_KERNELS", "compiled")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("VTK_SMP_BACKEND_IN_USE", "STDThread")


def make_labels(shape=(300, 512, 512), n=10, seed=0) -> np.ndarray:
    nz, ny, nx = shape
    rng = np.random.default_rng(seed)
    lab = np.zeros(shape, np.uint8)
    for k in range(1, n + 1):
        if k == 1:  # touches the volume border
            c = np.array([nx * 0.05, ny * 0.5, nz * 0.5])
            r = np.array([nx * 0.1, ny * 0.08, nz * 0.15])
        elif k == 3:  # touches object 2
            c2 = centres[2]
            r = np.array([nx * 0.06, ny * 0.06, nz * 0.1])
            c = c2 + np.array([radii[2][0] + r[0] * 0.8, 0, 0])
        else:
            r = rng.uniform(0.03, 0.1, 3) * np.array([nx, ny, nz])
            c = rng.uniform(0.2, 0.8, 3) * np.array([nx, ny, nz])
        centres[k], radii[k] = c, r
        lo = np.maximum(np.floor(c - r).astype(int), 0)
        hi = np.minimum(np.ceil(c + r).astype(int) + 1, [nx, ny, nz])
        zz, yy, xx = np.ogrid[lo[2]:hi[2], lo[1]:hi[1], lo[0]:hi[0]]
        inside = ((xx - c[0]) / r[0]) ** 2 + ((yy - c[1]) / r[1]) ** 2 + ((zz - c[2]) / r[2]) ** 2 <= 1
        sub = lab[lo[2]:hi[2], lo[1]:hi[1], lo[0]:hi[0]]
        sub[inside & (sub == 0)] = k
    return lab


centres: dict[int, np.ndarray] = {}
radii: dict[int, np.ndarray] = {}


def timed(fn, repeat):
    fn()  # warm-up
    ts = []
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts), ts, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", default="300,512,512")
    ap.add_argument("--objects", type=int, default=10)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    shape = tuple(int(s) for s in a.shape.split(","))
    t = time.perf_counter()
    lab = make_labels(shape, a.objects)
    ids = [int(i) for i in np.unique(lab) if i]
    print(f"label map {shape} uint8, {len(ids)} objects, built in {time.perf_counter() - t:.1f} s; "
          f"{os.cpu_count()} CPUs")

    from scipy.ndimage import find_objects

    from ctui.engine.mesh.marching import marching_cubes
    from ctui.engine.mesh.multilabel import multilabel_marching_cubes

    def one_pass():
        return multilabel_marching_cubes(lab)

    def per_label():
        out = {}
        for i, box in enumerate(find_objects(lab)):
            if box is None:
                continue
            sl = tuple(slice(max(s.start - 1, 0), s.stop + 1) for s in box)
            sub = np.pad(lab[sl] == i + 1, 1).view(np.uint8)
            v, f, _ = marching_cubes(sub, 0.5, normals=False)
            out[i + 1] = (v, f)
        return out

    results = {}
    m, ts, out = timed(one_pass, a.repeat)
    results["ctui one pass"] = m
    ntri = {k: len(f) for k, (v, f) in out.items()}
    print(f"ctui one pass      median {m:.3f} s  (runs {', '.join(f'{x:.3f}' for x in ts)})  "
          f"{sum(ntri.values())} triangles")
    m, ts, out = timed(per_label, a.repeat)
    results["ctui per label"] = m
    same = all(len(out[k][1]) == ntri[k] for k in ntri)
    print(f"ctui per label     median {m:.3f} s  (runs {', '.join(f'{x:.3f}' for x in ts)})  "
          f"{sum(len(f) for v, f in out.values())} triangles; same triangle counts as one pass: {same}")
    try:
        import vtk
        from vtk.util import numpy_support as ns

        img = vtk.vtkImageData()
        img.SetDimensions(shape[2], shape[1], shape[0])
        arr = ns.numpy_to_vtk(lab.ravel(), deep=False, array_type=vtk.VTK_UNSIGNED_CHAR)
        img.GetPointData().SetScalars(arr)

        def run_vtk():
            fe = vtk.vtkDiscreteFlyingEdges3D()
            fe.SetInputData(img)
            fe.ComputeNormalsOff()
            fe.ComputeGradientsOff()
            fe.ComputeScalarsOn()
            fe.SetNumberOfContours(len(ids))
            for j, k in enumerate(ids):
                fe.SetValue(j, k)
            fe.Update()
            return fe.GetOutput().GetNumberOfCells()

        m, ts, nt = timed(run_vtk, a.repeat)
        results["VTK discrete flying edges"] = m
        print(f"VTK discrete FE    median {m:.3f} s  (runs {', '.join(f'{x:.3f}' for x in ts)})  {nt} triangles")
    except ImportError:
        print("VTK: not installed (pip install '.[bench]')")
    try:
        from skimage.measure import marching_cubes as sk_mc

        def run_sk():
            return sum(len(sk_mc((lab == k).view(np.uint8), 0.5)[1]) for k in ids)

        m, ts, nt = timed(run_sk, 1)
        results["scikit-image per label"] = m
        print(f"skimage per label  median {m:.3f} s  (runs {', '.join(f'{x:.3f}' for x in ts)})  {nt} triangles")
    except ImportError:
        print("scikit-image: not installed")
    base = results["ctui one pass"]
    print("ratios (peer time / ctui one pass): "
          + "   ".join(f"{k}: {v / base:.2f}x" for k, v in results.items() if k != "ctui one pass"))


if __name__ == "__main__":
    main()
