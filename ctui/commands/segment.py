"""``ctui segment PATH --seed X,Y,Z (--range LO:HI | --tolerance T) [--background X,Y,Z] [--method ...]``.

Parses arguments and calls :func:`ctui.engine.actions.segment.segment`. The TUI's Enter fills
with the same neck-cut fill (``actions.edit.fill_slice``); its ``p`` propagates slice by slice
on screen (``screens/propagation.py``).
"""

from __future__ import annotations

import argparse
import math
import os

from ctui.commands._args import HUGE, command, finite_list, number
from ctui.commands._progress import progress_bar
from ctui.commands.info import add_load_options, load_kwargs
from ctui.engine.actions.options import parse_pair
from ctui.engine.core.atomic import check_outputs
from ctui.engine.core.errors import CtuiError

FILTER_HELP = (
    "filter step NAME[:key=value,...], repeatable, run in order (stage 1 steps, then stage 2). "
    "Names: opening closing erode dilate median gaussian sharpen conservative invert equalize clahe. "
    "Keys: stage=1|2, shape=rect|ellipse|cross|custom, size=N, iterations=N, kernel=010/111/010 "
    "(custom 0/1 rows), sigma=S, amount=A (sharpen), clip_limit=C, tiles=N (clahe). "
    "Example: --filter opening:size=3,shape=ellipse --filter median:size=5,stage=2"
)


class _MethodChoices:
    """The segmentation methods (the engine's registry, ``actions.segment.METHODS``) as
    argparse choices, read when argparse checks or shows them: building the parser for
    ``ctui --help`` must not import numpy."""

    @staticmethod
    def _names() -> tuple[str, ...]:
        from ctui.engine.actions.segment import METHODS  # numpy and the segmentation stack

        return tuple(METHODS)

    def __iter__(self):
        return iter(self._names())

    def __contains__(self, name: object) -> bool:
        return name in self._names()

    def __len__(self) -> int:
        return len(self._names())


class _MethodHelp(str):
    """Help text that lists each registered method with its line of help when argparse
    formats it (``help % params``), so the registry is read only for ``--help``."""

    def __mod__(self, params):  # type: ignore[override]  # a str whose % formats the registry's help lazily
        from ctui.engine.actions.segment import METHODS

        return f"{self}: " + "; ".join(f"{m.name}: {m.help}" + (" (default)" if m.name == params.get("default") else "")
                                       for m in METHODS.values())


class _ThresholdAction(argparse.Action):
    """Keeps --range and --tolerance in one ordered list so the n-th pairs with the n-th --seed."""

    def __call__(self, parser, namespace, values, option_string=None):  # type: ignore[override]  # argparse.Action's signature, values untyped
        items = list(getattr(namespace, self.dest, None) or [])
        items.append((self.const, values))
        setattr(namespace, self.dest, items)


def add_segmentation_args(p: argparse.ArgumentParser, *, required: bool = True) -> None:
    """Options shared by ``segment`` and ``drift``. Slices are numbered from 0 everywhere."""
    from ctui.engine.actions import defaults  # plain constants: --help stays fast

    p.add_argument("--seed", action="append", default=[], metavar="X,Y,Z",
                   help="seed voxel inside the object: column, row, slice (numbered from 0, slice 0 lowest along "
                        "the slice normal, as in the TUI); repeat for several objects" + ("" if required else " (instead of --mask)"))
    p.add_argument("--background", action="append", default=[], metavar="X,Y,Z",
                   help="background seed: a voxel of a neighbour with the same values that the object must not "
                        "reach (column, row, slice from 0); repeatable, shared by every object")
    p.add_argument("--method", choices=_MethodChoices(), default=defaults.SEGMENT_METHOD, metavar="METHOD",  # metavar: not read now
                   help=_MethodHelp("segmentation method"))
    p.add_argument("--range", dest="thresholds", action=_ThresholdAction, const="range", metavar="LO:HI|auto",
                   help="in-range values LO..HI inclusive (HU for CT in the default hu domain); "
                        "one per --seed, or one for all; auto (or no --range/--tolerance): from the seed's "
                        "neighbourhood (median +- 2 robust sd), reported")
    p.add_argument("--tolerance", dest="thresholds", action=_ThresholdAction, const="tolerance", metavar="T",
                   help="in-range values: seed value +- T (in the seed slice's final view)")
    p.add_argument("--filter", action="append", default=[], metavar="SPEC", help=FILTER_HELP)
    p.add_argument("--domain", choices=defaults.DOMAINS, default=defaults.DOMAIN,
                   help="filters and thresholds work on HU values (hu, default) or on windowed 0..255 values (window8)")
    p.add_argument("--window", metavar="C,W", default=None, help="window centre,width for window8/equalize/invert (default: the series')")
    p.add_argument("--connectivity", type=int, choices=defaults.CONNECTIVITIES, default=defaults.CONNECTIVITY, help="in-slice connectivity (default %(default)s)")
    p.add_argument("--direction", choices=defaults.DIRECTIONS, default=defaults.DIRECTION,
                   help="propagate from the seed slice towards higher slices, lower, or both (default)")
    p.add_argument("--mode", choices=defaults.PROPAGATION_MODES, default=defaults.PROPAGATION_MODE,
                   help="slice-by-slice propagation (default) or one 3D flood fill; both cut necks (--neck)")
    p.add_argument("--slices", metavar="A:B", default=None,
                   help="propagate (and grow) only within slices A..B inclusive, numbered from 0")
    p.add_argument("--neck", type=_neck, default=None, metavar="auto|MM",
                   help="leak guard: follow the object only through necks at least MM wide; auto (default) "
                        "chooses the width from the data (the widest result before the volume jumps) and "
                        "reports it; 0 = off")
    p.add_argument("--fill-holes", action=argparse.BooleanOptionalAction, default=True,
                   help="holes enclosed in each slice of an object (renal sinus, vessels in the liver, noise) "
                        "are part of it (default; --no-fill-holes keeps only in-range voxels)")
    p.add_argument("--box", metavar="X0,Y0,Z0,X1,Y1,Z1", default=None,
                   help="two opposite corners (column, row, slice from 0, inclusive): fills, propagation and "
                        "growing stay inside this box")
    p.add_argument("--leak-factor", type=number("--leak-factor", 1, 1000, above=True), default=defaults.LEAK_FACTOR,
                   help="second leak guard, slice mode with --neck MM: stop when the area grows more than this factor "
                        "from one slice to the next (default %(default)g; in 3D mode only with --neck 0; with --neck auto "
                        "the width's region and its 3D cut do this)")
    p.add_argument("--neighbourhood", type=number("--neighbourhood", 0, 100, integer=True), default=defaults.NEIGHBOURHOOD,
                   help="pixels the previous slice's object is grown by to seed the next slice (default %(default)s; 0 = overlap only)")
    p.add_argument("--min-area", type=number("--min-area", 1, 1e9, integer=True), default=defaults.MIN_AREA, help="smallest accepted fill / object slice in pixels (default %(default)s)")
    p.add_argument("--curvature", type=number("--curvature", 0, 100), default=defaults.LEVELSET_CURVATURE_MM, metavar="MM",
                   help="levelset: weight of the curvature term in mm (default %(default)g): smooths corners sharper than "
                        "MM; the front does not enter necks narrower than about 2 x MM")
    p.add_argument("--keep-largest", action="store_true", help="keep only each object's largest 3D island")
    p.add_argument("--min-island", type=number("--min-island", 0, 1e12, integer=True), default=defaults.MIN_ISLAND_VOXELS, metavar="N", help="remove each object's islands under N voxels")
    p.add_argument("--interpolate", action="store_true",
                   help="fill the empty slices between each object's slices by signed-distance interpolation")
    p.add_argument("--series", default=None, help="SeriesInstanceUID (or index) when PATH holds several series")

    add_load_options(p, series=False)  # --shape, --dtype, --offset, --spacing, --crop, --downsample, --no-resample


def _neck(text: str) -> float | None:
    """--neck: ``auto`` (None) or a width in mm."""
    if text.strip().lower() == "auto":
        return None
    return number("--neck", 0, 1000)(text)


def parse_box(text: str | None):
    """--box X0,Y0,Z0,X1,Y1,Z1 -> ((z0, z1), (y0, y1), (x0, x1)) inclusive, corners in any order."""
    if not text:
        return None
    try:
        v = [int(t) for t in text.replace(" ", "").split(",")]
        if len(v) != 6:
            raise ValueError
    except ValueError:
        raise _err(f"--box {text!r}: expected X0,Y0,Z0,X1,Y1,Z1 (two corners: column, row, slice)") from None
    x0, y0, z0, x1, y1, z1 = v
    return ((min(z0, z1), max(z0, z1)), (min(y0, y1), max(y0, y1)), (min(x0, x1), max(x0, x1)))


def register(subparsers: argparse._SubParsersAction) -> None:
    p = command(
        subparsers, "segment", run,
        help="objects from seeds and an HU range: fill + propagation, grow, or level set",
        description="Fill each object from its seed on the seed slice (after the filter pipeline), "
        "propagate it slice by slice (or in 3D) keeping only what joins it through necks wider than --neck mm, "
        "and report voxels and volume. --background seeds mark neighbours the object must not reach. "
        "--seed/--range/--tolerance may repeat: one object per --seed (ids 1, 2, ...). "
        "Slices are numbered from 0 (as in the TUI).",
        epilog="Example: ctui segment scan/ --seed 94,81,40 --range 115:445 --background 140,90,40 --method grow --json",
    )
    p.add_argument("path", help="series folder/file (anything `ctui open` loads), or a .ctui project to edit "
                                "its objects (--interpolate, --keep-largest, --min-island) without --seed")
    add_segmentation_args(p)
    p.add_argument("--project", metavar="OUT.ctui", help="write a project (source, pipeline, labels, objects)")
    p.add_argument("--mask", metavar="OUT", help="write the label volume (.nii, .nii.gz, .nrrd, .seg.nrrd)")
    p.add_argument("--mric", metavar="OUT.mric", help="write the borders as an MRIC contour file")
    p.add_argument("--objects", metavar="IDS", default=None,
                   help="with a .ctui PATH and no --seed: the objects --interpolate/--keep-largest/--min-island "
                        "edit, e.g. 1,3 (default: all); write the result with --project NEW.ctui")
    p.add_argument("--json", action="store_true", help="print a JSON report")
    p.add_argument("--server", metavar="URL", default="",
                   help="--method nninteractive: the nnInteractive server (default: $CTUI_NNI_SERVER), e.g. "
                        "http://127.0.0.1:8000 through `ssh -L 8000:127.0.0.1:8000 gpu-box`; never saved")
    p.add_argument("--key", metavar="KEY", default=None,
                   help="--method nninteractive: the server's API key (default: $CTUI_NNI_KEY); never saved")
    p.add_argument("--refine", action="store_true",
                   help="--method nninteractive with a .ctui PATH: send its object (--objects N, default the "
                        "first) as the initial segmentation and refine it with the prompts")


# ----------------------------------------------------------------------------- helpers
def _err(msg: str):
    return CtuiError(msg)


def parse_seed(text: str) -> tuple[int, int, int]:
    parts = text.replace(" ", "").split(",")
    if len(parts) != 3:
        raise _err(f"--seed {text!r}: expected X,Y,Z (column,row,slice)")
    try:
        x, y, z = (int(v) for v in parts)
    except ValueError:
        raise _err(f"--seed {text!r}: X,Y,Z must be integers") from None
    return x, y, z


def parse_range(text: str) -> tuple[float, float]:
    lo, hi = parse_pair(text, "--range", example="115:445")
    if not (math.isfinite(lo) and math.isfinite(hi) and max(abs(lo), abs(hi)) <= HUGE):
        raise _err(f"--range {text!r}: LO and HI must be finite numbers within +-{HUGE:g}")
    if lo > hi:
        raise _err(f"--range {text!r}: LO is above HI")
    return lo, hi


def build_pipeline(args: argparse.Namespace):
    from ctui.engine.actions.series import Pipeline, parse_filter_spec

    window = None
    if args.window:
        try:
            c, w = finite_list(args.window, "--window", n=2)
        except ValueError:
            raise _err(f"--window {args.window!r}: expected CENTRE,WIDTH (finite numbers)") from None
        if w <= 0:
            raise _err(f"--window {args.window!r}: width must be > 0")
        window = (c, w)
    try:
        steps = [parse_filter_spec(s) for s in args.filter]
    except ValueError as exc:
        raise _err(f"--filter: {exc}") from None
    return Pipeline(steps, domain=args.domain, window=window)


def load_volume(path: str, *, series: str | None = None, **load_options):
    """The series at ``path`` with the loader options (``commands.info.load_kwargs``)."""
    if not os.path.exists(path):
        raise _err(f"{path}: no such file or folder")
    from ctui.engine.actions.series import load

    opts = {**load_options, **({"series": series} if series else {})}
    return load(path, **opts)


def parse_slices(text: str | None) -> tuple[int, int] | None:
    if not text:
        return None

    lo, hi = parse_pair(text, "--slices", integer=True, form="A:B", what="slice numbers from 0",
                        example="10:40")
    if lo > hi or lo < 0:
        raise _err(f"--slices {text!r}: need 0 <= A <= B")
    return lo, hi


def _options(args: argparse.Namespace):
    from ctui.engine.actions.segment import SegmentOptions

    return SegmentOptions(method=getattr(args, "method", "fill"), mode=args.mode, direction=args.direction,
                          connectivity=args.connectivity, neighbourhood=args.neighbourhood, min_area=args.min_area,
                          leak_factor=args.leak_factor, neck_mm=getattr(args, "neck", None),
                          fill_holes=getattr(args, "fill_holes", True), box=parse_box(getattr(args, "box", None)),
                          slices=parse_slices(getattr(args, "slices", None)),
                          keep_largest=getattr(args, "keep_largest", False), min_island=getattr(args, "min_island", 0),
                          interpolate=getattr(args, "interpolate", False), curvature=getattr(args, "curvature", 0.5),
                          server=getattr(args, "server", "") or "", api_key=getattr(args, "key", None) or "")


def _thresholds(args: argparse.Namespace) -> list:
    out = []
    for kind, value in args.thresholds or []:
        if kind == "range" and value.strip().lower() == "auto":
            out.append(None)
        elif kind == "range":
            out.append(parse_range(value))
        else:
            try:
                out.append(finite_list(value, "--tolerance", n=1)[0])
            except ValueError:
                raise _err(f"--tolerance {value!r}: expected a finite number") from None
            if out[-1] < 0:
                raise _err(f"--tolerance {value!r}: expected a number >= 0")
    return out


def segment_volume(volume, args: argparse.Namespace, *, pipeline=None, progress=None, segmentation=None,
                   object_ids=None):
    """Run the segment action for the parsed arguments; returns (Segmentation, pipeline, settings, results).

    ``results``: one dict per object (id, seed, range, stops, warnings, neck_cut_slices), as the
    JSON report and the project record them.
    """
    from ctui.engine.actions.segment import segment

    seeds = [parse_seed(s) for s in args.seed]
    prompted = getattr(args, "method", "fill") == "nninteractive"  # seeds, background seeds or a box are prompts
    if not seeds and not (prompted and (args.background or args.box)):
        raise _err("give a prompt: --seed X,Y,Z, --background X,Y,Z or --box" if prompted
                   else "give at least one --seed X,Y,Z")
    background = [parse_seed(s) for s in getattr(args, "background", [])]
    pipeline = pipeline or build_pipeline(args)
    res = segment(volume, seeds, _thresholds(args), background=background, options=_options(args), pipeline=pipeline,
                  progress=progress, segmentation=segmentation, object_ids=object_ids)
    results = [o.to_dict() | {"message": o.message()} for o in res.objects]
    return res.segmentation, res.pipeline, res.settings, results


def objects_report(seg, volume, results) -> list[dict]:
    from ctui.engine.actions.series import label_counts

    vox_ml = volume.voxel_volume_mm3() / 1000.0
    counts = label_counts(seg.labels)  # slab by slab: no int64 copy of the volume
    out = []
    for r in results:
        oid = r["id"]
        rng = seg.slice_range(oid)
        n = int(counts[oid])
        out.append({**r, "id": oid, "voxels": n, "volume_ml": round(n * vox_ml, 4),
                    "slices": None if rng is None else [int(rng[0]), int(rng[1])]})
    return out


def make_project(path: str, volume, seg, pipeline, settings: list[dict], *, series: str | None = None,
                 drift: dict | None = None, source_options: dict | None = None):
    """The project of a segmentation (the one constructor: ``actions.project.new_project``)."""
    from ctui.engine.actions.project import new_project, propagation_record

    return new_project(volume, source_path=path, source_options=source_options or ({"series": series} if series else {}),
                       pipeline=pipeline.to_dict(), labels=seg.labels, objects=seg.object_list(),
                       propagation=propagation_record(settings), drift=drift)


def write_outputs(args: argparse.Namespace, volume, seg, pipeline, settings: list[dict]) -> list[str]:
    """--project, --mask and --mric: the project by ``actions.project``, the label map and
    the contours by ``actions.export`` (what ``ctui export`` writes)."""
    written = []

    project = make_project(args.path, volume, seg, pipeline, settings, series=args.series,
                           source_options={k: v for k, v in load_kwargs(args).items() if k != "resample" or not v})
    if getattr(args, "project", None):
        from ctui.engine.actions.project import save_project

        save_project(args.project, project, inputs=[args.path])
        written.append(args.project)
    mask, mric = getattr(args, "mask", None), getattr(args, "mric", None)
    if mask or mric:
        from ctui.engine.actions.export import export
        from ctui.engine.actions.formats import LABELMAP_KINDS, format_for_path
        from ctui.engine.actions.opened import Opened

        opened = Opened.of_volume(volume, seg.labels, path=args.path, project=project)
        if mask:
            fmt = format_for_path(mask, kinds=LABELMAP_KINDS)
            if fmt is None:
                raise _err(f"--mask {mask}: a label map's name ends in .nii, .nii.gz, .nrrd or .seg.nrrd")
            export(opened, format=fmt.name, out=mask)
            written.append(mask)
        if mric:
            export(opened, format="mric", out=mric)
            written.append(mric)
    return written


def run(args: argparse.Namespace) -> int:
    import json  # 2 ms: loaded when a command prints, not for `ctui --help`

    from ctui.engine.actions.defaults import PROJECT_SUFFIXES

    check_outputs({o: getattr(args, o[2:], None) for o in ("--project", "--mask", "--mric")}, inputs=[args.path])

    if getattr(args, "refine", False):
        volume, start, ids = _refine_input(args)
    elif args.path.endswith(PROJECT_SUFFIXES) and not args.seed:
        return _edit_project(args)
    else:
        volume, start, ids = load_volume(args.path, **load_kwargs(args)), None, None
    with progress_bar(args, "segmenting") as progress:
        seg, pipeline, settings, results = segment_volume(volume, args, progress=progress, segmentation=start,
                                                          object_ids=ids)
    written = write_outputs(args, volume, seg, pipeline, settings)
    objs = objects_report(seg, volume, results)
    if args.json:
        print(json.dumps({"path": args.path, "shape_zyx": list(volume.shape), "spacing_zyx_mm": list(volume.spacing),
                          "pipeline": pipeline.to_dict(), "objects": objs, "written": written,
                          "assumptions": [a.to_dict() for a in volume.assumptions]}, indent=1))
    else:
        print(*(f"note: assumed ({a.kind}): {a}" for a in volume.assumptions), sep="\n", end="\n" * bool(volume.assumptions))
        for o in objs:
            sl = "-" if o["slices"] is None else f"{o['slices'][0]}..{o['slices'][1]}"
            print(f"object {o['id']}: {o['voxels']} voxels, {o['volume_ml']:.3f} ml, slices {sl} (numbered from 0)")
            if o.get("message"):
                print(f"  {o['message']}")
            if (o.get("auto_range") or {}).get("why"):
                print(f"  range: {o['auto_range']['why']}")
            if o.get("neck", {}).get("reason"):
                print(f"  leak guard: {o['neck']['reason']}")
            for w in o["warnings"]:
                print(f"  warning: {w}")
        for w in written:
            print(f"wrote {w}")
    return 0


def _refine_input(args: argparse.Namespace):
    """--refine: (volume, Segmentation, [object id]) from the project PATH, whose source series is loaded;
    ``args.path`` becomes the series' path (the new project's source)."""
    from ctui.engine.actions.defaults import PROJECT_SUFFIXES
    from ctui.engine.actions.opened import open_input
    from ctui.engine.actions.series import Segmentation

    if args.method != "nninteractive" or not args.path.endswith(PROJECT_SUFFIXES):
        raise _err("--refine refines an object of a .ctui project PATH with --method nninteractive")
    opened = open_input(args.path, kind="project", require_labels=True, with_series=True)
    proj = opened.project
    seg = Segmentation(opened.labels.shape, labels=opened.labels.astype("uint8", copy=True), objects=proj.objects or [])
    try:
        ids = [int(v) for v in args.objects.split(",") if v.strip()] if args.objects else sorted(seg.objects)[:1]
    except ValueError:
        raise _err(f"--objects {args.objects!r}: expected an id like 2") from None
    if not ids or ids[0] not in seg.objects:
        raise _err(f"{args.path}: no object {ids[0] if ids else ''} to refine (objects: "
                   f"{', '.join(map(str, sorted(seg.objects))) or 'none'})")
    args.path = proj.source_path
    return opened.volume, seg, ids[:1]


def _edit_project(args: argparse.Namespace) -> int:
    """``ctui segment PROJECT.ctui --interpolate|--keep-largest|--min-island N [--objects IDS] --project OUT``."""
    import json  # 2 ms: loaded when a command prints, not for `ctui --help`

    from ctui.engine.actions.opened import open_input
    from ctui.engine.actions.segment import edit_objects
    from ctui.engine.actions.series import Segmentation

    if not (args.interpolate or args.keep_largest or args.min_island):
        raise _err(f"{args.path}: a project with no --seed: give --interpolate, --keep-largest or --min-island N")
    if not args.project or args.mask or args.mric:
        raise _err("write the edited objects with --project NEW.ctui (then `ctui export` for other formats)")
    try:
        ids = [int(v) for v in args.objects.split(",") if v.strip()] if args.objects else None
    except ValueError:
        raise _err(f"--objects {args.objects!r}: expected ids like 1,3") from None
    opened = open_input(args.path, kind="project", require_labels=True, with_series=False)
    proj = opened.project
    seg = Segmentation(opened.labels.shape, labels=opened.labels.astype("uint8", copy=True), objects=proj.objects or [])
    spacing = tuple(opened.geometry.spacing) if opened.geometry is not None else (1.0, 1.0, 1.0)
    rows = edit_objects(seg, ids, spacing=spacing, interpolate=args.interpolate, keep_largest=args.keep_largest,
                        min_island=args.min_island, slices=parse_slices(args.slices))
    from ctui.engine.actions.project import save_project

    proj.labels = seg.labels
    save_project(args.project, proj)
    written = [args.project]
    if args.json:
        print(json.dumps({"path": args.path, "objects": rows, "written": written}, indent=1))
    else:
        for r in rows:
            print(f"object {r['id']}: {r['voxels_before']} -> {r['voxels']} voxels (+{r['added']} interpolated, "
                  f"-{r['removed']} in islands)")
        for w in written:
            print(f"wrote {w}")
    return 0
