"""Transfer-function presets for direct volume rendering.

Each preset is a list of control points ``(value, r, g, b, alpha)``; values are HU
for CT presets (``units="HU"``) or fractions of the volume's display window
(0 = window bottom, 1 = window top) for MR (``units="window"``). Alpha is the
opacity per voxel length. Shapes follow 3D Slicer's volume-rendering presets
(CT-Bone, CT-Soft-Tissue, CT-Coronary-Arteries/AAA, MR-Default), re-tuned for
ctui's shading.
"""

from __future__ import annotations

import numpy as np

from ctui.engine.core.errors import CtuiError

PRESETS: dict[str, dict] = {
    "ct-bone": {
        "units": "HU",
        "points": [(-3024, 0, 0, 0, 0.0), (-16, 0.73, 0.25, 0.30, 0.0), (200, 0.85, 0.62, 0.45, 0.12),
                   (641, 0.91, 0.82, 0.55, 0.72), (3071, 1, 1, 1, 0.71)],
    },
    "ct-soft-tissue": {
        "units": "HU",
        "points": [(-3024, 0, 0, 0, 0.0), (-400, 0.55, 0.25, 0.15, 0.0), (-100, 0.85, 0.65, 0.45, 0.02),
                   (20, 0.75, 0.32, 0.25, 0.06), (80, 0.85, 0.45, 0.38, 0.15), (300, 0.95, 0.9, 0.82, 0.45),
                   (3071, 1, 1, 1, 0.6)],
    },
    "ct-vessels": {
        "units": "HU",
        "points": [(-3024, 0, 0, 0, 0.0), (120, 0.55, 0.05, 0.05, 0.0), (200, 0.85, 0.15, 0.12, 0.35),
                   (400, 0.95, 0.55, 0.45, 0.6), (700, 0.95, 0.92, 0.85, 0.75), (3071, 1, 1, 1, 0.8)],
    },
    "mr-default": {
        "units": "window",
        "points": [(0.0, 0, 0, 0, 0.0), (0.25, 0.45, 0.3, 0.25, 0.0), (0.5, 0.8, 0.6, 0.5, 0.08),
                   (0.8, 0.95, 0.88, 0.8, 0.3), (1.0, 1, 1, 1, 0.5)],
    },
}

ALIASES = {"bone": "ct-bone", "soft": "ct-soft-tissue", "soft-tissue": "ct-soft-tissue",
           "vessels": "ct-vessels", "ct-angio": "ct-vessels", "mr": "mr-default"}


def preset_names() -> list[str]:
    return list(PRESETS)


def resolve_preset(name: str) -> str:
    key = str(name).lower().replace("_", "-")
    key = ALIASES.get(key, key)
    if key not in PRESETS:
        raise CtuiError(f"unknown transfer-function preset {name!r} (choose from {', '.join(PRESETS)})")
    return key


def transfer_table(name: str, vmin: float, vmax: float, *, window: tuple[float, float] | None = None,
                   n: int = 1024) -> np.ndarray:
    """RGBA table (n, 4) float32 for values ``vmin..vmax`` (entry i = vmin + i/(n-1)*(vmax-vmin)).

    ``window`` (centre, width) places "window"-unit presets.
    """
    p = PRESETS[resolve_preset(name)]
    pts = np.array(p["points"], dtype=np.float64)
    x = pts[:, 0]
    if p["units"] == "window":
        c, w = window if window else ((vmin + vmax) / 2.0, max(vmax - vmin, 1e-6))
        x = (c - w / 2.0) + x * w
    vals = np.linspace(vmin, vmax, n)
    out = np.empty((n, 4), np.float32)
    for k in range(4):
        out[:, k] = np.interp(vals, x, pts[:, k + 1])
    return out
