"""``ctui edit PROJECT.ctui``: the TUI's 3D edits of one object (keep or remove the island at
a voxel, scissors inside/outside a box or polygon, smoothing in mm), each through the same
engine function as the TUI (``ctui.engine.actions.edit``), written to a new project."""

from __future__ import annotations

import argparse

from ctui.commands._args import command
from ctui.engine.core.atomic import check_outputs
from ctui.engine.core.errors import CtuiError


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions import defaults  # plain constants: --help stays fast

    p = command(
        subparsers, "edit", run,
        help="3D edits of an object: keep/remove the island at a voxel, scissors, smoothing",
        description="Edit one object of a project as the TUI's edit tools do, in this order: keep "
        "(--keep-island) or remove (--remove-island) the island through a voxel, scissors (--cut inside|outside "
        "the --box or --polygon, on --slices or the box's slices), smoothing (--smooth METHOD:MM). --box also "
        "confines the island and smoothing edits, as the TUI's ROI box. Voxel indices x,y,z numbered from 0 "
        "as in the TUI and `ctui segment --seed`. Writes --project NEW.ctui (then `ctui export`).",
        epilog="Examples: ctui edit kidney.ctui --keep-island 120,88,40 --project kidney2.ctui\n"
        "          ctui edit liver.ctui --object 2 --box 100,80,10,180,160,40 --cut outside --project out.ctui\n"
        "          ctui edit spleen.ctui --smooth closing:4 --json --project out.ctui",
        raw=True,
    )
    p.add_argument("path", help="a .ctui project")
    p.add_argument("--object", type=int, default=None, metavar="N", help="object id (default: the only/first object)")
    p.add_argument("--box", default=None, metavar="X0,Y0,Z0,X1,Y1,Z1",
                   help="ROI box by two opposite corners (voxels, as ctui segment --box; X0,Y0,X1,Y1: every slice)")
    p.add_argument("--keep-island", default=None, metavar="X,Y,Z", help="keep only the island through this voxel")
    p.add_argument("--remove-island", default=None, metavar="X,Y,Z", help="remove the island through this voxel")
    p.add_argument("--island-slice", action="store_true", help="islands of the voxel's slice only (2D)")
    p.add_argument("--cut", choices=defaults.CUT_SIDES, default=None,
                   help="scissors: erase the object inside/outside the --box or --polygon")
    p.add_argument("--polygon", default=None, metavar='"X,Y;X,Y;X,Y..."', help="scissors polygon (pixels, every slice)")
    p.add_argument("--slices", default=None, metavar="A:B", help="scissors on slices A..B (inclusive)")
    p.add_argument("--smooth", default=None, metavar="METHOD:MM", help="median, opening or closing with a ball of MM mm")
    p.add_argument("--project", required=True, metavar="OUT.ctui", help="the edited project (a new file)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")


def _err(msg: str, path: str | None = None):
    return CtuiError(msg, path=path)


def _point(text: str, opt: str) -> tuple[int, int, int]:
    try:
        x, y, z = (int(v) for v in text.split(","))
    except ValueError:
        raise _err(f"{opt} {text!r}: expected x,y,z voxel indices") from None
    return z, y, x


def _ops(args, seg, oid: int, spacing, box) -> list[dict]:
    from ctui.engine.actions import edit as et

    rows = []
    for opt, text, keep in (("--keep-island", args.keep_island, True), ("--remove-island", args.remove_island, False)):
        if text:
            r = et.island(seg, _point(text, opt), object_id=oid, keep=keep, in_slice=args.island_slice, box=box)
            rows.append({"op": opt[2:], **r})
    if args.cut:
        polygon = None
        if args.polygon:
            try:
                polygon = [tuple(float(v) for v in pt.split(",")) for pt in args.polygon.split(";") if pt.strip()]
            except ValueError:
                raise _err(f"--polygon {args.polygon!r}: expected x,y;x,y;x,y") from None
        elif box is None:
            raise _err("--cut needs a --box or a --polygon")
        slices = None
        if args.slices:
            try:
                a, b = (int(v) for v in args.slices.split(":"))
            except ValueError:
                raise _err(f"--slices {args.slices!r}: expected A:B") from None
            slices = (a, b)
        r = et.cut(seg, object_id=oid, box=None if polygon else box, polygon=polygon, inside=args.cut == "inside",
                   slices=slices)
        rows.append({"op": f"cut-{args.cut}", **r})
    if args.smooth:
        method, _, mm = args.smooth.partition(":")
        try:
            size = float(mm or 3.0)
        except ValueError:
            raise _err(f"--smooth {args.smooth!r}: expected METHOD:MM, e.g. median:3") from None
        r = et.smooth(seg, object_id=oid, method=method, size_mm=size, spacing=spacing, box=box)
        rows.append({"op": f"smooth-{method}", **r})
    return rows


def run(args: argparse.Namespace) -> int:
    import json  # 2 ms: loaded when a command prints, not for `ctui --help`

    import numpy as np

    from ctui.engine.actions import edit as et
    from ctui.engine.actions.opened import open_input
    from ctui.engine.actions.project import save_project

    check_outputs({"--project": args.project}, inputs=[args.path])
    if not (args.keep_island or args.remove_island or args.cut or args.smooth):
        raise _err("nothing to do: give --keep-island, --remove-island, --cut or --smooth", args.path)
    opened = open_input(args.path, kind="project", require_labels=True, with_series=False)
    proj = opened.project
    labels = opened.labels.astype("uint8", copy=True)
    present = [int(i) for i in np.flatnonzero(np.bincount(labels.ravel(), minlength=256)[1:]) + 1]
    oid = args.object if args.object is not None else (present[0] if present else 1)
    if oid not in present:
        raise _err(f"no object {oid} in the project (objects: {', '.join(map(str, present)) or 'none'})", args.path)
    seg = et.Segmentation(labels.shape, labels=labels, objects=proj.objects or [])
    spacing = tuple(float(v) for v in opened.geometry.spacing) if opened.geometry is not None else (1.0, 1.0, 1.0)
    box = et.parse_box(args.box, labels.shape) if args.box else None
    rows = _ops(args, seg, oid, spacing, box)
    proj.labels = seg.labels
    save_project(args.project, proj)
    vox_ml = float(np.prod(spacing)) / 1000.0
    if args.json:
        print(json.dumps({"path": args.path, "object": oid, "edits": rows, "voxels": seg.voxels(oid),
                          "volume_ml": round(seg.voxels(oid) * vox_ml, 6), "written": [args.project]}, indent=1))
    else:
        for r in rows:
            added = f" +{r['added']}" if "added" in r else ""
            print(f"{r['op']}: object {oid} {r['voxels_before']} -> {r['voxels']} voxels (-{r['removed']}{added}), "
                  f"{r['voxels_before'] * vox_ml:.2f} -> {r['voxels'] * vox_ml:.2f} ml")
        print(f"wrote {args.project}")
    return 0
