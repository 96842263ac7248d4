"""Everything ``ctui measure`` reports for one object: :func:`measure_object`.

The top of the measure package: volumes and shape (:mod:`~ctui.engine.measure.stats`),
the path (automatic centreline or user points), sections along it with their status
(:mod:`~ctui.engine.measure.sections`), and the volume between two planes
(:mod:`~ctui.engine.measure.between`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.measure import DEFAULT_SECTION_STEP_MM
from ctui.engine.measure.between import volume_between
from ctui.engine.measure.centreline import centreline
from ctui.engine.measure.fields import (
    object_field,
    partial_volume_field,
    partial_volume_fraction,
)
from ctui.engine.measure.paths import parse_points, path_from_points, path_length
from ctui.engine.measure.report import flag_summary, sections_table
from ctui.engine.measure.sections import sections_along_path
from ctui.engine.measure.stats import object_stats

_FLAG_WORDS = {
    "outside": "lie outside the object",
    "open": "have no closed section around the path",
    "cap": "meet an end cap of the object",
    "branch": "meet a side branch or a bifurcation",
}


def _flag_warnings(flags: dict[str, Any], n: int, object_id: int) -> list[str]:
    """One warning per kind of section left out of the numbers, with where along the path (s mm)."""
    counts = flags["counts"]

    def where(k: str) -> str:
        spans = [(r["from_s_mm"], r["to_s_mm"]) for r in flags.get("ranges", []) if r["status"] == k]
        return ", ".join(f"{a:g}" if a == b else f"{a:g}-{b:g}" for a, b in spans)

    return [f"{counts[k]} of {n} sections of object {object_id} {words} (s {where(k)} mm): not reported as numbers"
            for k, words in _FLAG_WORDS.items() if counts.get(k) and k != "cap"]


def _path_of(path, mask, *, step_mm, path_voxels, spacing, origin, direction) -> np.ndarray:
    """The path (n, 3) mm that ``path`` describes (see :func:`measure_object`)."""
    fine = min(step_mm, 0.5)
    if isinstance(path, str) and path.strip().lower() == "auto":
        return centreline(mask, spacing=spacing, origin=origin, direction=direction, step_mm=fine)
    if isinstance(path, str) or path_voxels:
        pts = parse_points(path) if isinstance(path, str) else np.asarray(path, dtype=np.float64)
        return path_from_points(pts, step_mm=fine, voxel=path_voxels, spacing=spacing, origin=origin,
                                direction=direction)
    return np.asarray(path, dtype=np.float64)


def _sections_part(out: dict[str, Any], path: np.ndarray, field, *, step_mm, area, average_mm, between,
                   cuts: bool = False) -> None:
    """Fill ``out``'s path, section and between-planes keys (see :func:`measure_object`);
    ``cuts``: a given path keeps every section that cuts the object (``sections_along_path``)."""
    rows = sections_along_path(None, path, field=field, step_mm=step_mm, area=area, average_mm=average_mm,
                               cuts=cuts)
    out["path_mm"] = path
    out["path_length_mm"] = path_length(path)
    out["rows"] = rows
    out["sections"] = sections_table(rows)
    out["section_flags"] = flag_summary(rows)
    out["warnings"] += _flag_warnings(out["section_flags"], len(rows), out["object"])
    if between is not None:
        s1, s2 = between
        vb = volume_between(None, path, s1, s2, field=field)
        out["between"] = {"volume_ml": vb["volume_ml"], "area1_mm2": vb["area1_mm2"], "area2_mm2": vb["area2_mm2"]}
        out["warnings"] += vb["warnings"]


def measure_object(
    labels: np.ndarray,
    object_id: int,
    *,
    spacing=(1.0, 1.0, 1.0),
    origin=(0.0, 0.0, 0.0),
    direction=None,
    path: str | np.ndarray | None = None,
    path_voxels: bool = False,
    step_mm: float = DEFAULT_SECTION_STEP_MM,
    between: tuple[float, float] | None = None,
    mesh: bool = True,
    area: str = "pv",
    average_mm: float = 0.0,
    image: np.ndarray | None = None,
) -> dict[str, Any]:
    """Everything ``ctui measure`` reports for one object, for the TUI and scripts.

    Parameters
    ----------
    labels, object_id, spacing, origin, direction
        As :func:`object_stats`.
    path : "auto", "x,y,z;x,y,z;...", (n, 3) array, or None
        "auto": automatic centreline (:func:`ctui.engine.measure.centreline.centreline`);
        a string of points: a spline through them (patient mm, or voxel (z, y, x)
        when ``path_voxels``); an array: a dense path in mm used as given (or control
        points in voxels with ``path_voxels``; for a few mm control points call
        :func:`ctui.engine.measure.centreline.path_from_points` first); None: no sections.
    step_mm : float
        Distance between sections along the path.
    between : (s1, s2) or None
        Arc lengths (mm) of two planes for :func:`ctui.engine.measure.between.volume_between`.
    mesh : bool
        Compute the mesh (Gauss) volume and area with MESH's ``mask_surface``.
    area : "pv" or "contour"
        Section area estimate (see :mod:`ctui.engine.measure.sections`).
    average_mm : float
        Thin-slab averaging of each section along the path (0 = single planes).
    image : ndarray (z, y, x), optional
        The series the object was segmented from. Given, sections and the volume
        between planes are measured on the object's partial-volume fraction from the
        grey levels (:func:`partial_volume_fraction`) instead of its binary mask, and
        ``volume_ml`` gains ``partial_volume``. The centreline still comes from the mask.

    Returns
    -------
    dict with the JSON keys of ``ctui measure``: ``object``, ``volume_ml``
    ({``voxels``, ``mesh``}), ``volume_difference_percent``, ``area_mm2``,
    ``path_length_mm``, ``sections`` (list of {s_mm, area_mm2, eq_diameter_mm,
    min_diameter_mm, max_diameter_mm}, the "ok" sections only), ``section_flags``
    ({counts, ranges} of the others: :func:`ctui.engine.measure.report.flag_summary`),
    ``between`` ({volume_ml, area1_mm2, area2_mm2} or None), ``centroid_mm``, ``principal_axes_mm``, ``warnings``; plus,
    not for JSON: ``stats`` (:func:`object_stats`), ``path_mm`` (n, 3) and ``rows``
    (full section dicts with ``contour_mm`` (k, 3) and ``point_mm``, for drawing;
    pass them to :func:`ctui.engine.measure.report.plot_sections` for the area plot).
    """
    st = object_stats(labels, object_id, spacing=spacing, origin=origin, direction=direction, mesh=mesh)
    out: dict[str, Any] = {
        "object": int(object_id),
        "volume_ml": {"voxels": st["volume_voxels_ml"], "mesh": st["volume_mesh_ml"]},
        "volume_difference_percent": st["volume_difference_percent"],
        "area_mm2": st["area_mm2"],
        "path_length_mm": None,
        "sections": [],
        "between": None,
        "centroid_mm": [float(v) for v in st["centroid_mm"]],
        "principal_axes_mm": [float(v) for v in st["principal_axes_mm"]],
        "warnings": list(st["warnings"]),
        "stats": st,
        "path_mm": None,
        "rows": [],
    }
    if image is None and path is None:  # volumes and area only: no whole-volume mask
        if between is not None:
            raise CtuiError("a volume between planes needs a path")
        return out
    lab = np.asarray(labels)
    mask = lab.astype(bool) if lab.dtype == bool else lab == object_id
    if image is not None:
        pv = partial_volume_fraction(image, mask)
        out["partial_volume"] = pv
        out["volume_ml"]["partial_volume"] = pv["volume_voxels"] * float(np.prod(spacing)) / 1000.0
    if path is None:
        if between is not None:
            raise CtuiError("a volume between planes needs a path")
        return out
    given = not (isinstance(path, str) and path.strip().lower() == "auto")  # the user's path, not a centreline
    path = _path_of(path, mask, step_mm=step_mm, path_voxels=path_voxels, spacing=spacing, origin=origin,
                    direction=direction)
    if image is not None:
        field = partial_volume_field(out["partial_volume"], spacing=spacing, origin=origin, direction=direction)
    else:
        field = object_field(mask, spacing=spacing, origin=origin, direction=direction)
    _sections_part(out, path, field, step_mm=step_mm, area=area, average_mm=average_mm, between=between,
                   cuts=given)
    return out
