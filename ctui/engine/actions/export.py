"""Export: :func:`export`, the one engine function behind ``ctui export`` and the TUI's export screen.

Formats (:data:`FORMATS`): ``dicom-seg`` (highdicom, over the source series' SOP
instances), ``rtstruct`` (closed planar contours per slice), ``nifti`` / ``nrrd`` (label
maps with the series' geometry; ``.seg.nrrd`` names the segments for 3D Slicer),
``stl`` / ``ply`` / ``obj`` (object surfaces in patient mm, merged in one file), ``mric``
(contours) and ``csv`` (one row of measurements per object).

The input is a ``.ctui`` project, a label file (DICOM-SEG, RTSTRUCT, NIfTI, NRRD) placed
on ``series`` when given, or an :class:`~ctui.engine.actions.opened.Opened` (what the TUI
holds). DICOM exports need the DICOM series the labels were drawn on: ``series``, else the
project's recorded source. No patient name, ID or birth date is written unless
``keep_identifiers``.
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
from ctui.engine.actions.opened import Opened, input_kind, open_project
from ctui.engine.core.atomic import check_output, write_text
from ctui.engine.core.colors import object_color
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.progress import Progress, report, scaled
from ctui.engine.core.volume import Volume

#: format -> default file suffix
FORMATS: dict[str, str] = {"dicom-seg": ".dcm", "rtstruct": ".dcm", "nifti": ".nii.gz", "nrrd": ".seg.nrrd",
                           "stl": ".stl", "ply": ".ply", "obj": ".obj", "mric": ".mric", "csv": ".csv"}
CSV_KEYS = ("id", "name", "voxels", "volume_voxels_ml", "volume_mesh_ml", "volume_difference_percent", "area_mm2",
            "centroid_x_mm", "centroid_y_mm", "centroid_z_mm")


@dataclass
class ExportSource:
    """Labels to export: ``labels`` (z, y, x) uint8 on ``geometry``; ``objects`` [{id, name, color}];
    ``masks`` full masks of overlapping objects; ``series`` / ``series_uid``: the DICOM source."""

    path: str
    labels: np.ndarray
    geometry: Geometry
    objects: list[dict]
    series: str = ""
    series_uid: str | None = None
    volume: Any = None
    masks: dict[int, np.ndarray] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def mask(self, oid: int) -> np.ndarray:
        m = self.masks.get(int(oid))
        return m if m is not None else self.labels == int(oid)


@dataclass
class ExportResult:
    """What :func:`export` wrote: ``format``, ``path``, ``objects`` [{id, name}], ``rows`` (csv), ``warnings``."""

    format: str
    path: str
    objects: list[dict] = field(default_factory=list)
    rows: list[dict] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        d: dict[str, Any] = {"format": self.format, "written": [self.path],
                             "objects": [{"id": o["id"], "name": o["name"]} for o in self.objects],
                             "warnings": list(self.warnings)}
        if self.rows:
            d["rows"] = self.rows
        return d


# =========================================================================== input
def _objects(labels: np.ndarray, recorded: Sequence[dict] | None) -> list[dict]:
    info = {int(o["id"]): o for o in recorded or [] if isinstance(o, dict) and "id" in o}
    ids = [int(i) for i in np.flatnonzero(np.bincount(np.asarray(labels, np.uint8).ravel(), minlength=256)) if i]
    out = []
    for i in ids:
        o = info.get(i, {})
        out.append({"id": i, "name": str(o.get("name") or f"object {i}"),
                    "color": [int(c) for c in (o.get("color") or object_color(i))][:3]})
    return out


def _load_series(series: str, series_uid: str | None) -> Any:
    from ctui.engine.io.series import load

    if not os.path.exists(series):
        raise CtuiError("no such series folder or file", path=series)
    return load(series, **({"series": series_uid} if series_uid else {}))


def export_source(source: str | os.PathLike | Opened, *, series: str | os.PathLike | None = None,
                  series_uid: str | None = None) -> ExportSource:
    """The labels, geometry and objects an export works on (see the module docstring)."""
    from ctui.engine.io.imports import is_label_file, read_label_file

    if isinstance(source, Opened):
        return _from_opened(source, series, series_uid)
    p = os.fspath(source)
    if not os.path.exists(p):
        raise CtuiError("no such file", path=p)
    if input_kind(p) == "project":
        return _from_opened(open_project(p, with_series=None, require_labels=True), series, series_uid)
    if not is_label_file(p):
        raise CtuiError("not a project or a label file (.ctui, DICOM-SEG, RTSTRUCT, .nii, .nii.gz, .nrrd)", path=p)
    volume = _load_series(os.fspath(series), series_uid) if series else None
    imp = read_label_file(p, grid=volume)
    return ExportSource(p, imp.labels, imp.geometry, imp.objects, os.fspath(series or ""), series_uid, volume,
                        imp.masks, list(imp.warnings))


def _from_opened(opened: Opened, series: Any, series_uid: str | None) -> ExportSource:
    proj = opened.project
    if opened.labels is None:
        raise CtuiError("no label volume to export (segment an object first)", path=opened.path)
    geometry = opened.geometry or (Geometry.of(opened.volume) if opened.volume is not None else None)
    if geometry is None:
        raise CtuiError("the labels have no geometry (the project's series is missing)", path=opened.path)
    src = os.fspath(series) if series else (str(proj.source_path or "") if proj is not None else "")
    if not src and opened.kind == "series":
        src = opened.path
    uid = series_uid or (proj.series_uid if proj is not None else None)
    if uid is None and proj is not None:
        uid = (proj.source_options or {}).get("series")
    masks = dict(getattr(opened, "masks", None) or {})
    return ExportSource(opened.path, np.asarray(opened.labels), geometry,
                        _objects(opened.labels, proj.objects if proj is not None else None), src, uid,
                        opened.volume, masks, list(opened.notes))


# =========================================================================== writers
def _dicom_sources(src: ExportSource) -> list[Any]:
    from ctui.engine.io.dicomseg import source_datasets

    if not src.series:
        raise CtuiError("DICOM-SEG and RTSTRUCT need the DICOM series the labels were drawn on: give --series",
                        path=src.path)
    return source_datasets(src.series, src.volume if src.volume is not None else src.geometry, series=src.series_uid)


def _write_csv(path: Path, src: ExportSource, objs: list[dict], progress: Progress | None) -> list[dict]:
    from ctui.engine.measure.stats import object_stats

    g = src.geometry
    rows = []
    for n, o in enumerate(objs):
        report(progress, n, len(objs), f"measuring {o['name']}")
        st = object_stats(src.mask(o["id"]), o["id"], spacing=g.spacing, origin=g.origin, direction=g.direction)
        c = [float(v) for v in st["centroid_mm"]]
        rows.append({"id": o["id"], "name": o["name"], "voxels": st["voxels"],
                     "volume_voxels_ml": round(st["volume_voxels_ml"], 6),
                     "volume_mesh_ml": None if st["volume_mesh_ml"] is None else round(st["volume_mesh_ml"], 6),
                     "volume_difference_percent": None if st["volume_difference_percent"] is None
                     else round(st["volume_difference_percent"], 4),
                     "area_mm2": None if st["area_mm2"] is None else round(st["area_mm2"], 4),
                     "centroid_x_mm": round(c[0], 4), "centroid_y_mm": round(c[1], 4), "centroid_z_mm": round(c[2], 4)})
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_KEYS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    write_text(path, buf.getvalue())
    return rows


def _write_mesh(path: Path, src: ExportSource, objs: list[dict], method: str | None, progress: Progress | None) -> None:
    from ctui.engine.actions.mesh import label_meshes
    from ctui.engine.io.meshes import save_mesh
    from ctui.engine.mesh.meshtools import merge

    meshes = {}
    for n, o in enumerate(objs):
        lab = src.mask(o["id"]).astype(np.uint8) * np.uint8(o["id"]) if o["id"] in src.masks else src.labels
        meshes.update(label_meshes(lab, src.geometry, [o["id"]], method=method or defaults.MESH_METHOD,
                                   progress=scaled(progress, n / len(objs), (n + 1) / len(objs))))
    parts = [meshes[k] for k in sorted(meshes)]
    mesh = parts[0] if len(parts) == 1 else merge(parts, object_id=0, meta={"objects": sorted(meshes)})
    save_mesh(path, mesh)


def _write_mric(path: Path, src: ExportSource, ids: list[int]) -> None:
    from ctui.engine.core.borders import borders_for_mric
    from ctui.engine.io.mric import write_mric

    nz, ny, nx = src.labels.shape
    image = None
    if src.volume is not None:
        from ctui.engine.core.windows import apply_window

        image = apply_window(src.volume.data[nz // 2], tuple(src.volume.window))
    g = src.geometry  # the sidecar <name>.mric.json keeps the true voxel size
    write_mric(path, borders_for_mric(src.labels, ids), width=nx, height=ny, image=image,
               spacing=g.spacing, origin=g.origin, direction=g.direction)


def export(source: str | os.PathLike | Opened, *, format: str, out: str | os.PathLike,
           series: str | os.PathLike | None = None, series_uid: str | None = None,
           objects: int | Sequence[int] | None = None, keep_identifiers: bool = False,
           mesh_method: str | None = None, progress: Progress | None = None) -> ExportResult:
    """Write ``source``'s objects to ``out`` in ``format`` (one of :data:`FORMATS`).

    ``series``: the DICOM series the labels were drawn on (DICOM-SEG, RTSTRUCT; also puts a
    label file on that series' grid); ``series_uid`` picks one series in a folder of several.
    ``objects``: ids to export (default all). Returns an :class:`ExportResult`.
    """
    fmt = str(format).lower()
    if fmt not in FORMATS:
        raise CtuiError(f"unknown format {format!r} (one of {', '.join(FORMATS)})")
    report(progress, 0.0, 1.0, "reading")
    check_output(out, inputs=[source.path if isinstance(source, Opened) else source, series], label="--out")
    src = export_source(source, series=series, series_uid=series_uid)
    objs = _objects(src.labels, src.objects)
    if src.masks:  # objects hidden under overlaps still count
        have = {o["id"] for o in objs}
        objs += [o for o in src.objects if o["id"] in src.masks and o["id"] not in have]
        objs.sort(key=lambda o: o["id"])
    if objects is not None:
        want = [int(objects)] if isinstance(objects, (int, np.integer)) else [int(v) for v in objects]
        missing = [v for v in want if v not in {o["id"] for o in objs}]
        if missing:
            raise CtuiError(f"no object {', '.join(map(str, missing))} (objects: "
                            f"{', '.join(str(o['id']) for o in objs)})", path=src.path)
        objs = [o for o in objs if o["id"] in want]
    if not objs:
        raise CtuiError("no object in the labels: nothing to export", path=src.path)
    ids = [o["id"] for o in objs]
    labels = src.labels if objects is None else np.where(np.isin(src.labels, ids), src.labels, 0).astype(np.uint8)
    if src.series:
        check_output(out, inputs=[src.series], label="--out")
    res = ExportResult(fmt, os.fspath(out), [{"id": o["id"], "name": o["name"]} for o in objs],
                       warnings=list(src.notes))
    p = Path(out)
    sub = scaled(progress, 0.1, 1.0)
    if fmt == "dicom-seg":
        from ctui.engine.io.dicomseg import write_seg

        masks = {k: m for k, m in src.masks.items() if k in ids}  # overlapping segments stay overlapping
        write_seg(p, labels, _dicom_sources(src), objects=objs, keep_identifiers=keep_identifiers, masks=masks,
                  progress=sub)
    elif fmt == "rtstruct":
        from ctui.engine.io.rtstruct import write_rtstruct

        masks = {k: m for k, m in src.masks.items() if k in ids}  # overlapping segments keep their contours
        write_rtstruct(p, labels, src.geometry, _dicom_sources(src), objects=objs, keep_identifiers=keep_identifiers,
                       masks=masks, progress=sub)
    elif fmt in ("nifti", "nrrd"):
        from ctui.engine.io.labels import save_labels

        name = p.name.lower()
        if fmt == "nifti" and not name.endswith((".nii", ".nii.gz")):
            raise CtuiError("a NIfTI file name ends in .nii or .nii.gz", path=p)
        if fmt == "nrrd" and not name.endswith(".nrrd"):
            raise CtuiError("an NRRD file name ends in .nrrd or .seg.nrrd", path=p)
        g = src.geometry  # save_labels takes a Volume: the labels on their grid
        grid = Volume(labels, spacing=g.spacing, origin=g.origin, direction=g.direction, modality="SEG", window=(5, 10))
        save_labels(p, labels, grid, names={o["id"]: o["name"] for o in objs})
    elif fmt in ("stl", "ply", "obj"):
        if p.suffix.lower() != "." + fmt:
            raise CtuiError(f"a {fmt.upper()} file name ends in .{fmt}", path=p)
        _write_mesh(p, src, objs, mesh_method, sub)
    elif fmt == "mric":
        _write_mric(p, src, ids)
    else:
        res.rows = _write_csv(p, src, objs, sub)
    report(progress, 1.0, 1.0, f"wrote {p.name}")
    return res
