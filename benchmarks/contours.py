"""Contour connecting: 300 slices of 512-point contours, minimum-area DP vs greedy shortest diagonal.

Run: ``python3 benchmarks/contours.py [--slices 300] [--points 512] [--repeat 5]``

Two stacks are tiled with both methods (after one warm-up call, so numba's cached
compile is excluded):

* "wobbly tube": a contour of ~512 points per slice whose radius and centre drift slowly
  (the common case: similar consecutive contours);
* "tilted, twisting": elongated elliptic contours (aspect 2.5) shifted 4 px and rotated
  12 degrees per slice (consecutive contours overlap only partly);
* "branching 1-2-1": an oval that splits into two lobes for 10 of every 20 slices (each
  split and join is tiled against a bridged composite contour).

Printed: median time, triangles, total area, triangle quality (4*sqrt(3)*A / sum of
squared edges: 1 equilateral, 0 degenerate; mean and 1st percentile), slivers
(quality < 0.05), watertightness, volume against the polygon-slab volume, peak memory
(tracemalloc, numpy allocations). The goal is <= 0.5 s for the 300 x 512 stack.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

# measure the compiled kernels, never the first-use fallback (ctui.engine.mesh.jit)
os.environ.setdefault("CTUI_KERNELS", "compiled")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def branching(n_slices: int, n_points: int) -> list[list[tuple[np.ndarray, bool]]]:
    """A tube that splits into two lobes for 10 of every 20 slices (1 -> 2 -> 1 branchings)."""
    t = np.linspace(0, 2 * np.pi, n_points, endpoint=False)
    r0 = n_points / (2 * np.pi)
    out = []
    for z in range(n_slices):
        if (z // 10) % 2:
            lobes = []
            for sx in (-1, 1):
                r = 0.45 * r0
                lobes.append((np.column_stack([300 + sx * 0.55 * r0 + r * np.cos(t[::2]), 300 + r * np.sin(t[::2])]),
                              False))
            out.append(lobes)
        else:
            out.append([(np.column_stack([300 + r0 * np.cos(t), 300 + 0.7 * r0 * np.sin(t)]), False)])
    return out


def stack(n_slices: int, n_points: int, *, tilt: bool) -> list[list[tuple[np.ndarray, bool]]]:
    r0 = n_points / (2 * np.pi)  # perimeter ~ n_points pixels -> ~n_points points at step 1
    out = []
    t = np.linspace(0, 2 * np.pi, n_points, endpoint=False)
    for z in range(n_slices):
        r = r0 * (1 + 0.15 * np.sin(z / 17.0)) * (1 + 0.05 * np.sin(5 * t + z / 9.0))
        cx = 300 + 20 * np.sin(z / 40.0)
        cy = 300 + 15 * np.cos(z / 33.0)
        if tilt:
            ang = np.deg2rad(12.0 * z)
            ex, ey = r * 1.5 * np.cos(t), r * 0.6 * np.sin(t)
            x = cx + 4.0 * z + ex * np.cos(ang) - ey * np.sin(ang)
            y = cy + ex * np.sin(ang) + ey * np.cos(ang)
        else:
            x, y = cx + r * np.cos(t), cy + r * np.sin(t)
        out.append([(np.column_stack([x, y]), False)])
    return out


def quality(mesh) -> tuple[float, float, float]:
    v = np.asarray(mesh.vertices, np.float64)
    f = np.asarray(mesh.faces, np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    s2 = ((b - a) ** 2).sum(1) + ((c - b) ** 2).sum(1) + ((a - c) ** 2).sum(1)
    q = 4 * np.sqrt(3) * area / np.maximum(s2, 1e-30)
    return float(q.mean()), float(np.percentile(q, 1)), float((q < 0.05).mean())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--slices", type=int, default=300)
    ap.add_argument("--points", type=int, default=512)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    from ctui.engine.mesh.contour_connect import connect_contours
    from ctui.engine.mesh.meshtools import mesh_report

    spacing = (1.0, 0.7, 0.7)
    cases = (("wobbly tube", stack(args.slices, args.points, tilt=False)),
             ("tilted, twisting", stack(args.slices, args.points, tilt=True)),
             ("branching 1-2-1", branching(args.slices, args.points)))
    for name, st in cases:
        slab = sum(abs(0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))
                   for sl in st for p, _ in sl) * np.prod(spacing)
        print(f"{name}: {args.slices} slices x {args.points} points")
        for method in ("dp", "greedy"):
            kw = dict(spacing=spacing, method=method, pixel_centres=False)
            connect_contours(st[:3], **kw)  # warm-up (numba cache)
            times = []
            for _ in range(args.repeat):
                t = time.perf_counter()
                mesh = connect_contours(st, **kw)
                times.append(time.perf_counter() - t)
            tracemalloc.start()
            connect_contours(st, **kw)
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            rep = mesh_report(mesh)
            qm, q1, sliver = quality(mesh)
            print(f"  {method:6s} median {np.median(times):.3f} s  {rep['triangles']} triangles  "
                  f"area {rep['area_mm2']:.0f} mm2  quality mean {qm:.3f} p1 {q1:.3f} slivers {100 * sliver:.2f} %  "
                  f"watertight {rep['watertight']}  volume/slab {rep['volume_ml'] * 1000 / slab:.4f}  "
                  f"peak {peak / 2**20:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
