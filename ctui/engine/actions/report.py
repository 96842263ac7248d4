"""Measurement reports: :func:`write_report` (``ctui report``, the ``sr`` export format) and
:func:`read_report` (``ctui measure report.dcm``).

A report holds, per object, the numbers of :func:`ctui.engine.actions.measure.measure_object`
(the same call as ``ctui measure --json --values``: voxel and mesh volume, surface area,
principal axes, mean and SD of HU and, with ``path``, the path's length and its extreme
sections with their positions) as a DICOM SR (TID 1500, :mod:`ctui.engine.io.srwriter`)
referencing each object's segment in a DICOM-SEG (written by the engine's SEG export in the
same run, or given: ``seg``; a DICOM-SEG input is its own) and the source images; or as JSON
or CSV. No patient identifiers unless ``keep_identifiers``.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.actions.measure import MeasureResult, measure_object
from ctui.engine.actions.opened import Opened, existing_path, input_kind, open_input
from ctui.engine.core.atomic import check_output, write_text
from ctui.engine.core.colors import object_color
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.jsonio import dumps
from ctui.engine.core.progress import Progress, report, scaled
from ctui.engine.core.safetext import csv_cell
from ctui.engine.io.project import Project
from ctui.engine.io.series import load

#: ``format`` choices of :func:`write_report` (``ctui report --format``; the names: ``defaults.REPORT_FORMATS``)
REPORT_FORMATS = dict(zip(defaults.REPORT_FORMATS, (
    "DICOM SR (TID 1500) referencing a DICOM-SEG and the source images", "the measurements as JSON",
    "one row of measurements per object")))
#: scalar keys of a report row (CSV columns after id, name), in order
ROW_KEYS = ("volume_voxels_ml", "volume_mesh_ml", "area_mm2", "mean", "sd", "mean_value", "sd_value", "axis_1_mm",
            "axis_2_mm", "axis_3_mm", "path_length_mm", "max_diameter_mm", "max_diameter_s_mm", "min_diameter_mm",
            "min_diameter_s_mm", "max_area_mm2", "max_area_s_mm", "min_area_mm2", "min_area_s_mm")
#: which sections of a path go in a report (:func:`write_report`'s ``sections``)
SECTION_CHOICES = defaults.REPORT_SECTIONS
#: a segment of a given SEG matches an object when their masks' Dice is at least this
SEG_MATCH_DICE = 0.99


@dataclass
class ReportResult:
    """What :func:`write_report` wrote: ``format``, ``path``, ``seg`` (the DICOM-SEG referenced,
    ``seg_written`` when this run wrote it), ``objects`` [{id, name, segment_number, values
    {ROW_KEYS key: number or None}, sections [the extreme section rows, ``extremes`` naming which]}],
    ``measures`` (each object's
    :class:`MeasureResult`, not in JSON), ``warnings``."""

    format: str
    path: str
    seg: str | None = None
    seg_written: bool = False
    objects: list[dict] = field(default_factory=list)
    measures: list[MeasureResult] = field(default_factory=list, repr=False)
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        written = [self.path] + ([self.seg] if self.seg_written and self.seg else [])
        return {"format": self.format, "written": written, "seg": self.seg, "objects": self.objects,
                "warnings": list(self.warnings)}


def row_of(res: MeasureResult, *, sections: str = "extremes") -> tuple[dict[str, float | None], list[dict]]:
    """A measurement's report values {ROW_KEYS key: number or None} and its sections: the
    ``ctui measure --json`` section rows of largest and smallest diameter and area (each once,
    ``extremes`` naming which), or every section (``sections="all"``), with ``contour_mm`` (k, 3)
    patient mm."""
    v: dict[str, float | None] = dict.fromkeys(ROW_KEYS)
    v["volume_voxels_ml"], v["volume_mesh_ml"] = res.volume_ml.get("voxels"), res.volume_ml.get("mesh")
    v["area_mm2"] = res.area_mm2
    if res.values is not None:
        suffix = "" if res.values["unit"] == "HU" else "_value"
        v["mean" + suffix], v["sd" + suffix] = res.values["mean"], res.values["sd"]
    for k, a in enumerate(res.principal_axes_mm or [], start=1):
        v[f"axis_{k}_mm"] = a
    v["path_length_mm"] = res.path_length_mm
    contours = {round(float(r["s_mm"]), 6): r.get("contour_mm") for r in res.rows if r.get("status", "ok") == "ok"}
    picked: dict[float, dict] = {}
    for key, col, pick in (("max_diameter", "max_diameter_mm", max), ("min_diameter", "min_diameter_mm", min),
                           ("max_area", "area_mm2", max), ("min_area", "area_mm2", min)):
        rows = [r for r in res.sections if r.get(col) is not None and np.isfinite(r[col])]
        if not rows:
            continue
        best = pick(rows, key=lambda r: r[col])
        unit = "mm2" if col == "area_mm2" else "mm"
        v[f"{key}_{unit}"], v[f"{key}_s_mm"] = best[col], best["s_mm"]
        s = round(float(best["s_mm"]), 6)
        sec = picked.setdefault(s, {**best, "extremes": [], "contour_mm": contours.get(s)})
        sec["extremes"].append(key)
    if sections == "all":
        for r in res.sections:
            s = round(float(r["s_mm"]), 6)
            picked.setdefault(s, {**r, "extremes": [], "contour_mm": contours.get(s)})
    return v, sorted(picked.values(), key=lambda r: r["s_mm"])


def _open(source: str | os.PathLike | Opened, series: str | os.PathLike | None) -> Opened:
    """The labels with their series loaded (grey levels for HU), as ``ctui measure`` opens them."""
    if isinstance(source, Opened):
        return source
    p = existing_path(source, "file")
    if input_kind(p) == "project":
        return open_input(p, require_labels=True, with_series=True)
    if input_kind(p) != "labels":
        raise CtuiError("not a project or a label file (.ctui, DICOM-SEG, RTSTRUCT, .nii, .nii.gz, .nrrd)", path=p)
    if not series:
        raise CtuiError("a label file needs the series it was drawn on", path=p, option="series")
    return open_input(series, labels=p)


def _series_of(opened: Opened, series: str | os.PathLike | None) -> tuple[str, str | None]:
    proj = opened.project
    src = os.fspath(series) if series else (str(proj.source_path or "") if proj is not None else "")
    uid = proj.series_uid if proj is not None else None
    if uid is None and proj is not None:
        uid = (proj.source_options or {}).get("series")
    return src, uid


def _seg_segments(seg_path: str, opened: Opened, ids: Sequence[int], sources: Sequence[Any]) -> dict[int, int]:
    """{object id: segment number} of a DICOM-SEG over the same series, matched by mask (Dice >=
    :data:`SEG_MATCH_DICE`); CtuiError naming the SEG when it is over another series or lacks one."""
    from ctui.engine.io.dicomseg import import_pydicom  # pydicom: only for DICOM reports
    from ctui.engine.io.imports import read_label_file  # pydicom, highdicom

    ds = import_pydicom().dcmread(seg_path, stop_before_pixels=True)
    want = str(sources[0].get("SeriesInstanceUID", ""))
    refs = {str(r.get("SeriesInstanceUID", "")) for r in ds.get("ReferencedSeriesSequence", [])}
    if want not in refs:
        raise CtuiError("the DICOM-SEG is not over the measured series (its ReferencedSeriesSequence names "
                        "another SeriesInstanceUID)", path=seg_path, option="seg")
    imp = read_label_file(seg_path, grid=opened.volume)
    out = {}
    for oid in ids:
        mine = opened.mask(oid)
        best, score = None, 0.0
        for o in imp.objects:
            theirs = imp.mask(o["id"])
            inter = np.count_nonzero(mine & theirs)
            dice = 2.0 * inter / max(1, int(np.count_nonzero(mine) + np.count_nonzero(theirs)))
            if dice > score:
                best, score = o, dice
        if best is None or score < SEG_MATCH_DICE:
            raise CtuiError(f"no segment of the DICOM-SEG matches object {oid} (best Dice {score:.3f})",
                            path=seg_path, option="seg")
        out[oid] = int(best["source_number"])
    return out


def _sr(out: Path, opened: Opened, ids: list[int], names: dict[int, str], rows: list[tuple], *,
        series: str | os.PathLike | None, seg: str | os.PathLike | None, keep_identifiers: bool,
        progress: Progress | None) -> tuple[str, bool, dict[int, int]]:
    """Write the SR (and the SEG unless given); returns (SEG path, written, {id: segment number})."""
    from ctui.engine.io.dicomrefs import require_references  # pydicom
    from ctui.engine.io.dicomseg import import_pydicom, source_datasets  # pydicom
    from ctui.engine.io.srwriter import SrObject, write_sr  # highdicom: seconds to import

    src, uid = _series_of(opened, series)
    if not src or opened.volume is None or (opened.volume.meta or {}).get("format") != "dicom":
        raise CtuiError("a DICOM SR report needs the DICOM series the labels were drawn on", path=opened.path,
                        option="series")
    sources = source_datasets(src, opened.volume, series=uid)
    require_references(sources, what="DICOM SR", path=src)
    written = False
    if seg is None and opened.kind == "project" and input_kind(opened.path) == "labels" \
            and _is_seg(opened.path):
        seg = opened.path  # a DICOM-SEG input: the report references it
    if seg is None:
        seg = out.with_name(out.name[: -len(".dcm")] + "-seg.dcm" if out.name.lower().endswith(".dcm")
                            else out.name + "-seg.dcm")
        check_output(seg, inputs=[opened.path, src, out], label="the DICOM-SEG")
        _write_seg(seg, opened, ids, sources, keep_identifiers=keep_identifiers, progress=scaled(progress, 0.6, 0.8))
        written = True
    seg = os.fspath(seg)
    numbers = _seg_segments(seg, opened, ids, sources)
    seg_ds = import_pydicom().dcmread(seg, stop_before_pixels=True)
    report(progress, 0.9, 1.0, "DICOM SR: writing")
    objs = [SrObject(names[oid], numbers[oid], v, secs) for oid, (v, secs) in zip(ids, rows)]
    write_sr(out, objs, sources, seg_ds, keep_identifiers=keep_identifiers)
    return seg, written, numbers


def _write_seg(path: Path, opened: Opened, ids: list[int], sources: Sequence[Any], *, keep_identifiers: bool,
               progress: Progress | None) -> None:
    """The objects ``ids`` as a DICOM-SEG over ``sources`` by the engine's SEG writer (``ctui export
    --format dicom-seg``'s): one segment per object in ascending ids, overlaps kept."""
    from ctui.engine.io.dicomseg import write_seg  # pydicom (highdicom for multi-frame sources)

    labels = np.asarray(opened.labels)
    labels = np.where(np.isin(labels, ids), labels, 0).astype(np.uint8)
    info = {int(o["id"]): o for o in (opened.project.objects if opened.project else []) or [] if "id" in o}
    objs = [{"id": i, "name": str(info.get(i, {}).get("name") or f"object {i}"),
             "color": [int(c) for c in (info.get(i, {}).get("color") or object_color(i))][:3]} for i in sorted(ids)]
    masks = {k: m for k, m in opened.masks.items() if k in ids}
    write_seg(path, labels, sources, objects=objs, keep_identifiers=keep_identifiers, masks=masks, progress=progress)


def _is_seg(path: str) -> bool:
    from ctui.engine.io.imports import label_kind  # pydicom for DICOM files

    return label_kind(path) == "dicom-seg"


def write_report(source: str | os.PathLike | Opened, *, out: str | os.PathLike, format: str = defaults.REPORT_FORMAT,
                 series: str | os.PathLike | None = None, seg: str | os.PathLike | None = None,
                 objects: int | Sequence[int] | None = None, path: Any = None,
                 step_mm: float = defaults.SECTION_STEP_MM, sections: str = "extremes",
                 keep_identifiers: bool = False, progress: Progress | None = None) -> ReportResult:
    """Measure every object (or ``objects``) of a project or a label file over ``series`` and write
    the report ``out`` in ``format`` (:data:`REPORT_FORMATS`).

    ``path``: None, "auto" (sections along the centreline every ``step_mm``) or points, as
    :func:`measure_object`; ``seg``: a DICOM-SEG over the same series whose segments the SR
    references (default: the input when it is one, else ``<out>-seg.dcm`` written now).
    ``sections``: "extremes" (the sections of largest and smallest diameter and area) or "all":
    each one a planar group of the SR with its contour, and a row in ``objects``.
    """
    if sections not in SECTION_CHOICES:
        raise CtuiError(f"sections must be one of {', '.join(SECTION_CHOICES)}, got {sections!r}", option="sections")
    fmt = str(format).lower()
    if fmt not in REPORT_FORMATS:
        raise CtuiError(f"unknown report format {format!r} (one of {', '.join(REPORT_FORMATS)})", option="format")
    inputs = [source.path if isinstance(source, Opened) else source, series, seg]
    check_output(out, inputs=inputs, label="the report")
    if fmt == "sr" and not os.fspath(out).lower().endswith(".dcm"):
        raise CtuiError("a DICOM SR file name ends in .dcm", path=out, option="out")
    if seg is not None:
        existing_path(seg, "DICOM-SEG file")
    report(progress, 0.0, 1.0, "reading")
    opened = _open(source, series)
    ids = opened.pick_objects(objects)
    recorded = {int(o["id"]): str(o.get("name") or "") for o in (opened.project.objects if opened.project else [])
                or [] if isinstance(o, dict) and "id" in o}
    names = {oid: recorded.get(oid) or f"object {oid}" for oid in ids}
    res = ReportResult(fmt, os.fspath(out), warnings=list(opened.notes))
    rows = []
    for n, oid in enumerate(ids):
        report(progress, 0.1 + 0.5 * n / len(ids), 1.0, f"measuring {names[oid]}")
        m = measure_object(opened, object=oid, path=path, step_mm=step_mm, values=True)
        res.measures.append(m)
        rows.append(row_of(m, sections=sections))
        res.warnings += [w for w in m.warnings if w not in res.warnings]
    numbers: dict[int, int] = {}
    if fmt == "sr":
        res.seg, res.seg_written, numbers = _sr(Path(out), opened, ids, names, rows, series=series, seg=seg,
                                                keep_identifiers=keep_identifiers, progress=progress)
    res.objects = [{"id": oid, "name": names[oid], "segment_number": numbers.get(oid), "values": v,
                    "sections": [{k: x for k, x in sec.items() if k != "contour_mm"} for sec in secs]}
                   for oid, (v, secs) in zip(ids, rows)]
    if fmt == "json":
        write_text(out, dumps({"objects": res.objects, "measurements": [m.to_dict() for m in res.measures]},
                              indent=1) + "\n")
    elif fmt == "csv":
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(("id", "name", *ROW_KEYS))
        for o in res.objects:
            w.writerow([o["id"], csv_cell(o["name"]), *("" if o["values"][k] is None else o["values"][k]
                                                         for k in ROW_KEYS)])
        write_text(out, buf.getvalue())
    report(progress, 1.0, 1.0, f"wrote {Path(out).name}")
    return res


# =========================================================================== read back
@dataclass
class ReportContents:
    """A read report (:func:`read_report`): ``input``, ``groups`` [{name, finding, site, segment
    {sop_instance_uid, segment_number, source_images}, values {ROW_KEYS key: number},
    measurements [{key, name, value, unit, method, derivation, point}]}], ``evidence``."""

    input: str
    groups: list[dict]
    evidence: list[str] = field(default_factory=list)
    sop_instance_uid: str = ""

    def to_dict(self) -> dict:
        return {"input": self.input, "kind": "dicom-sr", "sop_instance_uid": self.sop_instance_uid,
                "groups": self.groups, "evidence": self.evidence}


def is_report(path: str | os.PathLike) -> bool:
    """True when ``path`` is a DICOM SR file."""
    from ctui.engine.io.srwriter import is_sr  # pydicom, only for DICOM files

    return is_sr(path)


def read_report(path: str | os.PathLike) -> ReportContents:
    """The measurement groups of a DICOM SR (TID 1500) report, any writer's; ctui's quantities
    under ``values`` by their :data:`ROW_KEYS` names."""
    from ctui.engine.io.srwriter import read_sr  # highdicom: seconds to import

    p = existing_path(path, "file")
    doc = read_sr(p)
    for g in doc["groups"]:
        g["values"] = {m["key"]: m["value"] for m in g["measurements"] if m["key"]}
    return ReportContents(os.path.basename(p), doc["groups"], doc["evidence"], doc["sop_instance_uid"])


def write_export(job: Any) -> list[dict]:
    """The ``sr`` export format's writer (``ctui export --format sr``, the TUI's ``e`` menu):
    :func:`write_report` of the job's objects over its DICOM series, the SEG beside it; returns
    the objects' rows."""
    src = job.src
    volume = src.volume
    if volume is None or (volume.meta or {}).get("labels_only"):
        if not src.series:
            raise CtuiError("a DICOM SR report needs the DICOM series the labels were drawn on", path=src.path,
                            option="series")
        volume = load(existing_path(src.series, "series folder or file"),
                      **({"series": src.series_uid} if src.series_uid else {}))
    project = Project(source_path=src.series, labels=job.labels, objects=list(job.objs))
    project.series_uid = src.series_uid
    opened = Opened.of_volume(volume, job.labels, path=src.path, project=project)
    opened.masks = dict(job.masks())
    res = write_report(opened, out=job.path, series=src.series or None, keep_identifiers=job.keep_identifiers,
                       progress=job.progress)
    return [{"id": o["id"], "name": o["name"], **o["values"]} for o in res.objects]
