"""The render thread: one moderngl EGL context, owned by one dedicated thread.

OpenGL contexts are bound to the thread that made them current (a context created on
one thread fails on another, e.g. "cannot create renderbuffer"), so every GL call in
ctui goes through :class:`Renderer`, which runs jobs from a queue on its own thread
and hands back :class:`concurrent.futures.Future` objects.

>>> r = get_renderer()                       # process-wide singleton
>>> img = r.render(scene, size=(640, 480))   # blocking, (480, 640, 3) uint8
>>> fut = r.submit(scene, (640, 480), supersede_key="view3d")  # from any thread
>>> fut.add_done_callback(lambda f: f.cancelled() or show(f.result()))
"""

from __future__ import annotations

import os
import queue
import threading
import time
from concurrent.futures import Future
from typing import Any, Callable

from ctui.engine.core.errors import CtuiError
from ctui.engine.core.limits import check_allocation

EGL_PACKAGES = "libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri"


class EGLUnavailable(CtuiError):
    """No offscreen OpenGL (EGL) context could be created."""


#: memory one image takes while it is rendered, per pixel: colour, depth, the
#: transparency accumulation (RGBA float) and revealage, composite and FXAA targets,
#: the volume targets and the read-back copies (in RAM with Mesa's software renderer)
BYTES_PER_PIXEL = 56
MSAA_BYTES_PER_PIXEL = 4 * 28  # 4 samples of colour, depth and the float OIT targets


def check_image_size(size: tuple[int, int], *, msaa: bool = False, max_side: int | None = None) -> None:
    """Refuse (CtuiError, one line) an image this context or the process's memory cannot
    hold, before any GL object is made (``--size 8192x8192`` on a small machine)."""
    w, h = int(size[0]), int(size[1])
    if w < 1 or h < 1:
        raise CtuiError(f"image size {w}x{h}: width and height must be at least 1")
    if max_side and (w > max_side or h > max_side):
        raise CtuiError(f"image size {w}x{h}: this OpenGL context draws at most {max_side} pixels a side")
    check_allocation(float(w) * h * (BYTES_PER_PIXEL + (MSAA_BYTES_PER_PIXEL if msaa else 0)),
                     what=f"rendering a {w}x{h} image", hint="use a smaller image size")


def _egl_message(exc: BaseException) -> str:
    why = " ".join(str(exc).split())[:160] or type(exc).__name__
    return (f"cannot create an offscreen OpenGL (EGL) context ({why}); "
            f"on Debian/Ubuntu install: apt-get install {EGL_PACKAGES}")


def create_context():
    """A standalone moderngl context on EGL (no display needed). Raises EGLUnavailable."""
    try:
        import moderngl
    except Exception as exc:  # pragma: no cover - moderngl is a dependency
        raise EGLUnavailable(_egl_message(exc)) from exc
    backend = os.environ.get("CTUI_GL_BACKEND", "egl")
    try:
        ctx = moderngl.create_context(standalone=True, backend=backend, require=330)
    except Exception as exc:
        raise EGLUnavailable(_egl_message(exc)) from exc
    return ctx


class Renderer:
    """Runs all GL work on one thread. Use :func:`get_renderer` for the shared instance."""

    def __init__(self) -> None:
        self._queue: queue.Queue = queue.Queue()
        self._lock = threading.Lock()
        self._pending: dict[Any, Future] = {}
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._closed = False
        self.engine = None
        self.info: dict[str, Any] = {}
        self._thread = threading.Thread(target=self._loop, name="ctui-render", daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            raise self._error

    # ------------------------------------------------------------------ thread
    def _loop(self) -> None:
        try:
            ctx = create_context()
            from ctui.engine.render.gl import GLEngine  # the GL engine: built on the render thread with the first frame

            self.engine = GLEngine(ctx)
            self.info = {"renderer": ctx.info.get("GL_RENDERER", "?"), "version": ctx.info.get("GL_VERSION", "?"),
                         "vendor": ctx.info.get("GL_VENDOR", "?"), "max_samples": self.engine.max_samples,
                         "max_side": _max_side(ctx)}
        except BaseException as exc:  # noqa: BLE001 - reported to the caller
            self._error = exc if isinstance(exc, CtuiError) else EGLUnavailable(_egl_message(exc))
            self._ready.set()
            return
        self._ready.set()
        while True:
            job = self._queue.get()
            if job is None:
                break
            fut, fn, args, kwargs, key = job
            with self._lock:
                if key is not None and self._pending.get(key) is fut:
                    del self._pending[key]
            if not fut.set_running_or_notify_cancel():
                continue
            try:
                res = fn(self.engine, *args, **kwargs)
            except BaseException as exc:  # noqa: BLE001
                fut.set_exception(exc)
            else:
                fut.set_result(res)
        try:
            self.engine.clear_cache()
            self.engine.ctx.release()
        except Exception:
            pass

    # ------------------------------------------------------------------ API
    def call(self, fn: Callable[..., Any], *args: Any, supersede_key: Any = None, **kwargs: Any) -> Future:
        """Run ``fn(engine, *args, **kwargs)`` on the render thread; returns a Future.

        With ``supersede_key``, a job with the same key still waiting in the queue is
        cancelled (its future reports ``cancelled()``): only the newest runs.
        """
        if self._closed:
            raise CtuiError("the renderer is closed")
        fut: Future = Future()
        with self._lock:
            if supersede_key is not None:
                old = self._pending.pop(supersede_key, None)
                if old is not None:
                    old.cancel()
                self._pending[supersede_key] = fut
            self._queue.put((fut, fn, args, kwargs, supersede_key))
        return fut

    def submit(self, scene, size: tuple[int, int] = (800, 600), *, supersede_key: Any = None) -> Future:
        """Queue ``scene`` for rendering at ``size`` = (width, height); the Future's
        result is an (h, w, 3) uint8 RGB array. The scene is snapshotted now, so the
        caller may keep changing its copy."""
        check_image_size(size, msaa=getattr(scene.options, "antialias", "") == "msaa",
                         max_side=self.info.get("max_side"))
        snap = scene.snapshot()
        return self.call(_render_job, snap, (int(size[0]), int(size[1])), supersede_key=supersede_key)

    def render(self, scene, *, size: tuple[int, int] = (800, 600), timeout: float | None = None):
        """Render and wait: (h, w, 3) uint8 RGB array."""
        return self.submit(scene, size).result(timeout)

    def close(self) -> None:
        """Stop the thread and release the context (pending jobs still run first)."""
        if not self._closed:
            self._closed = True
            self._queue.put(None)
            self._thread.join(timeout=10)


def _max_side(ctx) -> int | None:
    """The largest image side the context can render to (texture, renderbuffer, viewport)."""
    sides = []
    for key in ("GL_MAX_TEXTURE_SIZE", "GL_MAX_RENDERBUFFER_SIZE", "GL_MAX_VIEWPORT_DIMS"):
        v = ctx.info.get(key)
        if isinstance(v, (tuple, list)):
            sides += [int(x) for x in v]
        elif v:
            sides.append(int(v))
    return min(sides) if sides else None


def _render_job(engine, scene, size):
    t0 = time.perf_counter()
    img = engine.render(scene, size)
    engine.timings["last_render_s"] = time.perf_counter() - t0
    return img


_renderer: Renderer | None = None
_renderer_error: BaseException | None = None
_singleton_lock = threading.Lock()


def get_renderer() -> Renderer:
    """The process-wide :class:`Renderer` (created on first use). Raises
    :class:`EGLUnavailable` (one line naming the Debian packages) when no context can
    be created; the failure is remembered, later calls fail fast."""
    global _renderer, _renderer_error
    with _singleton_lock:
        if _renderer is not None:
            return _renderer
        if _renderer_error is not None:
            raise EGLUnavailable(str(_renderer_error))
        try:
            _renderer = Renderer()
        except CtuiError as exc:
            _renderer_error = exc
            raise
        return _renderer


def egl_available() -> bool:
    """True when an EGL context can be created (creates the renderer)."""
    try:
        get_renderer()
        return True
    except EGLUnavailable:
        return False
