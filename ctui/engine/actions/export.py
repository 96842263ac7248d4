"""Export: :func:`export`, the one engine function behind ``ctui export`` and the TUI's export screen.

Formats (:data:`ctui.engine.actions.formats.FORMATS`, the registry the CLI and the TUI read): ``dicom-seg`` (highdicom, over the source series' SOP
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

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.actions.formats import FORMATS, ExportFormat, unsupported
from ctui.engine.actions.opened import Opened, existing_path, input_kind, open_project
from ctui.engine.core.atomic import check_output
from ctui.engine.core.colors import object_color
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.progress import Progress, report, scaled
from ctui.engine.core.volume import Volume
from ctui.engine.io.imports import is_label_file, read_label_file
from ctui.engine.io.series import load
from ctui.engine.segment.selection import label_counts

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
    ids = [int(i) for i in np.flatnonzero(label_counts(np.asarray(labels, np.uint8))) if i]  # not bincount: 8 B a voxel
    out = []
    for i in ids:
        o = info.get(i, {})
        out.append({"id": i, "name": str(o.get("name") or f"object {i}"),
                    "color": [int(c) for c in (o.get("color") or object_color(i))][:3]})
    return out


def _load_series(series: str, series_uid: str | None) -> Any:
    return load(existing_path(series, "series folder or file"), **({"series": series_uid} if series_uid else {}))


def export_source(source: str | os.PathLike | Opened, *, series: str | os.PathLike | None = None,
                  series_uid: str | None = None) -> ExportSource:
    """The labels, geometry and objects an export works on (see the module docstring)."""
    if isinstance(source, Opened):
        return _from_opened(source, series, series_uid)
    p = existing_path(source, "file")
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


# =========================================================================== one export
@dataclass
class ExportJob:
    """What a writer (:attr:`ExportFormat.write`) gets: the file ``path``, the ``src``,
    the objects ``objs`` [{id, name, color}] to write and their ``ids``, ``labels`` (z, y,
    x) uint8 holding only those objects, and the options."""

    path: Path
    src: ExportSource
    objs: list[dict]
    labels: np.ndarray
    keep_identifiers: bool = False
    mesh_method: str | None = None
    progress: Progress | None = None

    @property
    def ids(self) -> list[int]:
        return [o["id"] for o in self.objs]

    def masks(self) -> dict[int, np.ndarray]:
        """Full masks of the written objects that overlap others (DICOM keeps them overlapping)."""
        return {k: m for k, m in self.src.masks.items() if k in self.ids}

    def grid(self) -> Volume:
        """The labels as a Volume on their geometry (what the label-map writers take)."""
        g = self.src.geometry
        return Volume(self.labels, spacing=g.spacing, origin=g.origin, direction=g.direction, modality="SEG",
                      window=(5, 10))


def series_kind(src: ExportSource | Opened) -> str | None:
    """The format of the series the labels were drawn on, as :func:`formats.unsupported`
    takes it: ``"dicom"``, ``"nifti"``...; ``""`` when there is none (labels only, or the
    recorded series is gone); None when only loading it would tell."""
    volume = src.volume
    if volume is not None and not (volume.meta or {}).get("labels_only"):
        return str((volume.meta or {}).get("format") or "") or None
    if isinstance(src, Opened):
        proj = src.project
        series = str(proj.source_path or "") if proj is not None else ""
    else:
        series = src.series
    return None if series and os.path.exists(series) else ""


def available_formats(source: ExportSource | Opened) -> list[tuple[ExportFormat, str | None]]:
    """Every registered format with the reason it cannot be written for ``source`` (None when it can)."""
    kind = series_kind(source)
    return [(fmt, unsupported(name, series_kind=kind)) for name, fmt in FORMATS.items()]


def export(source: str | os.PathLike | Opened, *, format: str, out: str | os.PathLike,
           series: str | os.PathLike | None = None, series_uid: str | None = None,
           objects: int | Sequence[int] | None = None, keep_identifiers: bool = False,
           mesh_method: str | None = None, progress: Progress | None = None) -> ExportResult:
    """Write ``source``'s objects to ``out`` in ``format`` (a name in :data:`formats.FORMATS`).

    ``series``: the DICOM series the labels were drawn on (DICOM-SEG, RTSTRUCT; also puts a
    label file on that series' grid); ``series_uid`` picks one series in a folder of several.
    ``objects``: ids to export (default all). Returns an :class:`ExportResult`.
    """
    fmt = str(format).lower()
    if fmt not in FORMATS:
        raise CtuiError(f"unknown format {format!r} (one of {', '.join(FORMATS)})")
    report(progress, 0.0, 1.0, "reading")
    check_output(out, inputs=[source.path if isinstance(source, Opened) else source, series], label="the output")
    src = export_source(source, series=series, series_uid=series_uid)
    why = unsupported(fmt, series_kind=series_kind(src))
    if why:
        raise CtuiError(f"{FORMATS[fmt].title} {why}", path=src.path, option="series")
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
        check_output(out, inputs=[src.series], label="the output")
    res = ExportResult(fmt, os.fspath(out), [{"id": o["id"], "name": o["name"]} for o in objs],
                       warnings=list(src.notes))
    p = Path(out)
    spec = FORMATS[fmt]
    if spec.strict_suffix and not p.name.lower().endswith(spec.suffixes):
        raise CtuiError(f"a {spec.title} file name ends in {' or '.join(spec.suffixes)}", path=p)
    rows = spec.write(ExportJob(p, src, objs, labels, keep_identifiers, mesh_method, scaled(progress, 0.1, 1.0)))
    res.rows = list(rows or [])
    report(progress, 1.0, 1.0, f"wrote {p.name}")
    return res
