"""``ctui drift PATH|PROJECT``: per-slice object centroids and slices that drifted."""

from __future__ import annotations

import argparse
import os

from ctui.commands._args import command, number
from ctui.commands.info import load_kwargs
from ctui.commands.segment import add_segmentation_args, build_pipeline, load_volume, segment_volume
from ctui.engine.core.atomic import check_outputs
from ctui.engine.core.errors import CtuiError


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions import defaults  # plain constants: --help stays fast

    p = command(
        subparsers, "drift", run,
        help="per-slice centroids of segmented objects and slices that drifted",
        description="Compute each object's centroid on every slice, fit a smooth curve along the "
        "slices and flag slices deviating more than --threshold mm (patient motion between slices). "
        "Objects come from a .ctui project, a label file (--mask) or seeds (--seed with --range/"
        "--tolerance, as in `ctui segment`).",
        epilog="Example: ctui drift scan/ --seed 94,81,40 --range 115:445 --plot drift.png --json",
    )
    p.add_argument("path", help="series folder/file, or a .ctui project")
    add_segmentation_args(p, required=False)
    p.add_argument("--labels", "--mask", dest="labels", metavar="FILE",
                   help="label volume (.nii, .nii.gz, .nrrd, .seg.nrrd) on the series' grid")
    p.add_argument("--objects", metavar="IDS", default=None, help="object ids to check, e.g. 1,3 (default: all)")
    p.add_argument("--threshold", type=number("--threshold", 0, 1e4, above=True), default=None, metavar="MM",
                   help="flag slices whose centroid deviates more than MM (default: max(1 mm, 0.75 pixel))")
    p.add_argument("--fit", choices=defaults.DRIFT_FITS, default=defaults.DRIFT_FIT,
                   help="smooth fit along the slices: running median (default) or robust polynomial")
    p.add_argument("--fit-window", type=number("--fit-window", 1, 10001, integer=True), default=defaults.DRIFT_FIT_WINDOW, metavar="N", help="running-median window in slices (default %(default)s)")
    p.add_argument("--estimate", choices=defaults.DRIFT_ESTIMATES, default=defaults.DRIFT_ESTIMATE,
                   help="correction shift from centroid alignment (default) or phase correlation")
    p.add_argument("--project", metavar="OUT.ctui",
                   help="write a project with the drift corrections recorded (undoable; data unchanged)")
    p.add_argument("--plot", metavar="PNG", help="write a PNG plot of centroids and deviations")
    p.add_argument("--json", action="store_true", help="print a JSON report")


def _source(args: argparse.Namespace):
    """(Opened with labels, seg or None, pipeline or None, settings) for the drift check."""
    from ctui.engine.actions.defaults import PROJECT_SUFFIXES
    from ctui.engine.actions.opened import Opened, open_input


    if args.path.endswith(PROJECT_SUFFIXES):
        if not os.path.exists(args.path):
            raise CtuiError("no such file", path=args.path)
        return open_input(args.path, kind="project", require_labels=True,
                          with_series=True if args.estimate == "phase" else None), None, None, []
    if args.labels:  # placed on the series' grid: its geometry (not only its shape) must match
        return open_input(args.path, labels=args.labels, **({"series": args.series} if args.series else {})), \
            None, None, []

    volume = load_volume(args.path, **load_kwargs(args))
    if args.seed:
        seg, pipeline, settings, _ = segment_volume(volume, args)
        return Opened.of_volume(volume, seg.labels, path=args.path), seg, pipeline, settings
    raise CtuiError("give a .ctui project, --labels FILE, or --seed X,Y,Z with --range/--tolerance")


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.drift import drift_check
    from ctui.engine.actions.project import new_project, propagation_record, save_project
    from ctui.engine.core.jsonio import dumps


    check_outputs({"--project": args.project, "--plot": args.plot}, inputs=[args.path, args.labels])
    try:
        ids = [int(v) for v in args.objects.split(",") if v.strip()] if args.objects else None
    except ValueError:
        raise CtuiError(f"--objects {args.objects!r}: expected ids like 1,3") from None
    opened, seg, pipeline, settings = _source(args)
    res = drift_check(opened, objects=ids, threshold_mm=args.threshold, fit=args.fit, fit_window=args.fit_window,
                      estimate=args.estimate, plot=args.plot)
    written = [args.plot] if args.plot else []
    if args.project:
        project = opened.project
        if project is not None:
            project.drift = res.project_drift()
            save_project(args.project, project)
        else:
            pipeline = pipeline or build_pipeline(args)
            project = new_project(opened.volume, source_path=args.path,
                                  source_options={k: v for k, v in load_kwargs(args).items() if k != "resample" or not v},
                                  labels=opened.labels, objects=seg.object_list() if seg is not None else [],
                                  pipeline=pipeline.to_dict(), propagation=propagation_record(settings),
                                  drift=res.project_drift())
            save_project(args.project, project)
        written.append(args.project)
    if args.json:
        print(dumps({**res.to_dict(), "written": written}, indent=1, ndigits=None))
        return 0
    for o in res.report.objects:
        print(f"object {o.object_id}: slices {int(o.slices[0])}..{int(o.slices[-1])}, "
              f"max deviation {float(o.distance_mm.max()):.2f} mm, flagged {o.flagged or 'none'}")
    print(f"flagged slices (> {res.threshold_mm:.2f} mm): {res.flagged or 'none'}")
    for c in res.corrections:
        print(f"  slice {c['slice']}: shift dx {c['dx']:+.2f} px, dy {c['dy']:+.2f} px to realign")
    for w in written:
        print(f"wrote {w}")
    return 0
