"""`ctui mesh INPUT --out FILE`: surfaces of a series, a project's objects or MRIC contours.

INPUT is
* a series (anything ``ctui info`` loads) with ``--iso VALUE``: marching cubes at that
  value (HU for CT), or ``--method contours`` on the slices thresholded at it;
* a project (``.ctui``) or a label file (.nii, .nii.gz, .nrrd, .seg.nrrd): the objects'
  surfaces (``--object N`` for one), by smoothed signed-distance marching cubes or by
  contour connecting;
* an MRIC contour file (``.mric``): contour connecting (``--spacing dz,dy,dx``; MRIC
  stores no voxel size).

Output format from --out's extension: .stl (binary; --ascii for text), .ply, .obj.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from ctui.commands._args import command, number
from ctui.commands._progress import progress_bar
from ctui.commands.info import add_load_options, load_kwargs
from ctui.engine.actions.options import parse_floats
from ctui.engine.core.atomic import check_output
from ctui.engine.core.errors import CtuiError


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions import defaults  # plain constants: cheap for --help

    p = command(
        subparsers, "mesh", run,
        help="surface of a series (--iso), a project's objects or an MRIC file, written as STL/PLY/OBJ",
        description="Build a closed triangle surface in patient mm and write it atomically. INPUT: a series "
        "with --iso VALUE (marching cubes), a .ctui project or label file (object surfaces: smoothed "
        "signed-distance marching cubes, or contour connecting), or an .mric contour file.",
    )
    p.add_argument("input", metavar="INPUT", help="series path, .ctui project, label file or .mric file")
    p.add_argument("--out", required=True, metavar="FILE", help="output mesh: .stl, .ply or .obj")
    p.add_argument("--method", choices=defaults.MESH_METHODS, default=None,
                   help="marching-cubes (default for series and projects) or contours (default for .mric)")
    p.add_argument("--iso", type=number("--iso"), metavar="VALUE", help="iso value for a series (HU for CT)")
    p.add_argument("--object", type=number("--object", 0, 65535, integer=True), metavar="N", help="object id in a project / label file (default: all)")
    p.add_argument("--smooth", type=number("--smooth", 0, 1000, integer=True), default=defaults.MESH_SMOOTH_ITERATIONS, metavar="ITER", help="Taubin smoothing iterations (volume-preserving)")
    p.add_argument("--decimate", type=number("--decimate", 4, 1e9, integer=True), metavar="N", help="reduce to about N triangles")
    p.add_argument("--tiling", choices=defaults.CONTOUR_TILINGS, default=defaults.CONTOUR_TILING, help="contour tiling: minimum-area DP or greedy")
    p.add_argument("--terraced", action="store_true",
                   help="project / label file: plain marching cubes of the label map, every object in one pass "
                   "(voxel staircase kept) instead of smoothed signed-distance surfaces")
    p.add_argument("--ascii", action="store_true", help="ASCII STL/PLY instead of binary")
    p.add_argument("--labels", metavar="FILE", default=None,
                   help="a label file (DICOM-SEG, RTSTRUCT, .nii, .nii.gz, .nrrd, .gipl) over the series INPUT: its geometry must match the series'; INPUT is then the series")
    p.add_argument("--json", action="store_true", help="print a JSON report")
    add_load_options(p)


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.mesh import MESH_SUFFIXES, mesh_objects, save_mesh
    from ctui.engine.core.jsonio import dumps


    src = args.input
    out = Path(args.out)
    if out.suffix.lower() not in MESH_SUFFIXES:
        raise CtuiError(f"unknown mesh format {out.suffix or '(no extension)'}; use .stl, .ply or .obj", path=out)
    if not os.path.exists(src):
        raise CtuiError("no such file or folder", path=src)
    if out.parent and not out.parent.exists():
        raise CtuiError(f"folder {out.parent} does not exist", path=out)
    check_output(out, inputs=[src, args.labels], label="--out")
    spacing = parse_floats(args.spacing, "spacing") if getattr(args, "spacing", None) else None
    load = {k: v for k, v in load_kwargs(args).items() if k != "spacing"}
    if args.labels:  # a label file over its series
        from ctui.engine.actions.opened import open_input

        src, load = open_input(src, labels=args.labels, spacing=spacing, **load), {}
    with progress_bar(args, "meshing") as progress:
        res = mesh_objects(src, objects=args.object, method=args.method, iso=args.iso, terraced=args.terraced,
                           tiling=args.tiling, smooth=args.smooth, decimate=args.decimate, spacing=spacing,
                           progress=progress, **load)
    check_output(out, inputs=[res.source_series], label="--out")  # not into a project's series folder (as export)
    save_mesh(out, res.mesh, ascii=args.ascii)
    rep = res.to_dict()
    if args.json:
        print(dumps({**rep, "out": str(out)}))
    else:
        print(f"{out}: {rep['triangles']} triangles, {rep['vertices']} vertices, "
              f"{'watertight' if rep['watertight'] else 'NOT watertight'}, volume {rep['volume_ml']:.2f} ml, "
              f"area {rep['area_mm2']:.0f} mm2 ({res.method})")
        for note in res.notes:
            print(f"note: {note}")
    return 0
