"""The one syntax of loader options (CLI flags, TUI prompts, batch files).

Lists are comma-separated in (z, y, x) order: ``--shape 40,256,256`` (or ``256,256`` per
slice), ``--spacing 2,0.5,0.5``, ``--crop z0,z1,y0,y1,x0,x1``, ``--downsample 2`` or
``1,2,2``, ``--memory 4G``. :func:`load_options` turns the text into keyword arguments for
:func:`ctui.engine.io.series.load`, with a one-line error naming the option
(``CtuiError.option``: the CLI adds its flag).
"""

from __future__ import annotations

from typing import Any

from ctui.engine.core.errors import CtuiError
from ctui.engine.core.limits import parse_memory


def _key(option: str) -> str | None:
    """The keyword an option label names ("spacing" -> "spacing"); None for a label that is
    already a CLI flag ("--range": the message names it)."""
    return None if option.startswith("-") else option.replace("-", "_")


def _items(text: str, option: str, what: str) -> list[str]:
    s = str(text).strip()
    if "x" in s.lower():
        raise CtuiError(option=_key(option),
                        message=f"{option} {text!r}: write {what} separated by commas (e.g. 40,256,256), not with 'x'")
    return [v.strip() for v in s.split(",")]


def _listed(value: Any) -> list:
    if isinstance(value, (int, float)):
        return [value]
    try:
        return list(value)
    except TypeError:
        return [value]


def parse_floats(text: Any, option: str, *, n: tuple[int, ...] = (3,), positive: bool = True) -> tuple[float, ...]:
    """``"2,0.5,0.5"`` -> (2.0, 0.5, 0.5); a list/tuple is checked the same way."""
    items = _items(text, option, "numbers") if isinstance(text, str) else _listed(text)
    try:
        vals = tuple(float(v) for v in items)
    except (TypeError, ValueError):
        raise CtuiError(option=_key(option),
                        message=f"{option} {text!r}: expected numbers separated by commas") from None
    if len(vals) not in n:
        raise CtuiError(option=_key(option), message=f"{option} {text!r}: expected {' or '.join(map(str, n))} numbers")
    if any(v != v or v in (float("inf"), float("-inf")) for v in vals) or (positive and min(vals) <= 0):
        raise CtuiError(option=_key(option),
                        message=f"{option} {text!r}: expected {'positive ' if positive else ''}finite numbers")
    return vals


def parse_ints(text: Any, option: str, *, n: tuple[int, ...], minimum: int | None = 1,
               allow_empty: bool = False) -> tuple[int | None, ...]:
    """``"40,256,256"`` -> (40, 256, 256); empty items become None when ``allow_empty``."""
    items = _items(text, option, "integers") if isinstance(text, str) else _listed(text)
    out: list[int | None] = []
    for v in items:
        if allow_empty and (v is None or str(v).strip() == ""):
            out.append(None)
            continue
        try:
            out.append(int(str(v)))
        except ValueError:
            raise CtuiError(option=_key(option),
                            message=f"{option} {text!r}: expected integers separated by commas") from None
    if len(out) not in n:
        raise CtuiError(option=_key(option), message=f"{option} {text!r}: expected {' or '.join(map(str, n))} integers")
    if minimum is not None and any(v is not None and v < minimum for v in out):
        raise CtuiError(option=_key(option), message=f"{option} {text!r}: every value must be >= {minimum}")
    return tuple(out)


def parse_pair(text: Any, option: str, *, integer: bool = False, form: str = "LO:HI", what: str = "",
               example: str = "") -> tuple[float, float] | tuple[int, int]:
    """``"LO:HI"`` -> (lo, hi): numbers, or whole numbers when ``integer``; a one-line error
    naming ``option`` ("expected LO:HI (numbers), e.g. 150:300") otherwise. The order is not checked."""
    a, sep, b = str(text).partition(":")
    conv = int if integer else float
    try:
        if not sep:
            raise ValueError
        lo, hi = conv(a), conv(b)
    except ValueError:
        what = what or ("whole numbers" if integer else "numbers")
        eg = f", e.g. {example}" if example else ""
        raise CtuiError(f"{option} {text!r}: expected {form} ({what}){eg}", option=_key(option)) from None
    return lo, hi


def load_options(*, series: Any = None, spacing: Any = None, shape: Any = None, dtype: Any = None,
                 offset: Any = None, crop: Any = None, downsample: Any = None, resample: bool = True,
                 memory: Any = None, cache: bool = False) -> dict:
    """Keyword arguments for ``ctui.engine.io.series.load`` from option text. ``cache``: load
    through the memory-mapped voxel cache (``io/voxcache``; the memory plan's "cache"). ``memory``
    (``4G``, ``512M``, bytes) -> ``memory_limit`` bytes: the loader's and the memory plan's
    limit (``io/memplan``; else ``CTUI_MEMORY``, else what is available)."""
    kw: dict[str, Any] = {}
    if series not in (None, ""):
        s = str(series).strip()
        kw["series"] = int(s) if s.isdigit() and len(s) < 6 else s
    if spacing not in (None, ""):
        vals = parse_floats(spacing, "spacing", n=(1, 3))
        kw["spacing"] = vals * 3 if len(vals) == 1 else vals
    if shape not in (None, ""):
        kw["shape"] = parse_ints(shape, "shape", n=(2, 3))
    if dtype not in (None, ""):
        kw["dtype"] = str(dtype)
    if offset is not None:
        if int(offset) < 0:
            raise CtuiError(f"offset {offset}: must be >= 0", option="offset")
        kw["offset"] = int(offset)
    if crop not in (None, ""):
        kw["crop"] = parse_ints(crop, "crop", n=(6,), minimum=None, allow_empty=True)
    if downsample not in (None, ""):
        steps = parse_ints(downsample, "downsample", n=(1, 3))
        kw["downsample"] = steps[0] if len(steps) == 1 else steps
    if not resample:
        kw["resample"] = False
    if memory not in (None, ""):
        kw["memory_limit"] = parse_memory(memory)
    if cache:
        kw["cache"] = True
    return kw
