"""Tiny line plots drawn straight into an RGB array (OpenCV), for the terminal.

At half-block resolution (a 120x60-pixel panel) matplotlib's text is unreadable and
costs ~1 s; the TUI draws lines, points and bands itself and prints axis figures as
text beside the picture. (The engine's PNG plots, drawn with matplotlib, are what
``ctui drift --plot`` / ``ctui measure --plot`` and the export write.)
"""

from __future__ import annotations

import cv2
import numpy as np


def line_plot(
    size: tuple[int, int],
    series: list[dict],
    *,
    bands: list[float] | None = None,
    hlines: list[float] | None = None,
    xlim: tuple[float, float] | None = None,
    ylim: tuple[float, float] | None = None,
    background=(12, 12, 16),
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """Draw series into an (h, w, 3) uint8 image.

    series: dicts ``{x, y, color (r,g,b), points: bool, dim: bool}``.
    bands: x positions highlighted with a red vertical band (flagged slices).
    Returns the image and (x0, x1, y0, y1) data limits used.
    """
    w, h = max(int(size[0]), 8), max(int(size[1]), 8)
    img = np.empty((h, w, 3), np.uint8)
    img[:] = background
    xs = [np.asarray(s["x"], float) for s in series if len(s["x"])]
    ys = [np.asarray(s["y"], float) for s in series if len(s["y"])]
    if not xs:
        return img, (0, 1, 0, 1)
    allx, ally = np.concatenate(xs), np.concatenate(ys)
    ally = ally[np.isfinite(ally)]
    x0, x1 = xlim or (float(allx.min()), float(allx.max()))
    y0, y1 = ylim or ((float(ally.min()), float(ally.max())) if ally.size else (0.0, 1.0))
    if x1 - x0 < 1e-9:
        x0, x1 = x0 - 1, x1 + 1
    if y1 - y0 < 1e-9:
        y0, y1 = y0 - 1, y1 + 1
    pad = 0.06 * (y1 - y0)
    y0, y1 = y0 - pad, y1 + pad
    m = 1

    def px(x, y):
        u = m + (np.asarray(x, float) - x0) / (x1 - x0) * (w - 1 - 2 * m)
        v = (h - 1 - m) - (np.asarray(y, float) - y0) / (y1 - y0) * (h - 1 - 2 * m)
        return u, v

    # axes frame
    cv2.rectangle(img, (0, 0), (w - 1, h - 1), (70, 70, 80), 1)
    for b in bands or []:
        u, _ = px(b, 0)
        half = max(1, int(round((w - 2) / max(x1 - x0, 1) / 2)))
        cv2.rectangle(img, (int(u) - half, 1), (int(u) + half, h - 2), (90, 20, 20), -1)
    for hv in hlines or []:
        _, v = px(x0, hv)
        cv2.line(img, (1, int(v)), (w - 2, int(v)), (90, 90, 110), 1)
    for s in series:
        if not len(s["x"]):
            continue
        u, v = px(s["x"], s["y"])
        ok = np.isfinite(u) & np.isfinite(v)
        pts = np.stack([u[ok], v[ok]], axis=1).round().astype(np.int32)
        col = tuple(int(c) for c in s.get("color", (220, 220, 220)))
        if s.get("dim"):
            col = tuple(int(c * 0.55) for c in col)
        if len(pts) > 1:
            cv2.polylines(img, [pts.reshape(-1, 1, 2)], False, col, 1, lineType=cv2.LINE_8)
        if s.get("points"):
            for p in pts:
                if 0 <= p[1] < h and 0 <= p[0] < w:
                    img[p[1], p[0]] = (255, 255, 255)
    return img, (x0, x1, y0, y1)
