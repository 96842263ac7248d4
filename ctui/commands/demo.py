"""`ctui demo OUTDIR`: write the synthetic CT phantom (DICOM series + truth.json)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ctui.commands._args import command
from ctui.engine.core.errors import CtuiError


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions import defaults  # plain constants: --help stays fast

    p = command(
        subparsers, "demo", run,
        help="write the synthetic CT phantom series (the bundled sample) to OUTDIR",
        description="Write the synthetic CT phantom used as ctui's sample data: a DICOM CT series "
        "(uint16, intercept -1024, shuffled file names) with a body, two contrast-enhanced "
        "kidneys, a spine, a stepped metal tube and a few drifted slices, plus truth.json "
        "with each object's analytic volume, HU, seed voxel and cross-sections.",
    )
    p.add_argument("outdir", help="folder to write into (created if missing)")
    p.add_argument("--seed", type=int, default=defaults.DEMO_SEED, help="noise seed (default %(default)s)")
    p.add_argument("--noise", type=float, default=defaults.DEMO_NOISE_HU, help="noise sigma in HU (default %(default)g)")
    p.add_argument("--no-drift", action="store_true", help="leave out the drifted slices")


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.series import load_truth, write_demo

    out = Path(args.outdir)
    if out.exists() and not out.is_dir():
        raise CtuiError("exists and is not a folder", path=out)
    try:
        write_demo(out, seed=args.seed, noise_sd=args.noise, drift=not args.no_drift)
    except PermissionError as exc:
        raise CtuiError(f"cannot write ({exc.strerror})", path=out) from exc
    truth = load_truth(out)
    nz, ny, nx = truth["shape_zyx"]
    print(f"wrote {truth['files']} DICOM slices ({nz}x{ny}x{nx}, spacing {truth['spacing_zyx_mm']} mm) and truth.json to {out}")
    for o in truth["objects"]:
        print(f"  {o['label']:>2} {o['name']:<13} {o['hu']:>7.0f} HU  {o['volume_ml']:9.2f} ml  seed zyx {o['seed_zyx']}")
    d = truth["drift"]
    if d["slices"]:
        print(f"  drifted slices {d['slices']} shifted (dy, dx) px {d['shifts_px_yx']}")
    return 0
