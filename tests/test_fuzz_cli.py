"""Fuzz the ctui COMMANDS end to end: mutated inputs through `ctui info/measure/mesh`.

The reader-level fuzzers (tests/test_fuzz_*.py on test_fuzz_harness) call one reader
in-process; this one drives the command line as a user does, so it also catches what
the commands do with a file that loads (a wrong shape, NaN spacing, a negative
volume) and how they report errors. Seeds: ctui's own outputs (a project, NIfTI,
NRRD and seg.nrrd label maps, an MRIC file, STL/PLY/OBJ meshes, a DICOM slice) made
from a small phantom series, plus real files from ../shared/data when present
(multi-frame MR, an MR slice without file meta, a MetaImage header, dcmqi NRRD label
maps). Mutations: byte-level (flips, interesting integers, cuts, inserts), text-header
edits (a value replaced by nan/inf/0/-1/huge, lines dropped or doubled), gzip payloads
mutated and recompressed (so the CRC does not reject everything), structured
project.json edits (a field replaced by a hostile value), and a quarter of the cases
drawn by hypothesis (integer edits, insertions, cuts; derandomized in CI).

Each case runs ``ctui.cli.main(argv)`` in a child FORKED from a warm server process
(imports done once: ~0.1 s a case instead of ~1.5 s for a fresh interpreter), with
``RLIMIT_AS`` capped, 30 s of CPU (RLIMIT_CPU) and a wall-clock alarm. Rules (a break of any one is a finding):

* ``traceback``: an uncaught exception (or exit status other than 0, 2);
* ``message``: exit 2 whose stderr is not one line ``ctui CMD: ...`` naming a file;
* ``slow``: no result within 30 s of CPU time (RLIMIT_CPU; the tests share a loaded
  machine, so wall time is only bounded by a 300 s alarm for hangs that use no CPU);
* ``alloc``: MemoryError (the cap was hit before a size check refused), or the child
  died of a signal (SIGSEGV/SIGABRT/SIGKILL from an allocation failure in C);
* ``wrong``: exit 0 with a result the input contradicts (an oracle per format: shape
  as declared by an independent header parser -- nibabel, pynrrd, pydicom, the MHD
  text --, spacing finite and > 0, every number in the JSON report finite, volumes,
  voxel counts and areas >= 0, a mesh written that reads back with the reported
  triangle count).

CI runs ``CTUI_FUZZ_CLI_CASES`` (default 120) cases; ``benchmarks/fuzz.py --cases
10000`` runs the long campaign with the same engine. Findings are saved with a
reproducer command (``ctui ...`` on the saved input).
"""

from __future__ import annotations

import gzip
import io
import json
import math
import os
import re
import resource
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import traceback
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SHARED = Path(os.environ.get("CTUI_SHARED_DATA", ROOT.parent / "shared" / "data"))
TIMEOUT_S = 30  # CPU seconds a case may use (RLIMIT_CPU: a loaded machine does not make a case "slow")
WALL_S = int(os.environ.get("CTUI_FUZZ_WALL_S", "300"))  # wall-clock alarm: hangs that use no CPU
CAP_MB = int(os.environ.get("CTUI_FUZZ_AS_MB", "2048"))  # address space a case may add to the warm server's
INTERESTING_TEXT = ["nan", "NaN", "inf", "-inf", "0", "-0", "-1", "1e308", "-1e308", "1e-300", "99999999",
                    "2147483648", "4294967296", "65535", "", "x", "1,2", "3 3", "0 0 0", "-5 4 3", "1e9 1 1"]


# --------------------------------------------------------------------- seeds
@dataclass
class Seed:
    """One input: ``files`` (relative name -> bytes) laid out in a case folder;
    ``argv`` run on them ({dir} = the case folder); ``kind`` picks mutators and oracle."""

    name: str
    kind: str  # nifti, nrrd, mhd, dicom, project, mric, stl, stl-ascii, ply, obj
    main: str  # the file that is mutated
    files: dict[str, bytes]
    argv: list[str]
    real: bool = False


def _small_series(folder: Path) -> Path:
    sys.path.insert(0, str(HERE))
    from test_privacy import write_series

    return write_series(folder, broken=False)


def make_seeds(work: Path) -> list[Seed]:
    """Build ctui's own seed files from a phantom series, add real files when present."""
    from ctui.cli import main

    work.mkdir(parents=True, exist_ok=True)
    series = _small_series(work / "series")
    seed = "24,24,8"
    out = io.StringIO()
    old = sys.stdout
    sys.stdout = out
    try:
        rc = main(["segment", str(series), "--seed", seed, "--range", "200:400", "--project", str(work / "p.ctui"),
                   "--mask", str(work / "m.nii.gz"), "--mric", str(work / "c.mric")])
        rc |= main(["segment", str(series), "--seed", seed, "--range", "200:400", "--mask", str(work / "m.nrrd")])
        rc |= main(["segment", str(series), "--seed", seed, "--range", "200:400", "--mask", str(work / "m.seg.nrrd")])
        rc |= main(["segment", str(series), "--seed", seed, "--range", "200:400", "--mask", str(work / "m.nii")])
    finally:
        sys.stdout = old
    if rc:
        raise RuntimeError(f"cannot build the fuzz seeds (segment exit {rc})")
    from ctui.engine.core.meshdata import Mesh
    from ctui.engine.io.meshes import save_mesh
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=1, radius=5.0)
    mesh = Mesh(vertices=np.asarray(s.vertices, np.float64), faces=np.asarray(s.faces))
    for name, asc in (("b.stl", False), ("a.stl", True), ("b.ply", False), ("a.ply", True), ("m.obj", False)):
        save_mesh(work / name, mesh, ascii=asc)
    rd = lambda n: (work / n).read_bytes()  # noqa: E731
    seeds = [
        Seed("project", "project", "p.ctui", {"p.ctui": rd("p.ctui")}, ["measure", "{dir}/p.ctui", "--json"]),
        Seed("project-mesh", "project", "p.ctui", {"p.ctui": rd("p.ctui")},
             ["mesh", "{dir}/p.ctui", "--out", "{dir}/o.stl", "--json"]),
        Seed("nii.gz", "nifti", "m.nii.gz", {"m.nii.gz": rd("m.nii.gz")}, ["info", "{dir}/m.nii.gz", "--json"]),
        Seed("nii", "nifti", "m.nii", {"m.nii": rd("m.nii")}, ["info", "{dir}/m.nii", "--json"]),
        Seed("nii-measure", "nifti", "m.nii", {"m.nii": rd("m.nii")}, ["measure", "{dir}/m.nii", "--json", "--no-mesh"]),
        Seed("nrrd", "nrrd", "m.nrrd", {"m.nrrd": rd("m.nrrd")}, ["info", "{dir}/m.nrrd", "--json"]),
        Seed("seg.nrrd", "nrrd", "m.seg.nrrd", {"m.seg.nrrd": rd("m.seg.nrrd")},
             ["measure", "{dir}/m.seg.nrrd", "--json", "--no-mesh"]),
        Seed("mric", "mric", "c.mric", {"c.mric": rd("c.mric"), **({"c.mric.json": rd("c.mric.json")} if (work / "c.mric.json").is_file() else {})},
             ["mesh", "{dir}/c.mric", "--out", "{dir}/o.stl", "--json"]),
        Seed("stl", "stl", "b.stl", {"b.stl": rd("b.stl")}, ["measure", "{dir}/b.stl", "--json"]),
        Seed("stl-ascii", "stl-ascii", "a.stl", {"a.stl": rd("a.stl")}, ["measure", "{dir}/a.stl", "--json"]),
        Seed("ply", "ply", "b.ply", {"b.ply": rd("b.ply")}, ["measure", "{dir}/b.ply", "--json"]),
        Seed("ply-ascii", "ply", "a.ply", {"a.ply": rd("a.ply")}, ["measure", "{dir}/a.ply", "--json"]),
        Seed("obj", "obj", "m.obj", {"m.obj": rd("m.obj")}, ["measure", "{dir}/m.obj", "--json"]),
        Seed("dicom-slice", "dicom", "s.dcm", {"s.dcm": (series / "slice008.dcm").read_bytes()},
             ["info", "{dir}/s.dcm", "--json"]),
    ]
    real = [
        ("mr-multiframe", "dicom", "mr_multiframe/emri_small.dcm", "emri.dcm", None),
        ("mr-nometa", "dicom", "misc_mr/mr.001", "mr.001", None),
        ("mhd", "mhd", "misc_mr/HeadMRVolume.mhd", "HeadMRVolume.mhd", ("misc_mr/HeadMRVolume.raw", "HeadMRVolume.raw")),
        ("dcmqi-nrrd", "nrrd", "dcmqi_seg/liver_seg.nrrd", "liver_seg.nrrd", None),
        ("dcmqi-sparse", "nrrd", "dcmqi_seg/sparse_labelmap_noppv_seg.nrrd", "sparse.nrrd", None),
    ]
    for name, kind, rel, local, extra in real:
        p = SHARED / rel
        if not p.is_file():
            continue
        files = {local: p.read_bytes()}
        if extra:
            q = SHARED / extra[0]
            if not q.is_file():
                continue
            files[extra[1]] = q.read_bytes()
        seeds.append(Seed(name, kind, local, files, ["info", "{dir}/" + local, "--json"], real=True))
    return seeds


# --------------------------------------------------------------------- mutators
def _byte_mutate(data: bytes, rng) -> bytes:
    sys.path.insert(0, str(HERE))
    from test_fuzz_harness import mutate

    r = rng.random()
    if r < 0.15 and data:  # truncation
        return data[: int(rng.integers(0, len(data)))]
    return mutate(data, rng)


def _text_mutate(text: str, rng) -> str:
    lines = text.split("\n")
    for _ in range(int(rng.integers(1, 3))):
        if not lines:
            break
        i = int(rng.integers(0, len(lines)))
        op = rng.random()
        line = lines[i]
        if op < 0.6:
            nums = list(re.finditer(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?", line))
            val = INTERESTING_TEXT[int(rng.integers(0, len(INTERESTING_TEXT)))]
            if nums:
                m = nums[int(rng.integers(0, len(nums)))]
                lines[i] = line[: m.start()] + val + line[m.end():]
            elif ":" in line or "=" in line:
                sep = ":" if ":" in line else "="
                lines[i] = line.split(sep, 1)[0] + sep + " " + val
        elif op < 0.75:
            del lines[i]
        elif op < 0.9:
            lines.insert(i, line)
        else:
            j = int(rng.integers(0, len(lines)))
            lines[i], lines[j] = lines[j], lines[i]
    return "\n".join(lines)


def _split_header(data: bytes, kind: str) -> tuple[bytes, bytes]:
    """(text header, binary rest) for formats with a text header; (b"", data) otherwise."""
    if kind == "nrrd" or (kind == "ply"):
        marker = b"\n\n" if kind == "nrrd" else b"end_header\n"
        i = data.find(marker)
        if i >= 0:
            return data[: i + len(marker)], data[i + len(marker):]
    if kind in ("mhd", "stl-ascii", "obj"):
        return data, b""
    return b"", data


HOSTILE_JSON = [None, True, -1, 0, 2**63, 1e308, -1e308, "x", "", [], {}, [[[]]], [-1, 2, 3], [0, 0, 0],
                [1e308, 1, 1], [2**31, 2**31, 2**31], ["a", "b", "c"], [1, 2], [1, 2, 3, 4]]


def _project_mutate(data: bytes, rng) -> bytes:
    """A project whose project.json has one field (or one list item) replaced by a hostile value."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            members = {n: zf.read(n) for n in zf.namelist()}
        doc = json.loads(members["project.json"])
    except Exception:  # noqa: BLE001 - not a valid seed: fall back to bytes
        return _byte_mutate(data, rng)
    paths: list[list] = []

    def walk(o, path):
        paths.append(path)
        if isinstance(o, dict):
            for k, v in o.items():
                walk(v, path + [k])
        elif isinstance(o, list):
            for i, v in enumerate(o[:8]):
                walk(v, path + [i])

    walk(doc, [])
    path = paths[int(rng.integers(1, len(paths)))] if len(paths) > 1 else []
    val = HOSTILE_JSON[int(rng.integers(0, len(HOSTILE_JSON)))]
    if path:
        o = doc
        for k in path[:-1]:
            o = o[k]
        if rng.random() < 0.1 and isinstance(o, dict):
            del o[path[-1]]
        else:
            o[path[-1]] = val
    members["project.json"] = json.dumps(doc).encode()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for n, b in members.items():
            zf.writestr(n, b)
    return buf.getvalue()


def mutate_seed(seed: Seed, rng) -> tuple[bytes, str]:
    """A mutated copy of the seed's main file and the mutator's name."""
    data = seed.files[seed.main]
    r = rng.random()
    if seed.kind == "project" and r < 0.6:
        return _project_mutate(data, rng), "project-json"
    if data[:2] == b"\x1f\x8b" and r < 0.6:
        try:
            inner = gzip.decompress(data)
        except OSError:
            inner = None
        if inner is not None:
            return gzip.compress(_inner_mutate(inner, seed.kind, rng), 6), "gzip-payload"
    if r < 0.75:
        return _inner_mutate(data, seed.kind, rng), "structured"
    return _byte_mutate(data, rng), "bytes"


NIFTI_FIELDS = [*[(40 + 2 * i, "<h") for i in range(8)], (70, "<h"), (72, "<h"), *[(76 + 4 * i, "<f") for i in range(8)],
                (108, "<f"), (112, "<f"), (116, "<f"), (252, "<h"), (254, "<h"), *[(280 + 4 * i, "<f") for i in range(12)]]
NIFTI_VALUES = [0, 1, 2, 3, 4, 7, 8, 16, 48, 64, 255, 256, -1, -5, 32767, -32768, float("nan"), float("inf"), -float("inf"),
                0.0, -1.0, 1e-30, 1e30, 0.5, 2.0]


def _inner_mutate(data: bytes, kind: str, rng) -> bytes:
    if kind == "nifti" and len(data) >= 348 and rng.random() < 0.7:
        b = bytearray(data)
        for _ in range(int(rng.integers(1, 3))):
            off, fmt = NIFTI_FIELDS[int(rng.integers(0, len(NIFTI_FIELDS)))]
            v = NIFTI_VALUES[int(rng.integers(0, len(NIFTI_VALUES)))]
            if fmt == "<h":
                v = int(v) if isinstance(v, int) else int(rng.integers(-3, 300))
                v = max(-32768, min(32767, v))
            struct.pack_into(fmt, b, off, v)
        return bytes(b)
    head, rest = _split_header(data, kind)
    if head and rng.random() < 0.8:
        return _text_mutate(head.decode("latin-1"), rng).encode("latin-1") + rest
    return _byte_mutate(data, rng)


# --------------------------------------------------------------------- oracles
def _numbers(o, path=""):
    if isinstance(o, bool):
        return
    if isinstance(o, (int, float)):
        yield path, o
    elif isinstance(o, dict):
        for k, v in o.items():
            yield from _numbers(v, f"{path}.{k}")
    elif isinstance(o, list):
        for i, v in enumerate(o):
            yield from _numbers(v, f"{path}[{i}]")


def _declared_shape(kind: str, path: Path) -> tuple | None:
    """The (z, y, x) shape the file's header declares, by an independent parser; None when
    that parser cannot tell (then only the generic rules apply)."""
    try:
        if kind == "nifti":
            import nibabel as nib

            raw = path.read_bytes()
            if raw[:2] == b"\x1f\x8b":
                raw = gzip.GzipFile(fileobj=io.BytesIO(raw)).read(348)
            hdr = nib.Nifti1Header.from_fileobj(io.BytesIO(raw[:348]), check=False)
            dim = [int(v) for v in hdr["dim"]]
            if dim[0] in (2, 3) and all(d >= 1 for d in dim[1 : 1 + dim[0]]):
                nx, ny = dim[1], dim[2]
                nz = dim[3] if dim[0] == 3 else 1
                return (nz, ny, nx)
            return None
        if kind == "nrrd":
            import nrrd

            with open(path, "rb") as fh:
                head = fh.read(65536)
            i = head.find(b"\n\n")
            if i < 0:
                return None
            h = nrrd.read_header(io.StringIO(head[: i + 1].decode("latin-1")))
            sizes = [int(s) for s in np.atleast_1d(h.get("sizes", []))]
            if int(h.get("dimension", 0)) == 3 and len(sizes) == 3 and min(sizes) >= 1:
                return tuple(reversed(sizes))
            return None
        if kind == "mhd":
            txt = path.read_text("latin-1")
            m = re.search(r"^\s*DimSize\s*=\s*(.*)$", txt, re.M)
            nd = re.search(r"^\s*NDims\s*=\s*(\S+)\s*$", txt, re.M)
            if m and nd and nd.group(1) == "3":
                vals = [int(v) for v in m.group(1).split()]
                if len(vals) == 3 and min(vals) >= 1:
                    return tuple(reversed(vals))
            return None
        if kind == "dicom":
            import pydicom

            ds = pydicom.dcmread(str(path), stop_before_pixels=True, force=True)
            rows, cols = int(ds.Rows), int(ds.Columns)
            if rows >= 1 and cols >= 1:
                return (None, rows, cols)
    except Exception:  # noqa: BLE001 - the reference cannot parse it: no shape oracle
        return None
    return None


def oracle(seed: Seed, case_dir: Path, stdout: str) -> str | None:
    """None when an exit-0 result is plausible for the mutated input, else why not."""
    try:
        rep = json.loads(stdout)
    except ValueError as exc:
        return f"--json output is not JSON ({exc})"
    for where, v in _numbers(rep):
        if isinstance(v, float) and not math.isfinite(v):
            return f"non-finite number {v} at {where}"
        low = where.lower()
        if any(w in low for w in ("volume", "voxels", "area", "triangles", "vertices")) and v < 0 and "warning" not in low:
            return f"negative {where} = {v}"
    cmd = seed.argv[0]
    if cmd == "info":
        shape = rep.get("shape_zyx") or []
        sp = rep.get("spacing_zyx_mm") or []
        if len(shape) != 3 or min(shape) < 1:
            return f"shape {shape}"
        if len(sp) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in sp):
            return f"spacing {sp}"
        want = _declared_shape(seed.kind, case_dir / seed.main)
        if want is not None:
            got = tuple(shape)
            if any(w is not None and w != g for w, g in zip(want, got)):
                return f"shape {list(got)} but the header declares {list(want)} (z, y, x)"
    if cmd == "mesh":
        out = case_dir / "o.stl"
        if not out.is_file():
            return "exit 0 but no mesh written"
        b = out.read_bytes()
        n = struct.unpack_from("<I", b, 80)[0] if len(b) >= 84 else -1
        if len(b) != 84 + 50 * n:
            return f"written STL is inconsistent ({len(b)} bytes for {n} triangles)"
        if "triangles" in rep and rep["triangles"] != n:
            return f"report says {rep['triangles']} triangles, the file holds {n}"
    return None


# --------------------------------------------------------------------- running cases
@dataclass
class Outcome:
    kind: str  # ok, error, traceback, message, slow, alloc, wrong
    rc: int
    seconds: float
    detail: str = ""


def _vm_size() -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


def _child(argv: list[str], case_dir: Path, cap: int) -> None:  # pragma: no cover - runs in the fork
    code = 1
    try:
        os.chdir(case_dir)
        out = open(case_dir / ".stdout", "w")
        err = open(case_dir / ".stderr", "w")
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        sys.stdout, sys.stderr = out, err
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
        resource.setrlimit(resource.RLIMIT_CPU, (TIMEOUT_S + 1, TIMEOUT_S + 2))
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        signal.signal(signal.SIGXCPU, signal.SIG_DFL)
        signal.alarm(WALL_S)
        from ctui.cli import main

        code = int(main(argv) or 0)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:  # noqa: BLE001 - an uncaught exception is what we look for
        traceback.print_exc()
        code = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except Exception:  # noqa: BLE001
            pass
        os._exit(code)


def run_case(seed: Seed, data: bytes, case_dir: Path) -> Outcome:
    """Lay out the case (mutated main file + the seed's other files) and run it in a fork."""
    if case_dir.exists():
        shutil.rmtree(case_dir)
    case_dir.mkdir(parents=True)
    for name, b in seed.files.items():
        (case_dir / name).write_bytes(data if name == seed.main else b)
    argv = [a.replace("{dir}", str(case_dir)) for a in seed.argv]
    cap = _vm_size() + CAP_MB * 2**20
    t0 = time.monotonic()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:  # pragma: no cover
        _child(argv, case_dir, cap)
    _, status, usage = os.wait4(pid, 0)
    dt = time.monotonic() - t0
    cpu = usage.ru_utime + usage.ru_stime
    stdout = (case_dir / ".stdout").read_text(errors="replace")
    stderr = (case_dir / ".stderr").read_text(errors="replace")
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        if sig in (signal.SIGALRM, signal.SIGXCPU):
            return Outcome("slow", -sig, cpu, f"no result within {TIMEOUT_S} s of CPU ({WALL_S} s of wall clock); "
                           f"used {cpu:.1f} s CPU in {dt:.0f} s")
        return Outcome("alloc" if sig in (signal.SIGSEGV, signal.SIGABRT, signal.SIGKILL, signal.SIGBUS) else "traceback",
                       -sig, dt, f"killed by signal {signal.Signals(sig).name}: {stderr.strip()[-300:]}")
    rc = os.WEXITSTATUS(status)
    if cpu > TIMEOUT_S:
        return Outcome("slow", rc, cpu, f"{cpu:.1f} s of CPU")
    dt = cpu  # the figure reported as a case's time: its CPU seconds (independent of the machine's load)
    if "Traceback (most recent call last)" in stderr or rc not in (0, 2):
        last = [ln for ln in stderr.strip().splitlines() if ln.strip()][-3:]
        kind = "alloc" if "MemoryError" in stderr else "traceback"
        return Outcome(kind, rc, dt, " | ".join(last)[-600:])
    if rc == 2:
        lines = [ln for ln in stderr.splitlines() if ln.strip()]
        if "MemoryError" in stderr:
            return Outcome("alloc", rc, dt, stderr.strip()[-300:])
        if len(lines) != 1 or not lines[0].startswith(f"ctui {seed.argv[0]}: "):
            return Outcome("message", rc, dt, repr(stderr[-400:]))
        names = set(seed.files) | {case_dir.name, "o.stl"}
        if not any(n in lines[0] for n in names):
            return Outcome("message", rc, dt, f"does not name the file: {lines[0][:300]}")
        return Outcome("error", rc, dt, lines[0][:300])
    why = oracle(seed, case_dir, stdout)
    if why:
        return Outcome("wrong", rc, dt, why)
    return Outcome("ok", rc, dt)


FINDINGS = ("traceback", "message", "slow", "alloc", "wrong")


def warm_up(seeds: list[Seed], work: Path) -> None:
    """Import every engine and command module (and the libraries they use) once, before
    forking: each case then runs the code as it was when the campaign started (a file
    being edited meanwhile cannot break a lazy import) and starts in ~0.1 s. Numba
    kernels are not run here, so no thread pool is forked."""
    import importlib
    import pkgutil

    import ctui

    for mod in ("pydicom", "nibabel", "nrrd", "trimesh", "scipy.ndimage", "skimage.measure", "PIL.Image"):
        try:
            importlib.import_module(mod)
        except Exception:  # noqa: BLE001
            pass
    for info in pkgutil.walk_packages(ctui.__path__, "ctui."):
        skip = info.name.startswith(("ctui.screens", "ctui.app", "ctui.tui")) or ".render" in info.name
        if skip or info.name.endswith("__main__"):  # __main__ would open the TUI
            continue
        try:
            importlib.import_module(info.name)
        except Exception:  # noqa: BLE001 - a module being rewritten by someone else: the cases will show it
            pass


def hypothesis_inputs(seeds: list[Seed], n: int) -> list[tuple[Seed, bytes, str]]:
    """``n`` structured mutations drawn by hypothesis (derandomized: the same cases every
    CI run unless CTUI_FUZZ_RANDOM=1): a seed, up to 6 little-endian 1/2/4-byte edits of
    interesting values, an optional insertion and an optional cut."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    interesting = st.sampled_from([0, 1, 2, 3, 0x7F, 0x80, 0xFF, 0x100, 0x7FFF, 0x8000, 0xFFFF, 0x10000,
                                   0x7FFFFFFF, 0x80000000, 0xFFFFFFFF])
    frac = st.floats(0, 1, allow_nan=False)
    edit = st.tuples(frac, st.one_of(interesting, st.integers(0, 2**32 - 1)), st.sampled_from([1, 2, 4]))
    drawn: list[tuple[Seed, bytes, str]] = []

    @settings(max_examples=n, deadline=None, database=None, derandomize=os.environ.get("CTUI_FUZZ_RANDOM") != "1",
              suppress_health_check=list(HealthCheck))
    @given(k=st.integers(0, len(seeds) - 1), edits=st.lists(edit, max_size=6),
           insert=st.one_of(st.none(), st.tuples(frac, st.binary(max_size=40))), cut=st.one_of(st.none(), frac))
    def draw(k, edits, insert, cut):
        seed = seeds[k]
        b = bytearray(seed.files[seed.main])
        for f, val, width in edits:
            off = int(f * max(len(b) - width, 0))
            if off + width <= len(b):
                struct.pack_into({1: "<B", 2: "<H", 4: "<I"}[width], b, off, val & ((1 << (8 * width)) - 1))
        if insert is not None:
            i = int(insert[0] * len(b))
            b[i:i] = insert[1]
        if cut is not None:
            del b[int(cut * len(b)):]
        drawn.append((seed, bytes(b), "hypothesis"))

    draw()
    return drawn[:n]


def campaign(n_cases: int, out: Path, *, seed_value: int = 0, log: Callable[[str], None] | None = None,
             report_every: int = 0, hypothesis_share: float = 0.25) -> dict:
    """Run ``n_cases`` mutated cases over all seeds (round robin); return the summary.

    Findings are copied to ``out/findings/<kind>-<n>-<name>`` with a ``README`` line
    giving the reproducer command.
    """
    out.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="ctui-fuzzcli-"))
    seeds = make_seeds(work / "seeds")
    warm_up(seeds, work)
    rng = np.random.default_rng(seed_value)
    counts: dict[str, int] = {k: 0 for k in ("ok", "error", *FINDINGS)}
    per_seed: dict[str, dict[str, int]] = {}
    findings: list[dict] = []
    slowest = 0.0
    t0 = time.monotonic()
    # every seed unmutated first: they must all give exit 0 and pass the oracle
    plan = [(s, s.files[s.main], "valid") for s in seeds]
    plan += hypothesis_inputs(seeds, max(0, int(hypothesis_share * (n_cases - len(plan)))))
    i = 0
    while i < n_cases:
        if plan:
            s, data, how = plan.pop(0)
        else:
            s = seeds[i % len(seeds)]
            data, how = mutate_seed(s, rng)
        res = run_case(s, data, work / "case")
        if how == "valid" and res.kind != "ok":
            res = Outcome("wrong" if res.kind == "error" else res.kind, res.rc, res.seconds,
                          f"the unmutated seed failed: {res.detail}")
        counts[res.kind] += 1
        per_seed.setdefault(s.name, {}).setdefault(res.kind, 0)
        per_seed[s.name][res.kind] += 1
        slowest = max(slowest, res.seconds)
        if res.kind in FINDINGS:
            fdir = out / "findings" / f"{res.kind}-{i:05d}-{s.name}"
            if fdir.exists():
                shutil.rmtree(fdir)
            shutil.copytree(work / "case", fdir, ignore=shutil.ignore_patterns(".stdout", "o.stl"))
            argv = " ".join(a.replace("{dir}", str(fdir)) for a in s.argv)
            f = {"case": i, "seed": s.name, "kind": res.kind, "mutator": how, "rc": res.rc,
                 "seconds": round(res.seconds, 2), "detail": res.detail, "repro": f"ctui {argv}"}
            (fdir / "README").write_text(json.dumps(f, indent=1) + "\n")
            findings.append(f)
            if log:
                log(f"FINDING {res.kind} [{s.name}/{how}] {res.detail[:200]}\n    repro: ctui {argv}")
        i += 1
        if log and report_every and i % report_every == 0:
            log(f"{i} cases in {time.monotonic() - t0:.0f} s: {counts}")
    shutil.rmtree(work, ignore_errors=True)
    summary = {"cases": i, "counts": counts, "per_seed": per_seed, "findings": findings,
               "seconds": round(time.monotonic() - t0, 1), "slowest_case_s": round(slowest, 2),
               "seeds": [s.name for s in seeds], "cap_mb": CAP_MB, "timeout_s": TIMEOUT_S}
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    return summary


# --------------------------------------------------------------------- the CI test
def _script_env() -> dict:
    return {**os.environ, "CTUI_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
            "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "CTUI_NO_PROGRESS": "1", "PYTHONHASHSEED": "0"}


def test_fuzz_commands(tmp_path):
    """A few hundred mutated inputs through the commands: no traceback, hang, runaway
    allocation, multi-line error or exit-0 wrong result (see the module docstring)."""
    n = int(os.environ.get("CTUI_FUZZ_CLI_CASES", "120"))
    r = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--cases", str(n), "--out", str(tmp_path)],
                       capture_output=True, text=True, cwd=ROOT, env=_script_env(), timeout=1800)
    assert r.returncode == 0, r.stderr[-3000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    print(f"fuzz commands: {summary['cases']} cases in {summary['seconds']} s, counts {summary['counts']}")
    assert summary["cases"] == n
    assert summary["counts"]["ok"] + summary["counts"]["error"] == n, summary["findings"][:8]


def test_oracle_catches_wrong_results(tmp_path):
    """The oracle itself: a shape that contradicts the header, NaN spacing, negative volume."""
    seed = Seed("nrrd", "nrrd", "m.nrrd", {}, ["info", "{dir}/m.nrrd", "--json"])
    (tmp_path / "m.nrrd").write_bytes(b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 5 4 3\nencoding: raw\n\n" + bytes(60))
    ok = {"shape_zyx": [3, 4, 5], "spacing_zyx_mm": [1.0, 1.0, 1.0]}
    assert oracle(seed, tmp_path, json.dumps(ok)) is None
    assert "declares" in oracle(seed, tmp_path, json.dumps({**ok, "shape_zyx": [3, 4, 6]}))
    assert "spacing" in oracle(seed, tmp_path, json.dumps({**ok, "spacing_zyx_mm": [1.0, 0.0, 1.0]}))
    assert "non-finite" in oracle(seed, tmp_path, json.dumps({**ok, "spacing_zyx_mm": [1.0, float("nan"), 1.0]}))
    m = Seed("stl", "stl", "b.stl", {}, ["measure", "{dir}/b.stl", "--json"])
    assert "negative" in oracle(m, tmp_path, json.dumps({"volume_ml": -3.0}))


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description="run the command fuzzer (see the module docstring)")
    ap.add_argument("--cases", type=int, default=160)
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--report-every", type=int, default=0)
    a = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    res = campaign(a.cases, Path(a.out), seed_value=a.seed, report_every=a.report_every,
                   log=lambda s: print(s, file=sys.stderr, flush=True))
    print(json.dumps({k: res[k] for k in ("cases", "counts", "seconds", "slowest_case_s")}))
