"""Offscreen rendering with moderngl on EGL: lit surfaces with shadows, transparency
(weighted blended OIT), wireframe, slice planes, and volume ray casting (MIP, MinIP,
DVR with transfer-function presets).

Typical use (from any thread)::

    from ctui.engine.render import Scene, get_renderer, save_png
    scene = Scene.from_meshes(meshes)          # list of ctui Mesh
    scene.camera.azimuth = 30
    img = get_renderer().render(scene, size=(800, 600))   # (600, 800, 3) uint8 RGB
    save_png("view.png", img)
"""

from .camera import CameraSetup, setup_camera
from .context import EGL_PACKAGES, EGLUnavailable, Renderer, egl_available, get_renderer
from .outputs import (encode_png, flythrough_cameras, flythrough_frames, save_animation, save_flythrough,
                      save_png, save_turntable, turntable_frames)
from .scene import (ANTIALIAS, MODES, Camera, Light, Material, RenderOptions, Scene, SceneMesh, SceneVolume,
                    SlicePlane)
from .transfer import PRESETS, preset_names

__all__ = [
    "ANTIALIAS", "MODES", "PRESETS", "EGL_PACKAGES", "Camera", "CameraSetup", "EGLUnavailable", "Light",
    "Material", "Renderer", "RenderOptions", "Scene", "SceneMesh", "SceneVolume", "SlicePlane",
    "egl_available", "encode_png", "flythrough_cameras", "flythrough_frames", "get_renderer", "preset_names",
    "render", "save_animation", "save_flythrough", "save_png", "save_turntable", "setup_camera",
]


def render(scene: Scene, size: tuple[int, int] = (800, 600)):
    """Render ``scene`` on the shared renderer and wait: (h, w, 3) uint8 RGB."""
    return get_renderer().render(scene, size=size)
