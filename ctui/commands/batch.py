"""``ctui batch MANIFEST.csv --out RESULTS.csv [--scheduler ADDRESS] [--workers N]``: jobs on Dask."""

from __future__ import annotations

import argparse
import os

from ctui.commands._args import command
from ctui.commands._progress import progress_bar
from ctui.engine.core.atomic import check_output
from ctui.engine.core.errors import CtuiError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = command(
        subparsers, "batch", run,
        help="segment, measure and mesh many series from a manifest, on Dask",
        description="Run one job per MANIFEST.csv row: columns series, seed (\"X,Y,Z\"), range (\"LO:HI\"), "
        "optional method (fill|grow|levelset), mode (slice|3d), background (\"X,Y,Z;...\"), filter "
        "(\"NAME:k=v;...\"), outdir, sections (auto), name. Each job segments one object, measures it (voxel and mesh volume, area; sections "
        "along the centreline with sections=auto) and writes its project and STL mesh to outdir. Jobs run "
        "on a local Dask cluster (--workers processes) or on a dask.distributed scheduler (--scheduler). "
        "RESULTS.csv is rewritten as each job finishes; a failed job gets status 'failed' and its error; "
        "a second run skips the jobs already done.",
        epilog="Example: ctui batch jobs.csv --out results.csv --workers 4\n"
        "manifest: series,seed,range,outdir\n"
        "          scans/a,\"94,81,40\",150:300,out",
        raw=True,
    )
    p.add_argument("manifest", help="the jobs, one CSV row each")
    p.add_argument("--out", required=True, metavar="RESULTS.csv", help="results table (one row per job)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="a running dask.distributed scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local cluster: N worker processes (default: CPU count, at most 4)")
    p.add_argument("--threads", action="store_true", help="local cluster: threads instead of processes")
    p.add_argument("--json", action="store_true", help="print a JSON summary")


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.batch import run_batch

    if args.workers is not None and args.workers < 1:
        raise CtuiError(f"--workers {args.workers}: must be 1 or more")

    check_output(args.out, inputs=[args.manifest], label="--out")
    workers = args.workers or min(os.cpu_count() or 1, 4)
    with progress_bar(args, "batch") as progress:
        res = run_batch(args.manifest, out=args.out, scheduler=args.scheduler, workers=workers,
                        processes=not args.threads, progress=progress)
    if args.json:
        from ctui.engine.core.jsonio import dumps

        print(dumps({**res.to_dict(), "rows": res.rows}, indent=1))
    else:
        print(f"{len(res.rows)} jobs: {res.ran} ran ({res.failed} failed), {res.skipped} already done; "
              f"results in {res.results}")
        for r in res.rows:
            if r.get("status") != "ok":
                print(f"  failed: {r.get('name')}: {r.get('error')}")
    return 1 if res.failed else 0
