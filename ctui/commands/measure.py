"""``ctui measure INPUT``: volumes, areas, centreline, cross-sections, volume between planes."""

from __future__ import annotations

import argparse

MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off", ".vtk", ".vtp", ".glb", ".gltf")
LABEL_SUFFIXES = (".nii", ".nii.gz", ".nrrd", ".seg.nrrd", ".nhdr")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "measure",
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
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="a .ctui project, a label volume (.nii/.nii.gz/.nrrd) or a mesh (.stl/.ply/.obj)")
    p.add_argument("--object", type=int, default=None, metavar="N",
                   help="object id to measure (default: the only/first object)")
    p.add_argument("--path", default=None, metavar='auto|"x,y,z;x,y,z;..."',
                   help="sections along the automatic centreline ('auto') or a path through points in mm")
    p.add_argument("--path-voxels", action="store_true", help="--path points are voxel indices (z,y,x), not mm")
    p.add_argument("--step", type=float, default=0.5, metavar="MM", help="distance between sections (default 0.5 mm)")
    p.add_argument("--between", default=None, metavar="S1,S2",
                   help="volume between the planes normal to the path at arc lengths S1 and S2 mm")
    p.add_argument("--area", choices=("pv", "contour"), default="pv",
                   help="section area estimate: partial-volume integral (default) or shoelace of the contour")
    p.add_argument("--average", type=float, default=0.0, metavar="MM",
                   help="average each section over MM of path (thin slab; halves the scatter of small binary "
                   "tubes, blurs changes over MM; default 0 = single planes)")
    p.add_argument("--reference", default=None, metavar="A1,A2,...",
                   help="reference areas (mm^2) drawn on the plot with a 2%% band")
    p.add_argument("--csv", metavar="OUT", help="write the section table as CSV")
    p.add_argument("--plot", metavar="PNG", help="write a PNG plot of section area against arc length")
    p.add_argument("--no-mesh", action="store_true", help="skip the mesh volume (faster)")
    p.add_argument("--partial-volume", action="store_true",
                   help="project input: measure sections, and a third volume, on the object's partial-volume "
                   "fraction from the series' grey levels (sub-voxel; for small vessels and rods)")
    p.add_argument("--json", action="store_true", help="print a JSON report")
    p.set_defaults(func=run)


def _err(msg: str):
    from ctui.engine.core.errors import CtuiError

    return CtuiError(msg)


def _kind(path: str) -> str:
    import os

    low = path.lower()
    if low.endswith(".ctui") or low.endswith(".ctui.autosave"):
        return "project"
    if low.endswith(LABEL_SUFFIXES):
        return "labels"
    if low.endswith(MESH_SUFFIXES):
        return "mesh"
    if os.path.isdir(path):
        raise _err(f"{path}: is a folder; give a .ctui project, a label file or a mesh")
    raise _err(f"{path}: unknown input type (expected .ctui, .nii, .nii.gz, .nrrd, .stl, .ply or .obj)")


def _load_labels(path: str):
    """(labels, spacing, origin, direction, notes, image or None) from a project (image: its
    source series when found) or a label file."""
    import os

    import numpy as np

    kind = _kind(path)
    if kind == "labels":
        from ctui.engine.io.labels import load_labels

        labels, geom = load_labels(path)
        return labels, geom.spacing, geom.origin, geom.direction, [], None
    from ctui.engine.io.project import load_project

    project = load_project(path)
    if project.labels is None:
        raise _err(f"{path}: the project holds no label volume")
    labels = np.asarray(project.labels)
    notes = []
    src = project.source_path
    meta = project.meta or {}
    if src and os.path.exists(src):
        from ctui.engine.io.series import load

        opts = {k: v for k, v in (project.source_options or {}).items() if v is not None}
        vol = load(src, **opts)
        if vol.data.shape != labels.shape:
            raise _err(f"{path}: labels {labels.shape} do not match the source series {vol.data.shape}")
        return labels, vol.spacing, vol.origin, vol.direction, notes, vol.data
    sp = meta.get("spacing_zyx_mm")
    if sp is None:
        raise _err(f"{path}: the source series {src!r} is missing and the project records no voxel spacing")
    notes.append(f"source series {src} not found: geometry from the project's metadata")
    return labels, tuple(sp), tuple(meta.get("origin_xyz_mm", (0.0, 0.0, 0.0))), meta.get("direction"), notes, None


def _pick_object(labels, requested, path: str) -> int:
    import numpy as np

    present = [int(v) for v in np.unique(labels) if v != 0]
    if not present:
        raise _err(f"{path}: no object in the label volume")
    if requested is None:
        return present[0]
    if requested not in present:
        raise _err(f"{path}: no object {requested} (objects present: {', '.join(map(str, present))})")
    return requested


def _floats(text: str, n: int | None, what: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise _err(f"{what} {text!r}: expected numbers separated by commas") from None
    if n is not None and len(vals) != n:
        raise _err(f"{what} {text!r}: expected {n} numbers")
    return vals


def run(args: argparse.Namespace) -> int:
    import json
    import math
    import os

    import numpy as np

    if args.step <= 0:
        raise _err(f"--step must be positive, got {args.step}")
    if args.average < 0:
        raise _err(f"--average must be >= 0, got {args.average}")
    if not os.path.exists(args.input):
        raise _err(f"{args.input}: no such file")
    from ctui.engine.core.atomic import check_outputs

    check_outputs({"--csv": args.csv, "--plot": args.plot}, inputs=[args.input])
    between = _floats(args.between, 2, "--between") if args.between else None
    refs = _floats(args.reference, None, "--reference") if args.reference else None
    if (between or args.csv or args.plot) and not args.path:
        raise _err("--between, --csv and --plot need --path (auto or points)")
    kind = _kind(args.input)
    report: dict = {"input": os.path.basename(args.input), "object": None,
                    "volume_ml": {"voxels": None, "mesh": None}, "volume_difference_percent": None,
                    "area_mm2": None, "path_length_mm": None, "sections": [], "between": None, "warnings": []}
    if kind == "mesh":
        if args.path or between:
            raise _err(f"{args.input}: a mesh gives volume and area only (no --path/--between)")
        from ctui.engine.measure.stats import mesh_stats
        from ctui.engine.io.meshes import load_mesh

        st = mesh_stats(load_mesh(args.input))
        report["volume_ml"]["mesh"] = st["volume_ml"]
        report["area_mm2"] = st["area_mm2"]
        report["warnings"] += st["warnings"]
    else:
        from ctui.engine.measure.stats import measure_object

        labels, spacing, origin, direction, notes, image = _load_labels(args.input)
        if args.partial_volume and image is None:
            raise _err(f"{args.input}: --partial-volume needs a project whose source series can be loaded")
        oid = _pick_object(labels, args.object, args.input)
        res = measure_object(labels, oid, spacing=spacing, origin=origin, direction=direction, path=args.path or None,
                             path_voxels=args.path_voxels, step_mm=args.step, between=tuple(between) if between else None,
                             mesh=not args.no_mesh, area=args.area, average_mm=args.average,
                             image=image if args.partial_volume else None)
        pv = res.pop("partial_volume", None)
        if pv is not None:
            res["partial_volume"] = {"object_value": pv["fg"], "surroundings_value": pv["bg"]}
        rows = res.pop("rows")
        res.pop("stats")
        res.pop("path_mm")
        res["warnings"] = notes + res["warnings"]
        report.update(res)
        if args.csv:
            from ctui.engine.measure.sections import write_sections_csv

            write_sections_csv(args.csv, rows)
        if args.plot:
            from ctui.engine.measure.sections import plot_sections

            plot_sections(args.plot, rows, references=refs, title=f"object {oid} sections")
    if args.json:
        def clean(v):
            if isinstance(v, dict):
                return {k: clean(x) for k, x in v.items()}
            if isinstance(v, (list, tuple)):
                return [clean(x) for x in v]
            if isinstance(v, (float, np.floating)):
                return None if not math.isfinite(float(v)) else round(float(v), 6)
            if isinstance(v, np.integer):
                return int(v)
            return v

        print(json.dumps(clean(report), indent=1))
        return 0
    vm = report["volume_ml"]
    head = f"object {report['object']}: " if report["object"] is not None else ""
    parts = []
    if vm["voxels"] is not None:
        parts.append(f"voxel volume {vm['voxels']:.3f} ml")
    if vm["mesh"] is not None:
        parts.append(f"mesh volume {vm['mesh']:.3f} ml")
    if vm.get("partial_volume") is not None:
        parts.append(f"partial-volume {vm['partial_volume']:.3f} ml")
    if report["volume_difference_percent"] is not None:
        parts.append(f"difference {report['volume_difference_percent']:+.2f}%")
    if report["area_mm2"] is not None:
        parts.append(f"area {report['area_mm2']:.1f} mm2")
    print(head + ", ".join(parts))
    if report["path_length_mm"] is not None:
        a = np.array([r["area_mm2"] if r["area_mm2"] is not None else np.nan for r in report["sections"]], dtype=float)
        ok = np.isfinite(a)
        if ok.any():
            print(f"path {report['path_length_mm']:.1f} mm, {len(a)} sections every {args.step:g} mm: area "
                  f"min {np.nanmin(a):.2f} / median {np.nanmedian(a):.2f} / max {np.nanmax(a):.2f} mm2")
        else:
            print(f"path {report['path_length_mm']:.1f} mm: no section inside the object")
    if report["between"]:
        b = report["between"]
        print(f"between {between[0]:g} and {between[1]:g} mm: volume {b['volume_ml']:.4f} ml, "
              f"sections {b['area1_mm2']:.2f} / {b['area2_mm2']:.2f} mm2")
    for w in report["warnings"]:
        print(f"warning: {w}")
    for name in (args.csv, args.plot):
        if name:
            print(f"wrote {name}")
    return 0
