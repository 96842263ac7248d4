"""Peak memory of whole commands against the series they work on, before and after in one run.

Run: ``python3 benchmarks/memory.py [--before TREE] [--cases kidney,synthetic] [--shape 300,512,512]
[--slices 75,150,300]``

Two cases, each command in a fresh process whose peak resident memory (``ru_maxrss`` from ``os.wait4``,
libraries' mapped code included) is read:

* ``kidney``: a real kidney. The shared abdomen CT (``../shared/data/totalseg_example/ct_abdomen_3mm.nii.gz``,
  30 x 101 x 122 at 3 mm) made a contrast CT (``phantoms.contrast_abdomen``: its labelled organs enhanced, a
  renal vein) and resampled to the 134 x 512 x 512 grid of the campaign's contrast kidney (0.67 x 0.71 x 0.71
  mm, trilinear; the rows padded with air), written as a DICOM series (``benchmarks/_cache/kidney_134x512x512``).
  ``ctui segment`` from a seed at the deepest point of the left kidney's reference label, the range automatic,
  as a user would run it: slice mode, 3D mode, and slice mode writing ``--mask out.nii.gz``.
* ``synthetic``: the CT-like series of ``benchmarks/end_to_end.py`` (``--shape``), loaded whole or in parts
  (``--crop`` of the first N slices): ``mesh --iso 300`` (bone) at each size, and at the full size
  ``segment --range 200:3000`` of the spine in 3D (``segment``) and slice by slice (``propagate``).

``load`` is the baseline: a process that imports the engine modules loading uses and only loads the series.
Printed: the peak above it, as a multiple of the series' size in memory (issue 41: segment <= 2.5x; issue 40:
<= 2x and <= series + 500 MB for an organ), and the peak in MB. ``--before TREE`` runs the same commands with
the ctui of another source tree too (``git worktree add /tmp/base <commit>``), alternating, in the same run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))

from end_to_end import CACHE, make_series  # noqa: E402

SHARED = Path(os.environ.get("CTUI_SHARED_DATA", ROOT.parent / "shared" / "data"))
KIDNEY_SHAPE = (134, 512, 512)


def peak_rss(cmd: list[str], tree: Path) -> int:
    """Peak resident bytes of one process (start to exit), running the ctui of ``tree``."""
    env = dict(os.environ, CTUI_NO_PROGRESS="1", CTUI_NO_BACKGROUND_COMPILE="1", PYTHONPATH=str(tree))
    proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}\n{err[-2000:]}")
    return int(usage.ru_maxrss) * 1024


def load_peak(series: str, tree: Path, crop: str = "") -> int:
    """The baseline: the engine's loading modules imported and the series loaded (nothing else)."""
    c = f"crop=(0, {int(crop)}, None, None, None, None)" if crop else ""
    return peak_rss([sys.executable, "-c", "import sys; import ctui.engine.mesh.surface, ctui.engine.mesh.meshtools, "
                     "ctui.engine.segment.pipeline; from ctui.engine.io.series import load; "
                     f"load(sys.argv[1], {c})", series], tree)


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


def make_kidney() -> tuple[Path, str]:
    """(the 134 x 512 x 512 contrast abdomen DICOM series, the left kidney's deepest voxel "x,y,z"); cached."""
    out = CACHE / f"kidney_{KIDNEY_SHAPE[0]}x{KIDNEY_SHAPE[1]}x{KIDNEY_SHAPE[2]}"
    done = out / ".done"
    if done.exists():
        return out, json.loads(done.read_text())["seed"]
    import shutil

    import numpy as np
    from scipy import ndimage

    from ctui.engine.actions.opened import open_input
    from ctui.engine.core.volume import Volume
    from ctui.engine.io.phantom import write_series
    from ctui.engine.io.series import load
    from ctui.engine.segment.phantoms import contrast_abdomen

    tot = SHARED / "totalseg_example"
    if not (tot / "ct_abdomen_3mm.nii.gz").exists():
        raise SystemExit(f"the kidney case needs {tot} (the shared data); run with --cases synthetic")
    vol = load(tot / "ct_abdomen_3mm.nii.gz")
    labels = open_input(tot / "ct_abdomen_3mm_labels.nii.gz").labels
    nz, ny, nx = KIDNEY_SHAPE
    f = nx / vol.data.shape[2]
    zoom = (nz / vol.data.shape[0], f, f)
    data = ndimage.zoom(contrast_abdomen(vol, labels).data.astype(np.float32), zoom, order=1)
    kidney = ndimage.zoom((labels == 3).astype(np.uint8), zoom, order=0).astype(bool)  # 3: kidney_left
    pad = ((0, 0), ((ny - data.shape[1]) // 2, ny - data.shape[1] - (ny - data.shape[1]) // 2), (0, 0))
    data = np.pad(np.rint(data).astype(np.int16), pad, constant_values=-1024)
    kidney = np.pad(kidney, pad)
    sp = (float(vol.spacing[0]) * vol.data.shape[0] / nz, float(vol.spacing[1]) / f, float(vol.spacing[2]) / f)
    dt = ndimage.distance_transform_edt(np.pad(kidney, 1), sampling=sp)[1:-1, 1:-1, 1:-1]
    z, y, x = np.unravel_index(int(np.argmax(dt)), kidney.shape)
    if out.exists():
        shutil.rmtree(out)
    write_series(out, Volume(data=data, spacing=sp, origin=tuple(vol.origin), modality="CT"),
                 description="ctui benchmark: contrast abdomen resampled")
    seed = f"{x},{y},{z}"
    done.write_text(json.dumps({"seed": seed, "kidney_ml": float(kidney.sum() * np.prod(sp) / 1000)}) + "\n")
    return out, seed


def _cell(peak: int, load: int, series_bytes: int) -> str:
    return f"{(peak - load) / series_bytes:5.2f}x {peak / 2**20:5.0f}"


def _in_child(fn: str, *args: str) -> str:
    """``fn(*args)`` run in a child process, its result as text: this process stays small, and the children's
    ``ru_maxrss`` (which counts the parent's pages until exec) stays theirs."""
    out = subprocess.run([sys.executable, __file__, "--child", fn, *args], check=True, capture_output=True, text=True)
    return out.stdout.strip().splitlines()[-1]


def kidney(trees: dict[str, Path], tmp: Path) -> None:
    series, seed = json.loads(_in_child("make_kidney"))
    series = Path(series)
    series_bytes = KIDNEY_SHAPE[0] * KIDNEY_SHAPE[1] * KIDNEY_SHAPE[2] * 2
    ctui = [sys.executable, "-m", "ctui.cli", "segment", str(series), "--seed", seed]
    runs = {"segment (slice)": ctui + ["--json"], "segment --mode 3d": ctui + ["--mode", "3d", "--json"],
            "segment --mask": ctui + ["--mask", str(tmp / "kidney.nii.gz")]}
    print(f"\nkidney: {series.name}, seed {seed} (left kidney's deepest voxel), series {series_bytes / 2**20:.0f} MB")
    for tree in trees.values():  # each tree compiles its own kernels (every mode's) once, outside the figures
        for cmd in runs.values():
            peak_rss(cmd, tree)
    load = load_peak(str(series), trees["after"])
    print(f"  load baseline {load / 2**20:.0f} MB; peak above it, x series, and the peak in MB:")
    print(f"  {'command':20s} " + " ".join(f"{name:>14s}" for name in trees))
    for name, cmd in runs.items():
        cells = [_cell(peak_rss(cmd, tree), load, series_bytes) for tree in trees.values()]
        print(f"  {name:20s} " + " ".join(f"{c:>14s}" for c in cells))


def synthetic(trees: dict[str, Path], tmp: Path, shape: tuple[int, ...], slices: list[int]) -> None:
    series = str(make_series(shape))
    ctui = [sys.executable, "-m", "ctui.cli"]
    print(f"\nsynthetic: {Path(series).name}; peak above load, x series (and MB), per tree: "
          + ", ".join(trees))
    print(f"  {'slices':>6s} {'series MB':>9s} {'load MB':>8s} | {'command':10s} "
          + " ".join(f"{name:>14s}" for name in trees))
    for n in (min(int(v), shape[0]) for v in slices):
        series_bytes = n * shape[1] * shape[2] * 2
        load = load_peak(series, trees["after"], crop=str(n))
        cmds = {"mesh": ctui + ["mesh", series, "--crop", f"0,{n},,,,", "--iso", "300", "--out", str(tmp / "m.stl")]}
        if n == shape[0]:  # ctui segment loads whole series (no --crop)
            seed = _in_child("_seed", series, str(n // 2))
            for name, mode in (("segment", "3d"), ("propagate", "slice")):
                cmds[name] = ctui + ["segment", series, "--seed", seed, "--range", "200:3000", "--mode", mode, "--json"]
        for name, cmd in cmds.items():
            cells = [_cell(peak_rss(cmd, tree), load, series_bytes) for tree in trees.values()]
            print(f"  {n:6d} {series_bytes / 2**20:9.0f} {load / 2**20:8.0f} | {name:10s} "
                  + " ".join(f"{c:>14s}" for c in cells))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="kidney,synthetic")
    ap.add_argument("--shape", default="300,512,512")
    ap.add_argument("--slices", default="75,150,300", help="synthetic series sizes: the first N slices")
    ap.add_argument("--before", default=None, help="also run the ctui of this source tree (before/after)")
    ap.add_argument("--tree", default=None, help="run the ctui of this source tree instead of this one")
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        fn, *rest = args.child
        got = make_kidney() if fn == "make_kidney" else _seed(rest[0], int(rest[1]))
        print(json.dumps([str(got[0]), got[1]]) if fn == "make_kidney" else got)
        return
    trees = {"after": Path(args.tree).resolve() if args.tree else ROOT}
    if args.before:
        trees = {"before": Path(args.before).resolve(), **trees}
    tmp = Path(tempfile.mkdtemp(prefix="ctui-mem-"))
    cases = set(args.cases.split(","))
    if "kidney" in cases:
        kidney(trees, tmp)
    if "synthetic" in cases:
        synthetic(trees, tmp, tuple(int(v) for v in args.shape.split(",")), [int(v) for v in args.slices.split(",")])


if __name__ == "__main__":
    main()
