"""``ctui vessel SERIES --start X,Y,Z --end X,Y,Z [--via X,Y,Z]...``: a vessel from its ends."""

from __future__ import annotations

import argparse

from ctui.commands._args import command
from ctui.commands._progress import progress_bar
from ctui.commands.info import add_load_options, load_kwargs
from ctui.commands.segment import load_volume, parse_range, parse_seed
from ctui.engine.core.errors import CtuiError

LUMEN_CHOICES = ("contrast", "wall")  # actions.vessel.LUMENS (checked by tests/architecture/test_single_definition.py)


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions import defaults  # plain constants: --help stays fast

    p = command(
        subparsers, "vessel", run,
        help="a vessel from its start, waypoints and end(s): path, surface, diameters along it",
        description="Extract a vessel: a minimal path through --start, each --via and each --end on a "
        "speed map from the lumen's values, a colliding-fronts core, growth plane by plane normal to the "
        "path (about 1 mm apart) with cut planes at both ends, and the sections along the path (area, "
        "equivalent, min and max diameter through the centroid, inscribed diameter). Points are voxels "
        "X,Y,Z: column, row, slice, numbered from 0, as `ctui segment --seed`.",
        epilog="Example: ctui vessel ct.nii.gz --start 56,47,83 --via 60,72,141 --end 47,70,1 --lumen wall "
        "--project aorta.ctui --csv aorta.csv --plot aorta.png",
    )
    p.add_argument("path", help="the series (a DICOM folder, NIfTI, NRRD, ...)")
    p.add_argument("--start", required=True, metavar="X,Y,Z", help="a voxel in the lumen where the vessel starts")
    p.add_argument("--end", action="append", default=[], metavar="X,Y,Z",
                   help="a voxel in the lumen where it ends (repeat: a tree from one start)")
    p.add_argument("--via", action="append", default=[], metavar="X,Y,Z",
                   help="a waypoint in the lumen (repeat; each belongs to the leg of the end it lies nearest)")
    p.add_argument("--range", default=defaults.VESSEL_RANGE, metavar="auto|LO:HI",
                   help="the lumen's values (default: from the values at the points)")
    p.add_argument("--lumen", choices=LUMEN_CHOICES, default=defaults.VESSEL_LUMEN,
                   help="contrast: the bright lumen; wall: also what lies inside the vessel's wall, up to the "
                        "fat around it (a dissection's false lumen, mural thrombus)")
    p.add_argument("--project", metavar="OUT.ctui", help="write a project with the vessel as object 1")
    p.add_argument("--mask", metavar="OUT", help="write the label map (.nii, .nii.gz, .nrrd, .seg.nrrd)")
    p.add_argument("--csv", metavar="OUT.csv", help="write the sections along the path")
    p.add_argument("--plot", metavar="OUT.png", help="plot the equivalent diameter along the path")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    add_load_options(p)


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.vessel import save_vessel, vessel
    from ctui.engine.core.atomic import check_outputs
    from ctui.engine.core.jsonio import dumps

    if not args.end:
        raise CtuiError("give at least one --end X,Y,Z")
    check_outputs({o: getattr(args, o[2:], None) for o in ("--project", "--mask", "--csv", "--plot")},
                  inputs=[args.path])
    start = parse_seed(args.start)
    ends = [parse_seed(e) for e in args.end]
    vias = [parse_seed(v) for v in args.via]
    rng = None if args.range.strip().lower() == "auto" else parse_range(args.range)
    volume = load_volume(args.path, **load_kwargs(args))
    with progress_bar(args, "vessel") as progress:
        res = vessel(volume, start=start, ends=ends, vias=vias, value_range=rng, lumen=args.lumen,
                     source=args.path, progress=progress)
    written = save_vessel(res, volume, source_path=args.path, project=args.project, mask=args.mask, csv=args.csv,
                          plot=args.plot)
    if args.json:
        print(dumps(res.to_dict() | {"written": written}, indent=1))
        return 0
    lengths = ", ".join(f"{v:.1f}" for v in res.path_length_mm)
    print(f"vessel: path {lengths} mm, {res.voxels} voxels, {res.volume_ml:.2f} ml, range {res.range[0]:.0f}.."
          f"{res.range[1]:.0f}" + (f", band {res.band[0]:.0f}..{res.band[1]:.0f}" if res.band else "")
          + f" ({res.seconds:.1f} s)")
    for m in res.maxima:
        print(f"  {m['from_mm']:.0f}-{m['to_mm']:.0f} mm: max diameter {m['max_diameter_mm']:.1f} mm at "
              f"{m['at_mm']:.0f} mm")
    for w in res.warnings:
        print(f"  warning: {w}")
    for w in written:
        print(f"wrote {w}")
    return 0
