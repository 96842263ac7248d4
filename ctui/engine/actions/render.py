"""Render a view: :func:`build_scene` (a mesh file, a project's objects, a series' volume or
isosurface) and :func:`render_view` (PNG, turntable GIF/APNG or fly-through), for
``ctui render`` and the TUI's 3D view."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.actions.mesh import label_meshes
from ctui.engine.actions.opened import Opened, existing_path, input_kind, open_input, open_project, series_available
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.rendermodes import SURFACE_MODES, VOLUME_MODES
from ctui.engine.io.project import load_project
from ctui.engine.measure.centreline import centreline
from ctui.engine.mesh.meshtools import decimate
from ctui.engine.mesh.surface import isosurface
from ctui.engine.render import (Light, Scene, SceneMesh, SceneVolume, SlicePlane, get_renderer, save_animation,
                                save_flythrough, save_png, turntable_frames)
from ctui.engine.render.transfer import resolve_preset


@dataclass
class RenderResult:
    out: str
    kind: str
    mode: str
    size: tuple[int, int]
    frames: int = 1
    flythrough_points: int = 0
    notes: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"out": self.out, "kind": self.kind, "mode": self.mode, "size": list(self.size),
                "frames": self.frames, "notes": list(self.notes)}

    def summary(self) -> str:
        w, h = self.size
        if self.flythrough_points:
            return f"wrote {self.out} ({self.frames} fly-through frames, {w}x{h}, path {self.flythrough_points} points)"
        if self.frames > 1 or self.out.lower().endswith((".gif", ".apng")):
            return f"wrote {self.out} ({self.frames} frames, {w}x{h}, mode {self.mode})"
        return f"wrote {self.out} ({w}x{h}, mode {self.mode})"


def _open(src: str, *, need_volume: bool, load_options: dict) -> Opened:
    if os.path.isfile(src) and src.lower().endswith(defaults.MESH_SUFFIXES):
        return open_input(src, kind="mesh")
    if os.path.isfile(src) and src.lower().endswith(defaults.PROJECT_SUFFIXES):
        available = series_available(load_project(src))
        opened = open_project(src, with_series=True if (need_volume or available) else None, require_labels=True)
        if opened.labels is None or not np.any(opened.labels):
            raise CtuiError("project has no segmented objects to render", path=src)
        return opened
    if os.path.isfile(src) and not src.lower().endswith(defaults.LABEL_SUFFIXES) and input_kind(src) == "labels":
        return open_input(src, kind="labels")  # a DICOM-SEG (an RTSTRUCT needs its series, labels over it)
    return open_input(src, kind="series", **load_options)


def _colour(c: Any) -> tuple[float, float, float] | None:
    if isinstance(c, (list, tuple)) and len(c) == 3:
        return tuple(float(v) / 255.0 if max(c) > 1 else float(v) for v in c)  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
    return None


def scene_meshes(opened: Opened, *, mode: str, objects: Sequence[int] | None = None,
                 iso: float | None = None) -> list:
    """The meshes a render of ``opened`` shows (objects of a project, a mesh, an isosurface)."""
    if opened.kind == "mesh":
        return [opened.mesh]
    if opened.kind in ("project", "labels"):
        assert opened.labels is not None and opened.geometry is not None
        ids = opened.pick_objects(list(objects) if objects else None)
        return [m for _, m in sorted(label_meshes(opened.labels, opened.geometry, ids).items())]
    if mode in SURFACE_MODES:
        vol = opened.volume
        if vol is None:
            raise CtuiError(f"mode {mode} needs a series", path=opened.path, option="mode")
        if iso is None:
            raise CtuiError(f"mode {mode} on a series needs an iso value (e.g. 300 HU for bone)", path=opened.path,
                           option="iso")
        m = isosurface(vol.data, iso, spacing=vol.spacing, origin=vol.origin, direction=vol.direction)
        if m.n_faces == 0:
            raise CtuiError(f"no surface at iso value {iso:g} (values range {vol.value_range()})", path=opened.path,
                           option="iso")
        return [m]
    return []


def _wire_budget(meshes: list, opened: Opened) -> list:
    """The meshes, decimated together to at most ``defaults.WIRE_MAX_FACES`` triangles for a wire view
    (each its share), with a note in ``opened.notes``."""
    total = sum(int(m.n_faces) for m in meshes)
    if total <= defaults.WIRE_MAX_FACES:
        return meshes
    out = []
    for m in meshes:
        d = decimate(m, max(4, int(m.n_faces * defaults.WIRE_MAX_FACES / total)))
        d.object_id, d.meta = m.object_id, dict(m.meta)
        out.append(d)
    opened.notes.append(f"wire view of {total} triangles drawn from a decimated copy of "
                        f"{sum(int(m.n_faces) for m in out)} (denser lines draw as a solid)")
    return out


def build_scene(opened: Opened, *, mode: str | None = None, objects: Sequence[int] | None = None,
                iso: float | None = None, opacity: float | None = None, azimuth: float = defaults.RENDER_AZIMUTH,
                elevation: float = defaults.RENDER_ELEVATION, roll: float = defaults.RENDER_ROLL, zoom: float = defaults.RENDER_ZOOM,
                perspective: bool = False, light: Sequence[float] | None = None, shadows: bool = False,
                antialias: str = defaults.RENDER_ANTIALIAS, wire_overlay: bool = False, window: Sequence[float] | None = None,
                background: Sequence[float] | None = None, slice_plane: str | None = None,
                preset: str | None = None, frame: str = defaults.RENDER_FRAME) -> tuple[Scene, str]:
    """(Scene, mode) for ``opened``; colours from the project's objects."""
    kind = opened.kind
    mode = mode or ("dvr" if kind == "series" and iso is None else "surface")
    meshes = scene_meshes(opened, mode=mode, objects=objects, iso=iso)
    if mode == "wire":
        meshes = _wire_budget(meshes, opened)
    volume = opened.volume
    if mode in VOLUME_MODES and volume is None:
        raise CtuiError(f"mode {mode} needs a series (volume), not a {kind}", path=opened.path, option="mode")
    if not meshes and mode not in VOLUME_MODES:
        raise CtuiError("nothing to render", path=opened.path)
    scene = Scene()
    colors = opened.object_colors()
    for m in meshes:
        item = SceneMesh(m)
        c = _colour(colors.get(int(m.object_id)))
        if c is not None:
            item.color = c
        if opacity is not None:
            item.opacity = float(opacity)
        scene.meshes.append(item)
    if volume is not None:
        scene.volume = SceneVolume.from_volume(volume)
    scene.mode = mode
    cam = scene.camera
    cam.azimuth, cam.elevation, cam.roll, cam.zoom = azimuth, elevation, roll, zoom
    if perspective:
        cam.projection = "perspective"
    if light is not None:
        scene.light = Light(azimuth=light[0], elevation=light[1])
    o = scene.options
    o.shadows, o.antialias, o.wireframe_overlay = bool(shadows), antialias, bool(wire_overlay)
    o.frame = frame  # "auto": the objects in surface modes (not the whole series), the volume in volume modes
    if window is not None:
        o.window = (float(window[0]), float(window[1]))
    if background is not None:
        r, g, b = (v / 255.0 for v in background)
        o.background = (r, g, b)
    if slice_plane:
        if volume is None:
            raise CtuiError("a slice plane needs a series or a project whose source series loads", path=opened.path,
                            option="slice_plane")
        ax, _, idx = slice_plane.partition(":")
        if ax.lower() not in ("x", "y", "z", "axial", "coronal", "sagittal"):
            raise CtuiError(f"slice plane {slice_plane}: axis must be z, y or x", option="slice_plane")
        try:
            index = int(idx) if idx else None
        except ValueError:
            raise CtuiError(f"slice plane {slice_plane}: the index must be a whole number",
                            option="slice_plane") from None
        n = volume.shape[{"z": 0, "axial": 0, "y": 1, "coronal": 1}.get(ax.lower(), 2)]
        if index is not None and not 0 <= index < n:  # was clamped to the last slice in silence
            raise CtuiError(f"slice plane {slice_plane}: the index is outside the series (0..{n - 1} along {ax})",
                            option="slice_plane")
        o.slice_plane = SlicePlane(axis=ax.lower(), index=index)
        if kind == "series" and mode in VOLUME_MODES:
            o.slice_plane = None
    if preset:
        o.preset = resolve_preset(preset)
    elif volume is not None:
        o.preset = "ct-bone" if str(volume.modality).upper() == "CT" else "mr-default"
    return scene, mode


def flythrough_path(spec: str, opened: Opened, objects: Sequence[int] | None = None) -> np.ndarray:
    """(n, 3) patient mm: 'auto' = the centreline of a project's object, else 'x,y,z;...'."""
    if spec.strip().lower() == "auto":
        ids = list(objects or [])
        if opened.kind == "project" and not ids and len(opened.object_ids) == 1:
            ids = opened.object_ids  # the project's only object
        if opened.kind != "project" or opened.geometry is None or opened.labels is None or len(ids) != 1:
            raise CtuiError("an automatic fly-through path needs a .ctui project and one object (a tubular one)",
                            path=opened.path, option="objects")
        g = opened.geometry
        path = centreline(opened.labels == ids[0], spacing=g.spacing, origin=g.origin, direction=g.direction)
        if path is None or len(path) < 2:
            raise CtuiError(f"no centreline found for object {ids[0]}", path=opened.path)
        return np.asarray(path, float)
    try:
        pts = np.array([[float(v) for v in p.split(",")] for p in spec.split(";") if p.strip()])
    except ValueError:
        pts = np.zeros((0, 0))
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2 or not np.isfinite(pts).all() or np.abs(pts).max() > 1e6:
        raise CtuiError(f"bad fly-through path {spec!r} (want 'auto' or 'x,y,z;x,y,z;...' in mm)", option="flythrough")
    return pts


_NUMBER_BOUNDS = {"turntable": (1, 720), "frames": (2, 2000), "fps": (0.1, 100.0), "fov": (1.0, 170.0),
                  "azimuth": (-36000.0, 36000.0), "elevation": (-36000.0, 36000.0), "roll": (-36000.0, 36000.0),
                  "zoom": (1e-6, 1000.0), "iso": (-1e9, 1e9)}


def _check_numbers(**values: Any) -> None:
    """Every numeric option finite and in range (bounded work: at most 720 turntable or
    2000 fly-through frames); a one-line CtuiError naming the option otherwise."""
    for key, (lo, hi) in _NUMBER_BOUNDS.items():
        v = values.get(key)
        if v is None:
            continue
        try:
            ok = lo <= float(v) <= hi
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise CtuiError(f"{key} {v!r}: want a finite number from {lo:g} to {hi:g}", option=key)


def render_view(source: str | os.PathLike | Opened, *, out: str | os.PathLike,
                size: tuple[int, int] = defaults.RENDER_SIZE, turntable: int | None = None,
                fps: float = defaults.ANIMATION_FPS, flythrough: str | None = None,
                frames: int = defaults.FLY_FRAMES, fov: float = defaults.FLY_FOV_DEG,
                load_options: dict | None = None, **scene_options: Any) -> RenderResult:
    """Render ``source`` to ``out``: .png (one image; with ``turntable`` an APNG), .gif/.apng
    (turntable), or with ``flythrough`` a .gif/.apng or a folder of PNG frames.

    ``scene_options`` go to :func:`build_scene` (mode, objects, iso, camera, light...).
    """
    outp = Path(out)
    w, h = (int(v) for v in size)
    if not (1 <= w <= defaults.MAX_RENDER_SIDE and 1 <= h <= defaults.MAX_RENDER_SIDE):
        raise CtuiError(f"image size {w}x{h}: width and height must be 1..{defaults.MAX_RENDER_SIDE}", option="size")
    if turntable is not None and turntable < 1:
        raise CtuiError("a turntable needs at least 1 frame", option="turntable")
    _check_numbers(turntable=turntable, frames=frames, fps=fps, fov=fov, **scene_options)
    op = scene_options.get("opacity")
    if op is not None and not 0.0 <= op <= 1.0:
        raise CtuiError("opacity must be between 0 and 1", option="opacity")
    if flythrough is not None and outp.suffix.lower() not in (".gif", ".apng", ""):
        raise CtuiError("a fly-through is written as a .gif/.apng or a folder of PNG frames", path=outp, option="out")
    if outp.suffix.lower() not in (".png", ".gif", ".apng") and flythrough is None:
        raise CtuiError("output must end in .png, .gif or .apng", path=outp)
    if isinstance(source, Opened):
        opened = source
    else:
        src = existing_path(source)
        need = scene_options.get("slice_plane") is not None or scene_options.get("mode") in VOLUME_MODES
        opened = _open(src, need_volume=need, load_options=load_options or {})
    scene, mode = build_scene(opened, **scene_options)
    renderer = get_renderer()
    res = RenderResult(os.fspath(outp), opened.kind, mode, (w, h), notes=list(opened.notes))
    if flythrough is not None:
        if frames < 2:
            raise CtuiError("a fly-through needs at least 2 frames", option="frames")
        path_mm = flythrough_path(flythrough, opened, scene_options.get("objects"))
        save_flythrough(outp, scene, path_mm, frames, (w, h), fov_deg=fov, fps=fps, renderer=renderer)
        res.frames, res.flythrough_points = frames, len(path_mm)
    elif outp.suffix.lower() in (".gif", ".apng") or turntable is not None:
        n = turntable or defaults.TURNTABLE_FRAMES
        save_animation(outp, turntable_frames(scene, n, (w, h), renderer=renderer), fps=fps)
        res.frames = n
    else:
        save_png(outp, renderer.render(scene, size=(w, h)))
    return res
