"""`ctui render INPUT --out FILE`: offscreen rendering of meshes, projects and series."""

from __future__ import annotations

import argparse

MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off", ".glb", ".gltf")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "render",
        help="render a mesh, project or series to PNG / turntable GIF (offscreen, EGL)",
        description="Render offscreen (moderngl on EGL: no display needed). INPUT is a mesh file "
        "(STL/PLY/OBJ), a .ctui project (its segmented objects) or a series (DICOM folder, image stack, "
        "volume file) for the volume modes mip/minip/dvr, or for surface modes with --iso. "
        "--out FILE: .png (one image; with --turntable N an APNG), .gif/.apng (turntable).",
    )
    p.add_argument("input", help="mesh file, .ctui project, or series path")
    p.add_argument("--out", "-o", required=True, help="output .png, .gif or .apng")
    p.add_argument("--mode", choices=("surface", "wire", "transparent", "mip", "minip", "dvr"),
                   help="default: surface for meshes/projects and with --iso, dvr for series")
    p.add_argument("--preset", default=None,
                   help="DVR transfer function: ct-bone, ct-soft-tissue, ct-vessels, mr-default "
                        "(default: ct-bone for CT, mr-default otherwise)")
    p.add_argument("--azimuth", type=float, default=30.0, help="degrees about the patient's z axis (0 = from the front)")
    p.add_argument("--elevation", type=float, default=15.0, help="degrees above the horizontal (90 = from above)")
    p.add_argument("--roll", type=float, default=0.0, help="degrees about the view axis")
    p.add_argument("--zoom", type=float, default=1.0, help="magnification (default 1 = fit)")
    p.add_argument("--size", default="800x600", help="WxH pixels (default 800x600)")
    p.add_argument("--light", default=None, help="AZ,EL of the movable light relative to the camera (default 35,35)")
    p.add_argument("--shadows", action="store_true", help="shadow mapping from the light")
    p.add_argument("--turntable", type=int, default=None, metavar="N", help="N frames around the object (GIF/APNG)")
    p.add_argument("--fps", type=float, default=15.0, help="turntable frames per second")
    p.add_argument("--iso", type=float, default=None, help="iso value (HU) for surface modes on a series")
    p.add_argument("--object", type=int, action="append", default=None, metavar="ID",
                   help="project: render only this object id (repeatable)")
    p.add_argument("--opacity", type=float, default=None, help="opacity of all surfaces (0..1)")
    p.add_argument("--perspective", action="store_true", help="perspective instead of orthographic projection")
    p.add_argument("--aa", choices=("fxaa", "msaa", "none"), default="fxaa", help="anti-aliasing (default fxaa)")
    p.add_argument("--wire-overlay", action="store_true", help="draw triangle edges over the surfaces")
    p.add_argument("--window", default=None, help="C,W display window for mip/minip and slice planes")
    p.add_argument("--slice", default=None, metavar="AXIS[:INDEX]",
                   help="show a slice plane in place (axis z|y|x; needs a series or project source)")
    p.add_argument("--series", default=None, help="series UID (or index) when the path holds several")
    p.add_argument("--shape", default=None, metavar="ZxYxX|YxX", help="raw data: volume or per-slice shape")
    p.add_argument("--dtype", default=None, help="raw data: numpy dtype, e.g. '>u2' for big-endian uint16")
    p.add_argument("--spacing", default=None, metavar="DZ,DY,DX", help="spacing in mm for stacks and raw data")
    p.add_argument("--background", default=None, help="R,G,B 0..255 (default dark grey)")
    p.add_argument("--flythrough", default=None, metavar="auto|X,Y,Z;X,Y,Z;...",
                   help="endoscopic fly-through along a path in patient mm, or 'auto': the centreline of "
                        "the project object given with --object; --out a .gif/.apng or a folder for PNG frames")
    p.add_argument("--frames", type=int, default=48, help="fly-through frames (default 48)")
    p.add_argument("--fov", type=float, default=70.0, help="fly-through view angle in degrees (default 70)")
    p.set_defaults(func=run)


def _pair(text: str, what: str, n: int = 2) -> tuple[float, ...]:
    from ctui.engine.core.errors import CtuiError

    try:
        vals = tuple(float(v) for v in text.replace("x", ",").split(","))
    except ValueError:
        vals = ()
    if len(vals) != n:
        raise CtuiError(f"bad {what} {text!r}")
    return vals


def _load_mesh_file(path):
    from ctui.engine.core.errors import CtuiError, FormatError

    try:
        from ctui.engine.io.meshes import load_mesh  # MESH engineer's reader
    except ImportError:
        load_mesh = None
    if load_mesh is not None:
        return load_mesh(path)
    import numpy as np
    import trimesh

    from ctui.engine.core.meshdata import Mesh

    try:
        tm = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise FormatError(f"not a readable mesh ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})",
                          path=path) from exc
    if not hasattr(tm, "faces") or len(tm.faces) == 0:
        raise FormatError("no triangles found", path=path)
    if not np.all(np.isfinite(tm.vertices)):
        raise FormatError("mesh has non-finite vertex coordinates", path=path)
    return Mesh(np.asarray(tm.vertices, np.float32), np.asarray(tm.faces, np.int64))
    raise CtuiError("unreachable")  # pragma: no cover


def _load_series(path, args):
    from ctui.engine.core.errors import CtuiError

    try:
        from ctui.engine.io.series import load
    except ImportError as exc:
        raise CtuiError("not a mesh (.stl/.ply/.obj), project (.ctui) or readable series", path=path) from exc
    opts = {}
    if getattr(args, "series", None):
        opts["series"] = int(args.series) if str(args.series).isdigit() else args.series
    if getattr(args, "shape", None):
        try:
            opts["shape"] = tuple(int(v) for v in str(args.shape).lower().replace(",", "x").split("x"))
        except ValueError:
            raise CtuiError(f"bad --shape {args.shape!r} (want ZxYxX or YxX)") from None
    if getattr(args, "dtype", None):
        opts["dtype"] = args.dtype
    if getattr(args, "spacing", None):
        opts["spacing"] = _pair(args.spacing, "--spacing (want DZ,DY,DX)", 3)
    return load(path, **opts)


def _project_meshes(path, args):
    """(meshes, volume or None) for a .ctui project's labelled objects."""
    import numpy as np

    from ctui.engine.core.errors import CtuiError
    from ctui.engine.core.meshdata import Mesh
    from ctui.engine.io.project import load_project

    proj = load_project(path)
    if proj.labels is None or not np.any(proj.labels):
        raise CtuiError("project has no segmented objects to render", path=path)
    vol = None
    spacing, origin, direction = (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), np.eye(3)
    try:
        vol = _load_series(proj.source_path, argparse.Namespace(series=proj.source_options.get("series")))
        if vol.shape == proj.labels.shape:
            spacing, origin, direction = vol.spacing, vol.origin, vol.direction
        else:
            vol = None
    except CtuiError:
        vol = None
        meta = proj.meta or {}
        if meta.get("spacing_zyx_mm"):
            spacing = tuple(meta["spacing_zyx_mm"])
        if meta.get("origin_xyz_mm"):
            origin = tuple(meta["origin_xyz_mm"])
    ids = [int(i) for i in np.unique(proj.labels) if i]
    if args.object:
        missing = [i for i in args.object if i not in ids]
        if missing:
            raise CtuiError(f"object(s) {missing} not in the project (has {ids})", path=path)
        ids = list(args.object)
    try:
        from ctui.engine.mesh.surface import label_surfaces
    except ImportError:
        label_surfaces = None
    meshes: list[Mesh] = []
    if label_surfaces is not None:
        sub = np.where(np.isin(proj.labels, ids), proj.labels, 0).astype(np.uint8)
        out = label_surfaces(sub, spacing=spacing, origin=origin, direction=direction)
        for oid in ids:
            if oid in out:
                out[oid].object_id = oid
                meshes.append(out[oid])
    else:
        from ctui.engine.mesh.surface import isosurface

        for oid in ids:
            m = isosurface((proj.labels == oid).astype(np.float32), 0.5, spacing=spacing, origin=origin,
                           direction=direction)
            m.object_id = oid
            meshes.append(m)
    colors = {int(o.get("id", 0)): o.get("color") for o in (proj.objects or []) if isinstance(o, dict)}
    args._project_geometry = (proj.labels, spacing, origin, direction)
    return meshes, vol, colors


def run(args: argparse.Namespace) -> int:
    from pathlib import Path


    from ctui.engine.core.errors import CtuiError
    from ctui.engine.render import (Light, Scene, SceneMesh, SceneVolume, SlicePlane, get_renderer, save_animation,
                                    save_png, turntable_frames)

    src = Path(args.input)
    out = Path(args.out)
    if not src.exists():
        raise CtuiError("no such file or folder", path=src)
    if out.parent and not out.parent.exists():
        raise CtuiError("output folder does not exist", path=out)
    from ctui.engine.core.atomic import check_output

    check_output(out, inputs=[src], label="--out")
    w, h = (int(v) for v in _pair(args.size, "--size (want WxH)"))
    if not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise CtuiError(f"--size {args.size}: width and height must be 1..8192")
    if args.turntable is not None and args.turntable < 1:
        raise CtuiError("--turntable needs N >= 1")
    if args.opacity is not None and not 0.0 <= args.opacity <= 1.0:
        raise CtuiError("--opacity must be between 0 and 1")

    scene = Scene()
    volume = None
    colors: dict = {}
    suffix = src.suffix.lower()
    fly = args.flythrough
    if fly is not None and out.suffix.lower() not in (".gif", ".apng", ""):
        raise CtuiError("--flythrough writes a .gif/.apng or a folder of PNG frames", path=out)
    if out.suffix.lower() not in (".png", ".gif", ".apng") and fly is None:
        raise CtuiError("output must end in .png, .gif or .apng", path=out)
    if src.is_file() and suffix in MESH_SUFFIXES:
        meshes = [_load_mesh_file(src)]
        kind = "mesh"
    elif src.is_file() and suffix == ".ctui":
        meshes, volume, colors = _project_meshes(src, args)
        kind = "project"
    else:
        volume = _load_series(src, args)
        meshes = []
        kind = "series"
    mode = args.mode or ("dvr" if kind == "series" and args.iso is None else "surface")
    if kind == "series" and mode in ("surface", "wire", "transparent"):
        if args.iso is None:
            raise CtuiError(f"--mode {mode} on a series needs --iso LEVEL (e.g. --iso 300 for bone)", path=src)
        from ctui.engine.mesh.surface import isosurface

        m = isosurface(volume.data, args.iso, spacing=volume.spacing, origin=volume.origin,
                       direction=volume.direction)
        if m.n_faces == 0:
            raise CtuiError(f"no surface at --iso {args.iso:g} (values range {volume.value_range()})", path=src)
        meshes = [m]
    if mode in ("mip", "minip", "dvr") and volume is None:
        raise CtuiError(f"--mode {mode} needs a series (volume), not a {kind}", path=src)
    if not meshes and mode not in ("mip", "minip", "dvr"):
        raise CtuiError("nothing to render", path=src)

    for m in meshes:
        item = SceneMesh(m)
        c = colors.get(int(m.object_id))
        if isinstance(c, (list, tuple)) and len(c) == 3:
            item.color = tuple(float(v) / 255.0 if max(c) > 1 else float(v) for v in c)
        if args.opacity is not None:
            item.opacity = float(args.opacity)
        scene.meshes.append(item)
    if volume is not None:
        scene.volume = SceneVolume.from_volume(volume)
    scene.mode = mode
    cam = scene.camera
    cam.azimuth, cam.elevation, cam.roll, cam.zoom = args.azimuth, args.elevation, args.roll, args.zoom
    if args.perspective:
        cam.projection = "perspective"
    if args.light:
        az, el = _pair(args.light, "--light (want AZ,EL)")
        scene.light = Light(azimuth=az, elevation=el)
    o = scene.options
    o.shadows = bool(args.shadows)
    o.antialias = args.aa
    o.wireframe_overlay = bool(args.wire_overlay)
    if args.window:
        o.window = _pair(args.window, "--window (want C,W)")
    if args.background:
        o.background = tuple(v / 255.0 for v in _pair(args.background, "--background (want R,G,B)", 3))
    if args.slice:
        if volume is None:
            raise CtuiError("--slice needs a series or a project whose source series loads", path=src)
        ax, _, idx = args.slice.partition(":")
        if ax.lower() not in ("x", "y", "z", "axial", "coronal", "sagittal"):
            raise CtuiError(f"--slice {args.slice}: axis must be z, y or x")
        o.slice_plane = SlicePlane(axis=ax.lower(), index=int(idx) if idx else None)
        if kind == "series" and mode in ("mip", "minip", "dvr"):
            o.slice_plane = None
    if args.preset:
        from ctui.engine.render.transfer import resolve_preset

        o.preset = resolve_preset(args.preset)
    elif volume is not None:
        o.preset = "ct-bone" if str(volume.modality).upper() == "CT" else "mr-default"

    renderer = get_renderer()
    if fly is not None:
        path_mm = _fly_path(fly, args, kind, src)
        from ctui.engine.render import save_flythrough

        if args.frames < 2:
            raise CtuiError("--frames must be at least 2")
        save_flythrough(out, scene, path_mm, args.frames, (w, h), fov_deg=args.fov, fps=args.fps, renderer=renderer)
        print(f"wrote {out} ({args.frames} fly-through frames, {w}x{h}, path {len(path_mm)} points)")
        return 0
    animated = out.suffix.lower() in (".gif", ".apng") or args.turntable is not None
    if animated:
        n = args.turntable or 36
        frames = turntable_frames(scene, n, (w, h), renderer=renderer)
        save_animation(out, frames, fps=args.fps)
        print(f"wrote {out} ({n} frames, {w}x{h}, mode {mode})")
    else:
        img = renderer.render(scene, size=(w, h))
        save_png(out, img)
        print(f"wrote {out} ({w}x{h}, mode {mode})")
    return 0


def _fly_path(spec: str, args, kind: str, src):
    """(n, 3) patient mm path for --flythrough."""
    import numpy as np

    from ctui.engine.core.errors import CtuiError

    if spec.strip().lower() == "auto":
        geo = getattr(args, "_project_geometry", None)
        objects = list(args.object or [])
        if kind == "project" and geo is not None and not objects:
            present = [int(v) for v in np.unique(geo[0]) if v]
            if len(present) == 1:  # the project's only object
                objects = present
        if kind != "project" or geo is None or len(objects) != 1:
            raise CtuiError("--flythrough auto needs a .ctui project and one --object (a tubular object)", path=src)
        labels, spacing, origin, direction = geo
        from ctui.engine.measure.centreline import centreline

        path = centreline(labels == objects[0], spacing=spacing, origin=origin, direction=direction)
        if path is None or len(path) < 2:
            raise CtuiError(f"no centreline found for object {objects[0]}", path=src)
        return np.asarray(path, float)
    try:
        pts = np.array([[float(v) for v in p.split(",")] for p in spec.split(";") if p.strip()])
    except ValueError:
        pts = np.zeros((0, 0))
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
        raise CtuiError(f"bad --flythrough {spec!r} (want 'auto' or 'x,y,z;x,y,z;...' in mm)")
    return pts
