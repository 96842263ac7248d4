"""Camera and light geometry: view/projection matrices (OpenGL conventions, column
vectors, row-major numpy 4x4) for a :class:`~ctui.engine.render.scene.Scene`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ctui.engine.render.scene import Camera, Light, Scene


@dataclass
class CameraSetup:
    """Resolved camera for one image.

    view, proj : 4x4 float64 (world -> eye, eye -> clip); vp = proj @ view.
    eye : camera position mm (for orthographic: a point far back along the view axis).
    forward, right, up : unit vectors (world).
    ortho : True for orthographic; half_height : visible half height mm (orthographic)
    or tan(fov/2) (perspective). target : axis point. radius : scene radius mm.
    """

    view: np.ndarray
    proj: np.ndarray
    vp: np.ndarray
    eye: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray
    ortho: bool
    half_height: float
    target: np.ndarray
    radius: float
    near: float
    far: float

    def pixels_per_mm(self, size: tuple[int, int]) -> float:
        """Orthographic scale: image pixels per mm."""
        return size[1] / (2.0 * self.half_height)

    def project(self, points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """Patient mm (n, 3) -> image pixel coordinates (n, 2) as (column, row), row 0 at top."""
        p = np.c_[np.asarray(points, float).reshape(-1, 3), np.ones(len(np.asarray(points).reshape(-1, 3)))]
        c = p @ self.vp.T
        ndc = c[:, :3] / c[:, 3:4]
        w, h = size
        return np.c_[(ndc[:, 0] + 1) * 0.5 * w, (1 - ndc[:, 1]) * 0.5 * h]


def _rot(axis: np.ndarray, deg: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    t = math.radians(deg)
    c, s = math.cos(t), math.sin(t)
    x, y, z = a
    return np.array([[c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                     [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                     [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)]])


def orbit_basis(azimuth: float, elevation: float, roll: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(back, right, up): back points from the target to the eye."""
    az, el = math.radians(azimuth), math.radians(elevation)
    front0 = np.array([math.sin(az) * 1.0, -math.cos(az), 0.0])  # az=0: (0,-1,0) anterior
    right = np.array([math.cos(az), math.sin(az), 0.0])
    zax = np.array([0.0, 0.0, 1.0])
    back = math.cos(el) * front0 + math.sin(el) * zax
    up = -math.sin(el) * front0 + math.cos(el) * zax
    if roll:
        r = _rot(back, roll)
        right, up = r @ right, r @ up
    return back, right, up


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    f = target - eye
    f = f / max(np.linalg.norm(f), 1e-12)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-9:  # up parallel to the view: pick another
        r = np.cross(f, [0.0, 1.0, 0.0] if abs(f[1]) < 0.9 else [1.0, 0.0, 0.0])
    r = r / np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = r, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def ortho(l: float, r: float, b: float, t: float, n: float, f: float) -> np.ndarray:  # noqa: E741 - glOrtho's names
    m = np.eye(4)
    m[0, 0], m[1, 1], m[2, 2] = 2 / (r - l), 2 / (t - b), -2 / (f - n)
    m[0, 3], m[1, 3], m[2, 3] = -(r + l) / (r - l), -(t + b) / (t - b), -(f + n) / (f - n)
    return m


def perspective(tan_half: float, aspect: float, n: float, f: float) -> np.ndarray:
    m = np.zeros((4, 4))
    m[0, 0] = 1 / (aspect * tan_half)
    m[1, 1] = 1 / tan_half
    m[2, 2] = -(f + n) / (f - n)
    m[2, 3] = -2 * f * n / (f - n)
    m[3, 2] = -1
    return m


def setup_camera(scene: Scene, size: tuple[int, int]) -> CameraSetup:
    """Resolve ``scene.camera`` for an image of ``size`` = (width, height) pixels."""
    cam: Camera = scene.camera
    w, h = size
    aspect = w / max(h, 1)
    centre = scene.centre()
    radius = scene.radius()
    target = np.asarray(cam.target, float) if cam.target is not None else centre
    zoom = max(float(cam.zoom), 1e-6)
    if cam.eye is not None:
        eye = np.asarray(cam.eye, float)
        tgt = np.asarray(cam.look_at, float) if cam.look_at is not None else target
        upv = np.asarray(cam.up, float) if cam.up is not None else np.array([0.0, 0.0, 1.0])
        view = look_at(eye, tgt, upv)
        if cam.roll:
            rz = np.eye(4)
            rz[:3, :3] = _rot([0, 0, 1], -cam.roll)
            view = rz @ view
        right, up, back = view[0, :3], view[1, :3], view[2, :3]
        target = tgt
    else:
        back, right, up = orbit_basis(cam.azimuth, cam.elevation, cam.roll)
        target = target + right * cam.pan[0] + up * cam.pan[1]
        if cam.projection == "perspective":
            dist = radius / math.sin(math.radians(cam.fov_deg) / 2.0) * 1.02
        else:
            dist = radius * 3.0 + 1.0
        eye = target + back * dist
        view = look_at(eye, target, up)
    forward = -back
    # depth range from the bounding sphere of everything drawn (the volume box and a slice
    # plane too, when the camera frames the objects only)
    lo_all, hi_all = scene.bounds(everything=True)
    centre = (lo_all + hi_all) / 2.0
    radius_all = max(float(np.linalg.norm(hi_all - lo_all)) / 2.0, 1e-3)
    d_c = float(np.dot(centre - eye, forward))
    span = radius_all + float(np.linalg.norm(centre - target)) + 1e-3
    far = max(d_c + span * 1.05, 1e-2)
    if cam.projection == "perspective":
        near = max(d_c - span * 1.05, far * 1e-4)
        tan_half = math.tan(math.radians(cam.fov_deg) / 2.0) / zoom
        proj = perspective(tan_half, aspect, near, far)
        half = tan_half
    else:
        near = d_c - span * 1.05
        extent = cam.extent_mm if cam.extent_mm else 2.0 * radius * 1.05
        half = extent / 2.0 / zoom
        if cam.eye is not None:
            near = min(near, 0.0)
        proj = ortho(-half * aspect, half * aspect, -half, half, near, far)
    return CameraSetup(view, proj, proj @ view, eye, forward, right, up, cam.projection != "perspective",
                       half, target, radius, near, far)


def light_position(scene: Scene, cs: CameraSetup) -> tuple[np.ndarray, np.ndarray]:
    """(position mm, direction unit vector from the light towards the axis point)."""
    lt: Light = scene.light
    az, el = math.radians(lt.azimuth), math.radians(lt.elevation)
    if lt.relative_to == "world":
        back, right, up = orbit_basis(0.0, 0.0)
    else:
        back, right, up = -cs.forward, cs.right, cs.up
    to_light = math.cos(el) * (math.sin(az) * right + math.cos(az) * back) + math.sin(el) * up
    to_light /= np.linalg.norm(to_light)
    dist = lt.distance if lt.distance else 4.0 * cs.radius
    centre = scene.centre()
    pos = centre + to_light * dist
    return pos, -to_light
