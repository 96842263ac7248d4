"""Which sections along a path are sections of the tube around it.

A plane normal to a centreline is a true cross-section only where the object is a
tube there. :func:`classify_sections` gives each section row a ``status``:

* "outside" - the path point is not inside the object (no section);
* "open" - no closed contour around the path point fits the largest grid;
* "cap" - the plane meets the object's end: near either end of the path, the
  object's border is not parallel to the path. Measured as the blur-normalised
  slope of the smoothed indicator along the path against its slope across the border,
  ``sigma_t * sum df/dt / sum (sigma_n * -df/dn)`` over the contour (``sigma``: the
  smoothing's width along t and along the in-plane normal n). Next to a flat cap at
  depth ``x`` blur widths this is about ``phi(x) / (2 * 0.4 * Phi(x)**2)`` and the
  section's area is short by ``1 - Phi(x)``: sections from each end inward are "cap"
  until the slope falls under :data:`CAP_SLOPE` (0.07: x > 2, area within 2.3%);
* "branch" - a side branch or the other limb of a bifurcation joins the section: its
  area or largest diameter stands out above the medians of the sections on *both*
  sides (over three tube diameters each way; a step in calibre is above one side
  only) and the section is elongated (max / min diameter) beyond both sides too (a
  symmetric bulge is not); runs are grown to neighbours still above both sides;
* "ok" - a cross-section: reported as numbers.

Imports only ``core`` (through the field) and :mod:`ctui.engine.measure.fields`.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from ctui.engine.measure.fields import ObjectField

OK, CAP, BRANCH, OUTSIDE, OPEN = "ok", "cap", "branch", "outside", "open"
STATUSES = (OK, CAP, BRANCH, OUTSIDE, OPEN)

#: Largest blur-normalised slope along the path of a section kept near an end.
CAP_SLOPE = 0.07
#: A branch section's area / largest diameter / elongation against both sides' medians.
BRANCH_AREA = 1.15
BRANCH_DIAMETER = 1.2
BRANCH_ELONGATION = 1.15
#: Neighbours of a branch run above both sides by these factors join the run.
BRANCH_GROW = (1.04, 1.06)


def cap_slopes(rows: list[dict[str, Any]], field: ObjectField) -> np.ndarray:
    """Blur-normalised slope (k,) of the indicator along the path over each section's
    contour (see the module docstring); > 0 where the object ends behind the section
    (towards s = 0), < 0 where it ends ahead; NaN for rows without a contour."""
    out = np.full(len(rows), np.nan)
    pts, tan, nrm, owner = [], [], [], []
    for i, r in enumerate(rows):
        c = r.get("contour_mm")
        if c is None or len(c) < 4:
            continue
        c = np.asarray(c, dtype=np.float64)
        if np.allclose(c[0], c[-1]):
            c = c[:-1]
        t = np.asarray(r["normal"], dtype=np.float64)
        e = np.roll(c, -1, axis=0) - np.roll(c, 1, axis=0)
        n = np.cross(e, t)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        if np.sum(n * (c - c.mean(axis=0))) < 0:  # outward
            n = -n
        pts.append(c)
        nrm.append(n)
        tan.append(np.broadcast_to(t, c.shape))
        owner.append(np.full(len(c), i))
    if not pts:
        return out
    c, n, t, who = (np.concatenate(x) for x in (pts, nrm, tan, owner))
    d = 0.5 * float(min(field.spacing))
    f = field.sample(np.concatenate([c + d * t, c - d * t, c + d * n, c - d * n]))
    m = len(c)
    f_t = (f[:m] - f[m : 2 * m]) / (2 * d)
    g_n = -(f[2 * m : 3 * m] - f[3 * m :]) / (2 * d)
    num = np.bincount(who, weights=field.blur_mm(t) * f_t, minlength=len(rows))
    den = np.bincount(who, weights=field.blur_mm(n) * g_n, minlength=len(rows))
    have = np.bincount(who, minlength=len(rows)) > 0
    out[have] = num[have] / np.where(den[have] > 0, den[have], np.nan)
    return out


def _mark_caps(status: list[str], slope: np.ndarray, limit: float) -> None:
    k = len(status)
    for order, sign in ((range(k), 1.0), (range(k - 1, -1, -1), -1.0)):
        for i in order:
            if status[i] != OK:  # no section (before the object or at its very end)
                continue
            if not np.isfinite(slope[i]) or sign * slope[i] > limit:
                status[i] = CAP
            else:
                break


def _side_medians(x: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Medians of the ``w`` values before and after each element (NaN where fewer than 3)."""
    from numpy.lib.stride_tricks import sliding_window_view

    pad = np.concatenate([np.full(w, np.nan), x, np.full(w + 1, np.nan)])
    win = sliding_window_view(pad, w)
    n = len(x)
    before, after = win[:n], win[w + 1 : w + 1 + n]
    out = []
    for side in (before, after):
        cnt = np.isfinite(side).sum(axis=1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows
            med = np.nanmedian(side, axis=1)
        out.append(np.where(cnt >= 3, med, np.nan))
    return out[0], out[1]


def _above_both(x: np.ndarray, w: int) -> np.ndarray:
    """x / the larger of the medians before and after (NaN when neither side has data)."""
    b, a = _side_medians(x, w)
    ref = np.fmax(b, a)
    with np.errstate(all="ignore"):
        return x / ref


def _mark_branches(rows: list[dict[str, Any]], status: list[str]) -> None:
    idx = np.array([i for i, st in enumerate(status) if st == OK], dtype=int)
    if len(idx) < 7:
        return
    s = np.array([rows[i]["s_mm"] for i in idx])
    area = np.array([rows[i]["area_mm2"] for i in idx], dtype=np.float64)
    dmax = np.array([rows[i]["max_diameter_mm"] for i in idx], dtype=np.float64)
    dmin = np.array([rows[i]["min_diameter_mm"] for i in idx], dtype=np.float64)
    step = float(np.median(np.diff(s))) if len(s) > 1 else 1.0
    eqd = float(np.nanmedian([rows[i]["eq_diameter_mm"] for i in idx]))
    w = max(int(round(3.0 * eqd / max(step, 1e-6))), 4)
    ra, rd = _above_both(area, w), _above_both(dmax, w)
    with np.errstate(all="ignore"):
        re = _above_both(dmax / dmin, w)
    hit = ((ra > BRANCH_AREA) | (rd > BRANCH_DIAMETER)) & (re > BRANCH_ELONGATION)
    grow = (ra > BRANCH_GROW[0]) | (rd > BRANCH_GROW[1])
    changed = True
    while changed:
        nb = np.zeros_like(hit)
        nb[1:] |= hit[:-1]
        nb[:-1] |= hit[1:]
        new = hit | (nb & grow)
        changed = bool((new != hit).any())
        hit = new
    for j in np.flatnonzero(hit):
        status[idx[j]] = BRANCH


def classify_sections(rows: list[dict[str, Any]], field: ObjectField, *, cap_slope: float = CAP_SLOPE,
                      branches: bool = True) -> list[dict[str, Any]]:
    """Set each row's ``status`` (see the module docstring), in place; returns ``rows``.

    Rows must come in path order (``s_mm`` increasing) and carry the keys of
    :func:`ctui.engine.measure.sections.sections_along_path`. Measured numbers stay in
    the rows (the TUI may draw them greyed out); writers report "ok" rows only.
    """
    if not rows:
        return rows
    status = [r.get("status") or (OK if r.get("contour_mm") is not None else OUTSIDE) for r in rows]
    slope = cap_slopes(rows, field)
    _mark_caps(status, slope, cap_slope)
    if branches:
        _mark_branches(rows, status)
    for r, st, sl in zip(rows, status, slope):
        r["status"] = st
        r["cap_slope"] = float(sl)
    return rows
