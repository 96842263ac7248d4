"""Which sections along a path are sections of the tube around it.

A plane normal to a centreline is a true cross-section only where the object is a
tube there. :func:`classify_sections` gives each section row a ``status``:

* "outside" - the path point is not inside the object (no section);
* "open" - no closed contour around the path point fits the largest grid;
* "cap" - the plane is near the object's end: from points :data:`CAP_DEPTH` in-plane
  blur widths inside the section's contour, the object does not go on for
  :data:`CAP_DEPTH` blur widths along the path towards that end (the smoothed
  indicator falls under one half there; ``sigma`` is the smoothing's width along each
  direction, 0.7 voxel per axis), or from points as far outside, it widens there
  (a sheet of mask stuck to the end). A plane at ``x`` blur widths from a flat cap loses
  about ``1 - Phi(x)`` of its area: 0.6% at 2.5. Sections from each end inwards are
  "cap" until two in a row are clear; an oblique cap (a tube cut by the slice planes)
  is caught where it first comes near the contour;
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
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ctui.engine.measure.fields import ObjectField

OK, CAP, BRANCH, OUTSIDE, OPEN = "ok", "cap", "branch", "outside", "open"
STATUSES = (OK, CAP, BRANCH, OUTSIDE, OPEN)

#: A section is clear of the object's end when the object goes on for this many blur
#: widths beyond it (2.5: a flat cap that near takes 0.6% of the area).
CAP_DEPTH = 2.5
#: A branch section's area / largest diameter / elongation against both sides' medians.
BRANCH_AREA = 1.15
BRANCH_DIAMETER = 1.2
BRANCH_ELONGATION = 1.15
#: Neighbours of a branch run above both sides by these factors join the run.
BRANCH_GROW = (1.04, 1.06)


def cap_clearance(rows: list[dict[str, Any]], field: ObjectField, idx: Sequence[int], *, ahead: bool,
                  depth: float = CAP_DEPTH) -> np.ndarray:
    """How clear the sections ``rows[idx]`` are of the object's end ahead of them
    (``ahead``: towards larger s) or behind them; NaN for rows without a contour.

    Points ``depth`` in-plane blur widths inside the contour should still be inside
    the object ``depth`` blur widths along the path (the object goes on), and points as
    far outside the contour should still be outside (the object does not widen into
    something else there). The clearance is the smallest of the indicator at the
    inner points and one minus the indicator at the outer points: under 0.5, the
    object ends or changes within ``depth`` blur widths of the plane on that side."""
    out = np.full(len(idx), np.nan)
    inner, outer, tan, owner = [], [], [], []
    for j, i in enumerate(idx):
        c = rows[i].get("contour_mm")
        if c is None or len(c) < 4:
            continue
        c = np.asarray(c, dtype=np.float64)
        if np.allclose(c[0], c[-1]):
            c = c[:-1]
        t = np.asarray(rows[i]["normal"], dtype=np.float64)
        n = np.cross(np.concatenate((c[1:], c[:1])) - np.concatenate((c[-1:], c[:-1])), t)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        o = c.mean(axis=0)
        if np.sum(n * (c - o)) < 0:  # outward
            n = -n
        reach = depth * field.blur_mm(n)
        inner.append(c - np.minimum(reach, 0.7 * np.linalg.norm(c - o, axis=1))[:, None] * n)
        outer.append(c + reach[:, None] * n)
        tan.append(np.broadcast_to(t * (depth * field.blur_mm(t[None])[0] * (1.0 if ahead else -1.0)), c.shape))
        owner.append(np.full(len(c), j))
    if not inner:
        return out
    qi, qo, d, who = (np.concatenate(x) for x in (inner, outer, tan, owner))
    f = field.sample(np.concatenate([qi + d, qo + d]))
    low = np.full(len(idx), np.inf)
    np.minimum.at(low, who, np.minimum(f[: len(qi)], 1.0 - f[len(qi) :]))
    have = np.isfinite(low)
    out[have] = low[have]
    return out


def _mark_caps(rows: list[dict[str, Any]], status: list[str], field: ObjectField, depth: float,
               run: int = 2, chunk: int = 16) -> None:
    """From each end inwards, sections are "cap" until ``run`` sections in a row are
    clear (:func:`cap_clearance`, computed ``chunk`` sections at a time)."""
    k = len(status)
    for order, ahead in ((list(range(k)), False), (list(range(k - 1, -1, -1)), True)):
        order = [i for i in order if status[i] == OK]  # skip rows with no section
        seen: list[int] = []
        passed = 0
        for c0 in range(0, len(order), chunk):
            part = order[c0 : c0 + chunk]
            clear = cap_clearance(rows, field, part, ahead=ahead, depth=depth)
            for i, cl in zip(part, clear):
                passed = passed + 1 if cl >= 0.5 else 0  # NaN: not clear
                seen.append(i)
                if passed >= run:
                    break
            if passed >= run:
                break
        for i in seen[: len(seen) - passed]:
            status[i] = CAP


def _side_medians(x: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Medians of the ``w`` values before and after each element (NaN where fewer than 3)."""
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
    w = max(round(3.0 * eqd / max(step, 1e-6)), 4)
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


def classify_sections(rows: list[dict[str, Any]], field: ObjectField, *, cap_depth: float = CAP_DEPTH,
                      branches: bool = True) -> list[dict[str, Any]]:
    """Set each row's ``status`` (see the module docstring), in place; returns ``rows``.

    Rows must come in path order (``s_mm`` increasing) and carry the keys of
    :func:`ctui.engine.measure.sections.sections_along_path`. Measured numbers stay in
    the rows (the TUI may draw them greyed out); writers report "ok" rows only.
    """
    if not rows:
        return rows
    status = [r.get("status") or (OK if r.get("contour_mm") is not None else OUTSIDE) for r in rows]
    _mark_caps(rows, status, field, cap_depth)
    if branches:
        _mark_branches(rows, status)
    for r, st in zip(rows, status):
        r["status"] = st
    return rows
