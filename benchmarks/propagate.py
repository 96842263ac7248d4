"""Benchmark: propagate one object through a generated 300-slice 512x512 series.

Pipeline: opening 3x3 ellipse (stage 1) + closing 3x3 rect (stage 2), both in HU.
ctui: slice-by-slice propagation from the middle slice in both directions (crop
filtering, seeded components, leak guard), then accept into the label volume.
Peer: the straightforward route: filter every full slice with the same OpenCV
pipeline, threshold the whole volume, scipy.ndimage.label in 3D, keep the seed's
component. Also timed: ctui's own 3D mode, and one-slice preview (both filters, full
512x512 slice, cache off) which the TUI needs under 30 ms.

Memory (``--memory``): the peak resident memory of ctui's propagation (slice and 3D
mode) and of the whole ``segment`` action (fill, grow) above the memory held once the
series is loaded, as a multiple of the series' size, each phase measured from a reset
peak (``/proc/self/clear_refs``); the peer's (scipy label) likewise. Goal (issue 15):
at most 2x the series.

Run: python3 benchmarks/propagate.py [--repeat N] [--slices 300] [--size 512] [--memory]
Goal: ctui propagation <= 1 s.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ctui.engine.core.volume import Volume
from ctui.engine.segment.pipeline import Pipeline
from ctui.engine.segment.propagate import PropagationSettings, propagate
from ctui.engine.segment.selection import Segmentation, threshold_fill


def make_series(nz: int, n: int, seed: int = 0) -> tuple[Volume, np.ndarray]:
    """A winding tube (200 HU) of varying radius in soft tissue (40 HU) with noise,
    next to a second, brighter structure it never touches. Returns (volume, truth mask)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:n, :n].astype(np.float32)
    data = np.empty((nz, n, n), np.int16)
    truth = np.zeros((nz, n, n), bool)
    c = n / 2
    for z in range(nz):
        t = z / nz
        cx = c + 0.12 * n * np.sin(2 * np.pi * t)
        cy = c + 0.08 * n * np.cos(3 * np.pi * t)
        r = n * (0.06 + 0.04 * np.sin(np.pi * t))
        tube = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
        other = (xx - (cx + 2.2 * r + 0.1 * n)) ** 2 + (yy - cy) ** 2 <= (0.08 * n) ** 2
        sl = np.full((n, n), 40.0, np.float32)
        sl[tube] = 200.0
        sl[other] = 260.0
        sl += rng.normal(0, 15, (n, n)).astype(np.float32)
        data[z] = sl.astype(np.int16)
        truth[z] = tube
    return Volume(data, spacing=(1.0, 0.7, 0.7), modality="CT"), truth


def make_pipeline() -> Pipeline:
    p = Pipeline(domain="hu")
    p.add("opening", size=3, shape="ellipse", stage=1)
    p.add("closing", size=3, shape="rect", stage=2)
    return p


def peer_scipy(vol: Volume, pipeline: Pipeline, seed_zyx, low: float, high: float) -> tuple[np.ndarray, dict]:
    import cv2
    from scipy import ndimage

    t0 = time.perf_counter()
    k1 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
    k2 = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))
    mask = np.empty(vol.data.shape, bool)
    for z in range(vol.data.shape[0]):
        f = cv2.morphologyEx(vol.data[z].astype(np.float32), cv2.MORPH_OPEN, k1)
        f = cv2.morphologyEx(f, cv2.MORPH_CLOSE, k2)
        mask[z] = (f >= low) & (f <= high)
    t1 = time.perf_counter()
    st = np.zeros((3, 3, 3), bool)
    st[1] = True
    st[0, 1, 1] = st[2, 1, 1] = True
    lab, _ = ndimage.label(mask, structure=st)
    comp = lab == lab[seed_zyx]
    t2 = time.perf_counter()
    return comp, {"filter": t1 - t0, "label": t2 - t1, "total": t2 - t0}


def _rss_mib(field: str) -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def memory(vol: Volume, p: Pipeline, seed, low: float, high: float) -> None:
    """Peak RSS above the loaded series for each phase, as a multiple of the series size."""
    import gc

    from ctui.engine.actions.segment import SegmentOptions, segment

    series = vol.data.nbytes / 2**20
    # before (commit 7eafd76, same harness): propagate slice 0.01x, 3d 1.01x, propagate + accept +
    # the report's np.bincount of the labels 4.77x; `ctui segment` of this series saved as NIfTI
    # (/usr/bin/time -v, peak minus a load-only run): slice mode 4.7x, 3D mode 6.8x.
    phases = {
        "propagate, slice mode": lambda: propagate(vol, p, threshold_fill(p.final_slice(vol, seed[2]), seed[0], seed[1],
                                                                        low=low, high=high), seed[2],
                                                   PropagationSettings(low=low, high=high)),
        "propagate, 3d mode": lambda: propagate(vol, p, threshold_fill(p.final_slice(vol, seed[2]), seed[0], seed[1],
                                                                     low=low, high=high), seed[2],
                                                PropagationSettings(low=low, high=high, mode="3d")),
        "segment action, fill (labels + accept)": lambda: segment(vol, [seed], [(low, high)], pipeline=p),
        "segment action, 3d": lambda: segment(vol, [seed], [(low, high)], pipeline=p,
                                              options=SegmentOptions(mode="3d")),
        "segment action, grow": lambda: segment(vol, [seed], [(low, high)], pipeline=p,
                                                options=SegmentOptions(method="grow")),
        "peer: filters + scipy.ndimage.label": lambda: peer_scipy(vol, p, (seed[2], seed[1], seed[0]), low, high),
    }
    for name, run in phases.items():
        gc.collect()
        base = _rss_mib("VmRSS")
        if not _reset_peak():
            print("memory: /proc/self/clear_refs not writable; skipped")
            return
        out = run()
        peak = _rss_mib("VmHWM")
        del out
        print(f"memory, {name}: peak {peak - base:.0f} MiB above the loaded series = {(peak - base) / series:.2f}x "
              f"the series ({series:.0f} MiB; goal <= 2x)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--slices", type=int, default=300)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--memory", action="store_true", help="only the memory measurements")
    args = ap.parse_args()

    t = time.perf_counter()
    vol, truth = make_series(args.slices, args.size)
    print(f"series {vol.data.shape} int16 generated in {time.perf_counter() - t:.1f} s")
    p = make_pipeline()
    low, high = 120.0, 230.0
    z0 = args.slices // 2
    ys, xs = np.nonzero(truth[z0])
    seed = (int(xs[len(xs) // 2]), int(ys[len(ys) // 2]), z0)

    # warm-up (OpenCV/numba initialisation)
    start = threshold_fill(p.final_slice(vol, z0), seed[0], seed[1], low=low, high=high)
    propagate(vol, p, start, z0, PropagationSettings(low=low, high=high, max_slices=5))
    if args.memory:
        propagate(vol, p, start, z0, PropagationSettings(low=low, high=high, mode="3d", max_slices=2))
        del truth
        memory(vol, p, seed, low, high)
        return 0

    # one-slice preview (cache cleared each time)
    prev = []
    for z in range(0, args.slices, max(1, args.slices // 40)):
        p.clear_cache()
        t = time.perf_counter()
        p.run_slice(vol, z)
        prev.append(time.perf_counter() - t)
    print(f"preview, one {args.size}x{args.size} slice, 2 filters: median {statistics.median(prev) * 1000:.2f} ms "
          f"(max {max(prev) * 1000:.2f} ms; goal < 30 ms)")

    heavy = Pipeline(domain="hu")
    heavy.add("median", size=7, stage=1)
    heavy.add("clahe", clip_limit=2.0, stage=2)
    heavy.run_slice(vol, 0)  # compile the numba median once
    prev = []
    for z in range(0, args.slices, max(1, args.slices // 20)):
        heavy.clear_cache()
        t = time.perf_counter()
        heavy.run_slice(vol, z)
        prev.append(time.perf_counter() - t)
    print(f"preview, one slice, median 7x7 + CLAHE: median {statistics.median(prev) * 1000:.2f} ms (max {max(prev) * 1000:.2f} ms)")

    runs, phases, accept_t = [], [], []
    prop = None
    for _ in range(args.repeat):
        p.clear_cache()
        seg = Segmentation(vol.data.shape)
        t = time.perf_counter()
        fill = seg.fill(p.final_slice(vol, z0), seed[0], seed[1], z0, low=low, high=high)
        prop = propagate(vol, p, seg.labels[z0] == fill_id(seg), z0, PropagationSettings(low=low, high=high),
                         labels=seg.labels, object_id=1)
        ta = time.perf_counter()
        prop.accept(seg)
        t_end = time.perf_counter()
        runs.append(t_end - t)
        accept_t.append(t_end - ta)
        phases.append(dict(prop.timings))
    med = statistics.median(runs)
    got = seg.labels == 1
    print(f"ctui propagate (slice mode, both directions, {prop.slices[1] - prop.slices[0] + 1} slices): "
          f"median {med:.3f} s over {args.repeat} runs (goal <= 1 s)")
    for key in ("filter", "fill", "necks", "bookkeeping"):
        print(f"  {key:<12} {statistics.median(ph.get(key, 0.0) for ph in phases):.3f} s")
    print(f"  {'accept':<12} {statistics.median(accept_t):.3f} s (write into labels, one undo step)")
    inter = np.count_nonzero(got & truth)
    print(f"  voxels {int(got.sum())}, truth {int(truth.sum())}, Dice {2 * inter / (got.sum() + truth.sum()):.4f}")

    t3 = []
    propagate(vol, p, start, z0, PropagationSettings(low=low, high=high, mode="3d", max_slices=2))  # compile
    for _ in range(max(1, args.repeat // 2)):
        p.clear_cache()
        t = time.perf_counter()
        prop3 = propagate(vol, p, start, z0, PropagationSettings(low=low, high=high, mode="3d"))
        t3.append(time.perf_counter() - t)
    print(f"ctui propagate (3d mode): median {statistics.median(t3):.3f} s (filter {prop3.timings['filter']:.3f} s, "
          f"3D fill {prop3.timings['fill']:.3f} s, necks {prop3.timings.get('necks', 0.0):.3f} s), voxels {prop3.voxels}")

    peer_t, peer_ph = [], []
    for _ in range(max(1, args.repeat // 2)):
        comp, ph = peer_scipy(vol, p, (z0, seed[1], seed[0]), low, high)
        peer_t.append(ph["total"])
        peer_ph.append(ph)
    pm = statistics.median(peer_t)
    print(f"peer: full-slice OpenCV filters + scipy.ndimage.label 3D: median {pm:.3f} s "
          f"(filter {statistics.median(x['filter'] for x in peer_ph):.3f} s, label {statistics.median(x['label'] for x in peer_ph):.3f} s), "
          f"voxels {int(comp.sum())}")
    print(f"ratio peer / ctui slice mode: {pm / med:.1f}x; peer / ctui 3d mode: {pm / statistics.median(t3):.1f}x")
    same = np.count_nonzero(comp & got)
    print(f"agreement with peer: Dice {2 * same / (comp.sum() + got.sum()):.4f}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS {peak:.0f} MiB (series itself {vol.data.nbytes / 2**20:.0f} MiB)")
    return 0


def fill_id(seg: Segmentation) -> int:
    return max(seg.objects)


if __name__ == "__main__":
    sys.exit(main())
