"""Peak memory of whole commands against the series they work on.

Run: ``python3 benchmarks/memory.py [--shape 300,512,512] [--slices 75,150,300]``

The CT-like DICOM series of ``benchmarks/end_to_end.py`` (written once into
``benchmarks/_cache/``) is loaded whole or in parts (``--crop`` of the first N slices), so
the series size varies without new files. For each size, each command runs in a fresh
process and its peak resident memory (``ru_maxrss`` from ``os.wait4``) is read:

* ``load``: a process that imports the same libraries and only loads the series (the
  baseline: what loading costs);
* ``mesh``: ``ctui mesh SERIES --iso 300`` (bone);
* ``segment``: ``ctui segment SERIES --seed ... --range 200:3000 --mode 3d`` (the spine);
* ``propagate``: the same, propagated slice by slice (``--mode slice``).

Printed: the peak above the load baseline, as a multiple of the series' size in memory
(the goal: at most 2x).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from end_to_end import make_series  # noqa: E402


TREE = ROOT  # the source tree ``python -m ctui.cli`` runs (--tree: an older one, for before/after)


def peak_rss(cmd: list[str]) -> int:
    """Peak resident bytes of one process (start to exit)."""
    env = dict(os.environ, CTUI_NO_PROGRESS="1", CTUI_NO_BACKGROUND_COMPILE="1", PYTHONPATH=str(TREE))
    proc = subprocess.Popen(cmd, cwd=TREE, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}\n{err[-2000:]}")
    return int(usage.ru_maxrss) * 1024


def _seed(series: str, z: int) -> str:
    """x,y,z of the centre voxel of the largest bone-range (200..3000 HU) region on slice z."""
    import numpy as np
    from scipy import ndimage as ndi

    from ctui.engine.io.series import load

    sl = load(series, crop=(z, z + 1, None, None, None, None)).data[0]
    lab, n = ndi.label((sl >= 200) & (sl <= 3000))
    big = 1 + int(np.argmax(np.bincount(lab.ravel())[1:]))
    ys, xs = np.nonzero(lab == big)
    i = int(np.argmin((ys - ys.mean()) ** 2 + (xs - xs.mean()) ** 2))
    return f"{xs[i]},{ys[i]},{z}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", default="300,512,512")
    ap.add_argument("--slices", default="75,150,300", help="series sizes: the first N slices")
    ap.add_argument("--tree", default=None, help="run the ctui of this source tree (before/after comparisons)")
    args = ap.parse_args()
    global TREE
    if args.tree:
        TREE = Path(args.tree).resolve()
    shape = tuple(int(v) for v in args.shape.split(","))
    series = str(make_series(shape))
    tmp = Path(tempfile.mkdtemp(prefix="ctui-mem-"))
    ctui = [sys.executable, "-m", "ctui.cli"]
    print(f"{'slices':>6s} {'series MB':>9s} {'load MB':>8s} | peak above load, x series: "
          f"{'mesh':>6s} {'segment':>8s} {'propagate':>9s}")
    for n in (int(v) for v in args.slices.split(",")):
        n = min(n, shape[0])
        crop = f"0,{n},,,,"
        series_bytes = n * shape[1] * shape[2] * 2
        # baseline: the same libraries imported (numba, scipy: ~150 MB whatever the series) and the series loaded
        load = peak_rss([sys.executable, "-c", "import sys; import ctui.engine.mesh.surface, ctui.engine.mesh.meshtools, ctui.engine.segment.pipeline; "
                         "from ctui.engine.io.series import load; "
                         f"load(sys.argv[1], crop=(0, {n}, None, None, None, None))", series])
        seed = _seed(series, n // 2)
        peaks = {"mesh": peak_rss(ctui + ["mesh", series, "--crop", crop, "--iso", "300", "--out", str(tmp / "m.stl")])}
        if n == shape[0]:  # ctui segment loads whole series (no --crop)
            for name, mode in (("segment", "3d"), ("propagate", "slice")):
                peaks[name] = peak_rss(ctui + ["segment", series, "--seed", seed, "--range", "200:3000", "--mode", mode,
                                              "--json"])
        ratios = {k: f"{(v - load) / series_bytes:.2f}" for k, v in peaks.items()}
        print(f"{n:6d} {series_bytes / 2**20:9.0f} {load / 2**20:8.0f} | {'':27s}"
              f"{ratios['mesh']:>6s} {ratios.get('segment', '-'):>8s} {ratios.get('propagate', '-'):>9s}")


if __name__ == "__main__":
    main()
