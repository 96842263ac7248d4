"""Benchmark: cross-sections every 0.5 mm along a 200 mm path through a 512x512x300 volume.

Goal (issue 7): <= 2 s for all the sections (the thesis: < 3 s for 256x256x60 in 2004).

ctui: ``object_field`` (Gaussian-smoothed indicator on the tube's bounding box +
margin) then ``sections_along_path`` (all planes sampled in a few batched
``map_coordinates`` calls, marching squares per plane). Split: field, sampling,
contours.

Peer ("naive"): what a straightforward implementation does - smooth the whole volume,
then for each plane build its grid, call ``map_coordinates`` and
``skimage.measure.find_contours``, keep the contour around the centre and take its
shoelace area. Same grid size and spacing as ctui's.

Usage: python benchmarks/sections.py [--repeat 3] [--naive-repeat 1] [--radius 4]
Prints medians, the ratio and peak (tracemalloc, separate run) memory of each.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ctui.engine.measure.fields import object_field
from ctui.engine.measure.paths import (
    arc_length,
    path_points,
    resample_path,
    rotation_minimising_frames,
)
from ctui.engine.measure.planes import shoelace_area
from ctui.engine.measure.sections import sections_along_path

SHAPE = (300, 512, 512)
SPACING = (1.0, 0.7, 0.7)  # z 300 mm, x/y 358 mm


def make_tube(radius: float):
    """A curved tube of the given radius along a ~200 mm path; returns mask, path (mm)."""
    from scipy import ndimage as ndi
    from scipy.spatial import cKDTree

    u = np.linspace(0.0, 1.0, 4001)
    raw = np.stack([180 + 35 * np.sin(2 * np.pi * u), 180 + 25 * np.sin(np.pi * u), 40 + 170 * u], 1)
    s = arc_length(raw)
    raw = raw[s <= 200.0]  # exactly 200 mm of it
    path = resample_path(raw, 0.05)
    sp = np.asarray(SPACING)
    idx = np.rint(path[:, ::-1] / sp).astype(int)
    lo = np.maximum(idx.min(0) - int(radius / sp.min()) - 3, 0)
    hi = np.minimum(idx.max(0) + int(radius / sp.min()) + 4, SHAPE)
    seeds = np.ones(tuple(hi - lo), bool)
    seeds[tuple((idx - lo).T)] = False
    near = ndi.distance_transform_edt(seeds, sampling=sp) <= radius + 1.5
    cand = np.argwhere(near)
    xyz = (cand + lo)[:, ::-1] * sp[::-1]
    d, _ = cKDTree(path).query(xyz)
    inside = cand[d <= radius] + lo
    mask = np.zeros(SHAPE, bool)
    mask[tuple(inside.T)] = True
    return mask, path


def ctui_sections(mask, path, step):
    t = {}
    t0 = time.perf_counter()
    f = object_field(mask, spacing=SPACING)
    t["field"] = time.perf_counter() - t0
    rows = sections_along_path(None, path, field=f, step_mm=step, timings=t)
    t["total"] = time.perf_counter() - t0
    return rows, t


def naive_sections(mask, path, step, *, half, n):
    """Per-plane loop on the whole smoothed volume (the peer)."""
    from scipy import ndimage as ndi
    from skimage.measure import find_contours, points_in_poly

    t = {}
    t0 = time.perf_counter()
    f = ndi.gaussian_filter(mask.astype(np.float32), 0.7)
    t["field"] = time.perf_counter() - t0
    s = np.arange(0.0, arc_length(path)[-1] + 1e-9, step)
    pts, tan = path_points(path, s)
    u, v = rotation_minimising_frames(pts, tan)
    sp = np.asarray(SPACING)
    g = (np.arange(n) - (n - 1) / 2) * (2 * half / (n - 1))
    U, V = np.meshgrid(g, g, indexing="ij")
    areas = []
    ts = tc = 0.0
    for i in range(len(s)):
        ta = time.perf_counter()
        xyz = pts[i] + U[..., None] * u[i] + V[..., None] * v[i]
        zyx = (xyz[..., ::-1] / sp).reshape(-1, 3).T
        plane = ndi.map_coordinates(f, zyx, order=1).reshape(n, n)
        tb = time.perf_counter()
        best = float("nan")
        c = (n - 1) / 2
        for cont in find_contours(plane, 0.5):
            if np.allclose(cont[0], cont[-1]) and points_in_poly([[c, c]], cont)[0]:
                a = abs(shoelace_area(cont)) * (g[1] - g[0]) ** 2
                best = a if not math.isfinite(best) else min(best, a)
        areas.append(best)
        ts += tb - ta
        tc += time.perf_counter() - tb
    t["sampling"], t["contours"] = ts, tc
    t["total"] = time.perf_counter() - t0
    return np.array(areas), t


def measure(fn, repeat):
    """Median timings of ``repeat`` untraced runs, then one run under tracemalloc for the
    peak memory (tracing slows Python-level allocations a lot, so it is kept out of
    the timed runs)."""
    times, out = [], None
    for _ in range(repeat):
        out, t = fn()
        times.append(t)
    med = {k: statistics.median(t[k] for t in times) for k in times[0]}
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return out, med, peak


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--naive-repeat", type=int, default=1)
    ap.add_argument("--radius", type=float, default=4.0)
    ap.add_argument("--step", type=float, default=0.5)
    args = ap.parse_args()
    t0 = time.perf_counter()
    mask, path = make_tube(args.radius)
    print(f"volume {SHAPE[2]}x{SHAPE[1]}x{SHAPE[0]} (x,y,z), spacing {SPACING} mm, tube r={args.radius} mm, "
          f"path {arc_length(path)[-1]:.1f} mm, step {args.step} mm (setup {time.perf_counter() - t0:.1f} s)")
    rows, tc, mc = measure(lambda: ctui_sections(mask, path, args.step), args.repeat)
    area = np.array([r["area_mm2"] for r in rows])
    true = math.pi * args.radius**2
    inner = area[10:-10]
    n_ok = sum(1 for r in rows if r["status"] == "ok")
    print(f"ctui : {len(rows)} sections ({n_ok} ok), median of {args.repeat}: total {tc['total']:.3f} s "
          f"(field {tc['field']:.3f}, sampling {tc['sampling']:.3f}, contours {tc['contours']:.3f}, "
          f"flags {tc.get('flags', 0.0):.3f}); "
          f"peak {mc / 2**20:.0f} MiB; area error mean {100 * (np.nanmean(inner) / true - 1):+.2f}% "
          f"max {100 * np.nanmax(np.abs(inner / true - 1)):.2f}%")
    half = 2.0 * args.radius + 2.0
    n = int(min(129, math.ceil(2 * half / (min(SPACING) / 4)) + 1)) | 1
    na, tn, mn = measure(lambda: naive_sections(mask, path, args.step, half=half, n=n), args.naive_repeat)
    ninner = na[10:-10]
    print(f"naive: {len(na)} sections, median of {args.naive_repeat}: total {tn['total']:.3f} s "
          f"(field {tn['field']:.3f}, sampling {tn['sampling']:.3f}, contours {tn['contours']:.3f}); "
          f"peak {mn / 2**20:.0f} MiB; contour area error mean {100 * (np.nanmean(ninner) / true - 1):+.2f}% "
          f"max {100 * np.nanmax(np.abs(ninner / true - 1)):.2f}%")
    print(f"ratio naive/ctui: {tn['total'] / tc['total']:.1f}x; goal <= 2 s: "
          f"{'met' if tc['total'] <= 2.0 else 'NOT met'} ({tc['total']:.2f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
