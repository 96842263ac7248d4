"""`ctui render INPUT --out FILE`: offscreen rendering of meshes, projects and series."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ctui.commands._args import command, number
from ctui.commands.info import add_load_options, load_kwargs
from ctui.engine.core.atomic import check_output
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.rendermodes import MODES, VOLUME_MODES



def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions import defaults

    p = command(
        subparsers, "render", run,
        help="render a mesh, project or series to PNG / turntable GIF (offscreen, EGL)",
        description="Render offscreen (moderngl on EGL: no display needed). INPUT is a mesh file "
        "(STL/PLY/OBJ), a .ctui project (its segmented objects) or a series (DICOM folder, image stack, "
        f"volume file) for the volume modes {'/'.join(VOLUME_MODES)}, or for surface modes with --iso. "
        "--out FILE: .png (one image; with --turntable N an APNG), .gif/.apng (turntable).",
    )
    p.add_argument("input", help="mesh file, .ctui project, or series path")
    p.add_argument("--out", "-o", required=True, help="output .png, .gif or .apng")
    p.add_argument("--mode", choices=MODES,
                   help="default: surface for meshes/projects and with --iso, dvr for series")
    p.add_argument("--preset", default=None,
                   help="DVR transfer function: ct-bone, ct-soft-tissue, ct-vessels, mr-default "
                        "(default: ct-bone for CT, mr-default otherwise)")
    p.add_argument("--azimuth", type=number("--azimuth", -36000, 36000), default=defaults.RENDER_AZIMUTH, help="degrees about the patient's z axis (0 = from the front)")
    p.add_argument("--elevation", type=number("--elevation", -36000, 36000), default=defaults.RENDER_ELEVATION, help="degrees above the horizontal (90 = from above)")
    p.add_argument("--roll", type=number("--roll", -36000, 36000), default=defaults.RENDER_ROLL, help="degrees about the view axis")
    p.add_argument("--zoom", type=number("--zoom", 0, 1000, above=True), default=defaults.RENDER_ZOOM, help="magnification (default %(default)g = fit)")
    p.add_argument("--size", default="{}x{}".format(*defaults.RENDER_SIZE),
                   help="WxH pixels (default {}x{})".format(*defaults.RENDER_SIZE))
    p.add_argument("--light", default=None, help="AZ,EL of the movable light relative to the camera (default 35,35)")
    p.add_argument("--shadows", action="store_true", help="shadow mapping from the light")
    p.add_argument("--turntable", type=number("--turntable", 1, 720, integer=True), default=None, metavar="N", help="N frames around the object (GIF/APNG)")
    p.add_argument("--fps", type=number("--fps", 0.1, 100), default=defaults.ANIMATION_FPS, help="turntable frames per second")
    p.add_argument("--iso", type=number("--iso"), default=None, help="iso value (HU) for surface modes on a series")
    p.add_argument("--object", type=number("--object", 0, 65535, integer=True), action="append", default=None, metavar="ID",
                   help="project: render only this object id (repeatable)")
    p.add_argument("--opacity", type=number("--opacity", 0, 1), default=None, help="opacity of all surfaces (0..1)")
    p.add_argument("--perspective", action="store_true", help="perspective instead of orthographic projection")
    p.add_argument("--aa", choices=defaults.ANTIALIAS, default=defaults.RENDER_ANTIALIAS, help="anti-aliasing (default %(default)s)")
    p.add_argument("--wire-overlay", action="store_true", help="draw triangle edges over the surfaces")
    p.add_argument("--window", default=None, help="C,W display window for mip/minip and slice planes")
    p.add_argument("--slice", default=None, metavar="AXIS[:INDEX]",
                   help="show a slice plane in place (axis z|y|x; needs a series or project source)")
    p.add_argument("--background", default=None, help="R,G,B 0..255 (default dark grey)")
    p.add_argument("--frame", choices=defaults.FRAMES, default=defaults.RENDER_FRAME,
                   help="what the camera frames: auto (the objects in surface modes, the volume in volume "
                        "modes), objects, or series (the whole volume box)")
    p.add_argument("--flythrough", default=None, metavar="auto|X,Y,Z;X,Y,Z;...",
                   help="endoscopic fly-through along a path in patient mm, or 'auto': the centreline of "
                        "the project object given with --object; --out a .gif/.apng or a folder for PNG frames")
    p.add_argument("--frames", type=number("--frames", 2, 2000, integer=True), default=defaults.FLY_FRAMES,
                   help=f"fly-through frames (default {defaults.FLY_FRAMES})")
    p.add_argument("--fov", type=number("--fov", 1, 170), default=defaults.FLY_FOV_DEG,
                   help=f"fly-through view angle in degrees (default {defaults.FLY_FOV_DEG:g})")
    p.add_argument("--labels", metavar="FILE", default=None,
                   help="a label file (DICOM-SEG, RTSTRUCT, .nii, .nii.gz, .nrrd, .gipl) over the series INPUT: its geometry must match the series'; INPUT is then the series")
    add_load_options(p)


def _pair(text: str, what: str, n: int = 2) -> tuple[float, ...]:
    sep = "x" if what.startswith("--size") else ","
    try:
        vals = tuple(float(v) for v in text.split(sep))
    except ValueError:
        vals = ()
    if len(vals) != n or not all(math.isfinite(v) and abs(v) <= 1e6 for v in vals):
        raise CtuiError(f"bad {what} {text!r}")
    return vals


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.render import render_view


    src = Path(args.input)
    out = Path(args.out)
    if not src.exists():
        raise CtuiError("no such file or folder", path=src)
    if out.parent and not out.parent.exists():
        raise CtuiError("output folder does not exist", path=out)
    check_output(out, inputs=[src, args.labels], label="--out")
    w, h = (int(v) for v in _pair(args.size, "--size (want WxH)"))
    if not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise CtuiError(f"--size {args.size!r}: width and height from 1 to 8192 pixels")
    if args.labels:  # a label file over its series
        from ctui.engine.actions.opened import open_input

        src = open_input(src, labels=args.labels, **load_kwargs(args))
    res = render_view(
        src, out=out, size=(w, h), turntable=args.turntable, fps=args.fps, flythrough=args.flythrough,
        frames=args.frames, fov=args.fov, load_options=load_kwargs(args),
        mode=args.mode, objects=args.object, iso=args.iso, opacity=args.opacity, azimuth=args.azimuth,
        elevation=args.elevation, roll=args.roll, zoom=args.zoom, perspective=args.perspective,
        light=_pair(args.light, "--light (want AZ,EL)") if args.light else None, shadows=args.shadows,
        antialias=args.aa, wire_overlay=args.wire_overlay,
        window=_pair(args.window, "--window (want C,W)") if args.window else None,
        background=_pair(args.background, "--background (want R,G,B)", 3) if args.background else None,
        slice_plane=args.slice, preset=args.preset, frame=args.frame)
    print(res.summary())
    for note in res.notes:
        print(f"note: {note}")
    return 0
