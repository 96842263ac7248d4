"""Cross-sections of an object along a path (thesis ch. 7.2).

Sections are measured on the object's smooth field
(:func:`~ctui.engine.measure.fields.object_field`), not on its binary mask. For each
point of the path at ``step_mm``, the tangent is the plane normal; an orthonormal plane
basis (u, v) is carried along the path by rotation-minimising frames (double
reflection, Wang et al. 2008) so it does not flip; a square grid centred on the point
is sampled by trilinear interpolation (all planes of a batch in one
``map_coordinates`` call) and :func:`~ctui.engine.measure.planes.section_of_plane`
measures the region around the path point. Reported per section:

* ``area_mm2`` - the partial-volume area (or the contour's shoelace area with
  ``area="contour"``); ``contour_area_mm2``, ``pv_area_mm2`` - both;
* ``eq_diameter_mm`` = 2 sqrt(area / pi); ``min_diameter_mm`` / ``max_diameter_mm`` -
  minimum and maximum Feret diameters, scaled by sqrt(area_mm2 / contour_area_mm2) so
  they agree with the area;
* ``status`` - whether the numbers are a section of the tube around the path
  (:func:`~ctui.engine.measure.flags.classify_sections`): "ok", "cap" (the plane meets
  the object's end), "branch" (a side branch or a bifurcation joins the section),
  "outside" (the path point is not inside the object) or "open" (no closed contour
  around the path point). Only "ok" rows are reported as numbers by the writers.

Paths are (n, 3) patient positions (x, y, z) in mm.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.measure import DEFAULT_SECTION_STEP_MM
from ctui.engine.measure.fields import ObjectField, object_field
from ctui.engine.measure.flags import BRANCH, CAP, OK, classify_sections
from ctui.engine.measure.paths import (
    path_points,
    path_spline,
    rotation_minimising_frames,
)
from ctui.engine.measure.planes import sample_planes, section_of_plane
from ctui.engine.measure.report import (  # noqa: F401  (the section tool's writers, re-exported)
    SECTION_KEYS,
    plot_sections,
    sections_plot_image,
    sections_table,
    write_sections_csv,
    write_sections_json,
)

_AVERAGED_KEYS = ("area_mm2", "eq_diameter_mm", "min_diameter_mm", "max_diameter_mm", "contour_area_mm2",
                  "pv_area_mm2")


def _default_half_size(field: ObjectField, path_len: float) -> float:
    sp = np.asarray(field.spacing)
    vol = float(field.indicator.sum()) * float(np.prod(sp))
    r = math.sqrt(vol / (math.pi * max(path_len, 1e-6)))
    return float(np.clip(2.0 * r, 4 * sp.max(), 80.0))


def _measure_planes(field: ObjectField, pts, u, v, *, h0: float, half0: float, max_grid: int, batch: int,
                    timings: dict) -> list[dict[str, Any]]:
    """:func:`section_of_plane` of every plane; planes whose section does not fit the
    grid are retried with a grid twice as large (4 times at most)."""
    minv = field.matrix
    c_idx = field.to_index(pts)  # (k, 3)
    u_idx = u @ minv.T
    v_idx = v @ minv.T
    k = len(pts)
    results: list[dict[str, Any]] = [{"inside": False} for _ in range(k)]
    half = np.full(k, half0)
    todo = np.arange(k)
    tail_mm = 3.3 * field.plane_blur_mm(u, v)  # the blur's reach within each plane
    for rnd in range(5):
        if len(todo) == 0:
            break
        retry = []
        for hs in np.unique(half[todo]):  # planes of one half-size share one grid
            grp = todo[half[todo] == hs]
            n = int(min(max_grid, math.ceil(2 * hs / h0) + 1))
            n += (n + 1) % 2  # odd: a grid node on the path point
            h = 2 * hs / (n - 1)
            t = (np.arange(n) - (n - 1) / 2) * h
            tails = np.ceil(tail_mm / h).astype(int) + 1
            for b0 in range(0, len(grp), batch):
                ids = grp[b0 : b0 + batch]
                ta = time.perf_counter()
                vals = sample_planes(field.indicator, c_idx[ids], u_idx[ids], v_idx[ids], t)
                tb = time.perf_counter()
                timings["sampling"] = timings.get("sampling", 0.0) + tb - ta
                for j, i in enumerate(ids):
                    r = section_of_plane(vals[j], h, int(tails[i]))
                    if r.get("needs_larger") and rnd < 4:
                        retry.append(i)
                        continue
                    results[i] = r
                timings["contours"] = timings.get("contours", 0.0) + time.perf_counter() - tb
        todo = np.array(sorted(retry), dtype=int)
        half[todo] *= 2.0
    return results


def _row(s: float, r: dict[str, Any], p, t, u, v, area: str) -> dict[str, Any]:
    """One section row from :func:`section_of_plane`'s result ``r`` at arc length ``s``."""
    row: dict[str, Any] = {"s_mm": float(s)}
    if "pv_area_mm2" in r:
        a = r["pv_area_mm2"] if area == "pv" else r["contour_area_mm2"]
        f = 1.0 if area == "pv" else math.sqrt(r["contour_area_mm2"] / r["pv_area_mm2"])
        cuv = r["contour_uv"]
        row.update(
            area_mm2=a,
            eq_diameter_mm=2.0 * math.sqrt(a / math.pi),
            min_diameter_mm=r["min_diameter_mm"] * f,
            max_diameter_mm=r["max_diameter_mm"] * f,
            contour_area_mm2=r["contour_area_mm2"],
            pv_area_mm2=r["pv_area_mm2"],
            contour_mm=p + cuv[:, :1] * u + cuv[:, 1:2] * v,
            centroid_mm=p + r["centroid_uv"][0] * u + r["centroid_uv"][1] * v,
            status=OK,
        )
    else:
        nan = float("nan")
        row.update(area_mm2=nan, eq_diameter_mm=nan, min_diameter_mm=nan, max_diameter_mm=nan,
                   contour_area_mm2=nan, pv_area_mm2=nan, contour_mm=None, centroid_mm=None,
                   status="open" if r.get("needs_larger") else "outside")
    row["point_mm"] = p
    row["normal"] = t
    return row


def _averaged(path_mm, field: ObjectField, *, step_mm: float, at_s, average_mm: float, flags: bool,
              **kw: Any) -> list[dict[str, Any]]:
    """Sections averaged over ``average_mm`` of path (thin slabs): see :func:`sections_along_path`."""
    _, total = path_spline(path_mm)
    targets = np.arange(0.0, total + 1e-9, step_mm) if at_s is None else np.asarray(at_s, dtype=np.float64)
    k = max(3, math.ceil(average_mm / 0.25) + 1)
    k += (k + 1) % 2
    offs = np.linspace(-average_mm / 2, average_mm / 2, k)
    all_s = np.clip(targets[:, None] + offs[None, :], 0.0, total)
    sub = sections_along_path(None, path_mm, field=field, at_s=all_s.ravel(), flags=False, **kw)
    rows = []
    for i, s_i in enumerate(targets):
        grp = sub[i * k : (i + 1) * k]
        row = dict(grp[k // 2])
        row["s_mm"] = float(s_i)
        for key in _AVERAGED_KEYS:
            vals = np.array([g[key] for g in grp], dtype=np.float64)
            row[key] = float(np.nanmean(vals)) if np.isfinite(vals).any() else float("nan")
        if math.isfinite(row["area_mm2"]):
            row["eq_diameter_mm"] = 2.0 * math.sqrt(row["area_mm2"] / math.pi)
        row["averaged_mm"] = float(average_mm)
        rows.append(row)
    if flags:
        classify_sections(rows, field)
    return rows


def sections_along_path(
    mask: np.ndarray | None,
    path_mm: np.ndarray,
    *,
    spacing=(1.0, 1.0, 1.0),
    step_mm: float = DEFAULT_SECTION_STEP_MM,
    origin=(0.0, 0.0, 0.0),
    direction=None,
    field: ObjectField | None = None,
    at_s: Sequence[float] | None = None,
    half_size_mm: float | None = None,
    grid_step_mm: float | None = None,
    max_grid: int = 129,
    area: str = "pv",
    batch: int = 96,
    timings: dict | None = None,
    average_mm: float = 0.0,
    flags: bool = True,
    cuts: bool = False,
) -> list[dict[str, Any]]:
    """Cross-sections of an object in planes normal to a path.

    Parameters
    ----------
    mask, spacing, origin, direction : the object (z, y, x; ignored when ``field`` is given), its geometry.
    path_mm : ndarray (n, 3)
        The path, patient mm (x, y, z); a dense polyline (e.g. :func:`~ctui.engine.measure.centreline.centreline`).
    step_mm : float
        Distance along the path between sections (from s = 0).
    field : ObjectField, optional
        Precomputed :func:`~ctui.engine.measure.fields.object_field` (reuse it for several calls).
    at_s : sequence of float, optional
        Explicit arc lengths (mm) instead of a regular step.
    half_size_mm : float, optional
        Initial half side of the square grid (grown when the section does not fit).
    grid_step_mm : float, optional
        Grid spacing; default a quarter of the smallest voxel size, coarsened so the
        grid has at most ``max_grid`` points a side.
    area : "pv" or "contour"
        Which estimate ``area_mm2`` reports (see module docstring).
    timings : dict, optional
        Filled with seconds spent in "field", "sampling", "contours", "flags".
    average_mm : float
        0 (default): each section is one plane, as in the thesis. > 0: area and
        diameters are the mean over planes spread evenly over
        [s - average_mm/2, s + average_mm/2] (every 0.25 mm at most): a thin-slab
        average that halves the aliasing scatter of binary masks of small tubes at
        the cost of blurring changes along the path over that length.
    flags : bool
        Classify the sections (``status``, see the module docstring); False leaves
        every measured section "ok".
    cuts : bool
        Keep every section that cuts the object (a path the user gave): see :func:`keep_cuts`.

    Returns
    -------
    list of dict, one per section, with keys ``s_mm``, ``area_mm2``,
    ``eq_diameter_mm``, ``min_diameter_mm``, ``max_diameter_mm``,
    ``contour_area_mm2``, ``pv_area_mm2``, ``status``, ``point_mm`` (3,), ``normal``
    (3,), ``contour_mm`` (k, 3) patient mm or None, ``centroid_mm`` (3,) or None; area
    and diameters are NaN where no section was found ("outside", "open").
    """
    timings = {} if timings is None else timings
    t0 = time.perf_counter()
    if field is None:
        if mask is None:
            raise CtuiError("sections_along_path needs a mask or a field")
        field = object_field(mask, spacing=spacing, origin=origin, direction=direction)
    timings["field"] = timings.get("field", 0.0) + time.perf_counter() - t0
    if average_mm and average_mm > 0:
        return keep_cuts(_averaged(path_mm, field, step_mm=step_mm, at_s=at_s, average_mm=average_mm, flags=flags,
                                   half_size_mm=half_size_mm, grid_step_mm=grid_step_mm, max_grid=max_grid,
                                   area=area, batch=batch, timings=timings), cuts)
    _, total = path_spline(path_mm)
    if at_s is None:
        if not step_mm > 0:
            raise CtuiError(f"step must be positive, got {step_mm}")
        if total / step_mm > MAX_SECTIONS:  # bounded work: a path of 1e6 mm at 0.5 mm ran for minutes
            raise CtuiError(f"a path of {total:.0f} mm at a step of {step_mm:g} mm gives {total / step_mm:.0f} "
                            f"sections (at most {MAX_SECTIONS}): give a larger --step or a shorter --path")
        s = np.arange(0.0, total + 1e-9, step_mm)
    else:
        s = np.asarray(at_s, dtype=np.float64)
        if np.any(s < -1e-6) or np.any(s > total + 1e-6):
            raise CtuiError(f"section positions must lie on the path (0 to {total:.1f} mm)")
    pts, tan = path_points(path_mm, s)
    u, v = rotation_minimising_frames(pts, tan)
    h0 = grid_step_mm if grid_step_mm else float(min(field.spacing)) / 4.0
    half0 = half_size_mm if half_size_mm else _default_half_size(field, total)
    results = _measure_planes(field, pts, u, v, h0=h0, half0=half0, max_grid=max_grid, batch=batch,
                              timings=timings)
    rows = [_row(s[i], results[i], pts[i], tan[i], u[i], v[i], area) for i in range(len(s))]
    if flags:
        tf = time.perf_counter()
        classify_sections(rows, field)
        timings["flags"] = timings.get("flags", 0.0) + time.perf_counter() - tf
    return keep_cuts(rows, cuts)


def keep_cuts(rows: list[dict[str, Any]], cuts: bool = True) -> list[dict[str, Any]]:
    """With ``cuts``: every row that is a section of the object ("cap", "branch") made "ok",
    its old status kept in ``flag`` (a path the user gave, not a centreline, may meet the
    object's ends or a branch by intent); rows with no section ("outside", "open") unchanged."""
    if cuts:
        for r in rows:
            if r.get("status") in (CAP, BRANCH):
                r["flag"], r["status"] = r["status"], OK
    return rows


MAX_SECTIONS = 20_000  # sections one path may have


# ------------------------------------------------------------------ steps
def find_steps(s_mm: np.ndarray, values: np.ndarray, *, min_rel_jump: float = 0.1, window_mm: float = 2.0,
               margin_mm: float | None = None) -> list[dict[str, float]]:
    """Positions where a section quantity steps (e.g. a rod whose radius changes).

    A step at s is a change between the medians of ``values`` over
    [s - window, s) and (s, s + window] larger than ``min_rel_jump`` times the larger
    of the two; the position is refined to the largest local change. Changes within
    ``margin_mm`` (default 2 windows) of the first/last valid section (the object's
    end caps) are not reported.

    Returns a list of ``{"s_mm", "before", "after"}``, ordered by s.
    """
    from scipy.signal import find_peaks

    s = np.asarray(s_mm, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(y)
    s, y = s[ok], y[ok]
    if len(s) < 5:
        return []
    step = float(np.median(np.diff(s)))
    w = max(round(window_mm / step), 2)
    margin = 2.0 * window_mm if margin_mm is None else float(margin_mm)
    jumps = np.zeros(len(s))
    for i in range(w, len(s) - w):
        a = np.median(y[i - w : i])
        b = np.median(y[i + 1 : i + 1 + w])
        jumps[i] = (b - a) / max(abs(a), abs(b), 1e-12)
    out = []
    for sign in (1, -1):
        peaks, _ = find_peaks(sign * jumps, height=min_rel_jump, distance=w)
        for p in peaks:
            if s[p] - s[0] < margin or s[-1] - s[p] < margin:
                continue
            out.append({
                "s_mm": float(s[p]),
                "before": float(np.median(y[max(p - w, 0) : p])),
                "after": float(np.median(y[p + 1 : p + 1 + w])),
            })
    return sorted(out, key=lambda d: d["s_mm"])
