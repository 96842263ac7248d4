"""``ctui export INPUT --format FORMAT --out PATH``: every export through one engine function."""

from __future__ import annotations

import argparse

from ctui.commands._args import command, number
from ctui.commands._progress import progress_bar
from ctui.engine.core.atomic import check_output


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions.formats import FORMATS  # the registry: plain data, cheap to import

    p = command(
        subparsers, "export", run,
        help=f"write a project's objects as {', '.join(f.title for f in FORMATS.values())}",
        description="Export the objects of INPUT (a .ctui project, or a label file: DICOM-SEG, RTSTRUCT, "
        ".nii, .nii.gz, .nrrd, placed on --series when given). dicom-seg and rtstruct reference the "
        "source DICOM series' images (the project's recorded series, or --series); nifti and nrrd carry "
        "the series' geometry; stl, ply and obj hold the object surfaces in patient mm; csv one row of "
        "measurements per object. No patient name, ID or birth date is written unless --keep-identifiers.\n\n"
        "Formats:\n" + "\n".join(f"  {f.name:<10} {f.label} ({', '.join(f.suffixes)})" for f in FORMATS.values()),
        epilog="Examples: ctui export kidney.ctui --format dicom-seg --out kidney-seg.dcm\n"
        "          ctui export labels.nii.gz --series scan/ --format rtstruct --out rt.dcm\n"
        "          ctui export kidney.ctui --format csv --out volumes.csv",
        raw=True,
    )
    p.add_argument("input", help="a .ctui project or a label file (DICOM-SEG, RTSTRUCT, .nii, .nii.gz, .nrrd)")
    p.add_argument("--format", required=True, choices=tuple(FORMATS), help="output format")
    p.add_argument("--out", required=True, metavar="PATH", help="file to write")
    p.add_argument("--series", default=None, metavar="SERIES",
                   help="the DICOM series the labels were drawn on (default: the project's source)")
    p.add_argument("--series-uid", default=None, metavar="UID",
                   help="SeriesInstanceUID (or index) when SERIES holds several")
    p.add_argument("--object", type=number("--object", 0, 65535, integer=True), action="append", default=None, metavar="N",
                   help="export only object N (repeatable; default all)")
    p.add_argument("--keep-identifiers", action="store_true",
                   help="DICOM exports: keep the patient name, ID and birth date of the source series")
    p.add_argument("--json", action="store_true", help="print a JSON report")


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.export import export

    check_output(args.out, inputs=[args.input, args.series], label="--out")
    with progress_bar(args, f"export {args.format}") as progress:
        res = export(args.input, format=args.format, out=args.out, series=args.series, series_uid=args.series_uid,
                     objects=args.object, keep_identifiers=args.keep_identifiers, progress=progress)
    if args.json:
        from ctui.engine.core.jsonio import dumps

        print(dumps(res.to_dict(), indent=1))
        return 0
    names = ", ".join(f"{o['id']} {o['name']}" for o in res.objects)
    print(f"wrote {res.path} ({res.format}; objects {names})")
    for w in res.warnings:
        print(f"warning: {w}")
    return 0
