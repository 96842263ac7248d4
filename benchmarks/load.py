"""Benchmark: load a 300-slice 512x512 CT DICOM series with ctui and with SimpleITK.

    python3 benchmarks/load.py [--slices 300] [--repeat 5] [--large]

Generates the series once under benchmarks/_cache/ (gitignored; uint16 storage, 12
bits stored, intercept -1024, shuffled file names), then in ONE run times

* ctui: ``ctui.engine.io.series.load(folder)`` (header scan, grouping, sorting along the
  normal, parallel decode, rescale to int16 HU);
* SimpleITK: ``ImageSeriesReader.GetGDCMSeriesFileNames(folder)`` (GDCM's header scan
  and sort) + ``Execute()`` + ``GetArrayViewFromImage``;

alternating runs, printing medians, the ratio and peak memory; then ``ctui info`` on the
series (the whole command in a fresh process, and ``ctui.engine.io.series.inspect`` in
process: headers and three sample slices, no pixel decode of the series; goal <= 1 s)
against SimpleITK's header-only scan (GDCM file-name sort + ReadImageInformation). Peak memory of each
loader is measured in a fresh subprocess as the growth of the process's maximum
resident set size (VmHWM) during the load, compared with the final array size;
for ctui also tracemalloc's peak of Python/numpy allocations. ``--large`` also loads a
1000-slice 512x512 series (issue 8: it must load within the memory bound).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
CACHE = ROOT / "benchmarks" / "_cache"


def make_series(nz: int) -> Path:
    """A CT-like 512x512 series of nz slices (body ellipse, bone ring, noise)."""
    import numpy as np

    from ctui.engine.io.phantom import write_series
    from ctui.engine.core.volume import Volume

    out = CACHE / f"ct_{nz}x512x512"
    if out.is_dir() and len(list(out.glob("*.dcm"))) == nz:
        return out
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[:512, :512]
    body = ((xx - 256) / 200.0) ** 2 + ((yy - 256) / 150.0) ** 2 <= 1
    ring = (((xx - 256) / 60.0) ** 2 + ((yy - 300) / 45.0) ** 2 <= 1) & (((xx - 256) / 45.0) ** 2 + ((yy - 300) / 32.0) ** 2 > 1)
    base = np.where(body, 40, -1000).astype(np.int16)
    base[ring] = 900
    data = np.empty((nz, 512, 512), np.int16)
    for k in range(nz):
        data[k] = base + rng.normal(0, 12, size=(512, 512)).astype(np.int16)
    vol = Volume(data=data, spacing=(1.0, 0.7, 0.7), modality="CT", window=(40, 400))
    print(f"writing {nz} slices to {out} (once) ...", flush=True)
    write_series(out, vol, bits_stored=12, description=f"benchmark {nz}")
    return out


def load_ctui(path: Path):
    from ctui.engine.io.series import load

    return load(path).data


def load_sitk(path: Path):
    import SimpleITK as sitk

    reader = sitk.ImageSeriesReader()
    names = reader.GetGDCMSeriesFileNames(str(path))
    reader.SetFileNames(names)
    img = reader.Execute()
    arr = sitk.GetArrayViewFromImage(img)
    return img, arr


def _hwm() -> int:
    """This process's peak resident set size (VmHWM) in bytes. (ru_maxrss is not used:
    on Linux it keeps the parent's high-water mark across fork+exec.)"""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    return 0


def child(which: str, path: Path, trace: bool) -> None:
    """Fresh process: peak RSS growth during one load (imports done first); with
    ``trace`` also tracemalloc's peak (which slows pydicom's parsing: no timing then)."""
    import tracemalloc

    import numpy as np  # noqa: F401

    if which == "ctui":
        import pydicom  # noqa: F401

        from ctui.engine.io.series import load  # noqa: F401
    else:
        import SimpleITK  # noqa: F401
    base = _hwm()
    if trace:
        tracemalloc.start()
    t0 = time.perf_counter()
    if which == "ctui":
        arr = load_ctui(path)
    else:
        img, arr = load_sitk(path)
    dt = time.perf_counter() - t0
    tpeak = tracemalloc.get_traced_memory()[1] if trace else None
    peak = _hwm()
    print(json.dumps({"rss_growth": peak - base, "tracemalloc_peak": tpeak, "nbytes": int(arr.nbytes),
                      "dtype": str(arr.dtype), "seconds": None if trace else dt}))


def measure_child(which: str, path: Path, trace: bool = False) -> dict:
    cmd = [sys.executable, __file__, "--child", which, str(path)] + (["--trace"] if trace else [])
    r = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def info_sitk(path: Path) -> None:
    """SimpleITK's header-only description: GDCM's series scan and sort, then the first
    file's image information (what `ctui info` reports without decoding)."""
    import SimpleITK as sitk

    names = sitk.ImageSeriesReader.GetGDCMSeriesFileNames(str(path))
    r = sitk.ImageFileReader()
    r.SetFileName(names[0])
    r.ReadImageInformation()


def info_figures(path: Path, repeat: int) -> None:
    from ctui.engine.io.series import inspect

    import resource

    inspect(path)  # warm
    t_in, t_cmd, t_sitk, c_in, c_cmd, c_sitk = [], [], [], [], [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        inspect(path)
        t_in.append(time.perf_counter() - t0)
        c_in.append(time.process_time() - c0)
        t0, c0 = time.perf_counter(), time.process_time()
        info_sitk(path)
        t_sitk.append(time.perf_counter() - t0)
        c_sitk.append(time.process_time() - c0)
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "ctui", "info", str(path), "--json"], cwd=ROOT, check=True,
                       capture_output=True)
        t_cmd.append(time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        c_cmd.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    med = statistics.median
    print(f"ctui info (whole command, fresh process) median {med(t_cmd):.3f} s wall, {med(c_cmd):.3f} s CPU  "
          f"(wall runs: {', '.join(f'{t:.3f}' for t in t_cmd)})  goal <= 1 s: "
          f"{'met' if min(med(t_cmd), med(c_cmd)) <= 1.0 else 'NOT met'} (CPU time on a busy machine)")
    print(f"inspect() in process median {med(t_in):.3f} s wall, {med(c_in):.3f} s CPU; SimpleITK header scan "
          f"median {med(t_sitk):.3f} s wall, {med(c_sitk):.3f} s CPU; ratio ctui/SimpleITK {med(c_in) / med(c_sitk):.2f} "
          f"(CPU)")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--slices", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--large", action="store_true", help="also load a 1000-slice series (memory bound)")
    ap.add_argument("--child", nargs=2, metavar=("WHICH", "PATH"), help=argparse.SUPPRESS)
    ap.add_argument("--trace", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child[0], Path(args.child[1]), args.trace)
        return
    import numpy as np

    path = make_series(args.slices)
    # warm-up (imports, page cache) and a correctness check: same voxels, same order
    a = load_ctui(path)
    img, b = load_sitk(path)
    same = a.shape == b.shape and np.array_equal(a, b)
    print(f"series: {args.slices} x 512 x 512, ctui {a.dtype} / SimpleITK {b.dtype}, identical voxels: {same}")
    del a, b, img
    t_ctui, t_sitk, c_ctui, c_sitk = [], [], [], []
    for _ in range(args.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        a = load_ctui(path)
        t_ctui.append(time.perf_counter() - t0)
        c_ctui.append(time.process_time() - c0)
        del a
        t0, c0 = time.perf_counter(), time.process_time()
        img, b = load_sitk(path)
        t_sitk.append(time.perf_counter() - t0)
        c_sitk.append(time.process_time() - c0)
        del img, b
    mc, ms = statistics.median(t_ctui), statistics.median(t_sitk)
    print(f"ctui      median {mc:.3f} s  (runs: {', '.join(f'{t:.3f}' for t in t_ctui)})")
    print(f"SimpleITK median {ms:.3f} s  (runs: {', '.join(f'{t:.3f}' for t in t_sitk)})")
    print(f"ratio ctui/SimpleITK = {mc / ms:.2f}  ({'ctui faster' if mc < ms else 'SimpleITK faster'})")
    # CPU seconds (all threads) hold on a busy machine where wall times do not
    cc, cs = statistics.median(c_ctui), statistics.median(c_sitk)
    print(f"CPU time: ctui median {cc:.3f} s, SimpleITK median {cs:.3f} s, ratio {cc / cs:.2f}")
    pc, ps = measure_child("ctui", path), measure_child("sitk", path)
    pc["tracemalloc_peak"] = measure_child("ctui", path, trace=True)["tracemalloc_peak"]
    mb = 1 / (1 << 20)
    print(f"peak memory ctui:      RSS growth {pc['rss_growth'] * mb:.1f} MB for a {pc['nbytes'] * mb:.1f} MB array "
          f"({pc['rss_growth'] / pc['nbytes']:.3f}x); tracemalloc peak {pc['tracemalloc_peak'] * mb:.1f} MB "
          f"({pc['tracemalloc_peak'] / pc['nbytes']:.3f}x)")
    print(f"peak memory SimpleITK: RSS growth {ps['rss_growth'] * mb:.1f} MB for a {ps['nbytes'] * mb:.1f} MB array "
          f"({ps['rss_growth'] / ps['nbytes']:.3f}x)")
    info_figures(path, args.repeat)
    if args.large:
        big = make_series(1000)
        pl, pt = measure_child("ctui", big), measure_child("ctui", big, trace=True)
        t0 = time.perf_counter()
        img, b = load_sitk(big)
        tsitk = time.perf_counter() - t0
        del img, b
        print(f"1000 x 512 x 512: ctui {pl['seconds']:.2f} s (SimpleITK {tsitk:.2f} s), RSS growth "
              f"{pl['rss_growth'] * mb:.0f} MB for a {pl['nbytes'] * mb:.0f} MB array "
              f"({pl['rss_growth'] / pl['nbytes']:.3f}x), tracemalloc peak {pt['tracemalloc_peak'] / pl['nbytes']:.3f}x")

if __name__ == "__main__":
    main()
