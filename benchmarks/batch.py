"""Batch throughput on Dask: the same manifest on a LocalCluster of 1 and of 2 worker processes.

Run: ``python3 benchmarks/batch.py [--jobs 6] [--slices 40] [--size 64] [--threads]``

Writes ``--jobs`` phantom series (the bundled phantom's objects on a ``slices x size x
size`` grid, a different noise seed each) to a temporary folder, then runs
``ctui.engine.actions.batch.run_batch`` (what ``ctui batch`` runs) on a fresh
``distributed.LocalCluster`` with 1 worker and with 2 workers (processes unless
``--threads``). Each job loads its series, segments the left kidney from its seed,
measures it (voxel and mesh volume, area) and writes the project and STL. Printed: wall
time including the cluster's start, jobs per minute, the speed-up of 2 workers over 1,
and each run's mean volume against the phantom's analytic kidney volume.

The peer here is the 1-worker run: the speed-up shows what Dask's second worker buys on
this machine (at most 2x on two idle cores; less when the cores are shared: compare the
per-job wall time with its CPU time, and ``uptime``'s load, printed first).
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def make_series(root: Path, n: int, slices: int, size: int) -> tuple[Path, float]:
    from ctui.engine.io.phantom import make_phantom, write_series

    spacing_xy = max(2.0, 260.0 / size)
    spacing_z = 200.0 / slices
    rows = ["series,seed,range,name"]
    truth_ml = 0.0
    for i in range(n):
        vol, truth = make_phantom(shape=(slices, size, size), spacing=(spacing_z, spacing_xy, spacing_xy),
                                  noise_sd=6.0, seed=i, drift=False, supersample=2)
        write_series(root / f"s{i}", vol, seed=i)
        k = next(o for o in truth["objects"] if o["name"] == "kidney_left")
        z, y, x = k["seed_zyx"]
        truth_ml = k["volume_ml"]
        rows.append(f's{i},"{x},{y},{z}",115:445,job{i}')
    (root / "jobs.csv").write_text("\n".join(rows) + "\n")
    return root / "jobs.csv", truth_ml


def run(manifest: Path, workers: int, processes: bool) -> tuple[float, list[dict]]:
    from ctui.engine.actions.batch import run_batch

    out = manifest.parent / f"results-{workers}.csv"
    shutil.rmtree(manifest.parent / f"results-{workers}-outputs", ignore_errors=True)
    out.unlink(missing_ok=True)
    t0 = time.perf_counter()
    run_batch(manifest, out=out, workers=workers, processes=processes)
    dt = time.perf_counter() - t0
    return dt, list(csv.DictReader(out.open()))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=6)
    ap.add_argument("--slices", type=int, default=40)
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--threads", action="store_true", help="thread workers instead of processes")
    args = ap.parse_args()
    root = Path(tempfile.mkdtemp(prefix="ctui-batch-bench-"))
    try:
        manifest, truth_ml = make_series(root, args.jobs, args.slices, args.size)
        print(f"load average {' '.join(f'{v:.1f}' for v in os.getloadavg())} on {os.cpu_count()} CPUs")
        print(f"{args.jobs} jobs, series {args.slices}x{args.size}x{args.size}, "
              f"{'threads' if args.threads else 'processes'}; left kidney {truth_ml:.2f} ml (analytic)")
        times = {}
        for w in (1, 2):
            dt, rows = run(manifest, w, not args.threads)
            ok = [r for r in rows if r["status"] == "ok"]
            vol = sum(float(r["volume_mesh_ml"]) for r in ok) / max(len(ok), 1)
            job_s = sum(float(r["seconds"]) for r in ok) / max(len(ok), 1)
            cpu_s = sum(float(r["cpu_seconds"]) for r in ok) / max(len(ok), 1)
            times[w] = dt
            print(f"  {w} worker{'s' if w > 1 else ' '}: {dt:7.2f} s wall ({args.jobs / dt * 60:6.1f} jobs/min), "
                  f"{len(ok)}/{len(rows)} ok, {job_s:.2f} s ({cpu_s:.2f} s CPU) per job on its worker, mean mesh volume {vol:.2f} ml "
                  f"({100 * (vol - truth_ml) / truth_ml:+.2f}%)")
        print(f"speed-up 2 workers / 1 worker: {times[1] / times[2]:.2f}x")
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
