"""Objects -> meshes: :func:`mesh_objects` (projects, label maps, series + iso, MRIC), the one
path the CLI (``ctui mesh``, ``ctui render``) and the TUI (3D view, export) build surfaces by."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.actions.opened import Opened, open_input
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.meshdata import Mesh
from ctui.engine.core.progress import Progress, report
from ctui.engine.io.meshes import FORMATS as MESH_SUFFIXES  # noqa: F401 - re-exported with save_mesh for ctui mesh --out
from ctui.engine.io.meshes import save_mesh  # noqa: F401 - re-exported (above)
from ctui.engine.io.mric import read_mric, require_spacing
from ctui.engine.mesh import meshtools
from ctui.engine.mesh.surface import isosurface, label_surfaces
from ctui.engine.mesh.warm import warm_up  # noqa: F401 - re-exported: the TUI compiles the mesh kernels while the user looks


def _contour_tools() -> tuple:
    """(connect_contours, object_borders), imported when the contours method runs: the tiler
    imports numba and the borders OpenCV (0.3-0.6 s a process, unused by marching cubes)."""
    from ctui.engine.core.borders import object_borders
    from ctui.engine.mesh.contour_connect import connect_contours

    return connect_contours, object_borders


@dataclass
class MeshResult:
    """Surfaces of one meshing action: ``meshes`` {object id: Mesh} (id 0 for an
    isosurface or MRIC surface), ``mesh`` all of them merged, and its report."""

    meshes: dict[int, Mesh]
    mesh: Mesh
    kind: str
    method: str
    objects: list[int] = field(default_factory=list)
    iso: float | None = None
    notes: list[str] = field(default_factory=list)
    source_series: str = ""  # a project's series folder: never an output's home

    @property
    def report(self) -> dict:
        return meshtools.mesh_report(self.mesh)

    def to_dict(self) -> dict:
        """The JSON of ``ctui mesh --json`` (without ``out``)."""
        rep = self.report
        d: dict[str, Any] = {
            "triangles": rep["triangles"], "vertices": rep["vertices"], "watertight": rep["watertight"],
            "volume_ml": round(rep["volume_ml"], 4), "area_mm2": round(rep["area_mm2"], 2),
            "components": rep["components"], "boundary_edges": rep["boundary_edges"],
            "non_manifold_edges": rep["non_manifold_edges"], "kind": self.kind, "method": self.method,
        }
        if self.kind in ("project", "labels"):
            d["objects"] = list(self.objects)
        if self.iso is not None:
            d["iso"] = self.iso
        if self.notes:
            d["notes"] = list(self.notes)
        return d


def label_meshes(labels: np.ndarray, geometry: Geometry, ids: Sequence[int], *, method: str = defaults.MESH_METHOD,
                 terraced: bool = False, tiling: str = defaults.CONTOUR_TILING,
                 progress: Progress | None = None) -> dict[int, Mesh]:
    """{id: Mesh} of the objects ``ids`` of a label map on ``geometry`` (patient mm)."""
    g = geometry
    if method == "contours":
        connect_contours, object_borders = _contour_tools()
        out = {}
        for n, k in enumerate(ids):
            m = connect_contours(object_borders(labels, k), spacing=g.spacing, origin=g.origin,
                                 direction=g.direction, method=tiling)
            m.object_id = k
            out[k] = m
            report(progress, n + 1, len(ids), f"object {k}")
        return out
    surf = label_surfaces(labels, spacing=g.spacing, origin=g.origin, direction=g.direction, smooth=not terraced,
                          objects=list(ids), progress=progress)
    out = {k: surf[k] for k in ids if k in surf}
    for k, m in out.items():
        m.object_id = k
    return out


def connect_mric(path: str | os.PathLike, *, object_index: int | None = None,
                 spacing: Sequence[float] | None = None, origin: Sequence[float] | None = None,
                 direction: np.ndarray | None = None, method: str = defaults.CONTOUR_TILING) -> Mesh:
    """Surface from an MRIC contour file (:func:`ctui.engine.io.mric.read_mric`).

    MRIC stores no object ids and no geometry: by default every border of every slice
    is used (objects are disjoint, so they become separate closed components);
    ``object_index`` (1-based) takes the N-th object list of each slice, as stored.
    Holes are recognised by their clockwise orientation (negative shoelace area).
    """
    data = read_mric(path)
    # the file's own geometry (sidecar <name>.mric.json), or the user's spacing; never a silent 1 mm
    spacing = require_spacing(data, path, spacing)
    origin = origin if origin is not None else data.origin
    direction = direction if direction is not None else data.direction
    per_slice = []
    for objs in data.slices:
        if object_index is None:
            per_slice.append([b for o in objs for b in o])
        else:
            k = int(object_index) - 1
            per_slice.append(list(objs[k]) if 0 <= k < len(objs) else [])
    connect_contours, _ = _contour_tools()
    return connect_contours(per_slice, spacing=spacing, origin=origin, direction=direction, method=method)


def _series_mesh(opened: Opened, iso: float | None, method: str, tiling: str,
                 progress: Progress | None = None) -> Mesh:
    vol = opened.volume
    assert vol is not None
    if iso is None:
        raise CtuiError("a series needs an iso value (e.g. 300 HU for bone in CT)", path=opened.path, option="iso")
    if not np.isfinite(iso) or abs(iso) > 1e9:
        raise CtuiError(f"iso value {iso!r}: want a finite value within +-1e9", path=opened.path, option="iso")
    if method == "contours":
        connect_contours, object_borders = _contour_tools()
        mask = (vol.data > iso).astype(np.uint8)
        mesh = connect_contours(object_borders(mask, 1), spacing=vol.spacing, origin=vol.origin,
                                direction=vol.direction, method=tiling)
    else:
        mesh = isosurface(vol.data, iso, spacing=vol.spacing, origin=vol.origin, direction=vol.direction, close=True,
                          progress=progress)
    if mesh.n_faces == 0:
        lo, hi = vol.value_range()
        raise CtuiError(f"no surface at iso value {iso:g} (values range {lo:g} .. {hi:g})", path=opened.path,
                        option="iso")
    return mesh


def mesh_objects(source: str | os.PathLike | Opened, *, objects: int | Sequence[int] | None = None,
                 method: str | None = None, iso: float | None = None, terraced: bool = False,
                 tiling: str = defaults.CONTOUR_TILING, smooth: int = defaults.MESH_SMOOTH_ITERATIONS,
                 decimate: int | None = None, spacing: Any = None, progress: Progress | None = None,
                 **load_options: Any) -> MeshResult:
    """Surfaces in patient mm of a project's / label map's objects, a series' isosurface
    (``iso``) or an MRIC file's contours.

    ``source`` is a path or an :class:`Opened` (the TUI passes its session's labels).
    ``method`` "marching-cubes" (default; smoothed signed distance, or ``terraced``
    plain marching cubes of the label map) or "contours" (default for MRIC);
    ``smooth`` Taubin iterations and ``decimate`` a triangle target apply afterwards.
    ``spacing`` (dz, dy, dx) mm: MRIC files (which store none) and old projects without
    geometry whose series is gone.
    """
    if smooth < 0:
        raise CtuiError(f"smoothing {smooth}: must be 0 or more iterations", option="smooth")
    if decimate is not None and decimate < 4:
        raise CtuiError(f"decimation to {decimate} triangles: need at least 4", option="decimate")
    if isinstance(source, Opened):
        opened = source
    else:
        p = os.fspath(source)
        # --iso asks for a series: a NIfTI/NRRD CT is a series then, not a label map (as info/render/segment)
        as_series = iso is not None and p.lower().endswith((".nii", ".nii.gz", ".nrrd", ".nhdr"))
        opened = open_input(p, kind="series" if as_series else None, require_labels=not as_series,
                            spacing=spacing if not p.lower().endswith(".mric") else None, **load_options)
    kind = opened.kind
    method = method or ("contours" if kind == "mric" else defaults.MESH_METHOD)
    if method not in defaults.MESH_METHODS:
        raise CtuiError(f"unknown surface method {method!r} ({' or '.join(defaults.MESH_METHODS)})", option="method")
    res = MeshResult({}, Mesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)), kind, method,
                     notes=list(opened.notes),
                     source_series=str(opened.project.source_path or "") if opened.project is not None else "")
    if kind == "mric":
        if method != "contours":
            raise CtuiError("an MRIC file holds contours only: mesh it with the contours method", path=opened.path,
                            option="method")
        if iso is not None:
            raise CtuiError("an iso value applies to a series, not to an MRIC file", path=opened.path, option="iso")
        obj = objects if isinstance(objects, (int, np.integer)) or objects is None else objects[0]
        mesh = connect_mric(opened.path, object_index=obj, spacing=spacing, method=tiling)
        if mesh.n_faces == 0:
            raise CtuiError("no contour found" + (f" for object {obj}" if obj else ""), path=opened.path)
        res.meshes = {0: mesh}
    elif kind in ("project", "labels"):
        if iso is not None:
            raise CtuiError("an iso value applies to a series; a project's objects are meshed from their labels",
                            path=opened.path, option="iso")
        if terraced and method == "contours":
            raise CtuiError("terraced surfaces come from marching cubes, not from the contours method",
                            option="terraced")
        assert opened.labels is not None and opened.geometry is not None
        res.objects = opened.pick_objects(objects)
        res.meshes = label_meshes(opened.labels, opened.geometry, res.objects, method=method, terraced=terraced,
                                  tiling=tiling, progress=progress)
    elif kind == "series":
        res.meshes = {0: _series_mesh(opened, iso, method, tiling, progress)}
        res.iso = iso
    else:
        raise CtuiError(f"cannot mesh a {kind} file", path=opened.path)
    parts = [res.meshes[k] for k in sorted(res.meshes)]
    for part in parts:  # a mesh-level note
        note = (part.meta or {}).get("note")
        if note and note not in res.notes:
            res.notes.append(str(note))
    mesh = parts[0] if len(parts) == 1 and kind in ("series", "mric") else meshtools.merge(
        parts, object_id=res.objects[0] if len(res.objects) == 1 else 0, meta={"method": method})
    if smooth:
        mesh = meshtools.smooth_taubin(mesh, iterations=smooth)
    if decimate:
        mesh = meshtools.decimate(mesh, decimate)
    res.mesh = mesh
    return res
