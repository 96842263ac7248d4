"""Measure an object: :func:`measure_object` (volumes, area, centreline, cross-sections,
volume between planes), the one path ``ctui measure`` and the TUI's measure screen take,
with one default section step (:data:`ctui.engine.actions.defaults.SECTION_STEP_MM`)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.actions.opened import Opened, existing_path, input_kind, open_input
from ctui.engine.core.atomic import check_outputs
from ctui.engine.core.errors import CtuiError
from ctui.engine.measure import stats, summary
from ctui.engine.measure.report import path_table, plot_sections, write_path_csv, write_sections_csv
from ctui.engine.measure.sections import find_steps  # noqa: F401 - re-exported: the measure screen marks steps in the profile
from ctui.engine.measure.paths import LINE_AXES, line_through  # noqa: F401 - re-exported: the measure screen's section at the cursor


@dataclass
class MeasureResult:
    """One object's measurements (JSON keys of ``ctui measure --json`` via :meth:`to_dict`).

    volume_ml : {"voxels", "mesh"[, "partial_volume"]} mL; area_mm2 : mesh surface area;
    path_length_mm, sections (list of {s_mm, area_mm2, eq_diameter_mm, min_diameter_mm,
    max_diameter_mm}: the cross-sections only), section_flags ({counts, ranges} of the
    sections left out: end caps, branches, outside), between ({volume_ml, area1_mm2,
    area2_mm2}) when a path was given; path ({index, s_mm, x_mm, y_mm, z_mm} per point: the
    centreline or given path, patient mm); values ({unit, mean, sd, min, p5, median, p95,
    max, voxels}: the object's grey levels, HU for CT) when asked for;
    rows (full section dicts with contours) and path_mm (n, 3) for drawing, not in JSON.
    """

    input: str
    object: int | None = None
    volume_ml: dict = field(default_factory=lambda: {"voxels": None, "mesh": None})
    volume_difference_percent: float | None = None
    area_mm2: float | None = None
    path_length_mm: float | None = None
    sections: list = field(default_factory=list)
    between: dict | None = None
    centroid_mm: list | None = None
    principal_axes_mm: list | None = None
    partial_volume: dict | None = None
    warnings: list = field(default_factory=list)
    section_flags: dict | None = None
    step_mm: float = defaults.SECTION_STEP_MM
    rows: list = field(default_factory=list, repr=False)
    path_mm: np.ndarray | None = field(default=None, repr=False)
    stats: dict | None = field(default=None, repr=False)
    values: dict | None = None

    def to_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("input", "object", "volume_ml", "volume_difference_percent", "area_mm2",
                                           "path_length_mm", "sections", "between", "warnings")}
        if self.centroid_mm is not None:
            d["centroid_mm"] = self.centroid_mm
            d["principal_axes_mm"] = self.principal_axes_mm
        if self.partial_volume is not None:
            d["partial_volume"] = self.partial_volume
        if self.section_flags is not None:
            d["section_flags"] = self.section_flags
        if self.values is not None:
            d["values"] = self.values
        if self.path_mm is not None:
            d["path"] = path_table(self.path_mm)
        return d


def object_values(image: np.ndarray, mask: np.ndarray, *, modality: str = "") -> dict | None:
    """Grey-level statistics of ``image`` (z, y, x) over the bool ``mask`` (same shape): {unit
    ("HU" for CT), mean, sd, min, p5, median, p95, max, voxels}; None for an empty mask."""
    v = np.asarray(image)[np.asarray(mask, dtype=bool)].astype(np.float64)
    if not v.size:
        return None
    p5, med, p95 = np.percentile(v, [5, 50, 95])
    return {"unit": "HU" if str(modality).upper() == "CT" else "value", "mean": float(v.mean()),
            "sd": float(v.std()), "min": float(v.min()), "p5": float(p5), "median": float(med), "p95": float(p95),
            "max": float(v.max()), "voxels": int(v.size)}


def _mesh_input(opened: Opened) -> MeasureResult:
    assert opened.mesh is not None
    st = stats.mesh_stats(opened.mesh)
    return MeasureResult(os.path.basename(opened.path), volume_ml={"voxels": None, "mesh": st["volume_ml"]},
                         area_mm2=st["area_mm2"], warnings=list(st["warnings"]))


def measure_object(source: str | os.PathLike | Opened, *, object: int | None = None, path: Any = None,
                   path_voxels: bool = False, step_mm: float = defaults.SECTION_STEP_MM,
                   between: Sequence[float] | None = None, mesh: bool = True, area: str = defaults.SECTION_AREA,
                   average_mm: float = defaults.SECTION_AVERAGE_MM, partial_volume: bool = False,
                   values: bool = False) -> MeasureResult:
    """Measure one object of a project / label map (or a mesh file: volume and area only).

    ``object``: its id (default: the first present). ``path``: None (no sections),
    "auto" (centreline) or points "x,y,z;..." mm (voxel z,y,x with ``path_voxels``) or an
    (n, 3) array; sections every ``step_mm``; ``between`` (s1, s2) mm: the volume between
    the planes normal to the path there. ``partial_volume``: sections and a third volume
    on the object's partial-volume fraction from the source series' grey levels.
    ``values``: the object's grey-level statistics (HU for CT) from the series (a
    project's series is loaded for it).
    """
    if not 0.01 <= step_mm <= 1000:  # also NaN: bounded work (sections = path length / step)
        raise CtuiError(f"the section step must be from 0.01 to 1000 mm, got {step_mm}", option="step_mm")
    if not 0 <= average_mm <= 1000:
        raise CtuiError(f"the slab average must be from 0 to 1000 mm, got {average_mm}", option="average_mm")
    if between is not None and not all(np.isfinite(v) and abs(v) <= 1e9 for v in between):
        raise CtuiError(f"between {between}: want finite arc lengths in mm", option="between")
    if isinstance(source, Opened):
        opened = source
    else:
        p = existing_path(source, "file")
        if os.path.isdir(p):
            raise CtuiError("is a folder; give a .ctui project, a label file or a mesh", path=p)
        if input_kind(p) not in ("project", "labels", "mesh"):
            raise CtuiError("unknown input type (expected .ctui, .nii, .nii.gz, .nrrd, .seg.nrrd, a DICOM-SEG or "
                            "RTSTRUCT file, .stl, .ply or .obj)", path=p)
        opened = open_input(p, require_labels=True, with_series=True if partial_volume or values else None)
    if opened.kind == "mesh":
        if path is not None or between is not None:
            raise CtuiError("a mesh gives volume and area only (no path, no volume between planes)", path=opened.path,
                            option="path")
        return _mesh_input(opened)
    image = None
    if partial_volume:
        if opened.volume is None:
            raise CtuiError("partial volumes need a project whose source series can be loaded", path=opened.path,
                            option="partial_volume")
        image = opened.volume.data
    oid = opened.pick_objects(object)[0]
    g = opened.geometry
    assert opened.labels is not None and g is not None
    labels = opened.mask(oid) if oid in opened.masks else opened.labels  # overlapping imported segments
    res = summary.measure_object(labels, oid, spacing=g.spacing, origin=g.origin, direction=g.direction,
                                 path=path, path_voxels=path_voxels, step_mm=step_mm,
                                 between=(float(between[0]), float(between[1])) if between is not None else None, mesh=mesh, area=area,
                                 average_mm=average_mm, image=image)
    pv = res.get("partial_volume")
    vol = opened.volume
    grey = None
    if values:
        if vol is None or (vol.meta or {}).get("labels_only") or tuple(vol.shape) != tuple(g.shape):
            raise CtuiError("grey-level statistics need the series the labels were drawn on", path=opened.path)
        grey = object_values(vol.data, opened.mask(oid), modality=vol.modality)
    return MeasureResult(
        os.path.basename(opened.path), object=res["object"], volume_ml=res["volume_ml"],
        volume_difference_percent=res["volume_difference_percent"], area_mm2=res["area_mm2"],
        path_length_mm=res["path_length_mm"], sections=res["sections"], between=res["between"],
        centroid_mm=res["centroid_mm"], principal_axes_mm=res["principal_axes_mm"],
        partial_volume=None if pv is None else {"object_value": pv["fg"], "surroundings_value": pv["bg"]},
        warnings=list(opened.notes) + list(res["warnings"]), step_mm=step_mm, rows=res["rows"],
        path_mm=res["path_mm"], stats=res["stats"], section_flags=res.get("section_flags"), values=grey)


def save_sections(result: MeasureResult, *, csv: str | os.PathLike | None = None,
                  plot: str | os.PathLike | None = None, references: Sequence[float] | None = None,
                  inputs: Sequence[str | os.PathLike] = (), path_csv: str | os.PathLike | None = None) -> list[str]:
    """Write the section table (CSV), the area plot (PNG) and/or the path's points (CSV:
    index, s_mm, x_mm, y_mm, z_mm); returns the paths written.

    Refuses (CtuiError) an output that is the measured input (``result.input``) or one of
    ``inputs``, or two outputs that are the same file, before writing anything."""
    check_outputs({"section table": csv, "section plot": plot, "path table": path_csv},
                  inputs=[result.input, *inputs])
    if path_csv and result.path_mm is None:
        raise CtuiError("no path to write: a path table needs a path (auto or points)", option="path")
    written = []
    if path_csv:
        write_path_csv(path_csv, result.path_mm)
        written.append(os.fspath(path_csv))
    if csv:
        write_sections_csv(csv, result.rows)
        written.append(os.fspath(csv))
    if plot:
        plot_sections(plot, result.rows, references=references, title=f"object {result.object} sections")
        written.append(os.fspath(plot))
    return written
