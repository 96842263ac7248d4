"""`ctui info PATH [--json]`: what a series is, without opening the TUI."""

from __future__ import annotations

import argparse


def add_load_options(p: argparse.ArgumentParser) -> None:
    """Loader options shared by the commands that read a series."""
    g = p.add_argument_group("loading")
    g.add_argument("--series", help="DICOM series to load: index as listed by `ctui info` (0-based) or SeriesInstanceUID")
    g.add_argument("--spacing", help="voxel size dz,dy,dx in mm (image stacks, raw; default 1 mm)")
    g.add_argument("--shape", help="raw data: z,y,x for one file, or y,x for one file per slice")
    g.add_argument("--dtype", help="raw data: uint8, int16, '>u2' (big-endian uint16), float32...")
    g.add_argument("--offset", type=int, help="raw data: header bytes to skip")
    g.add_argument("--crop", help="z0,z1,y0,y1,x0,x1 voxel ranges to load (end exclusive; empty = edge)")
    g.add_argument("--downsample", help="N (stride in y and x) or sz,sy,sx strides")
    g.add_argument("--no-resample", action="store_true", help="keep unevenly spaced DICOM slices as they are")


def load_kwargs(args: argparse.Namespace) -> dict:
    """Keyword arguments for ctui.engine.io.series.load from the options above."""
    from ctui.engine.core.errors import CtuiError

    kw: dict = {}
    if getattr(args, "series", None) not in (None, ""):
        s = str(args.series).strip()
        kw["series"] = int(s) if s.isdigit() and len(s) < 6 else s
    for name in ("spacing", "shape", "dtype", "offset"):
        v = getattr(args, name, None)
        if v is not None:
            kw[name] = v
    crop = getattr(args, "crop", None)
    if crop:
        parts = crop.split(",")
        if len(parts) != 6:
            raise CtuiError(f"--crop needs six values z0,z1,y0,y1,x0,x1 (empty for an edge), got {crop!r}")
        try:
            kw["crop"] = tuple(int(v) if v.strip() else None for v in parts)
        except ValueError:
            raise CtuiError(f"--crop values must be integers, got {crop!r}") from None
    ds = getattr(args, "downsample", None)
    if ds:
        try:
            vals = [int(v) for v in ds.split(",")]
        except ValueError:
            raise CtuiError(f"--downsample must be N or sz,sy,sx integers, got {ds!r}") from None
        kw["downsample"] = vals[0] if len(vals) == 1 else tuple(vals)
    if getattr(args, "no_resample", False):
        kw["resample"] = False
    return kw


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "info",
        help="describe a series: shape, spacing, orientation, series, skipped files, warnings",
        description="Load PATH (DICOM folder/files, image stack, multi-page TIFF, raw, MetaImage) and "
        "print its shape, spacing, orientation, modality, value range, window, the series found, each "
        "skipped file with its reason, and warnings. Exit status 2 when nothing can be loaded.",
    )
    p.add_argument("path", nargs="+", help="folder, file(s) or glob pattern")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    add_load_options(p)
    p.set_defaults(func=run)


def orientation_name(direction) -> str:
    """'axial', 'coronal', 'sagittal' or 'oblique' from the slice normal (direction[:, 2])."""
    n = [abs(float(v)) for v in (direction[0][2], direction[1][2], direction[2][2])]
    k = max(range(3), key=lambda i: n[i])
    name = ("sagittal", "coronal", "axial")[k]
    return name if n[k] > 0.995 else f"oblique (near {name})"


def run(args: argparse.Namespace) -> int:
    import json

    from ctui.engine.io.series import load

    path = args.path[0] if len(args.path) == 1 else list(args.path)
    vol = load(path, **load_kwargs(args))
    d = vol.describe()
    d["orientation"] = orientation_name(vol.direction)
    d["value_range"] = [float(v) for v in d["value_range"]]
    if vol.slice_positions is not None:
        d["slice_positions_mm"] = [round(float(v), 4) for v in vol.slice_positions]
    d["meta"] = {k: v for k, v in vol.meta.items() if isinstance(v, (str, int, float, bool, list, dict))}
    if args.json:
        print(json.dumps(d, indent=1, default=str))
        return 0
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
        f"values      {d['value_range'][0]:g} .. {d['value_range'][1]:g}" + (" HU" if vol.modality == "CT" else ""),
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
    if vol.skipped:
        lines.append(f"skipped     {len(vol.skipped)} file(s)")
        for sk in vol.skipped[:50]:
            lines.append(f"  {sk['file']}: {sk['reason']}")
        if len(vol.skipped) > 50:
            lines.append(f"  ... and {len(vol.skipped) - 50} more (--json lists all)")
    for w in vol.warnings:
        lines.append(f"warning     {w}")
    print("\n".join(lines))
    return 0


def _vec(v) -> str:
    return "(" + ", ".join(f"{float(x):.3f}" for x in v) + ")"
