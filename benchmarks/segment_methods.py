"""Benchmark: the segment methods (fill, grow, levelset) and a brush stroke, against scikit-image / SimpleITK.

Series: a generated 300 x 512 x 512 int16 CT (3 mm slices, 0.8 mm pixels, noise sd 10
HU) with a kidney-like ellipsoid (200 HU) and a neighbour of the same HU joined to it
by a 3-pixel neck, both inside a 100 x 200 x 200 region; one seed in the kidney and a
background seed in the neighbour.

* ``grow``: ctui's competition on the region (one SimpleITK distance map, bisection for
  the neck that parts the seeds) vs the marker watershed on the same landscape by
  SimpleITK (``MorphologicalWatershedFromMarkers``) and scikit-image (``watershed`` on
  scipy's ``distance_transform_edt`` with the spacing); and the whole ``segment``
  action on the series (threshold of 300 slices included).
* ``levelset``: ctui's level set (numba narrow band, :mod:`ctui.engine.segment.levelset`)
  vs SimpleITK's ``ThresholdSegmentationLevelSetImageFilter``, both 20 iterations from
  the same start (the fill eroded by 2 pixels) on the 100 x 200 x 200 region; and the
  whole ``segment --method levelset`` action (neck-cut fill + level set + background
  competition).
* ``fill``: the default (neck-cut propagation) for reference.
* brush: one dab (radius 10 px) into a 300 x 512 x 512 label volume, engine side.

* ``--memory``: peak resident memory of ``ctui segment SERIES --method levelset`` (and
  ``fill`` for reference) in a fresh process on the CT-like 300 x 512 x 512 DICOM series of
  benchmarks/end_to_end.py (the spine, range 200:3000), above a process that imports the same
  libraries and only loads the series, as a multiple of the series' size (goal <= 2x).

Wall times are medians; CPU seconds (``time.process_time``, all threads of the process)
are printed beside them: on a loaded machine they hold where wall times do not.

Goals (issue 14): grow and levelset on the 200 x 200 x 100 region <= 2 s; a brush
stroke <= 30 ms. Run: python3 benchmarks/segment_methods.py [--repeat N] [--only levelset] [--memory]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ctui.engine.actions.segment import SegmentOptions, segment
from ctui.engine.core.volume import Volume
from ctui.engine.segment import grow as G
from ctui.engine.segment.selection import Segmentation

SPACING = (3.0, 0.8, 0.8)
REGION = (slice(100, 200), slice(156, 356), slice(156, 356))  # 100 x 200 x 200


def make_series(seed: int = 0):
    rng = np.random.default_rng(seed)
    shape = (300, 512, 512)
    data = np.empty(shape, np.int16)
    zz = np.arange(shape[0])[:, None, None]
    yy = np.arange(shape[1])[None, :, None]
    xx = np.arange(shape[2])[None, None, :]
    kidney = ((zz - 150) / 40.0) ** 2 + ((yy - 256) / 70.0) ** 2 + ((xx - 215) / 45.0) ** 2 <= 1
    other = ((zz - 155) / 35.0) ** 2 + ((yy - 256) / 60.0) ** 2 + ((xx - 310) / 35.0) ** 2 <= 1
    other[140:160, 255:258, 255:280] = True  # a 3-pixel neck on 20 slices
    other &= ~kidney
    for z in range(shape[0]):
        sl = np.full(shape[1:], 40.0, np.float32)
        sl[kidney[z] | other[z]] = 200.0
        sl += rng.normal(0, 10, shape[1:]).astype(np.float32)
        data[z] = np.round(sl).astype(np.int16)
    return Volume(data, spacing=SPACING, modality="CT"), kidney, (215, 256, 150), (315, 256, 155)


def med(f, n):
    t, _cpu, out = timed(f, n)
    return t, out


def timed(f, n):
    """Median wall and CPU seconds (process_time: every thread of this process) of n runs, and the last result."""
    ts, cs, out = [], [], None
    for _ in range(n):
        c = time.process_time()
        t = time.perf_counter()
        out = f()
        ts.append(time.perf_counter() - t)
        cs.append(time.process_time() - c)
    return statistics.median(ts), statistics.median(cs), out


def peak_rss(cmd: list[str]) -> int:
    """Peak resident bytes of one fresh process (start to exit)."""
    import os
    import subprocess

    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, CTUI_NO_PROGRESS="1", CTUI_NO_BACKGROUND_COMPILE="1", PYTHONPATH=str(root))
    proc = subprocess.Popen(cmd, cwd=root, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}\n{proc.stderr.read().decode()[-2000:] if proc.stderr else ''}")
    return int(usage.ru_maxrss) * 1024


def memory() -> None:
    """Peak memory of ctui segment --method levelset / fill above loading, x the series (goal <= 2x)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from end_to_end import make_series as make_dicom

    shape = (300, 512, 512)
    series = str(make_dicom(shape))
    seed = "255,268,150"  # the spine's middle on slice 150 (range 200:3000 HU)
    nbytes = shape[0] * shape[1] * shape[2] * 2
    code = ("import sys; import ctui.engine.mesh.surface, ctui.engine.mesh.meshtools, ctui.engine.segment.pipeline; "
            "from ctui.engine.io.series import load; load(sys.argv[1])")
    load = peak_rss([sys.executable, "-c", code, series])
    for method in ("levelset", "fill"):
        peak = peak_rss([sys.executable, "-m", "ctui.cli", "segment", series, "--seed", seed, "--range", "200:3000",
                         "--method", method, "--json"])
        print(f"memory, ctui segment --method {method} on the {shape[0]}x{shape[1]}x{shape[2]} series "
              f"({nbytes / 2**20:.0f} MB): peak {peak / 2**20:.0f} MB, {(peak - load) / nbytes:.2f}x the series above "
              f"loading it ({load / 2**20:.0f} MB){' (goal <= 2x)' if method == 'levelset' else ''}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--only", choices=("all", "levelset"), default="all", help="levelset: skip grow, fill and brush")
    ap.add_argument("--memory", action="store_true", help="also the peak memory of ctui segment (fresh processes)")
    args = ap.parse_args()
    if args.memory:
        memory()
    t = time.perf_counter()
    vol, truth, seed, bg = make_series()
    print(f"series {vol.data.shape} generated in {time.perf_counter() - t:.1f} s; kidney {int(truth.sum())} voxels")
    lo, hi = 120.0, 300.0
    n = int(truth.sum())

    def score(labels):
        got = labels == 1
        return f"volume {got.sum() / n:.3f} x truth, Dice {2 * (got & truth).sum() / (got.sum() + n):.4f}"

    sub = vol.data[REGION]
    if args.only == "all":
        grow_section(vol, sub, seed, bg, lo, hi, score, args.repeat)
    levelset_section(vol, sub, truth, seed, bg, lo, hi, score, args.repeat)
    if args.only == "all":
        brush_section(vol)
    return 0


def grow_section(vol, sub, seed, bg, lo, hi, score, repeat):
    """grow on the region: ctui (SimpleITK) vs scikit-image, and the whole action."""
    inr = (sub >= lo) & (sub <= hi)
    org = np.array([r.start for r in REGION])
    fg = np.array([[seed[2], seed[1], seed[0]]]) - org
    bgz = np.array([[bg[2], bg[1], bg[0]]]) - org
    args = argparse.Namespace(repeat=repeat)
    G.compete(inr[:4], fg * 0, bgz * 0, spacing=SPACING)  # warm-up (imports, numba)
    t_ctui, share = med(lambda: G.compete(inr, fg, bgz, spacing=SPACING), args.repeat)
    t_ws, ws = med(lambda: G.compete_watershed(inr, fg, bgz, spacing=SPACING), 1)

    def skimage_grow():
        from scipy import ndimage
        from skimage.segmentation import watershed

        dist = ndimage.distance_transform_edt(inr, sampling=SPACING)
        markers = np.zeros(inr.shape, np.int32)
        markers[tuple(bgz.T)] = 2
        markers[tuple(fg.T)] = 1
        return watershed(-dist, markers, mask=inr) == 1

    t_sk, sk = med(skimage_grow, max(1, args.repeat - 1))
    agree = 2 * (share & sk).sum() / (share.sum() + sk.sum())
    agree_ws = 2 * (share & ws).sum() / (share.sum() + ws.sum())
    print(f"grow, 100x200x200 region: ctui (distance-map bisection) {t_ctui:.3f} s (goal <= 2 s); "
          f"SimpleITK marker watershed {t_ws:.3f} s; scikit-image watershed {t_sk:.3f} s; "
          f"ratio SimpleITK/ctui {t_ws / t_ctui:.1f}x, skimage/ctui {t_sk / t_ctui:.1f}x; "
          f"agreement Dice vs SimpleITK {agree_ws:.4f}, vs skimage {agree:.4f}")
    t_act, res = med(lambda: segment(vol, [seed], [(lo, hi)], background=[bg], options=SegmentOptions(method="grow")), 1)
    print(f"grow, whole action on the 300x512x512 series (threshold every slice + competition): {t_act:.3f} s; "
          f"{score(res.segmentation.labels)}")


def levelset_section(vol, sub, truth, seed, bg, lo, hi, score, repeat):
    """fill (the default, for reference) and levelset: ctui vs SimpleITK on the region, and the whole action."""
    args = argparse.Namespace(repeat=repeat)
    t_fill, res = med(lambda: segment(vol, [seed], [(lo, hi)], options=SegmentOptions()), args.repeat)
    print(f"fill (default, neck-cut slice propagation), whole action: {t_fill:.3f} s; {score(res.segmentation.labels)}")
    import cv2

    from ctui.engine.segment.levelset import evolve

    start = res.segmentation.labels[REGION] == 1
    k = np.ones((5, 5), np.uint8)
    start = np.stack([cv2.erode(s.astype(np.uint8), k) for s in start]).astype(bool)
    evolve(sub[40:52], start[40:52], low=lo, high=hi, spacing=SPACING, iterations=11)  # compile (or load the cache)
    t_ls, c_ls, got = timed(lambda: evolve(sub, start, low=lo, high=hi, spacing=SPACING, iterations=20), args.repeat)
    tr = truth[REGION]

    def sitk_levelset(iterations=20):
        import SimpleITK as sitk

        img = sitk.GetImageFromArray(sub.astype(np.float32))
        img.SetSpacing(SPACING[::-1])
        ini = sitk.GetImageFromArray(start.astype(np.uint8))
        ini.SetSpacing(SPACING[::-1])
        d = sitk.SignedMaurerDistanceMap(ini, insideIsPositive=True, squaredDistance=False, useImageSpacing=True)
        f = sitk.ThresholdSegmentationLevelSetImageFilter()
        f.SetLowerThreshold(lo)
        f.SetUpperThreshold(hi)
        f.SetMaximumRMSError(1e-7)
        f.SetNumberOfIterations(iterations)
        f.SetCurvatureScaling(1.0)
        f.SetPropagationScaling(1.0)
        f.ReverseExpansionDirectionOn()
        return sitk.GetArrayFromImage(f.Execute(d, img)) > 0

    t_peer, c_peer, peer = timed(sitk_levelset, 1)

    def dice(a):
        return 2 * (a & tr).sum() / (a.sum() + tr.sum())

    print(f"levelset, 100x200x200 region, 20 iterations from the fill eroded by 2 px ({start.sum() / tr.sum():.3f} x truth): "
          f"ctui {t_ls:.3f} s wall, {c_ls:.3f} s CPU ({got.sum() / tr.sum():.4f} x truth, Dice {dice(got):.4f}) "
          f"(goal <= 2 s); SimpleITK {t_peer:.3f} s wall, {c_peer:.3f} s CPU ({peer.sum() / tr.sum():.4f} x truth, "
          f"Dice {dice(peer):.4f}); ratio SimpleITK/ctui {t_peer / t_ls:.1f}x wall, {c_peer / c_ls:.1f}x CPU")
    t_act, c_act, res = timed(lambda: segment(vol, [seed], [(lo, hi)], background=[bg],
                                              options=SegmentOptions(method="levelset")), args.repeat)
    print(f"levelset, whole action (fill + level set + background competition): {t_act:.3f} s wall, {c_act:.3f} s CPU; "
          f"{score(res.segmentation.labels)}")


def brush_section(vol):
    """One brush dab into a 300 x 512 x 512 label volume, engine side."""
    seg = Segmentation(vol.data.shape)
    seg.paint_brush(256, 256, 150, 1, radius=10)
    ts = []
    for k in range(40):
        t = time.perf_counter()
        seg.paint_brush(200 + k, 256, 150, 1, radius=10, mode="add" if k % 2 else "subtract")
        ts.append(time.perf_counter() - t)
    print(f"brush dab radius 10 px into 300x512x512 labels: median {statistics.median(ts) * 1000:.2f} ms "
          f"(max {max(ts) * 1000:.2f} ms; goal <= 30 ms, engine side)")


if __name__ == "__main__":
    sys.exit(main())
