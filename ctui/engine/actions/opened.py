"""Open anything ctui reads: a series, a ``.ctui`` project, a label map, a mesh, an MRIC file.

:func:`open_input` returns an :class:`Opened` carrying the volume (series), or the labels
and their :class:`~ctui.engine.core.geometry.Geometry` (project, label map), or the mesh.
A project stands on its own: its labels come with the geometry it recorded, so measure,
mesh, render and drift work when the series has moved; the series is loaded only when
asked for (``with_series``) or when an old project recorded no geometry, and a series
whose voxels no longer match the project's hash is refused.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.core.assumptions import note_of
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.meshdata import Mesh
from ctui.engine.core.volume import Volume
from ctui.engine.io import memplan
from ctui.engine.io.imports import is_label_file, label_kind, read_label_file
from ctui.engine.io.memplan import MemoryPlan
from ctui.engine.io.meshes import load_mesh
from ctui.engine.io.project import Project, load_project, source_load_options, voxel_hash
from ctui.engine.io.series import load

KINDS = ("series", "project", "labels", "mesh", "mric")


def input_kind(path: str | os.PathLike) -> str:
    """"project", "labels", "mesh", "mric" or "series" from the file name."""
    low = os.fspath(path).lower()
    if low.endswith(defaults.PROJECT_SUFFIXES):
        return "project"
    if low.endswith(defaults.MRIC_SUFFIXES):
        return "mric"
    if low.endswith(defaults.MESH_SUFFIXES):
        return "mesh"
    if low.endswith(defaults.LABEL_SUFFIXES) and not os.path.isdir(path):
        return "labels"
    if os.path.isfile(path) and is_label_file(path):  # a DICOM-SEG or RTSTRUCT file
        return "labels"
    return "series"


@dataclass
class Opened:
    """What :func:`open_input` found.

    kind : one of :data:`KINDS`; volume : the series (kind "series", or a project's source
    when loaded); labels (z, y, x) uint8 and geometry : of a project or label map; mesh :
    of a mesh file; project : the loaded Project; notes : things the user should know
    (e.g. "source series not found: geometry from the project").
    """

    kind: str
    path: str
    volume: Volume | None = None
    labels: np.ndarray | None = None
    geometry: Geometry | None = None
    mesh: Mesh | None = None
    project: Project | None = None
    notes: list[str] = field(default_factory=list)
    masks: dict[int, np.ndarray] = field(default_factory=dict)  # full masks of overlapping imported segments

    def mask(self, object_id: int) -> np.ndarray:
        """Object ``object_id``'s bool mask (z, y, x): its own full mask where imported segments overlap."""
        m = self.masks.get(int(object_id))
        return m if m is not None else np.asarray(self.labels) == int(object_id)

    @property
    def object_ids(self) -> list[int]:
        """Ids present in the labels, ascending."""
        if self.labels is None:
            return []
        from ctui.engine.segment.selection import label_counts  # cv2's histogram: opened loads at start-up

        counts = label_counts(np.asarray(self.labels, np.uint8))  # not np.bincount: an int64 copy, 8 B a voxel
        ids = {int(i) for i in np.flatnonzero(counts[1:]) + 1}
        return sorted(ids | {int(k) for k, m in self.masks.items() if m.any()})  # + segments hidden by overlaps

    def pick_objects(self, requested: int | list[int] | None = None) -> list[int]:
        """The requested ids (all present when None); CtuiError naming the file otherwise."""
        present = self.object_ids
        if not present:
            raise CtuiError("no object in the label volume", path=self.path)
        if requested is None:
            return present
        want = [int(requested)] if isinstance(requested, (int, np.integer)) else [int(v) for v in requested]
        missing = [v for v in want if v not in present]
        if missing:
            raise CtuiError(f"no object {', '.join(map(str, missing))} (objects present: "
                            f"{', '.join(map(str, present))})", path=self.path)
        return want

    def object_colors(self) -> dict[int, Any]:
        objs = self.project.objects if self.project is not None else []
        return {int(o["id"]): o.get("color") for o in objs or [] if isinstance(o, dict) and "id" in o}

    @classmethod
    def of_volume(cls, volume: Volume, labels: np.ndarray | None = None, *, path: str = "",
                  project: Project | None = None) -> "Opened":
        """What the TUI holds: a loaded series and (optionally) its label volume."""
        return cls("project" if labels is not None else "series", path, volume=volume,
                   labels=None if labels is None else np.asarray(labels), geometry=Geometry.of(volume),
                   project=project)

    def to_dict(self) -> dict:
        d: dict[str, Any] = {"kind": self.kind, "input": os.path.basename(self.path), "notes": list(self.notes)}
        if self.geometry is not None:
            d["geometry"] = self.geometry.to_dict()
        if self.labels is not None:
            d["objects"] = self.object_ids
        if self.volume is not None:
            d["volume"] = self.volume.describe()
        if self.mesh is not None:
            d["mesh"] = {"triangles": int(self.mesh.n_faces), "vertices": int(self.mesh.n_vertices)}
        return d


def existing_path(path: str | os.PathLike, what: str = "file or folder") -> str:
    """``path`` as a string, or a one-line CtuiError "no such <what>" when nothing is there."""
    p = os.fspath(path)
    if not os.path.exists(p):
        raise CtuiError(f"no such {what}", path=p)
    return p


def open_input(path: str | os.PathLike, *, kind: str | None = None, with_series: bool | None = None,
               require_labels: bool = False, spacing: Any = None, labels: str | os.PathLike | None = None,
               **load_options: Any) -> Opened:
    """Open ``path`` (kind guessed from the name unless given).

    ``load_options`` (and ``spacing``) go to :func:`ctui.engine.io.series.load` for a series;
    for a project, ``spacing`` stands in for the geometry of an old project without one.
    ``with_series`` (projects): True loads the source series (error when it is gone),
    None loads it only when the project recorded no geometry, False never.
    ``require_labels``: a project without a label volume is an error.
    ``labels``: a label file (DICOM-SEG, RTSTRUCT, NIfTI, NRRD) opened over the series
    ``path``: :func:`open_with_labels`. A label file as ``path`` opens on its own geometry.
    """
    if labels is not None:
        return open_with_labels(path, labels, spacing=spacing, **load_options)
    p = os.fspath(path)
    if not p or not os.path.exists(p):
        raise CtuiError("no such file or folder", path=p or "(empty path)")
    kind = kind or input_kind(p)
    if kind == "project":
        return open_project(p, with_series=with_series, require_labels=require_labels, spacing=spacing)
    if kind == "labels":
        imp = read_label_file(p)
        return Opened("labels", p, labels=imp.labels, geometry=imp.geometry, notes=list(imp.warnings),
                      project=Project(labels=imp.labels, objects=imp.objects), masks=imp.masks)
    if kind == "mesh":
        return Opened("mesh", p, mesh=load_mesh(p))
    if kind == "mric":
        return Opened("mric", p)
    if kind != "series":
        raise ValueError(f"unknown input kind {kind!r}")
    if spacing is not None:
        load_options["spacing"] = spacing
    volume = load(p, **load_options)
    return Opened("series", p, volume=volume, notes=assumed(volume))


def assumed(volume: Volume | None) -> list[str]:
    """One note per thing the loader assumed in place of the file (spacing, slices,
    orientation, values: ``Volume.assumptions``), for every command's report."""
    return [note_of(a) for a in volume.assumptions] if volume is not None else []


def memory_plan(command: str, path: Any, *, overview: bool = False, **load_options: Any) -> MemoryPlan:
    """The memory plan of ``command`` on the series at ``path`` (``io/memplan``: from the
    headers, before loading): ``mode`` "memory", "overview" (only when ``overview``: the
    command may work from a ``downsample``-times coarser copy), "refuse" (``reason``: one line
    naming what would fit) or "unknown" (not a series). ``load_options["memory_limit"]``: the limit."""
    first = path[0] if isinstance(path, (list, tuple)) and path else path
    if not first or input_kind(os.fspath(first)) in ("project", "mesh", "mric"):  # (a .nii.gz may be either)
        return MemoryPlan(command, "unknown", "not a series")
    return memplan.plan(command, first, memory=load_options.pop("memory_limit", None), overview=overview,
                        **load_options)


def series_available(project: Project) -> bool:
    """True when the project names a source that exists (an empty path never does)."""
    src = str(project.source_path or "").strip()
    return bool(src) and os.path.exists(src)


def load_source(project: Project, path: str) -> Volume:
    """The project's source series, checked against the project (shape, voxel hash)."""
    if not series_available(project):
        raise CtuiError(f"the source series {project.source_path!r} is missing", path=path)
    vol = load(project.source_path, **source_load_options(project))
    check_source(project, vol, path)
    return vol


def check_source(project: Project, volume: Volume, path: str) -> None:
    """CtuiError when ``volume`` is not the series the project was segmented on."""
    if project.labels is not None and tuple(project.labels.shape) != tuple(volume.shape):
        raise CtuiError(f"labels {tuple(project.labels.shape)} do not match the source series "
                        f"{tuple(volume.shape)}", path=path)
    if project.voxel_hash and voxel_hash(volume.data) != project.voxel_hash:
        raise CtuiError(f"the series at {project.source_path} no longer matches the project (its voxels "
                        "changed since the project was saved); put the original series back or open the "
                        "project without it", path=path)


def open_project(path: str, *, with_series: bool | None = None, require_labels: bool = False,
                 spacing: tuple[float, float, float] | None = None) -> Opened:
    """A project's labels with their geometry (from the project, else from its series;
    ``spacing`` (dz, dy, dx) mm for an old project that recorded none and lost its series)."""
    project = load_project(path)
    if require_labels and project.labels is None:
        raise CtuiError("the project holds no label volume (segment an object first)", path=path)
    out = Opened("project", path, labels=project.labels, geometry=project.geometry, project=project)
    need = with_series or (with_series is None and project.geometry is None)
    if need and series_available(project):
        out.volume = load_source(project, path)
        out.notes += assumed(out.volume)
        if out.geometry is None:
            out.geometry = Geometry.of(out.volume)
    elif with_series:
        raise CtuiError(f"the source series {project.source_path!r} is missing (this needs its grey levels)",
                        path=path)
    elif project.geometry is None and project.labels is not None and spacing is not None:
        out.geometry = Geometry(tuple(project.labels.shape), spacing)
        out.notes.append(f"source series {project.source_path or '(none)'} not found: geometry from the given spacing "
                         "(origin 0, identity direction)")
    elif project.geometry is None:
        if project.labels is not None:
            raise CtuiError(f"the source series {project.source_path!r} is missing and the project records no "
                            "geometry (an old project: give its voxel spacing dz,dy,dx, or re-save it with its series)",
                            path=path, option="spacing")
    elif not series_available(project):
        out.notes.append(f"source series {project.source_path or '(none)'} not found: geometry from the project")
    if out.volume is None:  # what the loader assumed when the project was made, as recorded
        out.notes += [f"assumed ({a.get('kind')}): {a.get('text')}" for a in (project.meta or {}).get("assumptions") or []
                      if isinstance(a, dict)]
    return out


def open_with_labels(series: str | os.PathLike, labels: str | os.PathLike, *, spacing: Any = None,
                     **load_options: Any) -> Opened:
    """A series with a label file placed on its grid (``ctui open|measure|mesh|render SERIES --labels FILE``).

    ``series``: any volume input (a DICOM series, or a NIfTI / NRRD / MetaImage volume: a
    .nii.gz given here is read as grey levels, not as labels). The label file's geometry
    must match the series' (affines equal within 2% of a voxel; whole-voxel offsets and
    axis flips are placed; a CtuiError says how they differ otherwise); its
    segments / ROIs / values become objects with their names and colours (``project.objects``).
    """
    s, lp = os.fspath(series), os.fspath(labels)
    for q in (s, lp):
        if not q or not os.path.exists(q):
            raise CtuiError("no such file or folder", path=q or "(empty path)")
    kind = input_kind(s)
    if kind not in ("series", "labels") or (kind == "labels" and not s.lower().endswith(defaults.LABEL_SUFFIXES)):
        raise CtuiError("a label file goes over a volume (DICOM folder or file, NIfTI, NRRD, MetaImage...), not "
                        "over a project, mesh or DICOM-SEG/RTSTRUCT file", path=s, option="labels")
    if spacing is not None:
        load_options["spacing"] = spacing
    volume = load(s, **load_options)
    frame, instances = _series_references(s, volume, lp)
    imp = read_label_file(lp, grid=volume, frame_of_reference=frame, instances=instances)
    project = Project(source_path=os.path.abspath(s), source_options=dict(load_options), labels=imp.labels,
                      objects=imp.objects, window=tuple(volume.window) if volume.window else None)
    project.set_source(volume)
    return Opened("project", lp, volume=volume, labels=imp.labels, geometry=Geometry.of(volume), project=project,
                  notes=assumed(volume) + list(imp.warnings), masks=imp.masks)  # a series with labels: as a project (TUI's of_volume)


def _series_references(series: str, volume: Volume, labels: str) -> tuple[str, set[str]]:
    """(FrameOfReferenceUID, SOPInstanceUIDs) of the DICOM series when ``labels`` is an RTSTRUCT
    or a DICOM-SEG (what they reference is checked against them), else ("", set()) (not read:
    a header pass over the series)."""
    try:
        if label_kind(labels) not in ("rtstruct", "dicom-seg"):
            return "", set()
        from ctui.engine.io.dicomseg import source_datasets  # pydicom: only for DICOM labels over their series

        dss = source_datasets(series, volume)
        return (str(dss[0].get("FrameOfReferenceUID", "") or ""),
                {str(d.get("SOPInstanceUID", "")) for d in dss if d.get("SOPInstanceUID")})
    except (CtuiError, OSError, ValueError, IndexError):  # not a DICOM series, or not its own grid: no check
        return "", set()


def labels_only_volume(project: Project, path: str = "") -> Volume:
    """A stand-in series for a project whose series is gone (the TUI's "open labels only"):
    zeros (int16, memory of one label map x2) on the recorded geometry, with its modality
    and window; ``meta["labels_only"]`` is True. CtuiError when the project records no
    geometry or no labels."""
    g = project.geometry
    if g is None or project.labels is None:
        raise CtuiError("the project records no geometry or labels: it cannot open without its series", path=path)
    data = np.zeros(g.shape, np.int16)
    return Volume(data, spacing=g.spacing, origin=g.origin, direction=g.direction,
                  modality=project.modality or "OT", window=tuple(project.window) if project.window else (0.0, 1.0),
                  source=str(project.source_path or ""), meta={"labels_only": True},
                  warnings=[f"source series {project.source_path or '(none)'} not found: labels only (no grey levels)"])
