"""Display windows (centre, width) and conversion of slices to 8-bit for display.

* CT presets (Hounsfield units) with the usual centre/width: brain, subdural, stroke,
  bone, lung, abdomen / soft tissue, liver, mediastinum;
* the DICOM header's window (WindowCenter/WindowWidth, first of several values);
* an automatic percentile window for MR and plain images (0.5 - 99.5 percentiles).

Kept free of heavy imports (numpy only).
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

# (centre, width) in HU. Sources: common radiology practice (e.g. Radiopaedia "CT windows").
CT_PRESETS: dict[str, tuple[float, float]] = {
    "brain": (40.0, 80.0),
    "subdural": (75.0, 215.0),
    "stroke": (40.0, 40.0),
    "bone": (400.0, 1800.0),
    "lung": (-600.0, 1500.0),
    "abdomen": (40.0, 400.0),
    "soft_tissue": (50.0, 350.0),
    "liver": (60.0, 150.0),
    "mediastinum": (50.0, 350.0),
}
# order for cycling through presets in the TUI
PRESET_ORDER: tuple[str, ...] = tuple(CT_PRESETS)
_ALIASES = {"soft tissue": "soft_tissue", "soft-tissue": "soft_tissue", "softtissue": "soft_tissue", "abdominal": "abdomen",
            "abd": "abdomen", "mediastinal": "mediastinum", "mediastinum": "mediastinum", "bones": "bone"}


def preset(name: str) -> tuple[float, float]:
    """CT preset (centre, width) in HU by name (case-insensitive; 'soft tissue' etc. accepted).

    Raises KeyError naming the known presets.
    """
    key = str(name).strip().lower()
    key = _ALIASES.get(key, key.replace(" ", "_").replace("-", "_"))
    if key not in CT_PRESETS:
        raise KeyError(f"unknown window preset {name!r}; known: {', '.join(CT_PRESETS)}")
    return CT_PRESETS[key]


def header_window(centre: Any, width: Any) -> tuple[float, float] | None:
    """The DICOM header window: WindowCenter/WindowWidth values (numbers, strings or
    multi-valued lists, of which the first is used) -> (centre, width), or None when
    absent or invalid (width <= 0)."""

    def first(v: Any) -> float | None:
        if v is None:
            return None
        if isinstance(v, str):
            v = v.split("\\")[0]
        elif not isinstance(v, (int, float, np.number)):
            try:
                v = list(v)[0]
            except (TypeError, IndexError):
                return None
        try:
            f = float(v)
        except (TypeError, ValueError):
            return None
        return f if np.isfinite(f) else None

    c, w = first(centre), first(width)
    if c is None or w is None or w <= 0:
        return None
    return (c, w)


def percentile_window(data: np.ndarray, percentiles: tuple[float, float] = (0.5, 99.5), *, max_samples: int = 2_000_000) -> tuple[float, float]:
    """Window spanning the given percentiles of ``data`` (any shape); a strided sample
    of at most ``max_samples`` values is used for big volumes."""
    if data.size == 0:
        return (0.0, 1.0)
    sample = data
    if data.size > max_samples:
        if data.ndim == 3:
            step = int(np.ceil((data.size / max_samples) ** (1 / 3)))
            sample = data[::step, ::step, ::step]
        else:
            sample = data.ravel()[:: int(np.ceil(data.size / max_samples))]
    sample = np.asarray(sample)
    if sample.dtype.kind == "f":
        sample = sample[np.isfinite(sample)]
        if sample.size == 0:
            return (0.0, 1.0)
    lo, hi = np.percentile(sample, percentiles)
    width = float(max(hi - lo, 1e-6))
    return (float(lo + hi) / 2.0, width)


def auto_window(
    data: np.ndarray,
    *,
    modality: str = "OT",
    percentiles: tuple[float, float] = (0.5, 99.5),
    header: tuple[float, float] | None = None,
) -> tuple[float, float]:
    """Default window: the header's window when given, else abdomen / soft tissue
    (40, 400) for CT, else a percentile window (MR, plain images).

    Parameters
    ----------
    data : ndarray, any shape
    modality : str
    percentiles : (low, high) percentiles used for non-CT data.
    header : (centre, width) from the DICOM header, optional.

    Returns
    -------
    (centre, width) in the data's units.
    """
    if header is not None and header[1] > 0:
        return (float(header[0]), float(header[1]))
    if modality == "CT":
        return CT_PRESETS["abdomen"]
    return percentile_window(data, percentiles)


_CT_WORDS = ("ct", "computed tomograph", "hounsfield", "hu", "cta", "pet-ct", "pet/ct")


def ct_hint(text: str) -> bool:
    """Whether a free-text header field (NIfTI descrip/intent_name, NRRD content,
    MetaImage Modality) names CT or Hounsfield units."""
    words = re.findall(r"[a-z/-]+", str(text).lower())
    joined = " ".join(words)
    return any(w in _CT_WORDS for w in words) or "computed tomograph" in joined or "hounsfield" in joined


def looks_like_ct(data: np.ndarray, *, max_samples: int = 400_000) -> bool:
    """Whether voxel values look like CT in Hounsfield units: air near -1000 HU (or
    padding at -1024..-3024), soft tissue near 0 HU and almost nothing outside
    -3100..4000. A strided sample of at most ``max_samples`` values of ``data`` (any
    shape) is looked at. Label maps, MR and plain images (no negative air) fail."""
    if data.size == 0 or data.dtype.kind not in "if":
        return False
    step = int(np.ceil(data.size / max_samples)) if data.size > max_samples else 1
    s = np.asarray(data).ravel()[::step]
    if s.dtype.kind == "f":
        s = s[np.isfinite(s)]
        if s.size == 0:
            return False
    s = s.astype(np.float32)
    lo, hi = float(s.min()), float(np.percentile(s, 99.9))
    if lo < -3100 or lo > -900 or hi > 4000:
        return False
    air = float(np.mean((s >= -1100) & (s <= -850))) + float(np.mean(s < -1100))
    soft = float(np.mean((s >= -150) & (s <= 150)))
    return air >= 0.01 and soft >= 0.02


def window_range(window: tuple[float, float]) -> tuple[float, float]:
    """(centre, width) -> (low, high) values."""
    c, w = window
    return (c - w / 2.0, c + w / 2.0)


def window_from_range(lo: float, hi: float) -> tuple[float, float]:
    """(low, high) -> (centre, width)."""
    return ((lo + hi) / 2.0, max(hi - lo, 1e-6))


def apply_window(image: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    """Map values to uint8 through a (centre, width) window. Same shape as ``image``."""
    centre, width = window
    lo = centre - width / 2.0
    scale = 255.0 / max(width, 1e-6)
    out = (image.astype(np.float32) - np.float32(lo)) * np.float32(scale)
    np.clip(out, 0, 255, out=out)
    return out.astype(np.uint8)
