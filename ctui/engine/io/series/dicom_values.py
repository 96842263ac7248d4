"""Plausible values of DICOM header fields (numbers, vectors, rescale, pixel spacing):
the helpers :mod:`ctui.engine.io.series.dicom_headers` reads every Frame with."""

from __future__ import annotations

from typing import Any

import numpy as np


def _num(v: Any, default: float | None = None) -> float | None:
    try:
        if v is None or v == "":
            return default
        if isinstance(v, (list, tuple)) or hasattr(v, "__len__") and not isinstance(v, (str, bytes)):
            v = v[0]
        f = float(v)
    except (TypeError, ValueError, IndexError, OverflowError):
        return default
    return f if np.isfinite(f) else default


def _slope(v: Any, default: float = 1.0) -> float:
    """RescaleSlope, or ``default`` when missing or implausible (non-finite, |slope| under
    1e-6, which zeroes every voxel, or over 1e6)."""
    f = _num(v)
    return f if f is not None and 1e-6 <= abs(f) <= 1e6 else default


def _implausible(ds: Any) -> str:
    """What :func:`_slope`, :func:`_intercept` or the PixelSpacing bounds replace ("" when nothing)."""
    out = [f"{key} {str(v)[:24]} (ignored: {d:g} used)" for key, fn, d in (("RescaleSlope", _slope, 1.0),
           ("RescaleIntercept", _intercept, 0.0)) if (v := ds.get(key)) not in (None, "") and fn(v) == d != _num(v)]
    ps = _vec(ds.get("PixelSpacing"), 2)
    if ps is not None and not _plausible_spacing(ps):
        out.append(f"PixelSpacing {[float(v) for v in ps]} (outside 0.001..1e5 mm: 1 mm used)")
    return "; ".join(out)


def _plausible_spacing(ps: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(ps)) and np.all(ps >= 1e-3) and np.all(ps <= 1e5))  # core.limits bounds


def _intercept(v: Any, default: float = 0.0) -> float:
    """RescaleIntercept, or ``default`` when missing or implausible (non-finite, > 1e7)."""
    f = _num(v)
    return f if f is not None and abs(f) <= 1e7 else default


def _int_or_none(v: Any) -> int | None:
    f = _num(v)
    return int(f) if f is not None and np.isfinite(f) and abs(f) < 2**31 else None


def _vec(v: Any, n: int) -> np.ndarray | None:
    try:
        if v is None:
            return None
        a = np.array([float(x) for x in v], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        return None
    # positions / orientations beyond a kilometre are corrupt values, not geometry
    if a.shape != (n,) or not np.all(np.isfinite(a)) or np.abs(a).max() > 1e6:
        return None
    return a
