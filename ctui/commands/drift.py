"""``ctui drift PATH|PROJECT``: per-slice object centroids and slices that drifted."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.commands.segment import add_segmentation_args

    p = subparsers.add_parser(
        "drift",
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
    p.add_argument("--threshold", type=float, default=None, metavar="MM",
                   help="flag slices whose centroid deviates more than MM (default: max(1 mm, 0.75 pixel))")
    p.add_argument("--fit", choices=("median", "poly"), default="median",
                   help="smooth fit along the slices: running median (default) or robust polynomial")
    p.add_argument("--fit-window", type=int, default=9, metavar="N", help="running-median window in slices (default 9)")
    p.add_argument("--estimate", choices=("centroid", "phase"), default="centroid",
                   help="correction shift from centroid alignment (default) or phase correlation")
    p.add_argument("--project", metavar="OUT.ctui",
                   help="write a project with the drift corrections recorded (undoable; data unchanged)")
    p.add_argument("--plot", metavar="PNG", help="write a PNG plot of centroids and deviations")
    p.add_argument("--json", action="store_true", help="print a JSON report")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    import os

    import numpy as np

    from ctui.commands.segment import _err, build_pipeline, load_volume, make_project, segment_volume
    from ctui.engine.segment.drift import analyze_drift, corrections_from_report, plot_drift

    from ctui.engine.core.atomic import check_outputs

    check_outputs({"--project": args.project, "--plot": args.plot}, inputs=[args.path, args.labels])
    if args.fit_window < 3:
        raise _err("--fit-window must be >= 3")
    if args.threshold is not None and args.threshold <= 0:
        raise _err("--threshold must be > 0")
    project = None
    seg = pipeline = None
    settings: list[dict] = []
    if args.path.endswith(".ctui"):
        from ctui.engine.io.project import load_project

        if not os.path.exists(args.path):
            raise _err(f"{args.path}: no such file")
        project = load_project(args.path)
        if project.labels is None:
            raise _err(f"{args.path}: the project holds no label volume")
        labels = project.labels
        source = project.source_path
        volume = load_volume(source, series=(project.source_options or {}).get("series")) if source and os.path.exists(source) else None
        if volume is not None and volume.data.shape != labels.shape:
            raise _err(f"{args.path}: labels {labels.shape} do not match the source series {volume.data.shape}")
    else:
        volume = load_volume(args.path, series=args.series)
        if args.labels:
            from ctui.engine.io.labels import load_labels

            labels, _geom = load_labels(args.labels)
            if labels.shape != volume.data.shape:
                raise _err(f"{args.labels}: label shape {labels.shape} does not match the series {volume.data.shape}")
        elif args.seed:
            seg, pipeline, settings, _ = segment_volume(volume, args)
            labels = seg.labels
        else:
            raise _err("give a .ctui project, --labels FILE, or --seed X,Y,Z with --range/--tolerance")
    ids = None
    if args.objects:
        try:
            ids = [int(v) for v in args.objects.split(",") if v.strip()]
        except ValueError:
            raise _err(f"--objects {args.objects!r}: expected ids like 1,3") from None
    spacing = None if volume is not None else (1.0, 1.0, 1.0)
    if volume is None and project is not None:
        spacing = tuple((project.meta or {}).get("spacing_zyx_mm", (1.0, 1.0, 1.0)))
    report = analyze_drift(labels, volume, spacing=spacing, object_ids=ids, threshold_mm=args.threshold,
                           method=args.fit, window=args.fit_window)
    if args.estimate == "phase" and volume is None:
        raise _err("--estimate phase needs the source series")
    corrections = corrections_from_report(report, estimate=args.estimate, volume=volume)
    written = []
    if args.plot:
        plot_drift(report, args.plot)
        written.append(args.plot)
    drift_dict = {"threshold_mm": report.threshold_mm, "flagged": report.flagged, "corrections": corrections,
                  "method": args.fit, "estimate": args.estimate, "applied": False}
    if args.project:
        from ctui.engine.io.project import save_project

        if project is not None:
            project.drift = drift_dict
            save_project(args.project, project)
        else:
            if volume is None:
                raise _err("--project needs the source series")
            if pipeline is None:
                pipeline = build_pipeline(args)
            if seg is None:
                from ctui.engine.segment.selection import Segmentation

                seg = Segmentation(labels.shape, labels=np.ascontiguousarray(labels, dtype=np.uint8))
            save_project(args.project, make_project(args.path, volume, seg, pipeline, settings, series=args.series, drift=drift_dict))
        written.append(args.project)
    if args.json:
        out = report.to_dict()
        per_slice = []
        for o in report.objects:
            for k, z in enumerate(o.slices):
                per_slice.append({"object_id": o.object_id, "slice": int(z),
                                  "centroid_mm": [round(float(v), 3) for v in o.centroid_mm[k]],
                                  "deviation_mm": round(float(o.distance_mm[k]), 3), "flagged": int(z) in o.flagged})
        print(json.dumps({"path": args.path, "threshold_mm": report.threshold_mm, "flagged": report.flagged,
                          "corrections": corrections, "centroids": per_slice, "objects": out["objects"],
                          "written": written}, indent=1))
    else:
        for o in report.objects:
            print(f"object {o.object_id}: slices {int(o.slices[0])}..{int(o.slices[-1])}, "
                  f"max deviation {float(o.distance_mm.max()):.2f} mm, flagged {o.flagged or 'none'}")
        print(f"flagged slices (> {report.threshold_mm:.2f} mm): {report.flagged or 'none'}")
        for c in corrections:
            print(f"  slice {c['slice']}: shift dx {c['dx']:+.2f} px, dy {c['dy']:+.2f} px to realign")
        for w in written:
            print(f"wrote {w}")
    return 0
