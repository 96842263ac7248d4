"""Sessions to projects and back, and the engine's view of a session (an ``Opened``)
for the actions the screens call (measure, export)."""

from __future__ import annotations

from ctui.engine.actions.opened import Opened
from ctui.engine.actions.project import new_project, propagation_record
from ctui.engine.core.errors import CtuiError
from ctui.engine.actions.series import Pipeline, Segmentation
from ctui.engine.actions import edit as edittools
from ctui.screens.planes import PLANES
from ctui.screens.session import Session


def opened_of(s: Session) -> Opened:
    """The session as the actions see an opened project: its volume, labels, objects."""
    return Opened.of_volume(s.volume, s.labels(), path=str(s.project_path or s.source_path or "ctui"),
                            project=project_from_session(s))


def _editing_from_meta(s: Session, meta: dict) -> None:
    """Plane, edit mode, brush and limits saved in a project's meta (ignored when odd)."""
    if meta.get("plane") in PLANES:
        s.plane = str(meta["plane"])
    if meta.get("edit_mode") in edittools.MODES:
        s.edit_mode = str(meta["edit_mode"])
    try:
        s.brush = int(min(max(int(meta.get("brush", s.brush)), 0), 50))
        sl, vl = meta.get("limit_slices"), meta.get("limit_values")
        nz = s.shape[0]
        if sl and 0 <= int(sl[0]) <= int(sl[1]) < nz:
            s.limits.slices = (int(sl[0]), int(sl[1]))
        if vl and float(vl[0]) <= float(vl[1]):
            s.limits.values = (float(vl[0]), float(vl[1]))
    except (TypeError, ValueError, IndexError):
        pass


def project_from_session(s: Session):
    """A ctui.engine.io.project.Project of the session's state (built by the one project
    constructor, :func:`ctui.engine.actions.project.new_project`)."""
    seg = s.seg
    prop = {"tolerance": s.tolerance, "range": list(s.range_) if s.range_ else None, "connectivity": s.connectivity}
    return new_project(
        s.volume, source_path=str(s.source_path or ""), source_options=dict(s.source_options or {}),
        pipeline=s.pipeline.to_dict() if s.pipeline is not None else {},
        labels=getattr(seg, "labels", None), objects=seg.object_list() if seg is not None else [],
        propagation=propagation_record([prop], current=s.current, mode=s.prop_mode),
        drift=dict(s.drift_info or {}), window=tuple(s.window),
        meta={"z": s.z, "x": s.x, "y": s.y, "view": s.view, "plane": s.plane, "edit_mode": s.edit_mode,
              "brush": s.brush, "limit_slices": list(s.limits.slices) if s.limits.slices else None,
              "limit_values": list(s.limits.values) if s.limits.values else None},
        data=getattr(s, "original_data", None),  # the voxels as loaded (before a drift correction)
        identity=s.source_identity)  # labels only: the missing series' identity, not the stand-in's


def session_from_project(proj, volume, path: str) -> Session:
    """Rebuild a Session from a loaded Project and its source volume."""
    labels = proj.labels
    if labels is not None and tuple(labels.shape) != tuple(volume.shape):
        raise CtuiError(f"labels {labels.shape} do not match the series {volume.shape}", path=path)
    seg = Segmentation(volume.shape, labels=labels, objects=proj.objects or [])
    prop = proj.propagation or {}
    meta = proj.meta or {}
    s = Session(volume, source_path=proj.source_path, source_options=dict(proj.source_options or {}),
                pipeline=Pipeline.from_dict(proj.pipeline or {}), seg=seg,
                z=meta.get("z"), x=meta.get("x"), y=meta.get("y"))
    if proj.window:
        s.window = (float(proj.window[0]), float(proj.window[1]))
    s.tolerance = float(prop.get("tolerance", s.tolerance))
    s.range_ = tuple(prop["range"]) if prop.get("range") else None
    s.connectivity = int(prop.get("connectivity", 8))
    s.prop_mode = str(prop.get("mode", "slice")) if prop.get("mode") in ("slice", "3d") else "slice"
    s.current = int(prop.get("current", min(seg.objects) if seg.objects else 1))
    s.view = str(meta.get("view", s.view))
    _editing_from_meta(s, meta)
    s.drift_info = dict(proj.drift or {})
    s.project_path = path
    if (volume.meta or {}).get("labels_only"):
        s.source_identity = {"geometry": proj.geometry, "modality": proj.modality, "series_uid": proj.series_uid,
                             "voxel_hash": proj.voxel_hash}
    return s
