"""The one schema of ``project.json`` (format ``ctui-project``) and its validation.

Version 2 (written by this ctui)::

    {"format": "ctui-project", "version": 2,
     "source_path": str,                       # "" = no series (labels-only project)
     "source_options": {series, spacing, shape, dtype, offset, crop, downsample, resample},
     "geometry": {"shape_zyx": [nz, ny, nx], "spacing_zyx_mm": [dz, dy, dx],
                  "origin_xyz_mm": [x, y, z], "direction": [[3], [3], [3]]} | null,
     "modality": str | null, "series_uid": str | null,
     "voxel_hash": "blake2b-128:<hex>" | null,  # identity of the source voxels
     "window": [centre, width] | null,
     "pipeline": {...},                        # Pipeline.to_dict()
     "objects": [{"id": 1..255, "name": str, "color": [r, g, b], ...}],
     "propagation": {low, high, tolerance, range, direction, connectivity, neighbourhood,
                     min_area, leak_factor, mode, current, per_object: [{...}]},
     "drift": {...}, "meta": {...},
     "labels": {"member": "labels.npy", "shape": [nz, ny, nx], "dtype": "uint8"} | null}

Version 1 (no ``geometry``/identity; the geometry may sit in ``meta`` as
``spacing_zyx_mm``/``origin_xyz_mm``/``direction``) and files with no ``version`` still
open. :func:`validate` checks every field's type, length and finiteness and raises
:class:`~ctui.engine.core.errors.FormatError` naming the file and the field.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ctui.engine.core.errors import CtuiError, FormatError
from ctui.engine.core.geometry import Geometry

FORMAT_NAME = "ctui-project"
FORMAT_VERSION = 2
MAX_TEXT = 4096
#: The propagation keys every writer (CLI and TUI) uses, with their JSON types.
PROPAGATION_KEYS: dict[str, tuple] = {
    "low": (int, float), "high": (int, float), "tolerance": (int, float), "leak_factor": (int, float),
    "connectivity": (int,), "neighbourhood": (int,), "min_area": (int,), "current": (int,),
    "direction": (str,), "mode": (str,), "range": (list, type(None)), "per_object": (list,),
    "leak_min_pixels": (int,), "on_leak": (str,), "confine": (bool,), "overwrite": (bool,),
    "max_slices": (int,), "neck_mm": (int, float), "slices": (list,),
    "neck_rule": (str,), "fill_holes": (bool,), "box": (list,),
}
#: Loader options a project may record (see ctui.engine.io.series.load).
SOURCE_OPTION_KEYS = ("series", "spacing", "shape", "dtype", "offset", "crop", "downsample", "resample")


class _Bad(Exception):
    def __init__(self, field: str, msg: str) -> None:
        super().__init__(f"{field}: {msg}")


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _finite_everywhere(v: Any, where: str, depth: int = 0) -> None:
    """No NaN/inf anywhere (json.loads accepts NaN and Infinity tokens)."""
    if depth > 64:
        raise _Bad(where, "nested too deeply")
    if isinstance(v, float) and not math.isfinite(v):
        raise _Bad(where, f"not a finite number ({v})")
    if isinstance(v, dict):
        for k, x in v.items():
            _finite_everywhere(x, f"{where}.{k}" if where else str(k), depth + 1)
    elif isinstance(v, list):
        for i, x in enumerate(v):
            _finite_everywhere(x, f"{where}[{i}]", depth + 1)


def _numbers(v: Any, field: str, n: tuple[int, ...], *, positive: bool = False, integer: bool = False) -> None:
    if not isinstance(v, list) or len(v) not in n:
        raise _Bad(field, f"expected a list of {' or '.join(map(str, n))} numbers, got {_short(v)}")
    for x in v:
        if not (_is_int(x) if integer else _is_num(x)):
            raise _Bad(field, f"expected {'integers' if integer else 'numbers'}, got {_short(v)}")
        if positive and x <= 0:
            raise _Bad(field, f"every value must be > 0, got {_short(v)}")


def _short(v: Any) -> str:
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


def _text(v: Any, field: str, *, optional: bool = True, limit: int = MAX_TEXT) -> None:
    if v is None and optional:
        return
    if not isinstance(v, str):
        raise _Bad(field, f"expected text, got {_short(v)}")
    if len(v) > limit:
        raise _Bad(field, f"text longer than {limit} characters")


def _source_options(opts: dict) -> None:
    for key, v in opts.items():
        f = f"source_options.{key}"
        if v is None:
            continue
        if key == "series":
            if not (_is_int(v) or isinstance(v, str)):
                raise _Bad(f, f"expected an index or a SeriesInstanceUID, got {_short(v)}")
        elif key == "spacing":
            if _is_num(v):
                if v <= 0:
                    raise _Bad(f, "must be > 0")
            elif not isinstance(v, str):
                _numbers(v, f, (1, 3), positive=True)
        elif key == "shape":
            if not isinstance(v, str):
                _numbers(v, f, (2, 3), positive=True, integer=True)
        elif key == "dtype":
            _text(v, f, limit=32)
        elif key == "offset":
            if not _is_int(v) or v < 0:
                raise _Bad(f, f"expected an integer >= 0, got {_short(v)}")
        elif key == "crop":
            if not isinstance(v, list) or len(v) != 6 or not all(x is None or _is_int(x) for x in v):
                raise _Bad(f, f"expected six integers or nulls, got {_short(v)}")
        elif key == "downsample":
            if _is_int(v):
                if v < 1:
                    raise _Bad(f, "must be >= 1")
            else:
                _numbers(v, f, (3,), positive=True, integer=True)
        elif key == "resample":
            if not isinstance(v, bool):
                raise _Bad(f, f"expected true or false, got {_short(v)}")


def _propagation(prop: dict, field: str = "propagation") -> None:
    for key, types in PROPAGATION_KEYS.items():
        if key not in prop or prop[key] is None and key != "range":
            continue
        v = prop[key]
        f = f"{field}.{key}"
        if not isinstance(v, types) or (isinstance(v, bool) and bool not in types):
            raise _Bad(f, f"expected {'/'.join(t.__name__ for t in types)}, got {_short(v)}")
        if key == "range" and v is not None:
            _numbers(v, f, (2,))
        if key == "connectivity" and v not in (4, 6, 8, 18, 26):
            raise _Bad(f, f"expected 4 or 8, got {v}")
        if key == "slices":
            _numbers(v, f, (2,), integer=True)
        if key in ("direction", "mode", "on_leak", "neck_rule"):
            _text(v, f, limit=32)
        if key == "box":
            if len(v) != 3 or not all(isinstance(r, list) for r in v):
                raise _Bad(f, f"expected three [first, last] slice/row/column ranges, got {_short(v)}")
            for r in v:
                _numbers(r, f, (2,), integer=True)
        if key == "per_object":
            if field != "propagation":
                raise _Bad(f, "nested per_object")
            for i, d in enumerate(v):
                if not isinstance(d, dict):
                    raise _Bad(f"{f}[{i}]", "expected an object")
                _propagation(d, f"{f}[{i}]")


def _objects(objs: list) -> None:
    seen = set()
    for i, o in enumerate(objs):
        f = f"objects[{i}]"
        if not isinstance(o, dict):
            raise _Bad(f, f"expected an object, got {_short(o)}")
        oid = o.get("id")
        if not _is_int(oid) or not 1 <= oid <= 255:
            raise _Bad(f"{f}.id", f"expected an integer 1..255, got {_short(oid)}")
        if oid in seen:
            raise _Bad(f"{f}.id", f"object {oid} listed twice")
        seen.add(oid)
        _text(o.get("name"), f"{f}.name", limit=256)
        c = o.get("color")
        if c is not None:
            _numbers(c, f"{f}.color", (3,))
            if min(c) < 0 or max(c) > 255:
                raise _Bad(f"{f}.color", f"expected 0..255, got {_short(c)}")
        seeds = o.get("seeds")
        if seeds is not None:
            if not isinstance(seeds, list):
                raise _Bad(f"{f}.seeds", "expected a list of [x, y, z]")
            for s in seeds:
                _numbers(s, f"{f}.seeds", (3,))


def _window(w: Any) -> None:
    if w is None:
        return
    _numbers(w, "window", (2,))
    if w[1] <= 0:
        raise _Bad("window", f"width must be > 0, got {w[1]}")


def legacy_geometry(meta: dict, shape: list | None) -> dict | None:
    """Version 1: the geometry some writers kept in ``meta`` (spacing_zyx_mm...)."""
    m = meta.get("meta")
    if not isinstance(m, dict) or m.get("spacing_zyx_mm") is None or shape is None:
        return None
    return {"shape_zyx": shape, "spacing_zyx_mm": m.get("spacing_zyx_mm"),
            "origin_xyz_mm": m.get("origin_xyz_mm", [0.0, 0.0, 0.0]), "direction": m.get("direction")}


def geometry_of(meta: dict, labels_shape: list | None) -> Geometry | None:
    """The validated Geometry of a project.json (None when it records none)."""
    g = meta.get("geometry")
    where = "geometry"
    if g is None:
        g = legacy_geometry(meta, labels_shape)
        where = "meta"
        if g is None:
            return None
    if not isinstance(g, dict):
        raise _Bad("geometry", f"expected an object, got {_short(g)}")
    shape = g.get("shape_zyx")
    if not (isinstance(shape, list) and len(shape) == 3 and all(_is_int(s) and s >= 1 for s in shape)):
        raise _Bad(f"{where}.shape_zyx", f"expected three integers >= 1, got {_short(shape)}")
    _numbers(g.get("spacing_zyx_mm"), f"{where}.spacing_zyx_mm", (3,), positive=True)
    _numbers(g.get("origin_xyz_mm", [0, 0, 0]), f"{where}.origin_xyz_mm", (3,))
    d = g.get("direction")
    if d is not None:
        if not (isinstance(d, list) and len(d) == 3):
            raise _Bad(f"{where}.direction", "expected a 3x3 matrix")
        for row in d:
            _numbers(row, f"{where}.direction", (3,))
    try:
        geom = Geometry.from_dict(g)
    except CtuiError as exc:
        raise _Bad(where, str(exc)) from None
    if labels_shape is not None and list(geom.shape) != list(labels_shape):
        raise _Bad(f"{where}.shape_zyx", f"{list(geom.shape)} does not match the labels {list(labels_shape)}")
    return geom


def validate(meta: Any, path: str | Path) -> tuple[int, Geometry | None]:
    """Check a decoded project.json; returns (version, geometry or None).

    The labels entry itself (shape, member) is checked by the reader; its shape is used
    here to check the geometry. Raises FormatError "<path>: not a valid ctui project:
    <field>: <fault>".
    """
    def bad(msg: str) -> FormatError:
        return FormatError(f"{path}: not a valid ctui project: {msg}")

    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise bad("not a ctui project file")
    version = meta.get("version", 1)  # projects written before versions existed
    if not _is_int(version) or version < 1:
        raise bad(f"version: bad version {_short(version)}")
    if version > FORMAT_VERSION:
        raise FormatError(f"{path}: project format version {version} is newer than this ctui supports "
                          f"({FORMAT_VERSION}); update ctui")
    try:
        _finite_everywhere(meta, "")
        for key, typ in (("source_options", dict), ("pipeline", dict), ("objects", list), ("propagation", dict),
                         ("drift", dict), ("meta", dict)):
            v = meta.get(key)
            if v is not None and not isinstance(v, typ):
                raise _Bad(key, f"must be a {typ.__name__}, got {_short(v)}")
        _text(meta.get("source_path", ""), "source_path", optional=False)
        for key in ("modality", "series_uid", "voxel_hash"):
            _text(meta.get(key), key, limit=256)
        _source_options(meta.get("source_options") or {})
        _objects(meta.get("objects") or [])
        _propagation(meta.get("propagation") or {})
        _window(meta.get("window"))
        lab = meta.get("labels")
        shape = lab.get("shape") if isinstance(lab, dict) else None
        ok_shape = isinstance(shape, list) and len(shape) == 3 and all(_is_int(s) for s in shape)
        geom = geometry_of(meta, shape if ok_shape else None)
    except _Bad as exc:
        raise bad(str(exc)) from None
    return version, geom
