"""Image outputs: PNG (OpenCV encoder), turntable animations (GIF/APNG) and
endoscopic fly-throughs along a path."""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np

from ctui.engine.core.atomic import atomic_write, write_bytes
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.limits import check_allocation
from ctui.engine.render.context import get_renderer
from ctui.engine.render.scene import Camera, Scene


def encode_png(image: np.ndarray, *, compression: int = 3) -> bytes:
    """(h, w, 3) RGB or (h, w) grey uint8 -> PNG bytes (OpenCV: several times faster
    than Pillow at 1024x1024)."""
    import cv2

    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise ValueError("encode_png expects uint8 pixels")
    if img.ndim == 3:
        img = img[..., ::-1] if img.shape[2] == 3 else img[..., [2, 1, 0, 3]]
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(img), [cv2.IMWRITE_PNG_COMPRESSION, int(compression)])
    if not ok:
        raise CtuiError("PNG encoding failed")
    return buf.tobytes()


def save_png(path: str | Path, image: np.ndarray) -> Path:
    """Write an RGB (h, w, 3) uint8 image as PNG, atomically."""
    write_bytes(path, encode_png(image))
    return Path(path)


#: bytes per pixel per frame of an animation held until it is written: the RGB frame, and
#: while encoding its palette (GIF) or RGB (APNG) image
ANIMATION_BYTES_PER_PIXEL = 7


def check_frames(n: int, size: tuple[int, int]) -> None:
    """Refuse (CtuiError) ``n`` frames of ``size`` that will not fit in memory, before rendering
    (``--turntable 2000`` on a small machine)."""
    w, h = int(size[0]), int(size[1])
    check_allocation(float(n) * w * h * ANIMATION_BYTES_PER_PIXEL, what=f"{n} frames of {w}x{h}",
                     hint="use fewer frames or a smaller image size")


def turntable_frames(scene: Scene, n: int, size: tuple[int, int], *, renderer=None,
                     start: float | None = None, degrees: float = 360.0) -> list[np.ndarray]:
    """``n`` images with the camera's azimuth stepped by degrees/n (all frames queued at
    once on the render thread)."""
    n = int(n)
    if n < 1:
        raise CtuiError(f"turntable needs at least 1 frame, got {n}")
    check_frames(n, size)
    r = renderer or get_renderer()
    a0 = scene.camera.azimuth if start is None else start
    futs = []
    for i in range(n):
        s = scene.snapshot()
        s.camera.azimuth = a0 + degrees * i / n
        futs.append(r.submit(s, size))
    return [f.result() for f in futs]


def save_animation(path: str | Path, frames: list[np.ndarray], *, fps: float = 15.0) -> Path:
    """Write frames as an animated GIF (``.gif``) or APNG (``.png``/``.apng``), atomically."""
    from PIL import Image

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".gif", ".png", ".apng"):
        raise CtuiError(f"{path}: animation must be .gif, .png or .apng")
    if not frames:
        raise CtuiError(f"{path}: no frames to write")
    duration = int(round(1000.0 / max(fps, 0.1)))
    if suffix == ".gif":
        # one shared palette: quantise a mosaic of some frames, then map all frames to it
        pick = frames[:: max(1, len(frames) // 8)]
        mosaic = Image.fromarray(np.concatenate([f[::2, ::2] for f in pick], axis=0))
        pal = mosaic.quantize(colors=255, method=Image.Quantize.MEDIANCUT)
        ims = [Image.fromarray(f).quantize(palette=pal, dither=Image.Dither.NONE) for f in frames]
        fmt, kw = "GIF", {"loop": 0, "optimize": False}
    else:
        ims = [Image.fromarray(f) for f in frames]
        fmt, kw = "PNG", {"loop": 0, "compress_level": 3}
    with atomic_write(path, "wb") as fh:
        ims[0].save(fh, format=fmt, save_all=True, append_images=ims[1:], duration=duration, **kw)
    return path


def save_turntable(path: str | Path, scene: Scene, n: int = 36, size: tuple[int, int] = (512, 512), *,
                   fps: float = 15.0, renderer=None) -> Path:
    """Render a turntable of ``n`` frames (azimuth 0..360) and write it as GIF or APNG."""
    return save_animation(path, turntable_frames(scene, n, size, renderer=renderer), fps=fps)


def resample_path(points: np.ndarray, n: int, *, end_margin_mm: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Resample a polyline (m, 3) mm to ``n`` points evenly spaced by arc length,
    leaving out ``end_margin_mm`` at each end (at most a quarter of the length);
    returns (positions (n, 3), unit tangents (n, 3)) (tangents from a lightly smoothed path)."""
    p = np.asarray(points, float).reshape(-1, 3)
    if len(p) < 2:
        raise CtuiError("a fly-through path needs at least 2 points")
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    keep = np.r_[True, seg > 1e-9]
    p = p[keep]
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    if s[-1] <= 0:
        raise CtuiError("a fly-through path needs at least 2 distinct points")
    m = min(max(float(end_margin_mm), 0.0), 0.25 * s[-1])
    u = np.linspace(m, s[-1] - m, int(n))
    pos = np.stack([np.interp(u, s, p[:, k]) for k in range(3)], axis=1)
    # tangents from a denser, smoothed copy of the path (Gaussian, ~2% of its length)
    dense_u = np.linspace(0.0, s[-1], max(4 * int(n), 64))
    dense = np.stack([np.interp(dense_u, s, p[:, k]) for k in range(3)], axis=1)
    from scipy.ndimage import gaussian_filter1d

    sm = gaussian_filter1d(dense, sigma=max(len(dense) / 50.0, 1.0), axis=0, mode="nearest")
    tan_d = np.gradient(sm, axis=0)
    tan = np.stack([np.interp(u, dense_u, tan_d[:, k]) for k in range(3)], axis=1)
    tan /= np.maximum(np.linalg.norm(tan, axis=1, keepdims=True), 1e-12)
    return pos, tan


def flythrough_cameras(path_mm: np.ndarray, n_frames: int, *, fov_deg: float = 70.0,
                       look_ahead_mm: float = 10.0) -> list[Camera]:
    """Perspective cameras inside along ``path_mm`` (m, 3), each looking along the path
    tangent; the up vector is parallel-transported so the view does not spin."""
    # a centreline runs to the object's end caps: a camera there would look out of the
    # object at nothing, so the flight stops one look-ahead short of each end
    pos, tan = resample_path(path_mm, n_frames, end_margin_mm=look_ahead_mm)
    up = np.array([0.0, 0.0, 1.0])
    if abs(np.dot(up, tan[0])) > 0.9:
        up = np.array([0.0, -1.0, 0.0])
    cams = []
    for p, t in zip(pos, tan):
        up = up - np.dot(up, t) * t
        nu = np.linalg.norm(up)
        up = up / nu if nu > 1e-6 else np.cross(t, [1.0, 0.0, 0.0])
        cams.append(Camera(projection="perspective", fov_deg=fov_deg, eye=tuple(p),
                           look_at=tuple(p + t * look_ahead_mm), up=tuple(up)))
    return cams


def flythrough_scene(scene: Scene, camera: Camera, *, endoscope_light: bool = True) -> Scene:
    """A snapshot of ``scene`` seen by one fly-through ``camera``; ``endoscope_light``:
    light mostly from the camera (head light 0.8, the movable light at 30 %, no
    shadows), as an endoscope's own lamp."""
    s = scene.snapshot()
    s.camera = camera
    if endoscope_light:
        s.options.headlight = max(s.options.headlight, 0.8)
        s.light.intensity *= 0.3
        s.options.shadows = False
    return s


def flythrough_frames(scene: Scene, path_mm: np.ndarray, n_frames: int = 60, size: tuple[int, int] = (512, 512),
                      *, fov_deg: float = 70.0, endoscope_light: bool = True,
                      renderer=None) -> Iterator[np.ndarray]:
    """Endoscopic views along ``path_mm`` (m, 3) (e.g. a centreline), one per frame.

    ``endoscope_light``: light mostly from the camera (head light 0.8, the movable
    light dimmed to 30%, no shadows), as an endoscope's own lamp."""
    check_frames(int(n_frames), size)
    r = renderer or get_renderer()
    futs = []
    for cam in flythrough_cameras(path_mm, n_frames, fov_deg=fov_deg):
        futs.append(r.submit(flythrough_scene(scene, cam, endoscope_light=endoscope_light), size))
    for f in futs:
        yield f.result()


def save_flythrough(path: str | Path, scene: Scene, path_mm: np.ndarray, n_frames: int = 60,
                    size: tuple[int, int] = (512, 512), *, fov_deg: float = 70.0, fps: float = 15.0,
                    renderer=None) -> Path:
    """Write a fly-through as GIF/APNG (``path`` ends .gif/.png/.apng) or, for a folder,
    as numbered PNG frames (``frame_0000.png``...)."""
    path = Path(path)
    frames = flythrough_frames(scene, path_mm, n_frames, size, fov_deg=fov_deg, renderer=renderer)
    if path.suffix.lower() in (".gif", ".png", ".apng"):
        return save_animation(path, list(frames), fps=fps)
    path.mkdir(parents=True, exist_ok=True)
    for i, f in enumerate(frames):
        save_png(path / f"frame_{i:04d}.png", f)
    return path
