"""Scene description for the offscreen renderer.

A :class:`Scene` is plain data: meshes with colour and opacity, an optional volume,
a camera, a movable light plus a head light, a material, a render mode and options.
The same description serves the CLI (``ctui render``) and the TUI's 3D view.
Everything except the mesh and volume arrays round-trips through JSON with
:meth:`Scene.to_dict` / :meth:`Scene.from_dict`.

Coordinates are patient mm (x, y, z) in DICOM LPS. The camera orbits an axis point
(``Camera.target``, default: the centre of the visible objects):

* azimuth 0, elevation 0 looks from the patient's front (anterior, -y) towards +y,
  with +z (superior) up and the patient's left (+x) on the right of the image;
* azimuth turns the camera about +z (positive: towards the patient's left side),
  elevation raises it towards +z (90 = from above, -90 = from the feet: the
  radiological axial view with anterior at the top of the image), roll turns the
  image about the viewing axis.
"""

from __future__ import annotations

import copy
import dataclasses
import weakref
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.core.colors import object_color_float
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.jsonio import to_jsonable
from ctui.engine.core.meshdata import Mesh
from ctui.engine.core.rendermodes import ANTIALIAS, FRAMES, MODES, VOLUME_MODES  # noqa: F401 - re-exported (ctui.engine.render)

PROJECTIONS = ("orthographic", "perspective")


@dataclass
class Camera:
    """Orbiting camera (angles in degrees, lengths in mm).

    projection : "orthographic" or "perspective".
    azimuth, elevation, roll : orbit angles about ``target`` (see module docstring).
    zoom : magnification (>1 enlarges); orthographic: visible height = extent_mm / zoom;
        perspective: view angle narrowed to atan(tan(fov/2) / zoom).
    pan : (right, up) shift of the view in mm, in the image plane.
    target : axis point (x, y, z) mm; None = centre of the scene's bounding box.
    extent_mm : visible height in mm at zoom 1 (orthographic); None = fit the scene.
    fov_deg : vertical view angle (perspective).
    eye, look_at, up : explicit placement (fly-through): when ``eye`` is set the orbit
        angles are ignored and the camera sits at ``eye`` looking at ``look_at``.
    """

    projection: str = "orthographic"
    azimuth: float = 0.0
    elevation: float = 0.0
    roll: float = 0.0
    zoom: float = 1.0
    pan: tuple[float, float] = (0.0, 0.0)
    target: tuple[float, float, float] | None = None
    extent_mm: float | None = None
    fov_deg: float = 30.0
    eye: tuple[float, float, float] | None = None
    look_at: tuple[float, float, float] | None = None
    up: tuple[float, float, float] | None = None


@dataclass
class Light:
    """The movable light.

    kind : "point", "spot" or "directional".
    azimuth, elevation : direction from the axis point towards the light, in degrees,
        measured in the camera's frame (``relative_to="camera"``: 0, 0 = from the
        viewer; positive azimuth = from the image's right, positive elevation = from
        above) or in the patient frame (``relative_to="world"``, same angles as the
        camera's orbit).
    intensity : 0..1+ scale of its diffuse and specular terms.
    distance : mm from the axis point (point/spot); None = 4 x the scene radius.
    spot_angle_deg : half-angle of the spot cone.
    """

    kind: str = "point"
    azimuth: float = 35.0
    elevation: float = 35.0
    intensity: float = 0.8
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    relative_to: str = "camera"
    distance: float | None = None
    spot_angle_deg: float = 25.0


@dataclass
class Material:
    """Blinn-Phong coefficients shared by all surfaces (and DVR gradient shading)."""

    ambient: float = 0.18
    diffuse: float = 0.72
    specular: float = 0.35
    shininess: float = 40.0


@dataclass
class SlicePlane:
    """A CT slice drawn in place inside the 3D view (needs ``Scene.volume``).

    axis : "z" (axial), "y" (coronal) or "x" (sagittal) index axis of the volume.
    index : slice index along that axis; None = the middle slice.
    """

    axis: str = "z"
    index: int | None = None
    opacity: float = 1.0


@dataclass
class RenderOptions:
    """Render options.

    shadows : shadow mapping from the movable light (surfaces).
    wireframe_overlay : draw triangle edges over the shaded surfaces.
    wire_color : RGB 0..1 of the overlay lines.
    antialias : "fxaa" (default: measured cheapest, see benchmarks/render.py),
        "msaa" (4x multisample + resolve) or "none".
    slice_plane : a :class:`SlicePlane` or None.
    crop_box : ((x0, y0, z0), (x1, y1, z1)) fractions 0..1 of the volume's index
        extent kept for volume rendering; None = all.
    preset : transfer-function preset for DVR (see ``transfer.PRESETS``).
    window : (centre, width) for MIP/MinIP and the slice plane; None = the volume's.
    background : RGB 0..1.
    headlight : intensity of the light at the eye.
    transparent_opacity : opacity given in "transparent" mode to meshes whose own
        opacity is 1.
    samples_per_voxel : ray-casting samples per voxel length.
    volume_scale : ray-cast at this fraction of the image size, then upscale (1 = full).
    shading : gradient shading in DVR.
    show_surfaces : in volume modes, draw the scene's meshes inside the volume (the
        rays stop at them).
    shadow_map_size : shadow map resolution in texels.
    lighting : "auto" (per-vertex lighting for meshes whose triangles cover under ~3
        pixels, per-pixel otherwise), "pixel" or "vertex".
    empty_space_skipping : skip volume bricks that cannot contribute (on; off only
        for measuring its effect).
    frame : what the camera frames, see :data:`FRAMES` (default "auto": the objects in
        surface modes, so a small object in a large series fills the image).
    """

    shadows: bool = False
    wireframe_overlay: bool = False
    wire_color: tuple[float, float, float] = (0.05, 0.05, 0.05)
    antialias: str = "fxaa"
    slice_plane: SlicePlane | None = None
    crop_box: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    preset: str = "ct-bone"
    window: tuple[float, float] | None = None
    background: tuple[float, float, float] = (0.07, 0.07, 0.09)
    headlight: float = 0.35
    transparent_opacity: float = 0.4
    samples_per_voxel: float = 1.0
    volume_scale: float = 1.0
    shading: bool = True
    show_surfaces: bool = True
    shadow_map_size: int = 2048
    lighting: str = "auto"
    empty_space_skipping: bool = True
    frame: str = "auto"


# FRAMES (core.rendermodes): what the camera frames (``RenderOptions.frame``): "auto" = the visible meshes
# in the surface modes and the volume box in the volume modes (or when there is no mesh);
# "objects" = the meshes; "series" = the volume box and the meshes


@dataclass
class SceneMesh:
    """One surface: a :class:`~ctui.engine.core.meshdata.Mesh` with display attributes.

    color : RGB 0..1; None = the object colour of ``mesh.object_id`` (bone white when 0).
    The renderer caches GPU buffers per mesh array: treat vertex/face arrays as
    immutable (make new arrays to change a mesh).
    """

    mesh: Mesh
    color: tuple[float, float, float] | None = None
    opacity: float = 1.0
    visible: bool = True
    name: str = ""

    def rgb(self) -> tuple[float, float, float]:
        if self.color is not None:
            return tuple(float(c) for c in self.color)  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
        if self.mesh.object_id:
            return object_color_float(self.mesh.object_id)
        return (0.89, 0.85, 0.77)


@dataclass
class SceneVolume:
    """A volume for MIP/MinIP/DVR and slice planes.

    data : ndarray (nz, ny, nx), any numeric dtype (HU for CT).
    spacing (dz, dy, dx) mm, origin (x, y, z) mm, direction 3x3 (columns = x, y, z
    index axes), as :class:`ctui.engine.core.volume.Volume`. Treat ``data`` as immutable
    (the GPU texture is cached per array).
    """

    data: np.ndarray
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: np.ndarray = field(default_factory=lambda: np.eye(3))
    modality: str = "CT"
    window: tuple[float, float] | None = None

    @classmethod
    def from_volume(cls, vol: Any) -> "SceneVolume":
        """From a :class:`ctui.engine.core.volume.Volume`."""
        return cls(vol.data, tuple(vol.spacing), tuple(vol.origin), np.asarray(vol.direction, float),
                   getattr(vol, "modality", "CT") or "CT", getattr(vol, "window", None))

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.data.shape)  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction

    def affine(self) -> np.ndarray:
        """4x4: homogeneous (x, y, z) voxel indices -> patient mm."""
        return Geometry(self.shape, self.spacing, self.origin, self.direction).affine

    def corners(self) -> np.ndarray:
        """(8, 3) patient mm of the voxel grid's outer corners (voxel edges)."""
        nz, ny, nx = self.shape
        c = np.array([[x, y, z, 1.0] for x in (-0.5, nx - 0.5) for y in (-0.5, ny - 0.5) for z in (-0.5, nz - 0.5)])
        return (c @ self.affine().T)[:, :3]


@dataclass
class Scene:
    """Everything the renderer needs for one image.

    mode : "surface", "wire", "transparent", "mip", "minip" or "dvr".
    """

    meshes: list[SceneMesh] = field(default_factory=list)
    volume: SceneVolume | None = None
    camera: Camera = field(default_factory=Camera)
    light: Light = field(default_factory=Light)
    material: Material = field(default_factory=Material)
    mode: str = "surface"
    options: RenderOptions = field(default_factory=RenderOptions)

    def __post_init__(self) -> None:
        self.meshes = self.mesh_items()

    def mesh_items(self) -> list[SceneMesh]:
        """``meshes`` with any bare Mesh wrapped in a SceneMesh (in place)."""
        self.meshes = [m if isinstance(m, SceneMesh) else SceneMesh(m) for m in self.meshes]
        return self.meshes

    # ------------------------------------------------------------------ building
    @classmethod
    def from_meshes(cls, meshes: Any, **kwargs: Any) -> "Scene":
        """Scene from a Mesh, a list of Meshes or a dict {id: Mesh}."""
        if isinstance(meshes, Mesh):
            meshes = [meshes]
        elif isinstance(meshes, dict):
            meshes = list(meshes.values())
        return cls(meshes=[m if isinstance(m, SceneMesh) else SceneMesh(m) for m in meshes], **kwargs)

    def add_mesh(self, mesh: Mesh, *, color: tuple[float, float, float] | None = None,
                 opacity: float = 1.0, name: str = "") -> SceneMesh:
        item = SceneMesh(mesh, color=color, opacity=opacity, name=name)
        self.meshes.append(item)
        return item

    def set_volume(self, vol: Any) -> None:
        """Attach a :class:`ctui.engine.core.volume.Volume` or a :class:`SceneVolume`."""
        self.volume = vol if isinstance(vol, SceneVolume) or vol is None else SceneVolume.from_volume(vol)

    def snapshot(self) -> "Scene":
        """A copy safe to hand to the render thread: settings are copied, the mesh and
        volume arrays are shared (they are never modified by the renderer)."""
        return Scene(
            meshes=[dataclasses.replace(m) for m in self.mesh_items()],
            volume=dataclasses.replace(self.volume) if self.volume is not None else None,
            camera=copy.deepcopy(self.camera), light=copy.deepcopy(self.light),
            material=copy.deepcopy(self.material), mode=self.mode, options=copy.deepcopy(self.options),
        )

    # ------------------------------------------------------------------ geometry
    def bounds(self, *, everything: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(min_xyz, max_xyz) mm of what the camera frames (``options.frame``): the visible
        meshes, and the volume box in volume modes, with ``frame="series"``, when there
        is no mesh, or with ``everything`` (the camera's depth range)."""
        pts = []
        for m in self.mesh_items():
            if m.visible and m.mesh.n_vertices:
                lo, hi = mesh_bounds(m.mesh)
                pts += [lo, hi]
        frame = getattr(self.options, "frame", "auto")
        with_volume = (everything or not pts or frame == "series"
                       or (frame == "auto" and self.mode in VOLUME_MODES))
        if self.volume is not None and with_volume:
            c = self.volume.corners()
            pts += [c.min(0), c.max(0)]
        if not pts:
            return np.full(3, -1.0), np.full(3, 1.0)
        p = np.array(pts)
        return p.min(0), p.max(0)

    def centre(self) -> np.ndarray:
        lo, hi = self.bounds()
        return (lo + hi) / 2.0

    def radius(self) -> float:
        """Half the diagonal of :meth:`bounds` (mm), at least 1e-3."""
        lo, hi = self.bounds()
        return max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-3)

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description; meshes and volume are summarised (no arrays)."""
        d: dict[str, Any] = {
            "mode": self.mode,
            "camera": dataclasses.asdict(self.camera),
            "light": dataclasses.asdict(self.light),
            "material": dataclasses.asdict(self.material),
            "options": dataclasses.asdict(self.options),
            "meshes": [
                {"name": m.name, "object_id": int(m.mesh.object_id), "color": list(m.rgb()),
                 "opacity": float(m.opacity), "visible": bool(m.visible),
                 "n_vertices": m.mesh.n_vertices, "n_faces": m.mesh.n_faces}
                for m in self.meshes
            ],
            "volume": None if self.volume is None else {
                "shape_zyx": list(self.volume.shape), "spacing_zyx_mm": list(self.volume.spacing),
                "origin_xyz_mm": list(self.volume.origin), "modality": self.volume.modality,
            },
        }
        return to_jsonable(d, ndigits=None)  # exact: from_dict must rebuild the same scene

    @classmethod
    def from_dict(cls, d: dict[str, Any], *, meshes: Any = (), volume: Any = None) -> "Scene":
        """Rebuild settings from :meth:`to_dict`; pass the meshes (same order) and volume.

        Mesh display attributes (colour, opacity, visibility, name) are restored from
        ``d["meshes"]`` where present.
        """
        opts = dict(d.get("options", {}))
        if opts.get("slice_plane"):
            opts["slice_plane"] = _make(SlicePlane, opts["slice_plane"])
        if opts.get("crop_box"):
            opts["crop_box"] = tuple(tuple(v) for v in opts["crop_box"])
        cam = dict(d.get("camera", {}))
        for k in ("pan", "target", "eye", "look_at", "up"):
            if cam.get(k) is not None:
                cam[k] = tuple(cam[k])
        scene = cls.from_meshes(list(meshes), mode=d.get("mode", "surface"), camera=_make(Camera, cam),
                                light=_make(Light, _tuples(d.get("light", {}))),
                                material=_make(Material, d.get("material", {})),
                                options=_make(RenderOptions, _tuples(opts)))
        for item, md in zip(scene.meshes, d.get("meshes", [])):
            item.color = tuple(md.get("color")) if md.get("color") else None
            item.opacity = float(md.get("opacity", 1.0))
            item.visible = bool(md.get("visible", True))
            item.name = md.get("name", "")
        if volume is not None:
            scene.set_volume(volume)
        return scene


_BOUNDS: dict[int, tuple[Any, np.ndarray, np.ndarray]] = {}


def mesh_bounds(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(min_xyz, max_xyz) of a mesh, cached per vertex array (a 1M-vertex min/max
    costs ~50 ms and the camera needs it several times per frame)."""
    v = mesh.vertices
    key = id(v)
    hit = _BOUNDS.get(key)
    if hit is not None and hit[0]() is v:
        return hit[1], hit[2]
    arr = np.asarray(v)
    lo, hi = arr.min(axis=0).astype(float), arr.max(axis=0).astype(float)
    try:
        ref = weakref.ref(v)
    except TypeError:
        return lo, hi
    if len(_BOUNDS) > 256:
        for k in [k for k, e in _BOUNDS.items() if e[0]() is None]:
            del _BOUNDS[k]
        if len(_BOUNDS) > 256:
            _BOUNDS.clear()
    _BOUNDS[key] = (ref, lo, hi)
    return lo, hi


def _make(cls: Any, d: dict[str, Any]) -> Any:
    """Dataclass from a dict, ignoring keys it does not know (newer/older versions)."""
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in d.items() if k in names})


def _tuples(d: dict[str, Any]) -> dict[str, Any]:
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}
