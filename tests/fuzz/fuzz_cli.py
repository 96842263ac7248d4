"""The command fuzzer's engine (tests/fuzz/test_fuzz_cli.py, benchmarks/fuzz.py). Fuzz the ctui COMMANDS end to end: mutated inputs through `ctui info/measure/mesh`.

The reader-level fuzzers (tests/fuzz/test_fuzz_*.py on test_fuzz_harness) call one reader
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

tests/fuzz/test_fuzz_cli.py runs ``CTUI_FUZZ_CLI_CASES`` (default 120) cases in CI;
``benchmarks/fuzz.py --cases 10000`` runs the long campaign with the same engine;
``python tests/fuzz/fuzz_cli.py --cases N --out DIR`` runs it directly. Findings are saved with a
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
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parent), str(Path(__file__).resolve().parents[1])]
import support  # noqa: E402  (tests/support.py: every test folder on sys.path, for the seeds' writers)

support.put_test_folders_on_path()
from fuzz_cli_families import control_chars, family_seeds, layout_specials, mutate_family, specials_intact
from fuzz_cli_families4 import KINDS4, family_seeds4, mutate_family4, oracle4
from fuzz_cli_mutators import hypothesis_inputs, mutate_seed

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
SHARED = Path(os.environ.get("CTUI_SHARED_DATA", ROOT.parent / "shared" / "data"))
TIMEOUT_S = 30  # CPU seconds a case may use (RLIMIT_CPU: a loaded machine does not make a case "slow")
WALL_S = int(os.environ.get("CTUI_FUZZ_WALL_S", "300"))  # wall-clock alarm: hangs that use no CPU
CAP_MB = int(os.environ.get("CTUI_FUZZ_AS_MB", "2048"))  # address space a case may add to the warm server's

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
    specials: dict[str, str] = field(default_factory=dict)  # output name -> "fifo", "devnull-link"... (families)
    limits: dict[str, int] = field(default_factory=dict)  # "NOFILE"/"FSIZE": rlimit; "close": a std fd (families4)


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
    import trimesh

    from ctui.engine.core.meshdata import Mesh
    from ctui.engine.io.meshes import save_mesh

    s = trimesh.creation.icosphere(subdivisions=1, radius=5.0)
    mesh = Mesh(vertices=np.asarray(s.vertices, np.float64), faces=np.asarray(s.faces))
    for name, asc in (("b.stl", False), ("a.stl", True), ("b.ply", False), ("a.ply", True), ("m.obj", False)):
        save_mesh(work / name, mesh, ascii=asc)
    rd = lambda n: (work / n).read_bytes()
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
    fam = os.environ.get("CTUI_FUZZ_FAMILIES", "1")  # "0": none, "only": the families alone, "four": issue 41's
    if fam in ("only", "four"):
        seeds = []
    if fam == "four":
        return family_seeds4(Seed, work, {"p.ctui": rd("p.ctui")}, series)
    if fam != "0":  # issue 26's hostile families (fuzz_cli_families)
        seeds += family_seeds(Seed, work, {"p.ctui": rd("p.ctui"), "s.dcm": (series / "slice008.dcm").read_bytes(),
                                           "b.stl": rd("b.stl")}, series)
        seeds += family_seeds4(Seed, work, {"p.ctui": rd("p.ctui")}, series)  # issue 41's families
    return seeds


#: family seeds whose unmutated form is not a valid run (an option placeholder, a FIFO output)
NO_VALID_RUN = ("options", "outputs", "fifo-source")
FAMILY_KINDS = ("options", "outputs", "nrrd-detached", "dicom-fields", "seg-frames", "nifti-types", "mesh-degenerate",
                "batch", *KINDS4)


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
            # a key given twice: the last one counts, as in ITK's MetaIO (SimpleITK reads it so)
            m = re.findall(r"^\s*DimSize\s*=\s*(.*)$", txt, re.MULTILINE)
            nd = re.findall(r"^\s*NDims\s*=\s*(\S+)\s*$", txt, re.MULTILINE)
            if m and nd and nd[-1] == "3":
                vals = [int(v) for v in m[-1].split()]
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


def _finite_stl(p: Path) -> bool:
    if not p.is_file():
        return True  # judged below
    b = p.read_bytes()
    if len(b) < 84 or b[:5] == b"solid":
        return True
    n = struct.unpack_from("<I", b, 80)[0]
    if len(b) != 84 + 50 * n:
        return True  # judged below
    tri = np.frombuffer(b, np.dtype([("n", "<3f4"), ("v", "<9f4"), ("a", "<u2")]), count=n, offset=84)
    return bool(np.isfinite(tri["v"]).all())


def oracle(seed: Seed, case_dir: Path, stdout: str) -> str | None:
    """None when an exit-0 result is plausible for the mutated input, else why not."""
    if "--json" not in seed.argv:
        return None  # text output: only the terminal rule (control characters) applies
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
    if cmd == "mesh" and (rep.get("volume_ml") is None or not _finite_stl(case_dir / "o.stl")):
        return "mesh: no volume or non-finite vertices in the STL written"
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
    return oracle4(seed, rep, (case_dir / seed.main).read_bytes()) if (case_dir / seed.main).is_file() else None


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


def _limit(limits: dict[str, int]) -> None:  # pragma: no cover - in the child
    for key, v in limits.items():
        if key == "close":  # a closed standard stream, as `ctui ... <&-` / `>&-` / `2>&-`
            os.close(v)
            setattr(sys, ("stdin", "stdout", "stderr")[v], None)
        else:
            resource.setrlimit(getattr(resource, f"RLIMIT_{key}"), (v, v))


def _child(argv: list[str], case_dir: Path, cap: int, target: Callable | None, cpu_s: int,
           limits: dict[str, int] | None = None) -> None:  # pragma: no cover
    code = 1
    try:
        os.chdir(case_dir)
        out = open(case_dir / ".stdout", "w")
        err = open(case_dir / ".stderr", "w")
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        sys.stdout, sys.stderr = out, err
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu_s + 1, cpu_s + 2))
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        signal.signal(signal.SIGXCPU, signal.SIG_DFL)
        signal.alarm(WALL_S)
        if target is None:
            from ctui.cli import main as target
        _limit(limits or {})

        code = int(target(argv) or 0)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:  # noqa: BLE001 - an uncaught exception is what we look for
        traceback.print_exc()
        code = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except Exception:  # noqa: BLE001 - a stream the case closed
            pass
        os._exit(code)


def run_case(seed: Seed, data: bytes, case_dir: Path, *, target: Callable | None = None, cpu_s: int = TIMEOUT_S) -> Outcome:
    """Lay out the case (mutated main file + the seed's other files) and run it in a fork."""
    if case_dir.exists():
        shutil.rmtree(case_dir)
    case_dir.mkdir(parents=True)
    for name, b in seed.files.items():
        (case_dir / name).parent.mkdir(parents=True, exist_ok=True)  # a series folder
        (case_dir / name).write_bytes(data if name == seed.main else b)
    layout_specials(case_dir, seed.specials)
    argv = [a.replace("{dir}", str(case_dir)) for a in seed.argv]
    cap = _vm_size() + CAP_MB * 2**20
    t0 = time.monotonic()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:  # pragma: no cover
        _child(argv, case_dir, cap, target, cpu_s, seed.limits)
    _, status, usage = os.wait4(pid, 0)
    dt = time.monotonic() - t0
    cpu = usage.ru_utime + usage.ru_stime
    # raw bytes kept (surrogateescape): a C1 byte of a folder name is a control character on an 8-bit terminal
    stdout = (case_dir / ".stdout").read_bytes().decode("utf-8", "surrogateescape")
    stderr = (case_dir / ".stderr").read_bytes().decode("utf-8", "surrogateescape")
    broken = specials_intact(case_dir, seed.specials) if seed.specials else None
    if broken:
        return Outcome("replaced", -1, time.monotonic() - t0, broken)
    ctl = control_chars(stdout) or (control_chars(stderr) if "Traceback" not in stderr else None)
    if ctl:
        return Outcome("control", -1, time.monotonic() - t0, f"a control character reached the terminal: {ctl}")
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        if sig in (signal.SIGALRM, signal.SIGXCPU):
            return Outcome("slow", -sig, cpu, f"no result within {cpu_s} s of CPU ({WALL_S} s of wall clock); "
                           f"used {cpu:.1f} s CPU in {dt:.0f} s")
        return Outcome("alloc" if sig in (signal.SIGSEGV, signal.SIGABRT, signal.SIGKILL, signal.SIGBUS) else "traceback",
                       -sig, dt, f"killed by signal {signal.Signals(sig).name}: {stderr.strip()[-300:]}")
    rc = os.WEXITSTATUS(status)
    if cpu > cpu_s:
        return Outcome("slow", rc, cpu, f"{cpu:.1f} s of CPU")
    dt = cpu  # the figure reported as a case's time: its CPU seconds (independent of the machine's load)
    if seed.argv[0] == "batch" and rc == 1 and "Traceback" not in stderr:
        rc = 0  # ctui batch: exit 1 says some jobs failed (each with its one-line error in RESULTS.csv)
    if "Traceback (most recent call last)" in stderr or rc not in (0, 2):
        last = [ln for ln in stderr.strip().splitlines() if ln.strip()][-3:]
        kind = "alloc" if "MemoryError" in stderr else "traceback"
        return Outcome(kind, rc, dt, " | ".join(last)[-600:])
    # a closed stdout/stderr or a file-size limit on them: what was said cannot be judged, only how it ended
    relaxed = seed.limits.get("close") in (1, 2) or "FSIZE" in seed.limits
    if relaxed:
        return Outcome("error" if rc == 2 else "ok", rc, dt)
    if rc == 2:
        lines = [ln for ln in stderr.splitlines() if ln.strip()]
        if "MemoryError" in stderr:
            return Outcome("alloc", rc, dt, stderr.strip()[-300:])
        if len(lines) != 1 or not lines[0].startswith(f"ctui {seed.argv[0]}: "):
            return Outcome("message", rc, dt, repr(stderr[-400:]))
        names = set(seed.files) | {case_dir.name, "o.stl"} | set(seed.specials)
        names |= {a for a in seed.argv if a.startswith("--")}  # an option's fault names the option
        names |= {a for a in seed.argv if "/" in a and "{dir}" not in a}  # or an input outside the case folder
        if not any(n in lines[0] for n in names):
            return Outcome("message", rc, dt, f"does not name the file: {lines[0][:300]}")
        return Outcome("error", rc, dt, lines[0][:300])
    why = oracle(seed, case_dir, stdout)
    if why:
        return Outcome("wrong", rc, dt, why)
    return Outcome("ok", rc, dt)


def _not_copied(folder: str, names: list[str]) -> list[str]:
    """What a finding's copy leaves out: the captured stdout, the mesh written, FIFOs (copying one blocks)."""
    import stat

    return [n for n in names if n in (".stdout", "o.stl")
            or stat.S_ISFIFO(os.lstat(os.path.join(folder, n)).st_mode)]


FINDINGS = ("traceback", "message", "slow", "alloc", "wrong", "replaced", "control")


def warm_up(seeds: list[Seed], work: Path) -> None:
    """Import every engine and command module (and the libraries they use) once, before
    forking: each case then runs the code as it was when the campaign started (a file
    being edited meanwhile cannot break a lazy import) and starts in ~0.1 s. Numba
    kernels are not run here, so no thread pool is forked."""
    import importlib
    import pkgutil

    import ctui

    for mod in ("pydicom", "nibabel", "nrrd", "trimesh", "scipy.ndimage", "skimage.measure", "PIL.Image", "highdicom",
                "cv2"):
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
    plan = [(s, s.files[s.main], "valid") for s in seeds if s.kind not in NO_VALID_RUN]
    plan += hypothesis_inputs(seeds, max(0, int(hypothesis_share * (n_cases - len(plan)))))
    i = 0
    while i < n_cases:
        if plan:
            s, data, how = plan.pop(0)
        else:
            s = seeds[i % len(seeds)]
            if s.kind in KINDS4:
                s, data, how = mutate_family4(s, rng)
            elif s.kind in FAMILY_KINDS:
                s, data, how = mutate_family(s, rng)
            else:
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
            shutil.copytree(work / "case", fdir, symlinks=True, ignore=_not_copied)
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
