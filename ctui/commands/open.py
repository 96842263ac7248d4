"""``ctui [PATH]`` / ``ctui open PATH|PROJECT.ctui``: the terminal app."""

from __future__ import annotations

import argparse
import os
import sys

from ctui.commands._args import command
from ctui.engine.actions.options import load_options
from ctui.engine.core.colors import MAX_OBJECTS
from ctui.engine.core.errors import CtuiError

from ctui.screens.graphics import MODES as GRAPHICS  # the terminal's image modes: one list (stdlib-only module)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = command(
        subparsers, "open", run,
        help="open the TUI on a series, or resume a .ctui project",
        description="Open the terminal app on PATH (any series `load` accepts), or resume a "
        "PROJECT.ctui. With no PATH: the bundled sample series.",
    )
    p.add_argument("path", nargs="?", help="series folder/file, or a .ctui project (default: bundled sample)")
    p.add_argument("--graphics", choices=GRAPHICS, default=None,
                   help="how images reach the terminal (default: $CTUI_GRAPHICS or auto)")
    p.add_argument("--series", default=None, help="SeriesInstanceUID (or index) to open when PATH holds several")
    p.add_argument("--downsample", type=int, default=None, metavar="N", help="load every N-th voxel (large series)")
    p.add_argument("--crop", default=None, metavar="z0,z1,y0,y1,x0,x1", help="load only this box (voxel indices)")
    p.add_argument("--labels", default=None, metavar="FILE",
                   help="open a label file over the series PATH for editing: DICOM-SEG, RTSTRUCT, .nii, .nii.gz, "
                   ".nrrd, .gipl (e.g. from 3D Slicer, TotalSegmentator or ITK-SNAP); its geometry must match the "
                   "series'")


def run(args: argparse.Namespace) -> int:
    if sys.__stdin__ is None or sys.stdin is None or sys.__stdout__ is None:  # Textual reads keys from stdin
        raise CtuiError("the TUI needs a terminal: standard input or output is closed (run it from a terminal, "
                        "or use the commands: ctui info/segment/mesh/measure/render/export)")
    if sys.stderr is not None and sys.stderr.isatty():  # on screen at once, before the heavy imports
        sys.stderr.write(f"ctui: opening {args.path or 'the bundled sample series'} ...\n")
        sys.stderr.flush()
    from ctui.screens.graphics import enable_truecolor, prepare_graphics

    enable_truecolor()  # tmux with RGB, or a terminal that always does 24-bit: no banding, no warning

    try:
        mode = prepare_graphics(args.graphics)  # before Textual owns the terminal
    except ValueError as exc:
        raise CtuiError(str(exc)) from None
    path = args.path
    project = None
    if path is not None:
        if not os.path.exists(path):
            raise CtuiError("no such file or folder", path=path)
        if path.endswith(".ctui") or path.endswith(".ctui.autosave"):
            project, path = path, None
    from ctui.screens.app import CtuiApp


    options = load_options(series=args.series, downsample=args.downsample, crop=args.crop)
    if "series" in options:
        options["series"] = args.series  # the TUI matches a UID or an index itself
    if args.labels:
        app = CtuiApp(path, graphics=mode, session=_labels_session(path, args.labels, options))
    else:
        app = CtuiApp(path, project=project, graphics=mode, **options)
    app.run()
    return int(app.return_code or 0)


def _labels_session(path, labels: str, options: dict):
    """A TUI session of the series ``path`` with the label file ``labels`` on it (unsaved project)."""
    from ctui.engine.actions.opened import open_input
    from ctui.screens.app import session_from_project

    if path is None:
        raise CtuiError("--labels needs the series the labels were drawn on: ctui open SERIES --labels FILE")
    opened = open_input(path, labels=labels, **options)
    ids = opened.object_ids
    if len(ids) > MAX_OBJECTS or max(ids, default=0) > MAX_OBJECTS:
        raise CtuiError(f"the TUI edits objects 1..{MAX_OBJECTS}; this file holds {len(ids)} (ids up to {max(ids)}): "
                        "use ctui measure/mesh/render SERIES --labels FILE, or export fewer labels", path=labels)
    opened.volume.warnings[:0] = list(opened.notes)  # shown as notifications when the workspace opens
    return session_from_project(opened.project, opened.volume, "")
