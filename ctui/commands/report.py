"""``ctui report INPUT --out report.dcm``: the objects' measurements as a DICOM SR (TID 1500), JSON or CSV."""

from __future__ import annotations

import argparse

from ctui.commands._args import command, number
from ctui.commands._progress import progress_bar
from ctui.engine.core.atomic import check_output


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions import defaults  # no imports of its own: --help stays fast

    p = command(
        subparsers, "report", run,
        help="measurement report of every object: DICOM SR (TID 1500) over a DICOM-SEG, JSON or CSV",
        description="Measure every object of INPUT (a .ctui project, or a label file over --series) as "
        "`ctui measure --json --values` does (voxel and mesh volume, surface area, mean and SD of HU, "
        "principal axes; with --path, the path's length and its extreme sections with their positions) "
        "and write a report. sr: a DICOM Comprehensive 3D SR (TID 1500) with one measurement group per "
        "object, each referencing the object's segment in a DICOM-SEG (written beside the report as "
        "<out>-seg.dcm, or --seg; a DICOM-SEG input is referenced as it is) and the source images. "
        "`ctui measure report.dcm` reads it back. No patient name, ID or birth date unless --keep-identifiers.",
        epilog="Examples: ctui report kidney.ctui --out kidney-sr.dcm\n"
        "          ctui report seg.dcm --series scan/ --out sr.dcm --path auto\n"
        "          ctui report labels.nii.gz --series scan/ --seg seg.dcm --out sr.dcm\n"
        "          ctui report kidney.ctui --format csv --out kidney.csv",
        raw=True,
    )
    p.add_argument("input", help="a .ctui project or a label file (DICOM-SEG, RTSTRUCT, .nii, .nii.gz, .nrrd)")
    p.add_argument("--out", required=True, metavar="PATH", help="file to write (.dcm for sr)")
    p.add_argument("--format", choices=defaults.REPORT_FORMATS, default=defaults.REPORT_FORMAT,
                   help="sr (default): DICOM SR TID 1500; json; csv: one row per object")
    p.add_argument("--series", default=None, metavar="SERIES",
                   help="the DICOM series the labels were drawn on (default: the project's source)")
    p.add_argument("--seg", default=None, metavar="SEG.dcm",
                   help="a DICOM-SEG over the same series whose segments the SR references (matched by mask); "
                   "default: written beside the report")
    p.add_argument("--object", type=number("--object", 0, 65535, integer=True), action="append", default=None,
                   metavar="N", help="report only object N (repeatable; default all)")
    p.add_argument("--path", default=None, metavar='auto|"x,y,z;..."',
                   help="sections along the automatic centreline ('auto') or a path through points in mm")
    p.add_argument("--step", type=number("--step", 0.01, 1000), default=defaults.SECTION_STEP_MM, metavar="MM",
                   help=f"distance between sections (default {defaults.SECTION_STEP_MM:g} mm)")
    p.add_argument("--sections", choices=defaults.REPORT_SECTIONS, default=defaults.REPORT_SECTIONS[0],
                   help="with --path: the sections of largest and smallest diameter and area (default), or all of "
                   "them (each a planar group of the SR with its contour)")
    p.add_argument("--keep-identifiers", action="store_true",
                   help="keep the patient name, ID and birth date of the source series (sr)")
    p.add_argument("--json", action="store_true", help="print a JSON summary")


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.report import write_report

    check_output(args.out, inputs=[args.input, args.series, args.seg], label="--out")
    with progress_bar(args, f"report {args.format}") as progress:
        res = write_report(args.input, out=args.out, format=args.format, series=args.series, seg=args.seg,
                           objects=args.object, path=args.path, step_mm=args.step, sections=args.sections,
                           keep_identifiers=args.keep_identifiers, progress=progress)
    if args.json:
        from ctui.engine.core.jsonio import dumps

        print(dumps(res.to_dict(), indent=1))
        return 0
    names = ", ".join(f"{o['id']} {o['name']}" for o in res.objects)
    print(f"wrote {res.path} ({res.format}; objects {names})")
    if res.seg:
        print(f"{'wrote' if res.seg_written else 'references'} DICOM-SEG {res.seg}")
    for w in res.warnings:
        print(f"warning: {w}")
    return 0


def report_lines(contents) -> list[str]:
    """``ctui measure report.dcm``: one line per measurement of each group."""
    lines = [f"{contents.input}: DICOM SR, {len(contents.groups)} measurement group(s)"]
    for g in contents.groups:
        seg = g.get("segment") or {}
        where = f" (segment {seg['segment_number']} of SEG {seg['sop_instance_uid']})" if seg else ""
        site = f" [{', '.join(x for x in (g['site'], g.get('laterality')) if x)}]" if g.get("site") else ""
        lines.append(f"{g['name']}{site}{where}")
        for m in g["measurements"]:
            how = ", ".join(x for x in (m["derivation"], m["method"]) if x)
            at = f" at ({', '.join(f'{c:.1f}' for c in m['point'])}) mm" if m.get("point") else ""
            lines.append(f"  {m['name']}{f' ({how})' if how else ''}: {m['value']:.6g} {m['unit']}{at}")
    return lines
