"""``ctui auto SERIES --engine totalsegmentator [--task T] [--roi-subset A,B] [--fast] [--device cpu|gpu]``.

Runs the user's TotalSegmentator on the series (``actions.auto.auto_segment``) and writes its
classes as named objects into a project (``--project``, default ``<series stem>-auto.ctui``);
a .ctui PATH merges them into that project's objects (``--merge add|replace|keep``).
"""

from __future__ import annotations

import argparse

from ctui.commands._args import command
from ctui.commands._progress import progress_bar
from ctui.commands.info import add_load_options, load_kwargs
from ctui.engine.core.atomic import check_outputs
from ctui.engine.core.errors import CtuiError


class _Choices:
    """A registry of ``actions.auto`` as argparse choices, read when argparse checks them (``ctui --help``
    must not import numpy)."""

    def __init__(self, name: str) -> None:
        self.name = name

    def _names(self) -> tuple[str, ...]:
        from ctui.engine.actions import auto  # numpy: read only when the command runs or its help is shown

        return tuple(getattr(auto, self.name))

    def __iter__(self):
        return iter(self._names())

    def __contains__(self, name: object) -> bool:
        return name in self._names()


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions import defaults  # plain constants: --help stays fast

    p = command(
        subparsers, "auto", run,
        help="a first draft from TotalSegmentator (where installed): its classes as named objects",
        description="Run TotalSegmentator (installed by you, with its weights: ctui downloads nothing) on the "
        "series and import its classes as named objects on the series' grid, ready to edit, measure, mesh and "
        "export. A .ctui PATH merges them into its objects by --merge.",
        epilog="Example: ctui auto ct.nii.gz --engine totalsegmentator --roi-subset liver,spleen,kidney_left "
               "--fast --project ct-auto.ctui",
    )
    p.add_argument("path", help="series folder/file (anything `ctui open` loads), or a .ctui project to add to")
    p.add_argument("--engine", choices=_Choices("ENGINES"), default=defaults.AUTO_ENGINE, metavar="ENGINE",
                   help="the model to run: totalsegmentator (default)")
    p.add_argument("--task", default=defaults.AUTO_TASK, metavar="TASK",
                   help="TotalSegmentator's task (default total: 117 CT classes; total_mr for MR; licensed tasks "
                        "need its licence number)")
    p.add_argument("--roi-subset", default="", metavar="NAME,...",
                   help="only these classes, e.g. liver,spleen,kidney_left (TotalSegmentator's --roi_subset)")
    p.add_argument("--fast", action="store_true", help="TotalSegmentator's 3 mm model (about a minute on a CPU)")
    p.add_argument("--device", choices=_Choices("DEVICES"), default=defaults.AUTO_DEVICE, metavar="cpu|gpu",
                   help="where the model runs (default %(default)s)")
    p.add_argument("--merge", choices=_Choices("MERGE"), default=defaults.AUTO_MERGE, metavar="add|replace|keep",
                   help="with a .ctui PATH: add (default: new objects, existing voxels stay theirs), replace "
                        "(a class named like an object replaces it), keep (such a class is skipped)")
    p.add_argument("--project", metavar="OUT.ctui", help="the project to write (default <stem>-auto.ctui)")
    p.add_argument("--json", action="store_true", help="print a JSON report")
    p.add_argument("--series", default=None, help="SeriesInstanceUID (or index) when PATH holds several series")
    add_load_options(p, series=False)


def _input(args: argparse.Namespace):
    """(volume, labels or None, objects, source path, source options) of PATH."""
    from ctui.engine.actions.defaults import PROJECT_SUFFIXES
    from ctui.engine.actions.opened import open_input

    if args.path.endswith(PROJECT_SUFFIXES):
        opened = open_input(args.path, kind="project", with_series=True)
        proj = opened.project
        return opened.volume, opened.labels, list(proj.objects or []), proj.source_path, dict(proj.source_options or {})
    opts = {**load_kwargs(args), **({"series": args.series} if args.series else {})}
    opened = open_input(args.path, kind="series", **opts)
    return opened.volume, None, [], args.path, {k: v for k, v in load_kwargs(args).items() if k != "resample" or not v}


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.auto import auto_segment
    from ctui.engine.actions.formats import output_name
    from ctui.engine.actions.project import new_project, save_project
    from ctui.engine.core.jsonio import dumps

    out = args.project or output_name(args.path, ".ctui", tag="auto")
    check_outputs({"--project": out}, inputs=[args.path])
    subset = [n.strip() for n in args.roi_subset.split(",") if n.strip()]
    volume, labels, objects, source, source_options = _input(args)
    with progress_bar(args, "TotalSegmentator") as progress:
        res = auto_segment(volume, engine=args.engine, task=args.task, roi_subset=subset, fast=args.fast,
                           device=args.device, labels=labels, objects=objects, merge=args.merge, progress=progress)
    if not res.added and not res.skipped:
        raise CtuiError(f"TotalSegmentator found none of the classes asked for in {args.path}")
    project = new_project(volume, source_path=source, source_options=source_options, labels=res.labels,
                          objects=res.objects)
    save_project(out, project, inputs=[args.path])
    if args.json:
        print(dumps({**res.to_dict(), "written": [out]}, indent=1))
        return 0
    for o in res.added:
        print(f"object {o['id']}: {o['name']}, {o['voxels']} voxels, {o['volume_ml']:.3f} ml")
    for s in res.skipped:
        print(f"  skipped {s}")
    for w in res.warnings:
        print(f"  note: {w}")
    print(f"wrote {out} ({len(res.added)} objects from TotalSegmentator {res.task} in {res.seconds:.0f} s)")
    return 0
