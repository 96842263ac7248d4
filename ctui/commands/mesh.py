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

LABEL_SUFFIXES = (".nii", ".nii.gz", ".nrrd", ".seg.nrrd")


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.commands.info import add_load_options

    p = subparsers.add_parser(
        "mesh",
        help="surface of a series (--iso), a project's objects or an MRIC file, written as STL/PLY/OBJ",
        description="Build a closed triangle surface in patient mm and write it atomically. INPUT: a series "
        "with --iso VALUE (marching cubes), a .ctui project or label file (object surfaces: smoothed "
        "signed-distance marching cubes, or contour connecting), or an .mric contour file.",
    )
    p.add_argument("input", metavar="INPUT", help="series path, .ctui project, label file or .mric file")
    p.add_argument("--out", required=True, metavar="FILE", help="output mesh: .stl, .ply or .obj")
    p.add_argument("--method", choices=("marching-cubes", "contours"), default=None,
                   help="marching-cubes (default for series and projects) or contours (default for .mric)")
    p.add_argument("--iso", type=float, metavar="VALUE", help="iso value for a series (HU for CT)")
    p.add_argument("--object", type=int, metavar="N", help="object id in a project / label file (default: all)")
    p.add_argument("--smooth", type=int, default=0, metavar="ITER", help="Taubin smoothing iterations (volume-preserving)")
    p.add_argument("--decimate", type=int, metavar="N", help="reduce to about N triangles")
    p.add_argument("--tiling", choices=("dp", "greedy"), default="dp", help="contour tiling: minimum-area DP or greedy")
    p.add_argument("--terraced", action="store_true",
                   help="project / label file: plain marching cubes of the label map, every object in one pass "
                   "(voxel staircase kept) instead of smoothed signed-distance surfaces")
    p.add_argument("--ascii", action="store_true", help="ASCII STL/PLY instead of binary")
    p.add_argument("--json", action="store_true", help="print a JSON report")
    add_load_options(p)
    p.set_defaults(func=run)


def _err(msg: str):
    from ctui.engine.core.errors import CtuiError

    return CtuiError(msg)


def _kind(path: str) -> str:
    low = path.lower()
    if low.endswith((".ctui", ".ctui.autosave")):
        return "project"
    if low.endswith(".mric"):
        return "mric"
    if low.endswith(LABEL_SUFFIXES):
        return "labels"
    return "series"


def _spacing(text: str | None, where: str) -> tuple[float, float, float] | None:
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in str(text).split(","))
    except ValueError:
        raise _err(f"{where}: --spacing {text!r}: expected dz,dy,dx in mm") from None
    if len(vals) != 3 or min(vals) <= 0:
        raise _err(f"{where}: --spacing {text!r}: expected three positive numbers dz,dy,dx")
    return vals  # type: ignore[return-value]


def _project_labels(path: str, args: argparse.Namespace):
    """(labels, spacing, origin, direction) of a project or a label file."""
    import os

    import numpy as np

    if _kind(path) == "labels":
        from ctui.engine.io.labels import load_labels

        labels, geom = load_labels(path)
        return np.asarray(labels), geom.spacing, geom.origin, geom.direction
    from ctui.engine.io.project import load_project

    project = load_project(path)
    if project.labels is None:
        raise _err(f"{path}: the project holds no label volume (segment an object first)")
    labels = np.asarray(project.labels)
    meta = project.meta or {}
    src = project.source_path
    if src and os.path.exists(src):
        from ctui.engine.io.series import load

        opts = {k: v for k, v in (project.source_options or {}).items() if v is not None}
        vol = load(src, **opts)
        if vol.data.shape != labels.shape:
            raise _err(f"{path}: labels {labels.shape} do not match the source series {vol.data.shape}")
        return labels, vol.spacing, vol.origin, vol.direction
    sp = meta.get("spacing_zyx_mm") or _spacing(getattr(args, "spacing", None), path)
    if sp is None:
        raise _err(f"{path}: the source series {src!r} is missing and the project records no voxel spacing "
                   "(give --spacing dz,dy,dx)")
    return labels, tuple(sp), tuple(meta.get("origin_xyz_mm", (0.0, 0.0, 0.0))), meta.get("direction")


def _objects(labels, requested: int | None, path: str) -> list[int]:
    import numpy as np

    present = [int(v) for v in np.unique(labels) if v != 0]
    if not present:
        raise _err(f"{path}: no object in the label volume")
    if requested is None:
        return present
    if requested not in present:
        raise _err(f"{path}: no object {requested} (objects present: {', '.join(map(str, present))})")
    return [requested]


def run(args: argparse.Namespace) -> int:
    import json
    import os
    from pathlib import Path

    import numpy as np

    from ctui.engine.mesh import meshtools
    from ctui.engine.io.meshes import FORMATS, save_mesh

    src = args.input
    out = Path(args.out)
    if out.suffix.lower() not in FORMATS:
        raise _err(f"{out}: unknown mesh format {out.suffix or '(no extension)'}; use .stl, .ply or .obj")
    if not os.path.exists(src):
        raise _err(f"{src}: no such file or folder")
    if out.parent and not out.parent.exists():
        raise _err(f"{out}: folder {out.parent} does not exist")
    from ctui.engine.core.atomic import check_output

    check_output(out, inputs=[src], label="--out")
    if args.smooth < 0:
        raise _err(f"--smooth {args.smooth}: must be 0 or more iterations")
    if args.decimate is not None and args.decimate < 4:
        raise _err(f"--decimate {args.decimate}: need at least 4 triangles")
    kind = _kind(src)
    method = args.method or ("contours" if kind == "mric" else "marching-cubes")
    info: dict = {"input": src, "kind": kind, "method": method}

    if kind == "mric":
        if method != "contours":
            raise _err(f"{src}: an MRIC file holds contours only: use --method contours")
        if args.iso is not None:
            raise _err(f"{src}: --iso applies to a series, not to an MRIC file")
        from ctui.engine.mesh.contour_connect import connect_mric

        sp = _spacing(getattr(args, "spacing", None), src) or (1.0, 1.0, 1.0)
        mesh = connect_mric(src, object_index=args.object, spacing=sp, method=args.tiling)
        if mesh.n_faces == 0:
            raise _err(f"{src}: no contour found" + (f" for object {args.object}" if args.object else ""))
    elif kind in ("project", "labels"):
        if args.iso is not None:
            raise _err(f"{src}: --iso applies to a series; a project's objects are meshed from their labels")
        if args.terraced and method == "contours":
            raise _err("--terraced applies to marching cubes, not to --method contours")
        labels, spacing, origin, direction = _project_labels(src, args)
        ids = _objects(labels, args.object, src)
        info["objects"] = ids
        if method == "contours":
            from ctui.engine.core.borders import object_borders
            from ctui.engine.mesh.contour_connect import connect_contours

            parts = []
            for k in ids:
                m = connect_contours(object_borders(labels, k), spacing=spacing, origin=origin, direction=direction,
                                     method=args.tiling)
                m.object_id = k
                parts.append(m)
        else:
            from ctui.engine.mesh.surface import label_surfaces

            surf = label_surfaces(labels, spacing=spacing, origin=origin, direction=direction,
                                  smooth=not args.terraced, objects=ids)
            parts = [surf[k] for k in ids if k in surf]
        mesh = meshtools.merge(parts, object_id=ids[0] if len(ids) == 1 else 0, meta={"method": method})
    else:
        if args.iso is None:
            raise _err(f"{src}: a series needs --iso VALUE (e.g. --iso 300 for bone in CT)")
        from ctui.engine.io.series import load

        from ctui.commands.info import load_kwargs

        vol = load(src, **load_kwargs(args))
        if method == "contours":
            from ctui.engine.core.borders import object_borders
            from ctui.engine.mesh.contour_connect import connect_contours

            mask = (vol.data > args.iso).astype(np.uint8)
            mesh = connect_contours(object_borders(mask, 1), spacing=vol.spacing, origin=vol.origin,
                                    direction=vol.direction, method=args.tiling)
        else:
            from ctui.engine.mesh.surface import isosurface

            mesh = isosurface(vol.data, args.iso, spacing=vol.spacing, origin=vol.origin, direction=vol.direction,
                              close=True)
        if mesh.n_faces == 0:
            lo, hi = vol.value_range()
            raise _err(f"{src}: no surface at --iso {args.iso:g} (values range {lo:g} .. {hi:g})")
        info["iso"] = args.iso
    if args.smooth:
        mesh = meshtools.smooth_taubin(mesh, iterations=args.smooth)
    if args.decimate:
        mesh = meshtools.decimate(mesh, args.decimate)
    save_mesh(out, mesh, ascii=args.ascii)
    rep = meshtools.mesh_report(mesh)
    result = {
        "triangles": rep["triangles"],
        "vertices": rep["vertices"],
        "watertight": rep["watertight"],
        "volume_ml": round(rep["volume_ml"], 4),
        "area_mm2": round(rep["area_mm2"], 2),
        "components": rep["components"],
        "boundary_edges": rep["boundary_edges"],
        "non_manifold_edges": rep["non_manifold_edges"],
        "out": str(out),
        **{k: v for k, v in info.items() if k not in ("input",)},
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"{out}: {rep['triangles']} triangles, {rep['vertices']} vertices, "
              f"{'watertight' if rep['watertight'] else 'NOT watertight'}, volume {rep['volume_ml']:.2f} ml, "
              f"area {rep['area_mm2']:.0f} mm2 ({method})")
    return 0
