"""`ctui info PATH [--json]`: what a series is, without opening the TUI."""

from __future__ import annotations

import argparse

from ctui.commands._args import command
from ctui.engine.actions.options import load_options


def add_load_options(p: argparse.ArgumentParser, *, series: bool = True) -> None:
    """Loader options shared by the commands that read a series (``series``: add --series too;
    segment and drift define their own)."""
    g = p.add_argument_group("loading")
    if series:
        g.add_argument("--series", help="DICOM series to load: index as listed by `ctui info` (0-based) or SeriesInstanceUID")
    g.add_argument("--spacing", help="voxel size dz,dy,dx in mm: image stacks and raw data (default 1 mm), "
                   "MetaImage (replaces the header's); DICOM: only dz counts, the z step of the regular grid an "
                   "unevenly spaced or tilted series is resampled onto (or the slice step when the headers give "
                   "no positions); in-plane spacing comes from the header")
    g.add_argument("--shape", help="raw data: z,y,x for one file, or y,x for one file per slice")
    g.add_argument("--dtype", help="raw data: uint8, int16, '>u2' (big-endian uint16), float32...")
    g.add_argument("--offset", type=int, help="raw data: header bytes to skip")
    g.add_argument("--crop", help="z0,z1,y0,y1,x0,x1 voxel ranges to load (end exclusive; empty = edge)")
    g.add_argument("--downsample", help="N (stride in y and x) or sz,sy,sx strides")
    g.add_argument("--no-resample", action="store_true", help="keep unevenly spaced DICOM slices as they are")
    g.add_argument("--memory", help="memory the command may use, e.g. 4G (default: CTUI_MEMORY, else what is free)")


def load_kwargs(args: argparse.Namespace) -> dict:
    """Keyword arguments for ctui.engine.io.series.load from the options above (one syntax:
    comma-separated z,y,x lists; :func:`ctui.engine.actions.options.load_options`)."""
    return load_options(series=getattr(args, "series", None), spacing=getattr(args, "spacing", None),
                        shape=getattr(args, "shape", None), dtype=getattr(args, "dtype", None),
                        offset=getattr(args, "offset", None), crop=getattr(args, "crop", None),
                        downsample=getattr(args, "downsample", None),
                        resample=not getattr(args, "no_resample", False), memory=getattr(args, "memory", None),
                        cache=getattr(args, "voxel_cache", False))


def register(subparsers: argparse._SubParsersAction) -> None:
    p = command(
        subparsers, "info", run,
        help="describe a series: shape, spacing, orientation, series, skipped files, warnings",
        description="Load PATH (DICOM folder/files, image stack, multi-page TIFF, raw, MetaImage) and "
        "print its shape, spacing, orientation, modality, value range, window, the series found, each "
        "skipped file with its reason, and warnings. Exit status 2 when nothing can be loaded.",
    )
    p.add_argument("path", nargs="+", help="folder, file(s) or glob pattern")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    add_load_options(p)


def run(args: argparse.Namespace) -> int:
    from ctui.engine.actions.info import describe_series
    from ctui.engine.core.jsonio import dumps

    path = args.path[0] if len(args.path) == 1 else list(args.path)
    vol, d = describe_series(path, **load_kwargs(args))
    if args.json:
        print(dumps(d, indent=1, ndigits=None))
        return 0
    print("\n".join(_lines(vol, d)))
    return 0


def _lines(vol, d: dict) -> list[str]:
    nz, ny, nx = vol.shape
    dz, dy, dx = vol.spacing
    lines = [
        f"source      {vol.source}",
        f"shape       {nz} x {ny} x {nx} (z, y, x)   {vol.data.dtype}",
        f"spacing     {dz:.4g} x {dy:.4g} x {dx:.4g} mm (z, y, x)",
        f"extent      {nz * dz:.1f} x {ny * dy:.1f} x {nx * dx:.1f} mm",
        f"orientation {d['orientation']}; origin {', '.join(f'{o:.2f}' for o in vol.origin)} mm (LPS)",
        f"            x axis {_vec(vol.direction[:, 0])}, y axis {_vec(vol.direction[:, 1])}, normal {_vec(vol.direction[:, 2])}",
        f"modality    {vol.modality}",
        _values_line(vol, d),
        f"window      centre {vol.window[0]:g}, width {vol.window[1]:g}",
    ]
    if vol.series:
        lines.append(f"series      {len(vol.series)} found")
        cur = vol.meta.get("series_index")
        for i, s in enumerate(vol.series):
            mark = "*" if i == cur or (cur is None and len(vol.series) == 1) else " "
            shp = "x".join(str(v) for v in s.get("shape_zyx", []))
            desc = s.get("description") or ""
            lines.append(f"  {mark}[{i}] {s.get('modality', '')} {shp} {s.get('files', '')} files "
                         f"{('‘' + desc + '’') if desc else ''} {s.get('uid', '')}".rstrip())
    objects = [sk for sk in vol.skipped if sk.get("object")]
    if objects:
        lines.append(f"non-image   {len(objects)} DICOM object(s), not volumes")
        lines += [f"  {sk['file']}: {sk['reason']}" for sk in objects[:50]]
    skipped = [sk for sk in vol.skipped if not sk.get("object")]
    if skipped:
        lines.append(f"skipped     {len(skipped)} file(s)")
        for sk in skipped[:50]:
            lines.append(f"  {sk['file']}: {sk['reason']}")
    if len(objects) > 50 or len(skipped) > 50:
        lines.append(f"  ... and {max(0, len(objects) - 50) + max(0, len(skipped) - 50)} more (--json lists all)")
    plan = d.get("memory_plan") or {}
    modes = [f"{c} {plan[c]['mode']}" for c in plan if isinstance(plan[c], dict)]  # the engine's order
    if modes:  # "cache": the voxels memory-mapped from the cache folder (ctui info --json says why)
        from ctui.engine.core.limits import fmt_bytes

        lines.append(f"memory      {', '.join(modes)} ({fmt_bytes(plan['limit_bytes'])}, {plan['limit_source']})")
    for w in vol.warnings:
        lines.append(f"warning     {w}")
    return lines


def _values_line(vol, d: dict) -> str:
    """The value range, saying when it comes from sampled slices only (DICOM: ``ctui info``
    decodes three slices, not the series)."""
    vr = d.get("value_range")
    unit = " HU" if vol.modality == "CT" else ""
    if d.get("value_range_sampled"):
        n = d.get("sampled_slices", 0)
        if not vr:
            return "values      unknown (no sampled slice could be decoded)"
        return f"values      {vr[0]:g} .. {vr[1]:g}{unit}   value range ({n} sampled slice{'s' * (n != 1)})"
    return f"values      {vr[0]:g} .. {vr[1]:g}{unit}" if vr else "values      unknown"


def _vec(v) -> str:
    return "(" + ", ".join(f"{float(x):.3f}" for x in v) + ")"
