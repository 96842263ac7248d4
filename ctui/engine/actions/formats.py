"""Export formats and output names: the one registry that ``ctui export --format``, the
TUI's export menu and :func:`ctui.engine.actions.export.export` read.

A format is one :class:`ExportFormat` row in :data:`FORMATS`: its name (the CLI's
``--format`` value), the menu's label, the file suffixes it writes (the first is the
default), the tag of default file names (``ct.nii.gz`` -> ``ct-<tag><suffix>``), what
series it needs, and its writer ``write(job) -> rows | None`` (``job``: an
:class:`~ctui.engine.actions.export.ExportJob`). Add one with :func:`register`.

This module is plain data and small functions: ``ctui --help`` imports it to list the
choices, so each writer imports its libraries (numpy, highdicom, nibabel...) inside.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ctui.engine.actions import defaults
from ctui.engine.core.atomic import write_text
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.progress import report, scaled
from ctui.engine.core.safetext import csv_cell

#: A writer's argument: an :class:`ctui.engine.actions.export.ExportJob` (not imported here:
#: export.py imports this registry).
ExportJob = Any

#: What a format may need from the input: nothing, or the DICOM series the labels were drawn on.
NEEDS = ("", "dicom")
LABELMAP_KINDS = ("nifti", "nrrd")  # the formats a --mask label map is written in
#: Suffixes of input files, removed to get the stem that output names start from.
INPUT_SUFFIXES = (".ctui.autosave", ".ctui", ".seg.nrrd", ".nii.gz", ".nii", ".nrrd", ".nhdr", ".mha", ".mhd",
                  ".gipl.gz", ".gipl", ".dcm", ".ima", ".tiff", ".tif", ".png", ".npy", ".raw", ".gz", ".zip")


@dataclass(frozen=True)
class ExportFormat:
    """One export format (see the module docstring)."""

    name: str
    label: str
    suffixes: tuple[str, ...]
    write: Callable[[ExportJob], list[dict] | None]
    tag: str = ""
    needs: str = ""
    #: the writer checks that the file name ends in one of ``suffixes``
    strict_suffix: bool = True
    #: objects written one by one make sense (meshes): the TUI also offers "current object only"
    per_object: bool = False

    def __post_init__(self) -> None:
        if self.needs not in NEEDS:
            raise ValueError(f"export format {self.name}: needs must be one of {NEEDS}")
        if not self.suffixes or not all(s.startswith(".") for s in self.suffixes):
            raise ValueError(f"export format {self.name}: suffixes start with '.'")

    @property
    def suffix(self) -> str:
        """The default suffix."""
        return self.suffixes[0]

    @property
    def title(self) -> str:
        """The label's first part (``"NIfTI"``, ``"DICOM-SEG"``)."""
        return self.label.split(":")[0]


FORMATS: dict[str, ExportFormat] = {}


def register(fmt: ExportFormat) -> ExportFormat:
    """Add (or replace) a format in :data:`FORMATS`; returns it."""
    FORMATS[fmt.name] = fmt
    return fmt


def unregister(name: str) -> None:
    """Remove a format (tests register tiny ones)."""
    FORMATS.pop(name, None)


#: How messages name a series format.
SERIES_NAMES = {"dicom": "DICOM", "nifti": "NIfTI", "nrrd": "NRRD", "metaimage": "MetaImage", "tiff": "TIFF",
                "image-stack": "an image stack", "raw-slices": "raw slices", "raw": "raw data"}


def unsupported(name: str, *, series_kind: str | None) -> str | None:
    """Why format ``name`` cannot be written for this input (a phrase to follow the
    format's title: "needs ..."), or None when it can.

    ``series_kind``: the format of the series the labels were drawn on, as loaded
    (``"dicom"``, ``"nifti"``, ``"nrrd"``...); ``""`` when there is no series; None when
    it is not known without loading it (the writer then says what is wrong).
    """
    fmt = FORMATS[name]
    if fmt.needs == "dicom" and series_kind is not None and series_kind != "dicom":
        if not series_kind:
            return "needs the DICOM series the labels were drawn on, and this input has none"
        return (f"needs the DICOM series the labels were drawn on; this input's series is "
                f"{SERIES_NAMES.get(series_kind, series_kind)}")
    return None


def format_for_path(path: str | os.PathLike, *, kinds: tuple[str, ...] | None = None) -> ExportFormat | None:
    """The format whose suffix ends ``path`` (longest suffix first; ``kinds`` limits the
    candidates), or None."""
    name = os.fspath(path).lower()
    best = None
    for fmt in FORMATS.values():
        if kinds is not None and fmt.name not in kinds:
            continue
        for sfx in fmt.suffixes:
            if name.endswith(sfx) and (best is None or len(sfx) > best[0]):
                best = (len(sfx), fmt)
    return None if best is None else best[1]


def output_stem(source: str | os.PathLike | None, default: str = "ctui") -> str:
    """The stem output names start from: ``ct.nii.gz`` -> ``ct``, ``scan/`` -> ``scan``,
    ``kidney.ctui`` -> ``kidney`` (spaces become ``_``)."""
    text = os.fspath(source or "").rstrip("/\\")
    base = Path(text).name if text else ""
    low = base.lower()
    for sfx in INPUT_SUFFIXES:
        if low.endswith(sfx) and len(base) > len(sfx):
            base = base[: -len(sfx)]
            break
    return base.replace(" ", "_") or default


def output_name(source: str | os.PathLike | None, suffix: str, *, tag: str = "") -> str:
    """A file name for an output of ``source``: ``<stem>[-<tag>]<suffix>``
    (``ct.nii.gz``, ".ctui" -> ``ct.ctui``; ``ct.nii.gz``, ".nii.gz", tag "labels" ->
    ``ct-labels.nii.gz``)."""
    stem = output_stem(source)
    return f"{stem}-{tag}{suffix}" if tag else f"{stem}{suffix}"


# =========================================================================== writers
def _dicom_sources(job: ExportJob, what: str) -> list[Any]:
    from ctui.engine.io.dicomseg import source_datasets  # pydicom: loaded only for DICOM exports

    src = job.src
    if not src.series:
        raise CtuiError("DICOM-SEG and RTSTRUCT need the DICOM series the labels were drawn on, and none is "
                        "recorded or given", path=src.path, option="series")
    sources = source_datasets(src.series, src.volume if src.volume is not None else src.geometry,
                              series=src.series_uid)
    from ctui.engine.io.dicomrefs import require_references  # pydicom

    require_references(sources, what=what, path=src.series)
    return sources


def write_dicom_seg(job: ExportJob) -> None:
    from ctui.engine.io.dicomseg import write_seg  # highdicom: seconds to import

    write_seg(job.path, job.labels, _dicom_sources(job, "DICOM-SEG"), objects=job.objs,
              keep_identifiers=job.keep_identifiers,
              masks=job.masks(), progress=job.progress)  # overlapping segments stay overlapping


def write_rtstruct(job: ExportJob) -> None:
    from ctui.engine.io.rtstruct import write_rtstruct as write  # pydicom: loaded only for DICOM exports

    write(job.path, job.labels, job.src.geometry, _dicom_sources(job, "RTSTRUCT"), objects=job.objs,
          keep_identifiers=job.keep_identifiers, masks=job.masks(), progress=job.progress)


def write_label_map(job: ExportJob) -> None:
    from ctui.engine.io.labels import save_labels  # numpy, nibabel/pynrrd

    save_labels(job.path, job.labels, job.grid(), names={o["id"]: o["name"] for o in job.objs})


def write_mesh(job: ExportJob) -> None:
    """The objects' surfaces (each closed on its own) merged in one file, in patient mm."""
    from ctui.engine.actions.mesh import label_meshes  # the mesh stack: numpy, scipy, numba
    from ctui.engine.io.meshes import save_mesh  # numpy
    from ctui.engine.mesh.meshtools import merge  # numpy

    src, objs = job.src, job.objs
    meshes = {}
    for n, o in enumerate(objs):
        lab = src.mask(o["id"]).astype("uint8") * o["id"] if o["id"] in src.masks else src.labels
        meshes.update(label_meshes(lab, src.geometry, [o["id"]], method=job.mesh_method or defaults.MESH_METHOD,
                                   progress=scaled(job.progress, n / len(objs), (n + 1) / len(objs))))
    parts = [meshes[k] for k in sorted(meshes)]
    mesh = parts[0] if len(parts) == 1 else merge(parts, object_id=0, meta={"objects": sorted(meshes)})
    save_mesh(job.path, mesh)


def write_mric(job: ExportJob) -> None:
    """Contours of every slice over the middle slice of the series (in its display window);
    the sidecar ``<name>.mric.json`` keeps the true voxel size."""
    from ctui.engine.core.borders import borders_for_mric  # numpy, OpenCV
    from ctui.engine.core.windows import apply_window  # numpy
    from ctui.engine.io.mric import write_mric as write  # numpy

    src = job.src
    nz, ny, nx = src.labels.shape
    image = None
    if src.volume is not None and not (src.volume.meta or {}).get("labels_only"):
        image = apply_window(src.volume.data[nz // 2], tuple(src.volume.window))
    g = src.geometry
    write(job.path, borders_for_mric(job.labels, job.ids), width=nx, height=ny, image=image,
          spacing=g.spacing, origin=g.origin, direction=g.direction)


def write_csv(job: ExportJob) -> list[dict]:
    """One row of measurements per object (:data:`CSV_KEYS`); returns the rows."""
    from ctui.engine.measure.stats import object_stats  # numpy, scipy, the mesh stack

    g = job.src.geometry
    rows = []
    for n, o in enumerate(job.objs):
        report(job.progress, n, len(job.objs), f"measuring {o['name']}")
        st = object_stats(job.src.mask(o["id"]), o["id"], spacing=g.spacing, origin=g.origin, direction=g.direction)
        c = [float(v) for v in st["centroid_mm"]]
        rows.append({"id": o["id"], "name": o["name"], "voxels": st["voxels"],
                     "volume_voxels_ml": round(st["volume_voxels_ml"], 6),
                     "volume_mesh_ml": _rounded(st["volume_mesh_ml"], 6),
                     "volume_difference_percent": _rounded(st["volume_difference_percent"], 4),
                     "area_mm2": _rounded(st["area_mm2"], 4),
                     "centroid_x_mm": round(c[0], 4), "centroid_y_mm": round(c[1], 4), "centroid_z_mm": round(c[2], 4)})
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_KEYS, lineterminator="\n")
    w.writeheader()
    w.writerows({k: csv_cell(v) for k, v in r.items()} for r in rows)  # names from files: no formulas (OWASP)
    write_text(job.path, buf.getvalue())
    return rows


def _rounded(v: float | None, ndigits: int) -> float | None:
    return None if v is None else round(v, ndigits)


def write_sr(job: ExportJob) -> list[dict]:
    """A DICOM SR measurement report (TID 1500) over a DICOM-SEG written beside it (``<name>-seg.dcm``)."""
    from ctui.engine.actions.report import write_export  # the measure stack and highdicom

    return write_export(job)


CSV_KEYS = ("id", "name", "voxels", "volume_voxels_ml", "volume_mesh_ml", "volume_difference_percent", "area_mm2",
            "centroid_x_mm", "centroid_y_mm", "centroid_z_mm")

for _row in (
    ExportFormat("dicom-seg", "DICOM-SEG: all objects over the series (PACS, 3D Slicer)", (".dcm",), write_dicom_seg,
                 tag="seg", needs="dicom", strict_suffix=False),
    ExportFormat("rtstruct", "RTSTRUCT: DICOM contours of all objects (radiotherapy planning)", (".dcm",),
                 write_rtstruct, tag="rtstruct", needs="dicom", strict_suffix=False),
    ExportFormat("nifti", "NIfTI: label map", (".nii.gz", ".nii"), write_label_map, tag="labels"),
    ExportFormat("nrrd", "NRRD: label map (.seg.nrrd, a 3D Slicer segmentation)", (".seg.nrrd", ".nrrd"),
                 write_label_map, tag="labels"),
    ExportFormat("stl", "STL: object surfaces in one file", (".stl",), write_mesh, tag="objects", per_object=True),
    ExportFormat("ply", "PLY: object surfaces in one file", (".ply",), write_mesh, tag="objects", per_object=True),
    ExportFormat("obj", "OBJ: object surfaces in one file", (".obj",), write_mesh, tag="objects", per_object=True),
    ExportFormat("mric", "MRIC: contours of every slice", (".mric",), write_mric, tag="contours",
                 strict_suffix=False),
    ExportFormat("csv", "CSV: measurements of all objects", (".csv",), write_csv, tag="measurements",
                 strict_suffix=False),
    ExportFormat("sr", "DICOM SR: measurement report (TID 1500) and a DICOM-SEG beside it", (".dcm",), write_sr,
                 tag="sr", needs="dicom"),
):
    register(_row)
