"""``ctui measure INPUT``: volumes, areas, centreline, cross-sections, volume between planes."""

from __future__ import annotations

import argparse
import math
import os

from ctui.commands._args import HUGE, command, number
from ctui.engine.core.atomic import check_outputs
from ctui.engine.core.errors import CtuiError



def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions import defaults  # no imports of its own: --help stays fast

    p = command(
        subparsers, "measure", run,
        help="volumes, areas, centreline and cross-sections of a segmented object",
        description="Measure one object: voxel and mesh (Gauss theorem) volumes, surface area; with "
        "--path, cross-sections along an automatic centreline or a given path (area, equivalent, "
        "min and max diameters against arc length); with --between, the volume between two planes "
        "normal to the path. INPUT is a .ctui project, a label file (.nii, .nii.gz, .nrrd, .seg.nrrd) "
        "or a mesh (.stl, .ply, .obj: volume and area only). Path points and positions are patient "
        "mm (x, y, z).",
        epilog='Examples: ctui measure seg.nii.gz --object 2 --path auto --step 0.5 --plot sec.png --json\n'
        '          ctui measure vessel.ctui --path "10,20,5;12,25,40" --between 10,30 --csv sec.csv\n'
        '          ctui measure seg.nrrd --path="-12,20,5;-14,25,40"   (use = when the path starts with -)',
        raw=True,
    )
    p.add_argument("input", help="a .ctui project, a label volume (.nii/.nii.gz/.nrrd) or a mesh (.stl/.ply/.obj)")
    p.add_argument("--object", type=number("--object", 0, 65535, integer=True), default=None, metavar="N",
                   help="object id to measure (default: the only/first object)")
    p.add_argument("--path", default=None, metavar='auto|"x,y,z;x,y,z;..."',
                   help="sections along the automatic centreline ('auto') or a path through points in mm")
    p.add_argument("--path-voxels", action="store_true", help="--path points are voxel indices (z,y,x), not mm")
    p.add_argument("--step", type=float, default=defaults.SECTION_STEP_MM, metavar="MM",
                   help=f"distance between sections (default {defaults.SECTION_STEP_MM:g} mm, as the TUI's M screen)")
    p.add_argument("--between", default=None, metavar="S1,S2",
                   help="volume between the planes normal to the path at arc lengths S1 and S2 mm")
    p.add_argument("--area", choices=defaults.SECTION_AREAS, default=defaults.SECTION_AREA,
                   help="section area estimate: partial-volume integral (default) or shoelace of the contour")
    p.add_argument("--average", type=number("--average", 0, 1000), default=defaults.SECTION_AVERAGE_MM, metavar="MM",
                   help="average each section over MM of path (thin slab; halves the scatter of small binary "
                   "tubes, blurs changes over MM; default 0 = single planes)")
    p.add_argument("--reference", default=None, metavar="A1,A2,...",
                   help="reference areas (mm^2) drawn on the plot with a 2%% band")
    p.add_argument("--csv", metavar="OUT", help="write the section table as CSV")
    p.add_argument("--path-csv", metavar="OUT",
                   help="write the path's points (the centreline with --path auto) as CSV: index, s_mm, x_mm, y_mm, "
                   "z_mm (patient mm; also under \"path\" in --json)")
    p.add_argument("--plot", metavar="PNG", help="write a PNG plot of section area against arc length")
    p.add_argument("--no-mesh", action="store_true", help="skip the mesh volume (faster)")
    p.add_argument("--partial-volume", action="store_true",
                   help="project input: measure sections, and a third volume, on the object's partial-volume "
                   "fraction from the series' grey levels (sub-voxel; for small vessels and rods)")
    p.add_argument("--values", action="store_true",
                   help="the object's grey-level statistics (HU for CT: mean, sd, percentiles) from the series "
                   "(a project's series is loaded; on with --labels)")
    p.add_argument("--labels", metavar="FILE", default=None,
                   help="a label file (DICOM-SEG, RTSTRUCT, .nii, .nii.gz, .nrrd, .gipl) over the volume INPUT (a DICOM "
                   "series or a NIfTI/NRRD/MetaImage CT: its grey levels give HU statistics and --partial-volume); "
                   "the two geometries must match (affines within 2%% of a voxel)")
    p.add_argument("--json", action="store_true", help="print a JSON report")


def _floats(text: str, n: int | None, what: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise CtuiError(f"{what} {text!r}: expected numbers separated by commas") from None
    if not all(math.isfinite(v) and abs(v) <= HUGE for v in vals):
        raise CtuiError(f"{what} {text!r}: expected finite numbers within +-{HUGE:g}")
    if n is not None and len(vals) != n:
        raise CtuiError(f"{what} {text!r}: expected {n} numbers")
    return vals


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.measure import measure_object, save_sections
    from ctui.engine.core.jsonio import dumps

    if not os.path.exists(args.input):
        raise CtuiError(f"{args.input}: no such file")
    if not args.labels and os.path.isfile(args.input) and _report(args):
        return 0  # a DICOM SR measurement report: its measurements
    check_outputs({"--csv": args.csv, "--plot": args.plot, "--path-csv": args.path_csv},
                  inputs=[args.input, args.labels])
    between = _floats(args.between, 2, "--between") if args.between else None
    refs = _floats(args.reference, None, "--reference") if args.reference else None
    if (between or args.csv or args.plot or args.path_csv) and not args.path:
        raise CtuiError("--between, --csv, --path-csv and --plot need --path (auto or points)")
    source = args.input
    if args.labels:  # a label file over its series
        from ctui.engine.actions.opened import open_input

        source = open_input(args.input, labels=args.labels)
    res = measure_object(source, object=args.object, path=args.path or None, path_voxels=args.path_voxels,
                         step_mm=args.step, between=between, mesh=not args.no_mesh, area=args.area,
                         average_mm=args.average, partial_volume=args.partial_volume,
                         values=bool(args.values or args.labels))
    written = save_sections(res, csv=args.csv, plot=args.plot, references=refs, path_csv=args.path_csv)
    if args.json:
        print(dumps(res, indent=1))
        return 0
    print("\n".join(_lines(res, between, written)))
    return 0


def _report(args: argparse.Namespace) -> bool:
    """Print the measurements of a DICOM SR report (``ctui report``'s, or any TID 1500); False if not one."""
    from ctui.engine.actions.report import is_report, read_report

    if not is_report(args.input):
        return False
    from ctui.commands.report import report_lines
    from ctui.engine.core.jsonio import dumps

    contents = read_report(args.input)
    print(dumps(contents, indent=1) if args.json else "\n".join(report_lines(contents)))
    return True


def _lines(res, between, written: list[str]) -> list[str]:
    import numpy as np

    vm = res.volume_ml
    head = f"object {res.object}: " if res.object is not None else ""
    parts = []
    if vm["voxels"] is not None:
        parts.append(f"voxel volume {vm['voxels']:.3f} ml")
    if vm["mesh"] is not None:
        parts.append(f"mesh volume {vm['mesh']:.3f} ml")
    if vm.get("partial_volume") is not None:
        parts.append(f"partial-volume {vm['partial_volume']:.3f} ml")
    if res.volume_difference_percent is not None:
        parts.append(f"difference {res.volume_difference_percent:+.2f}%")
    if res.area_mm2 is not None:
        parts.append(f"area {res.area_mm2:.1f} mm2")
    lines = [head + ", ".join(parts)]
    if res.values is not None:
        v = res.values
        lines.append(f"{v['unit']}: mean {v['mean']:.1f} sd {v['sd']:.1f}, median {v['median']:.1f} "
                     f"(p5 {v['p5']:.1f}, p95 {v['p95']:.1f}), min {v['min']:.1f}, max {v['max']:.1f}")
    if res.path_length_mm is not None:
        a = np.array([r["area_mm2"] if r["area_mm2"] is not None else np.nan for r in res.sections], dtype=float)
        if np.isfinite(a).any():
            lines.append(f"path {res.path_length_mm:.1f} mm, {len(a)} sections every {res.step_mm:g} mm: area "
                         f"min {np.nanmin(a):.2f} / median {np.nanmedian(a):.2f} / max {np.nanmax(a):.2f} mm2")
        else:
            lines.append(f"path {res.path_length_mm:.1f} mm: no section inside the object")
    if res.between:
        b = res.between
        lines.append(f"between {between[0]:g} and {between[1]:g} mm: volume {b['volume_ml']:.4f} ml, "
                     f"sections {b['area1_mm2']:.2f} / {b['area2_mm2']:.2f} mm2")
    lines += [f"warning: {w}" for w in res.warnings]
    lines += [f"wrote {name}" for name in written]
    return lines
