"""The long command-fuzzing campaign (issue 16): ``python benchmarks/fuzz.py --cases 10000``.

Runs the engine of tests/fuzz/fuzz_cli.py (mutated ctui projects, NIfTI, NRRD, MRIC,
meshes, DICOM, and real files from ../shared/data through `ctui info/measure/mesh`, each
case in a fork with RLIMIT_AS capped and a 30 s alarm) on ONE core, and prints the
figures: cases, tracebacks, runs over 30 s, allocations over the cap, exit-0 wrong
results, multi-line/unnamed errors, non-regular outputs replaced and control characters
reaching the terminal (issue 26's families: ``--families only`` runs them alone). Findings are saved under --out/findings/ with a
README giving the reproducer command; --out/summary.json holds the counts. There is no
peer tool to compare with: the figure to beat is zero findings.

Run it in the background at low priority on a shared machine:
``nice -n 19 python benchmarks/fuzz.py --cases 10000 --out /tmp/ctui-fuzz``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# one worker, single-threaded libraries (set before numpy is imported)
for var in ("CTUI_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(var, "1")
os.environ.setdefault("CTUI_NO_PROGRESS", "1")
sys.path[:0] = [str(ROOT / "tests" / "fuzz"), str(ROOT / "tests"), str(ROOT)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=10000)
    ap.add_argument("--out", default="/tmp/ctui-fuzz")
    ap.add_argument("--seed", type=int, default=1, help="random seed of the mutations (CI uses 0)")
    ap.add_argument("--report-every", type=int, default=250)
    ap.add_argument("--families", choices=("all", "only", "none", "four"), default="all",
                    help="issue 26's and 41's hostile families (tests/fuzz_cli_families*.py): with the other seeds, "
                    "alone, or not; four: issue 41's alone (deflate, JPEG-LS, enhanced geometry, FIFO sources, "
                    "C1 names, resource limits, temp races)")
    a = ap.parse_args()
    os.environ["CTUI_FUZZ_FAMILIES"] = {"all": "1", "only": "only", "none": "0", "four": "four"}[a.families]
    from fuzz_cli import FINDINGS, campaign

    res = campaign(a.cases, Path(a.out), seed_value=a.seed, report_every=a.report_every,
                   log=lambda s: print(s, file=sys.stderr, flush=True))
    c = res["counts"]
    print(f"ctui command fuzzing: {res['cases']} cases in {res['seconds']:.0f} s on 1 core "
          f"(slowest case {res['slowest_case_s']} s), seeds: {', '.join(res['seeds'])}")
    print(f"  clean: {c['ok']} exit 0 with a plausible result, {c['error']} one-line errors (exit 2)")
    print(f"  tracebacks {c['traceback']}, runs over {res['timeout_s']} s {c['slow']}, allocations over the "
          f"{res['cap_mb']} MiB cap {c['alloc']}, exit-0 wrong results {c['wrong']}, bad error messages {c['message']}")
    print(f"  non-regular outputs replaced {c['replaced']}, control characters reaching the terminal {c['control']}")
    print(json.dumps({"cases": res["cases"], **{k: c[k] for k in FINDINGS}}))
    return 0 if not any(c[k] for k in FINDINGS) else 1


if __name__ == "__main__":
    sys.exit(main())
