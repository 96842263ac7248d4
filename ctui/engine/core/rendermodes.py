"""The render modes, one registry for every face: ``ctui render --mode``, the 3D view's
``m`` cycle, :class:`ctui.engine.render.scene.Scene` and ``actions.render.build_scene``
all read :data:`RENDER_MODES`. Plain data (no numpy), so ``ctui --help`` can list it."""

from __future__ import annotations

#: mode -> (kind, what it shows). kind "surface": drawn from object meshes; "volume":
#: ray cast through the grey levels (needs the series).
RENDER_MODES: dict[str, tuple[str, str]] = {
    "surface": ("surface", "lit, opaque object surfaces"),
    "wire": ("surface", "triangle edges of the surfaces"),
    "transparent": ("surface", "see-through surfaces (order-independent blending)"),
    "mip": ("volume", "maximum intensity projection of the series"),
    "minip": ("volume", "minimum intensity projection of the series (airways)"),
    "dvr": ("volume", "direct volume rendering with a transfer-function preset"),
}
MODES: tuple[str, ...] = tuple(RENDER_MODES)
VOLUME_MODES: tuple[str, ...] = tuple(m for m, (kind, _) in RENDER_MODES.items() if kind == "volume")
SURFACE_MODES: tuple[str, ...] = tuple(m for m, (kind, _) in RENDER_MODES.items() if kind == "surface")
#: anti-aliasing of the rendered image: fast approximate, multisampled, or none
ANTIALIAS: tuple[str, ...] = ("fxaa", "msaa", "none")
#: what the camera frames: "auto" (the objects in surface modes, the volume in volume modes), the objects,
#: or the whole series
FRAMES: tuple[str, ...] = ("auto", "objects", "series")
