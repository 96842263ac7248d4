"""Fuzz harness shared by the tests/fuzz/test_fuzz_*.py files (and a test of the harness).

The rule every reader must follow on hostile input: return normally (the input was
valid after all) or raise a :class:`~ctui.engine.core.errors.CtuiError` with ONE line
naming the file; never another exception, never a hang, never an allocation the
input cannot justify.

Each campaign runs in a **worker subprocess** with ``RLIMIT_AS`` capped (a runaway
allocation cannot take the machine down) and, per case, a SIGALRM timeout and a
tracemalloc peak check (numpy registers its buffers with tracemalloc). The worker
announces each case before running it, so when it dies (segfault, hang inside C code
that ignores signals, OOM kill) the parent knows which input did it, saves it and
restarts the worker after it.

Campaigns are functions ``campaign(ctx)`` in the test modules; ``ctx.check(reader,
data, name=...)`` runs one case, ``ctx.examples`` is how many random cases to run
(``CTUI_FUZZ_EXAMPLES``, default small for CI). Findings (inputs that broke a rule)
are copied into ``$CTUI_FUZZ_OUT`` (default: a temp folder) for the regression corpus.

Run ``python tests/fuzz/test_fuzz_harness.py MODULE CAMPAIGN OUTDIR`` to run a campaign
directly (that is what the parent does).
"""

from __future__ import annotations

import hashlib
import json
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
import tracemalloc
import traceback
from pathlib import Path
from typing import Any, Callable

import pytest


HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CORPUS = HERE / "regression_corpus"


def fuzz_examples(default: int) -> int:
    """Number of random cases per campaign: ``CTUI_FUZZ_EXAMPLES`` or ``default``."""
    v = os.environ.get("CTUI_FUZZ_EXAMPLES")
    return int(v) if v else default


class CaseTimeout(BaseException):
    """Raised by SIGALRM inside a case (BaseException: readers must not swallow it)."""


def _alarm(signum, frame):  # pragma: no cover - signal handler
    raise CaseTimeout()


class Ctx:
    """Runs cases inside the worker and records their outcomes."""

    def __init__(self, outdir: Path, *, examples: int, timeout_s: float, mem_factor: int, mem_floor: int) -> None:
        self.outdir = outdir
        self.work = Path(tempfile.mkdtemp(prefix="ctui-fuzz-"))
        self.examples = examples
        self.timeout_s = timeout_s
        self.mem_factor = mem_factor
        self.mem_floor = mem_floor
        self.counts: dict[str, int] = {}
        self.findings: list[dict] = []
        self.n = 0
        signal.signal(signal.SIGALRM, _alarm)

    def tmp(self, name: str) -> Path:
        """A fresh path in the worker's scratch folder (parent folders created)."""
        p = self.work / name
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def _emit(self, obj: dict) -> None:
        sys.stdout.write(json.dumps(obj) + "\n")
        sys.stdout.flush()

    def check(self, reader: Callable[[Path], Any], data: bytes | Path, *, name: str = "case.bin", tag: str = "", size_hint: int | None = None, mem_budget: int | None = None, note: str = "") -> str:
        """Run ``reader(path)`` on ``data`` (bytes written to ``name``, or an existing path).

        Returns the outcome: "ok", "error" (a proper CtuiError) or "FINDING:...".
        """
        from ctui.engine.core.errors import CtuiError

        self.n += 1
        if isinstance(data, (bytes, bytearray)):
            path = self.tmp(f"case/{name}")
            if path.is_dir() or path.is_symlink():
                import shutil

                shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()
            path.write_bytes(bytes(data))
            size = len(data)
        else:
            path = Path(data)
            size = size_hint if size_hint is not None else _tree_size(path)
        self._emit({"start": self.n, "tag": tag, "path": str(path), "note": note})
        budget = mem_budget or max(self.mem_floor, self.mem_factor * size)
        outcome = "ok"
        detail = ""
        tracemalloc.start()
        signal.setitimer(signal.ITIMER_REAL, self.timeout_s)
        try:
            reader(path)
        except CaseTimeout:
            outcome, detail = "FINDING:hang", f"no result within {self.timeout_s} s"
        except CtuiError as exc:
            msg = str(exc)
            if "\n" in msg or not msg.strip():
                outcome, detail = "FINDING:message", repr(msg)
            elif "not enough memory" in msg:
                outcome, detail = "FINDING:alloc", msg
            else:
                outcome, detail = "error", msg
        except MemoryError:
            outcome, detail = "FINDING:alloc", "MemoryError"
        except RecursionError as exc:
            outcome, detail = "FINDING:exception", f"RecursionError {exc}"
        except Exception as exc:  # noqa: BLE001 - that is what we look for
            tb = traceback.extract_tb(exc.__traceback__)
            where = next((f"{Path(f.filename).name}:{f.lineno}" for f in reversed(tb) if "/ctui/" in f.filename), "?")
            outcome, detail = "FINDING:exception", f"{type(exc).__name__} at {where}: {' '.join(str(exc).split())[:200]}"
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
        if not outcome.startswith("FINDING") and peak > budget:
            outcome, detail = "FINDING:alloc", f"peak {peak / 2**20:.1f} MiB for a {size}-byte input"
        key = f"{tag or 'case'}:{outcome.split(':')[0]}"
        self.counts[key] = self.counts.get(key, 0) + 1
        if outcome.startswith("FINDING"):
            saved = self._save(path, tag, name)
            f = {"tag": tag, "kind": outcome[8:], "detail": detail, "saved": str(saved), "note": note}
            self.findings.append(f)
            self._emit({"finding": f})
        self._emit({"done": self.n, "key": key})
        return outcome

    def _save(self, path: Path, tag: str, name: str) -> Path:
        self.outdir.mkdir(parents=True, exist_ok=True)
        if path.is_file():
            data = path.read_bytes()
            h = hashlib.sha1(data).hexdigest()[:10]
            dest = self.outdir / f"{tag or 'case'}-{h}-{name.replace('/', '_')}"
            dest.write_bytes(data)
            return dest
        return path


def _tree_size(p: Path) -> int:
    try:
        if p.is_file():
            return p.stat().st_size
        if p.is_dir():
            return sum(f.stat().st_size for f in p.rglob("*") if f.is_file() and not f.is_symlink())
    except (OSError, RecursionError):
        pass
    return 0


def _vm_size() -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


def worker_main(argv: list[str]) -> int:
    """Entry point of the worker subprocess: MODULE CAMPAIGN OUTDIR [SKIP]."""
    module, campaign, outdir = argv[0], argv[1], Path(argv[2])
    skip = int(argv[3]) if len(argv) > 3 else 0
    sys.path.insert(0, str(HERE))
    sys.path.insert(0, str(ROOT))
    sys.path.insert(1, str(HERE.parent))  # tests/support.py: every test folder on sys.path
    __import__("support").put_test_folders_on_path()
    mod = __import__(module)
    ctx = Ctx(
        outdir,
        examples=int(os.environ.get("CTUI_FUZZ_N", "200")),
        timeout_s=float(os.environ.get("CTUI_FUZZ_TIMEOUT", "30")),
        mem_factor=int(os.environ.get("CTUI_FUZZ_MEM_FACTOR", "64")),
        mem_floor=int(os.environ.get("CTUI_FUZZ_MEM_FLOOR", str(96 * 2**20))),
    )
    ctx.skip = skip  # cases before this one were run by a previous worker that died
    # warm up imports before capping the address space
    getattr(mod, "warm_up", lambda: None)()
    cap = _vm_size() + int(os.environ.get("CTUI_FUZZ_AS_MB", "3072")) * 2**20
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    orig_check = ctx.check

    def check(*a, **k):
        if ctx.n + 1 <= skip:
            ctx.n += 1
            return "skipped"
        return orig_check(*a, **k)

    ctx.check = check  # type: ignore[method-assign]
    getattr(mod, campaign)(ctx)
    ctx._emit({"summary": {"cases": ctx.n - skip, "counts": ctx.counts}})
    return 0


def run_campaign(module: str, campaign: str, *, examples: int, timeout_s: float = 30.0, stall_s: float = 90.0, env: dict | None = None) -> dict:
    """Run ``module.campaign(ctx)`` in worker subprocesses; restart after crashes.

    Returns ``{"cases": n, "counts": {...}, "findings": [...]}``; findings include
    worker deaths and stalls, attributed to the case in flight.
    """
    outdir = Path(os.environ.get("CTUI_FUZZ_OUT") or tempfile.mkdtemp(prefix=f"ctui-fuzz-{campaign}-"))
    e = dict(os.environ, CTUI_FUZZ_N=str(examples), CTUI_FUZZ_TIMEOUT=str(timeout_s), PYTHONHASHSEED="0", **(env or {}))
    e.pop("CTUI_FUZZ_OUT", None)
    total = {"cases": 0, "counts": {}, "findings": [], "restarts": 0}
    skip = 0
    while True:
        proc = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), module, campaign, str(outdir), str(skip)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=e,
            cwd=str(ROOT),
            text=True,
        )
        inflight: dict | None = None
        summary = None
        import selectors

        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        last = time.monotonic()
        buf = ""
        stalled = False
        while True:
            if not sel.select(timeout=1.0):
                if time.monotonic() - last > stall_s:
                    stalled = True
                    proc.kill()
                    break
                if proc.poll() is not None:
                    break
                continue
            chunk = proc.stdout.readline()
            if not chunk:
                break
            last = time.monotonic()
            try:
                msg = json.loads(chunk)
            except json.JSONDecodeError:
                continue  # a reader printed something to stdout
            if "start" in msg:
                inflight = msg
            elif "done" in msg:
                inflight = None
                skip = msg["done"]
                total["cases"] += 1
                total["counts"][msg["key"]] = total["counts"].get(msg["key"], 0) + 1
            elif "finding" in msg:
                total["findings"].append(msg["finding"])
            elif "summary" in msg:
                summary = msg["summary"]
        proc.wait()
        err = proc.stderr.read()
        if summary is not None:
            return total
        # the worker died or stalled: blame the case in flight and go on after it
        total["restarts"] += 1
        if inflight is None:
            raise RuntimeError(f"fuzz worker {module}.{campaign} failed outside a case (rc {proc.returncode}):\n{err[-3000:]}")
        kind = "hang" if stalled else f"crash (rc {proc.returncode})"
        try:  # keep the input that killed the worker (the next case would overwrite it)
            src = Path(inflight.get("path", ""))
            if src.is_file():
                outdir.mkdir(parents=True, exist_ok=True)
                data = src.read_bytes()
                dest = outdir / f"crash-{inflight.get('tag') or 'case'}-{hashlib.sha1(data).hexdigest()[:10]}-{src.name}"
                dest.write_bytes(data)
                inflight["path"] = str(dest)
        except OSError:
            pass
        total["cases"] += 1
        ck = f"{inflight.get('tag') or 'case'}:FINDING"
        total["counts"][ck] = total["counts"].get(ck, 0) + 1
        total["findings"].append({"tag": inflight.get("tag"), "note": inflight.get("note", ""), "kind": kind, "detail": err.strip().splitlines()[-1:] if err.strip() else "", "saved": inflight.get("path")})
        skip = inflight["start"]
        if total["restarts"] > 20:
            raise RuntimeError(f"fuzz worker {module}.{campaign} keeps dying: {total['findings'][-3:]}")


def report(name: str, res: dict) -> str:
    """One line for the test log (visible with -s / -rA) and $CTUI_FUZZ_REPORT."""
    line = f"fuzz {name}: {res['cases']} cases, counts {res['counts']}, findings {len(res['findings'])}, restarts {res['restarts']}"
    out = os.environ.get("CTUI_FUZZ_REPORT")
    if out:
        with open(out, "a") as fh:
            fh.write(json.dumps({"name": name, **res}) + "\n")
    print(line)
    return line


def assert_clean(name: str, res: dict, *, min_cases: int) -> None:
    report(name, res)
    assert res["cases"] >= min_cases, f"{name}: only {res['cases']} cases ran"
    assert not res["findings"], f"{name}: {len(res['findings'])} findings, first: {res['findings'][:5]}"


# --------------------------------------------------------------------------- mutators
def truncations(data: bytes, limit: int | None = None) -> list[bytes]:
    """Every prefix of ``data`` (or ``limit`` evenly spread ones)."""
    n = len(data)
    if limit is None or n <= limit:
        cuts = range(n)
    else:
        cuts = sorted({int(i * n / limit) for i in range(limit)} | {n - 1, n - 2, n - 4, n - 8})
    return [data[:c] for c in cuts if 0 <= c < n]


def mutate(data: bytes, rng, *, n_ops: int | None = None) -> bytes:
    """Random byte-level mutations: bit flips, byte sets, interesting ints, cuts, inserts."""
    import struct

    b = bytearray(data)
    interesting = [0, 1, 0x7F, 0x80, 0xFF, 0x7FFF, 0x8000, 0xFFFF, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF]
    for _ in range(n_ops or int(rng.integers(1, 6))):
        if not b:
            b += bytes([int(rng.integers(0, 256))])
            continue
        op = int(rng.integers(0, 7))
        i = int(rng.integers(0, len(b)))
        if op == 0:
            b[i] ^= 1 << int(rng.integers(0, 8))
        elif op == 1:
            b[i] = int(rng.integers(0, 256))
        elif op in (2, 3) and i + 4 <= len(b):
            v = interesting[int(rng.integers(0, len(interesting)))]
            struct.pack_into("<I" if op == 2 else ">I", b, i, v & 0xFFFFFFFF)
        elif op == 4:
            del b[i:]
        elif op == 5:
            j = int(rng.integers(0, len(b)))
            b[i:i] = b[j : j + int(rng.integers(1, 64))]
        else:
            del b[i : i + int(rng.integers(1, 32))]
    return bytes(b)


def hypothesis_mutations(ctx: Ctx, reader, seed: bytes, *, name: str, tag: str, n: int) -> None:
    """Hypothesis-driven structured mutations of ``seed``: edits (offset, value, width)
    of 1/2/4-byte little-endian values, optional insertion and truncation.

    Runs derandomized (same cases every CI run) unless ``CTUI_FUZZ_RANDOM=1``.
    """
    import struct

    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    L = max(len(seed), 1)
    interesting = st.sampled_from([0, 1, 2, 3, 0x7F, 0x80, 0xFF, 0x100, 0x7FFF, 0x8000, 0xFFFF, 0x10000, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF])
    edit = st.tuples(st.integers(0, L - 1), st.one_of(interesting, st.integers(0, 2**32 - 1)), st.sampled_from([1, 2, 4]))

    @settings(
        max_examples=n,
        deadline=None,
        database=None,
        derandomize=os.environ.get("CTUI_FUZZ_RANDOM") != "1",
        suppress_health_check=list(HealthCheck),
    )
    @given(
        edits=st.lists(edit, max_size=6),
        insert=st.one_of(st.none(), st.tuples(st.integers(0, L), st.binary(max_size=40))),
        cut=st.one_of(st.none(), st.integers(0, L)),
    )
    def run(edits, insert, cut):
        b = bytearray(seed)
        for off, val, width in edits:
            if off + width <= len(b):
                fmt = {1: "<B", 2: "<H", 4: "<I"}[width]
                struct.pack_into(fmt, b, off, val & ((1 << (8 * width)) - 1))
        if insert is not None:
            b[insert[0] : insert[0]] = insert[1]
        if cut is not None:
            del b[cut:]
        ctx.check(reader, bytes(b), name=name, tag=tag)

    run()


def standard_campaign(ctx: Ctx, reader, seed: bytes, *, name: str, tag: str, flips_every: int = 1, trunc_limit: int | None = None, positions: int = 150) -> None:
    """Truncation at every offset, bit flips, interesting 32-bit values, random and
    hypothesis mutations of one valid ``seed`` file.

    In CI the deterministic loops are spread over at most ``positions`` offsets per seed
    (``CTUI_FUZZ_POSITIONS``); set ``CTUI_FUZZ_EXAMPLES`` / ``CTUI_FUZZ_POSITIONS``
    higher locally for every offset and more random cases.
    """
    import numpy as np

    positions = int(os.environ.get("CTUI_FUZZ_POSITIONS", str(positions)))
    flips_every = max(flips_every, -(-len(seed) // positions))
    trunc_limit = min(trunc_limit or positions, positions) if positions < len(seed) else trunc_limit

    ctx.check(reader, seed, name=name, tag=tag + "-valid")
    for t in truncations(seed, trunc_limit):
        ctx.check(reader, t, name=name, tag=tag + "-trunc")
    for i in range(0, len(seed), flips_every):
        for bit in (0, 7):
            b = bytearray(seed)
            b[i] ^= 1 << bit
            ctx.check(reader, bytes(b), name=name, tag=tag + "-flip")
    import struct

    for i in range(0, max(len(seed) - 3, 0), max(flips_every, 1)):
        for v in (0x7FFFFFFF, 0xFFFFFFFF):
            b = bytearray(seed)
            struct.pack_into("<I", b, i, v)
            ctx.check(reader, bytes(b), name=name, tag=tag + "-hugeint")
    rng = np.random.default_rng(12345)
    for _ in range(ctx.examples):
        ctx.check(reader, mutate(seed, rng), name=name, tag=tag + "-random")
    hypothesis_mutations(ctx, reader, seed, name=name, tag=tag + "-hyp", n=max(ctx.examples // 2, 10))


# --------------------------------------------------------------------------- self-test
def _greedy(path: Path) -> None:
    import numpy as np

    np.ones(200 * 2**20, np.uint8)  # a 200 MiB allocation from a 10-byte input


def _sleepy(path: Path) -> None:
    time.sleep(30)


def _buggy(path: Path) -> None:
    raise KeyError("oops")


def _polite(path: Path) -> None:
    from ctui.engine.core.errors import FormatError

    raise FormatError(f"{path}: not valid")


def _segfault(path: Path) -> None:
    import ctypes

    ctypes.string_at(0)


def selftest_campaign(ctx: Ctx) -> None:
    for f in (_polite, _buggy, _greedy, _sleepy, _segfault, _polite):
        ctx.check(f, b"0123456789", tag=f.__name__.strip("_"))


@pytest.mark.slow
def test_harness_detects_every_kind_of_failure():
    res = run_campaign("test_fuzz_harness", "selftest_campaign", examples=1, timeout_s=8.0, stall_s=40)  # greedy: 200 MiB under load
    kinds = {f["tag"]: f["kind"] for f in res["findings"]}
    assert kinds == {"buggy": "exception", "greedy": "alloc", "sleepy": "hang", "segfault": kinds.get("segfault")}
    assert kinds["segfault"].startswith("crash")
    assert res["counts"].get("polite:error") == 2  # the worker restarted after the crash
    assert res["restarts"] == 1


if __name__ == "__main__":
    sys.exit(worker_main(sys.argv[1:]))
