"""Sessions to projects and back, and the engine's view of a session (an ``Opened``)
for the actions the screens call (measure, export)."""

from __future__ import annotations

from typing import Any, cast

from ctui.engine.actions.opened import Opened
from ctui.engine.actions.project import new_project, propagation_record
from ctui.engine.core.errors import CtuiError
from ctui.engine.actions.series import Pipeline, Segmentation
from ctui.engine.actions import defaults, edit as edittools
from ctui.screens.planes import PLANES
from ctui.screens.session import PanelOptions, Session


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
        if meta.get("brush") is not None:
            s.brush = float(min(max(float(meta["brush"]), 0.1), 50.0))  # mm, as set (3.22266 stays 3.22266)
        sl, vl = meta.get("limit_slices"), meta.get("limit_values")
        nz = s.shape[0]
        if sl and 0 <= int(sl[0]) <= int(sl[1]) < nz:
            s.limits.slices = (int(sl[0]), int(sl[1]))
        if vl and float(vl[0]) <= float(vl[1]):
            s.limits.values = (float(vl[0]), float(vl[1]))
    except (TypeError, ValueError, IndexError):
        pass


#: The segmentation panel's options a project keeps (``Session.segment_options``) and the type of each.
_OPTION_TYPES: dict[str, type | tuple[type, ...]] = {"method": str, "neck": (int, float), "fill_holes": bool, "keep_largest": bool,
                 "min_island": int, "interpolate": bool}


def _setup_meta(s: Session) -> dict:
    """The set-up a project reopens with, beyond the labels: the G panel's options, background
    seeds, the ROI box and the zoom (all optional in ``meta``; older projects open without them)."""
    opts: dict[str, Any] = {k: v for k, v in s.segment_options.items() if k in _OPTION_TYPES or k == "range"}
    if isinstance(opts.get("range"), tuple):
        opts["range"] = list(opts["range"])
    return {"segment_options": opts, "background_seeds": [list(map(int, p)) for p in s.background_seeds],
            "roi_box": [list(map(int, r)) for r in s.roi_box] if s.roi_box is not None else None,
            "zoom": float(s.zoom)}


def _setup_from_meta(s: Session, meta: dict) -> None:
    """The set-up saved by :func:`_setup_meta`; each field checked (type, inside the volume) and
    skipped when odd, so a hand-edited or older project still opens."""
    opts = meta.get("segment_options")
    if isinstance(opts, dict):
        kept = {k: v for k, v in opts.items() if k in _OPTION_TYPES and isinstance(v, _OPTION_TYPES[k])
                and (_OPTION_TYPES[k] is bool or not isinstance(v, bool))}
        rng = opts.get("range")
        if rng in ("auto", "given"):
            kept["range"] = rng
        elif isinstance(rng, list) and len(rng) == 2 and all(isinstance(v, (int, float)) for v in rng) and rng[0] <= rng[1]:
            kept["range"] = (float(rng[0]), float(rng[1]))
        s.segment_options = cast(PanelOptions, kept)  # each key checked against _OPTION_TYPES above
    shape = s.shape
    seeds = meta.get("background_seeds")
    if isinstance(seeds, list):
        s.background_seeds = [(int(x), int(y), int(z)) for x, y, z in (p for p in seeds if _ints(p, 3))
                              if 0 <= x < shape[2] and 0 <= y < shape[1] and 0 <= z < shape[0]]
    box = meta.get("roi_box")
    if isinstance(box, list) and len(box) == 3 and all(_ints(r, 2) for r in box) \
            and all(0 <= r[0] <= r[1] < n for r, n in zip(box, shape)):
        s.roi_box = tuple((int(r[0]), int(r[1])) for r in box)  # type: ignore[assignment]  # 3 pairs, checked
    zoom = meta.get("zoom")
    if isinstance(zoom, (int, float)) and 1.0 <= zoom <= 16.0:
        s.zoom = float(zoom)


def _ints(v, n: int) -> bool:
    return isinstance(v, list) and len(v) == n and all(isinstance(u, int) and not isinstance(u, bool) for u in v)


def _meta_int(meta: dict, key: str, default: int) -> int:
    """``meta[key]`` as an int (a cursor coordinate the project recorded), else ``default``."""
    v = meta.get(key)
    return int(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else default


def project_from_session(s: Session):
    """A ctui.engine.io.project.Project of the session's state (built by the one project
    constructor, :func:`ctui.engine.actions.project.new_project`)."""
    seg = s.seg
    prop = {"tolerance": s.tolerance, "range": list(s.range_) if s.range_ else None, "connectivity": s.connectivity}
    return new_project(
        s.volume, source_path=str(s.source_path or ""), source_options=dict(s.source_options or {}),
        pipeline=s.pipeline.to_dict(),
        labels=seg.labels, objects=seg.object_list(),
        propagation=propagation_record([prop], current=s.current, mode=s.prop_mode),
        drift=dict(s.drift_info or {}), window=tuple(s.window),
        meta={"z": s.z, "x": s.x, "y": s.y, "view": s.view, "plane": s.plane, "edit_mode": s.edit_mode,
              "brush": s.brush, "limit_slices": list(s.limits.slices) if s.limits.slices else None,
              "limit_values": list(s.limits.values) if s.limits.values else None, **_setup_meta(s)},
        data=s.original_data,  # the voxels as loaded (before a drift correction)
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
                z=_meta_int(meta, "z", volume.shape[0] // 2), x=_meta_int(meta, "x", volume.shape[2] // 2),
                y=_meta_int(meta, "y", volume.shape[1] // 2))
    if proj.window:
        s.window = (float(proj.window[0]), float(proj.window[1]))
    s.tolerance = float(prop.get("tolerance", s.tolerance))
    s.range_ = tuple(prop["range"]) if prop.get("range") else None
    s.connectivity = int(prop.get("connectivity", 8))
    s.prop_mode = str(prop["mode"]) if prop.get("mode") in defaults.PROPAGATION_MODES else defaults.PROPAGATION_MODE
    s.current = int(prop.get("current", min(seg.objects) if seg.objects else 1))
    s.view = str(meta.get("view", s.view))
    _editing_from_meta(s, meta)
    _setup_from_meta(s, meta)
    s.drift_info = dict(proj.drift or {})
    s.project_path = path
    if (volume.meta or {}).get("labels_only"):
        s.source_identity = {"geometry": proj.geometry, "modality": proj.modality, "series_uid": proj.series_uid,
                             "voxel_hash": proj.voxel_hash}
    return s
