"""Big series: peak memory and wall time of whole commands at 300, 1,000 and 2,000 slices.

Run: ``nice -n 10 python3 benchmarks/scale.py [--slices 300,1000] [--formats dicom,nifti]
[--commands info,load,segment,mesh,render,measure,export] [--limit 4G] [--tree OLD_CHECKOUT]``

A synthetic CT-like series of 512 x 512 int16 slices (body, spine, ribs, pelvis, skull cap,
noise; ``--size`` for smaller slices) is written slice by slice into a temporary folder under
/tmp (DICOM: one file per slice; NIfTI: one ``.nii.gz``) and removed afterwards. Each command
runs in a fresh process; its peak resident memory is ``ru_maxrss`` of that child
(``os.wait4``), printed in MB and as a multiple of the series' voxels (nz x ny x nx x 2 bytes),
beside its wall time:

* ``info``: ``ctui info SERIES --json``; ``load``: a process that only loads the series;
* ``segment``: ``ctui segment SERIES --seed <spine> --range 200:3000 --mode 3d --project P``
  (one blob: the spine column through every slice);
* ``mesh``: ``ctui mesh SERIES --iso 300``; ``render``: ``ctui render SERIES --mode mip``;
* ``measure``: ``ctui measure P --json``; ``export``: ``ctui export P --format dicom-seg``
  (DICOM only: the SEG references the source images).
* ``tui`` (only when named in ``--commands``): ``benchmarks/first_paint.py`` on the series
  (first slice and workspace, in tmux) and ``benchmarks/tui.py --slices N`` (slice step and
  brush, median and p90; its last line is printed).

``--limit 4G`` runs every command with RLIMIT_AS at that size (and ``CTUI_MEMORY``): each must
succeed or refuse in one line; the line is printed. ``--tree``: run another checkout's ctui
(before/after).
"""

from __future__ import annotations

import argparse
import gzip
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the series are written in this process with this tree's ctui
TREE = ROOT
SPACING = (1.0, 0.7, 0.7)  # (dz, dy, dx) mm
ORIGIN = (-180.0, -180.0, -150.0)  # LPS mm of voxel (0, 0, 0)


# --------------------------------------------------------------------- the series
def ct_slice(z: int, nz: int, ny: int, nx: int, noise: np.ndarray) -> np.ndarray:
    """Slice ``z`` of a CT-like int16 volume (HU): body, spine, ribs, pelvis, skull cap
    (the shapes of ``benchmarks/isosurface.make_ct``), noise from a small bank."""
    y, x = np.ogrid[:ny, :nx]
    cy, cx = ny / 2, nx / 2
    zf = z / max(nz - 1, 1)
    body = ((x - cx) / (0.42 * nx)) ** 2 + ((y - cy) / (0.33 * ny)) ** 2 <= 1.0
    s = np.where(body, np.float32(40.0), np.float32(-1000.0))
    r = np.hypot(x - cx, y - (cy + 0.2 * ny))
    seg = 0.5 + 0.5 * np.cos(2 * np.pi * z / 25.0)
    s = np.where(r < 0.05 * nx * (0.8 + 0.2 * seg), 250.0 + 500.0 * (r > 0.04 * nx), s)
    if zf > 0.4 and (z % 20) < 6:
        e = np.hypot((x - cx) / (0.38 * nx), (y - cy) / (0.29 * ny))
        s = np.where(np.abs(e - 1.0) < 0.025, 800.0, s)
    if zf < 0.3:
        for sx in (-1, 1):
            e = np.hypot((x - cx - sx * 0.22 * nx) / (0.12 * nx), (y - cy) / (0.18 * ny))
            s = np.where(np.abs(e - 1.0) < 0.06 * (1.0 - zf), 900.0, s)
    if zf > 0.9:
        e = np.hypot((x - cx) / (0.3 * nx), (y - cy) / (0.25 * ny))
        s = np.where(np.abs(e - 0.8) < 0.05, 1200.0, s)
    s = s + noise[z % len(noise)]
    return np.clip(s, -1024, 3071).astype(np.int16)


def _slices(nz: int, ny: int, nx: int):
    noise = np.random.default_rng(0).normal(0.0, 15.0, size=(7, ny, nx)).astype(np.float32)
    for z in range(nz):
        yield z, ct_slice(z, nz, ny, nx, noise)


def write_dicom(out: Path, nz: int, ny: int, nx: int) -> Path:
    """One CT file per slice, written as generated (the template: ``io.phantom.write_series``)."""
    import pydicom

    from ctui.engine.core.volume import Volume
    from ctui.engine.io.phantom import write_series

    tmpl_dir = out / "_tmpl"
    write_series(tmpl_dir, Volume(data=np.zeros((1, ny, nx), np.int16), spacing=SPACING, origin=ORIGIN,
                                  modality="CT"), description="ctui scale CT")
    ds = pydicom.dcmread(next(tmpl_dir.glob("*.dcm")))
    shutil.rmtree(tmpl_dir)
    base_uid = ds.SOPInstanceUID
    for z, sl in _slices(nz, ny, nx):
        ds.SOPInstanceUID = ds.file_meta.MediaStorageSOPInstanceUID = f"{base_uid[:50]}.{z + 1}"
        ds.InstanceNumber = z + 1
        zmm = ORIGIN[2] + z * SPACING[0]
        ds.ImagePositionPatient = [ORIGIN[0], ORIGIN[1], zmm]
        ds.SliceLocation = zmm
        ds.PixelData = (sl.astype(np.int32) + 1024).astype(np.uint16).tobytes()
        pydicom.dcmwrite(out / f"IM{z + 1:05d}.dcm", ds, enforce_file_format=True)
    return out


def write_nifti(out: Path, nz: int, ny: int, nx: int) -> Path:
    """One ``.nii.gz`` (int16, no scaling), streamed slice by slice (gzip level 1)."""
    import nibabel as nib

    aff = np.diag([-SPACING[2], -SPACING[1], SPACING[0], 1.0])
    aff[:3, 3] = (-ORIGIN[0], -ORIGIN[1], ORIGIN[2])
    hdr = nib.Nifti1Header()
    hdr.set_data_shape((nx, ny, nz))
    hdr.set_data_dtype(np.int16)
    hdr.set_qform(aff, 1)
    hdr.set_sform(aff, 1)
    hdr.set_slope_inter(1.0, 0.0)
    hdr["vox_offset"] = 352
    path = out / "ct.nii.gz"
    with gzip.open(path, "wb", compresslevel=1) as fh:
        fh.write(hdr.binaryblock + b"\0" * 4)
        for _, sl in _slices(nz, ny, nx):
            fh.write(sl.tobytes())  # (y, x) C order = NIfTI's x-fastest slice
    return path


# --------------------------------------------------------------------- running
def _limit(nbytes: int | None):
    def pre() -> None:
        os.nice(0)
        if nbytes:
            resource.setrlimit(resource.RLIMIT_AS, (nbytes, nbytes))
    return pre


def run(cmd: list[str], *, limit: int | None, lines: str = "") -> tuple[float, int, int, str]:
    """(wall s, peak RSS bytes, exit code, last stderr/stdout line) of one child process
    (``lines``: the stdout lines holding one of these words, "|"-separated, instead)."""
    env = dict(os.environ, CTUI_NO_PROGRESS="1", PYTHONPATH=str(TREE))
    if limit:
        env["CTUI_MEMORY"] = str(limit)
    t = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(cmd, cwd=TREE, env=env, stdout=out, stderr=err, preexec_fn=_limit(limit))
        _, status, usage = os.wait4(proc.pid, 0)
        dt = time.perf_counter() - t
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(errors="replace").strip(), err.read().decode(errors="replace").strip()
    rc = os.waitstatus_to_exitcode(status)
    text = stderr or stdout
    last = text.splitlines()[-1] if text else ""
    if lines and rc == 0:
        last = "; ".join(" ".join(ln.split()) for ln in stdout.splitlines() if any(w in ln for w in lines.split("|")))
    return dt, int(usage.ru_maxrss) * 1024, rc, last


def commands(path: Path, kind: str, tmp: Path, nz: int, ny: int, nx: int) -> dict[str, list[str]]:
    ctui = [sys.executable, "-m", "ctui.cli"]
    p, proj = str(path), str(tmp / "s.ctui")
    seed = f"{nx // 2},{int(ny / 2 + 0.2 * ny)},{nz // 2}"
    cmds = {
        "info": ctui + ["info", p, "--json"],
        "load": [sys.executable, "-c", "import sys; from ctui.engine.io.series import load; load(sys.argv[1])", p],
        "segment": ctui + ["segment", p, "--seed", seed, "--range", "200:3000", "--mode", "3d", "--project", proj,
                           "--json"],
        "mesh": ctui + ["mesh", p, "--iso", "300", "--out", str(tmp / "m.stl")],
        "render": ctui + ["render", p, "--mode", "mip", "--out", str(tmp / "mip.png")],
        "measure": ctui + ["measure", proj, "--json"],
    }
    if kind == "dicom":
        cmds["export"] = ctui + ["export", proj, "--format", "dicom-seg", "--out", str(tmp / "seg.dcm")]
    return cmds


def parse_size(text: str) -> int:
    t = text.strip().upper().rstrip("B")
    mult = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}.get(t[-1:], 1)
    return int(float(t.rstrip("KMGT")) * mult)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--slices", default="300", help="series sizes in slices, e.g. 300,1000,2000")
    ap.add_argument("--size", type=int, default=512, help="rows = columns of a slice")
    ap.add_argument("--formats", default="dicom,nifti")
    ap.add_argument("--commands", default="info,load,segment,mesh,render,measure,export")
    ap.add_argument("--limit", default=None, help="RLIMIT_AS of every command (e.g. 4G) and CTUI_MEMORY")
    ap.add_argument("--tree", default=None, help="run the ctui of this source tree (before/after comparisons)")
    args = ap.parse_args()
    global TREE
    if args.tree:
        TREE = Path(args.tree).resolve()
    limit = parse_size(args.limit) if args.limit else None
    wanted = args.commands.split(",")
    print(f"tree {TREE}; limit {args.limit or 'none'}; peak RSS of each command's process")
    print(f"{'series':>16s} {'command':>8s} {'wall s':>7s} {'peak MB':>8s} {'x series':>8s}  result")
    for nz in (int(v) for v in args.slices.split(",")):
        for kind in args.formats.split(","):
            tmp = Path(tempfile.mkdtemp(prefix="ctui-scale-", dir="/tmp"))
            try:
                t = time.perf_counter()
                data = tmp / "series"
                data.mkdir()
                ny = nx = args.size
                path = write_dicom(data, nz, ny, nx) if kind == "dicom" else write_nifti(data, nz, ny, nx)
                series_bytes = nz * ny * nx * 2
                label = f"{nz} {kind} {series_bytes / 2**20:.0f}MB"
                print(f"{label:>16s} {'(write)':>8s} {time.perf_counter() - t:7.1f}", flush=True)
                for name, cmd in commands(path, kind, tmp, nz, ny, nx).items():
                    if name not in wanted:
                        continue
                    dt, peak, rc, last = run(cmd, limit=limit)
                    res = "ok" if rc == 0 else f"exit {rc}: {last[:150]}"
                    print(f"{label:>16s} {name:>8s} {dt:7.1f} {peak / 2**20:8.0f} {peak / series_bytes:8.2f}  {res}",
                          flush=True)
                if "tui" in wanted:  # first slice and workspace (tmux), slice step and brush (headless)
                    for script, extra in (("first_paint.py", ["--runs", "1", str(path)]),
                                          ("tui.py", ["--slices", str(nz), "--n", "20"])):
                        dt, peak, rc, last = run([sys.executable, str(ROOT / "benchmarks" / script), *extra],
                                                 limit=limit, lines="first slice|median")
                        print(f"{label:>16s} {'tui':>8s} {dt:7.1f} {peak / 2**20:8.0f} {peak / series_bytes:8.2f}  "
                              f"{script}: {last[:400] if rc == 0 else f'exit {rc}: ' + last[:150]}", flush=True)
            finally:
                shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
