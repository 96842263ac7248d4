"""The one way ctui turns results into JSON.

:func:`to_jsonable` converts dataclasses, numpy scalars/arrays, tuples, paths and
non-finite floats (-> ``None``) into plain JSON values, rounding floats to ``ndigits``
significant decimals (default 6) so every command and file reports numbers the same way.
"""

from __future__ import annotations

import dataclasses
import json
import math
from enum import Enum
from pathlib import PurePath
from typing import Any

import numpy as np

NDIGITS = 6


def _float(x: float | np.floating, ndigits: int | None) -> float | None:
    x = float(x)
    if not math.isfinite(x):
        return None
    return round(x, ndigits) if ndigits is not None else x


def to_jsonable(obj: Any, *, ndigits: int | None = NDIGITS, strict: bool = False) -> Any:
    """A JSON-ready copy of ``obj`` (NaN/inf become null).

    ``ndigits=None`` keeps floats exact (files that must round-trip); ``strict`` raises
    TypeError for a value with no JSON form instead of storing its ``str()``.
    """
    kw: dict[str, Any] = {"ndigits": ndigits, "strict": strict}
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return _float(obj, ndigits)
    if isinstance(obj, Enum):
        return to_jsonable(obj.value, **kw)
    if isinstance(obj, PurePath):
        return str(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        if hasattr(obj, "to_dict"):
            return to_jsonable(obj.to_dict(), **kw)
        return {f.name: to_jsonable(getattr(obj, f.name), **kw)
                for f in dataclasses.fields(obj) if not f.name.startswith("_")}
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist(), **kw)
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v, **kw) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [to_jsonable(v, **kw) for v in obj]
    if hasattr(obj, "to_dict"):
        return to_jsonable(obj.to_dict(), **kw)
    if strict:
        raise TypeError(f"a {type(obj).__name__} has no JSON form")
    return str(obj)


def dumps(obj: Any, *, ndigits: int | None = NDIGITS, indent: int | None = None, sort_keys: bool = False) -> str:
    """``json.dumps(to_jsonable(obj))``: strict JSON (no NaN)."""
    return json.dumps(to_jsonable(obj, ndigits=ndigits), indent=indent, sort_keys=sort_keys, allow_nan=False)
