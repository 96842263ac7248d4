"""Long jobs of the workspace as thread workers that post messages (progress, result,
failure) to the screen: the 3D cell of the 2x2 layout, exports, the AI draft
(:class:`JobRunner`, the workspace's ``work``). Each is cancellable (Escape) through its
Worker (tracked by :class:`ctui.screens.ws_state.Jobs`); a late answer to a closed screen is dropped."""

from __future__ import annotations

import time
from typing import Any, Callable

from textual.worker import Worker, get_current_worker

from ctui.engine.core.progress import Cancelled
from ctui.screens.messages import CellRendered, JobFailed, JobFinished, JobProgress
from ctui.screens.ws_host import Owner


class JobRunner(Owner):
    """Starts the workspace's jobs and ends them when their messages come back."""

    def render_cell(self, size: tuple[int, int]) -> Worker:
        """Surfaces of the objects (or a MIP when there are none) rendered at ``size`` for the 3D cell."""
        return self.ws.run_worker(lambda: self._render_cell(size), thread=True, exclusive=True, group="cell3d",
                                  name="3D cell")

    def _render_cell(self, size: tuple[int, int]) -> None:
        from ctui.engine import render  # the renderer loads with the first 3D cell
        from ctui.screens.view3d import build_meshes  # the 3D view's module (meshing) too

        ws = self.ws
        worker = get_current_worker()
        ws.post_message(JobProgress("3D: building surfaces", 0, 2))
        try:
            meshes = build_meshes(ws.s, "marching-cubes")
            if worker.is_cancelled:
                return
            ws.post_message(JobProgress(f"3D: rendering {len(meshes)} surface(s)", 1, 2))
            scene = render.Scene.from_meshes(list(meshes.values()))
            if not meshes:
                scene.set_volume(ws.s.volume)
                scene.mode = "mip"
            img = render.get_renderer().submit(scene, size).result()
        except Exception as exc:  # no EGL, no objects: the cell says so, no error toast on every edit
            why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            if isinstance(exc, render.EGLUnavailable):
                why = f"no offscreen OpenGL (EGL); apt-get install {render.EGL_PACKAGES}"
            ws.post_message(CellRendered(None, f"[b]3d unavailable[/b]: {why[:150]}"))
            return
        if not worker.is_cancelled:
            ws.post_message(CellRendered(img, f"3d: {len(meshes)} object(s), r opens the 3D view"))

    def progress(self, what: str) -> Callable[..., None]:
        """In a worker: a ``progress(done, total, message="")`` callback for the engine that shows on the
        workspace's progress row (as messages, at most 20 a second) and stops the job when Escape
        cancelled its worker (raises :class:`ctui.engine.core.progress.Cancelled`)."""
        worker = get_current_worker()
        ws = self.ws
        last = [0.0]

        def progress(done: float, total: float | None, message: str = "") -> None:
            if worker.is_cancelled:
                raise Cancelled(f"{what} cancelled")
            now = time.monotonic()
            if now - last[0] >= 0.05:
                last[0] = now
                ws.post_message(JobProgress(f"{what}: {message}" if message else what, float(done),
                                            float(total or 0) or None))

        return progress

    def run(self, fn: Callable[[], Any], *, what: str, name: str) -> Worker:
        """Run ``fn()`` (returns a message) in a thread; its text becomes the status line."""
        ws = self.ws

        def body() -> None:
            ws.post_message(JobProgress(f"{what} ...", 0, None))
            try:
                msg = fn()
            except Exception as exc:  # a clear notification, the work stays in memory
                ws.post_message(JobFailed(what, str(exc)))
                return
            ws.post_message(JobFinished(str(msg)))

        return ws.jobs.track(ws.run_worker(body, thread=True, group="job", name=name))

    def finished(self, text: str) -> None:
        """A job's ``JobFinished``: its text on the status line (not a toast over the image and the strip)."""
        self.ws.jobs.worker_ended()
        self.ws.show_progress(None)
        self.set_status(text)

    def failed(self, what: str, reason: str) -> None:
        """A job's ``JobFailed``: an error notification ("cancelled": the status line says so)."""
        self.ws.jobs.worker_ended()
        self.work_failed(what, reason)
