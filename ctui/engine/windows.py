"""Display windows (centre, width) and conversion of slices to 8-bit for display.

Placeholder core; the loader helper extends presets. Kept free of heavy imports.
"""

from __future__ import annotations

import numpy as np

# (centre, width) in HU
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


def auto_window(data: np.ndarray, *, modality: str = "OT", percentiles: tuple[float, float] = (0.5, 99.5)) -> tuple[float, float]:
    """Default window: abdomen for CT, a percentile window otherwise.

    Parameters
    ----------
    data : ndarray, any shape
    modality : str
    percentiles : (low, high) percentiles used for non-CT data.

    Returns
    -------
    (centre, width) in the data's units.
    """
    if modality == "CT":
        return CT_PRESETS["abdomen"]
    if data.size == 0:
        return (0.0, 1.0)
    sample = data
    if data.size > 2_000_000:  # a strided sample is plenty for percentiles
        step = int(np.ceil((data.size / 2_000_000) ** (1 / 3)))
        sample = data[::step, ::step, ::step] if data.ndim == 3 else data.ravel()[:: step**3]
    lo, hi = np.percentile(sample, percentiles)
    width = float(max(hi - lo, 1e-6))
    return (float(lo + hi) / 2.0, width)


def apply_window(image: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    """Map values to uint8 through a (centre, width) window. Same shape as ``image``."""
    centre, width = window
    lo = centre - width / 2.0
    scale = 255.0 / max(width, 1e-6)
    out = (image.astype(np.float32) - np.float32(lo)) * np.float32(scale)
    np.clip(out, 0, 255, out=out)
    return out.astype(np.uint8)
