"""Offscreen rendering with moderngl on EGL: lit surfaces with shadows, transparency
(weighted blended OIT), wireframe, slice planes, and volume ray casting (MIP, MinIP,
DVR with transfer-function presets).

Blocking use (any thread)::

    from ctui.engine.render import Scene, get_renderer, save_png
    scene = Scene.from_meshes(meshes)          # ctui Mesh, list of Mesh, or {id: Mesh}
    scene.camera.azimuth = 30
    img = get_renderer().render(scene, size=(800, 600))   # (600, 800, 3) uint8 RGB, row 0 = top
    save_png("view.png", img)

From a UI (non-blocking, newest request wins)::

    fut = get_renderer().submit(scene, (w, h), supersede_key="view3d")
    # a request with the same key still waiting in the queue is cancelled
    fut.add_done_callback(lambda f: f.cancelled() or f.exception() or app.call_from_thread(show, f.result()))
    # or, in asyncio code: img = await asyncio.wrap_future(fut)

The callback runs on the render thread: hand the image to the UI thread. ``submit``
snapshots the scene's settings, so the caller may keep changing its Scene; mesh and
volume arrays are shared, treat them as immutable (the GPU copies are cached per array).
For interactive volume rendering set ``scene.options.volume_scale = 0.5`` while the
user moves the camera and 1.0 for the still frame.
"""

from ctui.engine.render.camera import CameraSetup, setup_camera
from ctui.engine.render.context import EGL_PACKAGES, EGLUnavailable, Renderer, egl_available, get_renderer
from ctui.engine.render.outputs import (encode_png, flythrough_cameras, flythrough_frames, flythrough_scene, save_animation,
                      save_flythrough, save_png, save_turntable, turntable_frames)
from ctui.engine.render.scene import (ANTIALIAS, MODES, Camera, Light, Material, RenderOptions, Scene, SceneMesh, SceneVolume,
                    SlicePlane)
from ctui.engine.render.transfer import PRESETS, preset_names

__all__ = [
    "ANTIALIAS", "MODES", "PRESETS", "EGL_PACKAGES", "Camera", "CameraSetup", "EGLUnavailable", "Light",
    "Material", "Renderer", "RenderOptions", "Scene", "SceneMesh", "SceneVolume", "SlicePlane",
    "egl_available", "encode_png", "flythrough_cameras", "flythrough_frames", "flythrough_scene", "get_renderer", "preset_names",
    "render", "save_animation", "save_flythrough", "save_png", "save_turntable", "setup_camera", "turntable_frames",
]


def render(scene: Scene, size: tuple[int, int] = (800, 600)):
    """Render ``scene`` on the shared renderer and wait: (h, w, 3) uint8 RGB."""
    return get_renderer().render(scene, size=size)
