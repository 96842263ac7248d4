"""Compile every meshing kernel ahead of use: :func:`warm_up`.

The TUI calls :func:`warm_up` in a background thread when it opens (the user looks at
slices meanwhile); the CLI starts ``python -m ctui.engine.mesh.warm`` detached after a
command that had to use the vectorised path (:func:`ctui.engine.mesh.jit.compile_in_background`).
With numba's disk cache (``cache=True``) a kernel is compiled once per install; loading
it from the cache takes milliseconds, so calling :func:`warm_up` again is cheap.
"""

from __future__ import annotations

import threading

import numpy as np

from ctui.engine.core.progress import Progress, report

_lock = threading.Lock()
_done = False


def _marching(dtype) -> None:
    from ctui.engine.mesh.marching import _marching_cubes_compiled, _threshold

    d = np.zeros((4, 4, 4), dtype)
    d[1:3, 1:3, 1:3] = 2
    m = np.eye(3)
    _marching_cubes_compiled(d, _threshold(d, 1.0), 1.0, m, np.zeros(3), m, True, None)


def _multilabel() -> None:
    from ctui.engine.mesh.multilabel import multilabel_marching_cubes

    lab = np.zeros((4, 4, 4), np.uint8)
    lab[1:3, 1:3, 1:3] = 1
    multilabel_marching_cubes(lab)


def _normals() -> None:
    from ctui.engine.mesh.meshtools import vertex_normals

    vertex_normals(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.int32))


def _contours() -> None:
    from ctui.engine.mesh.contour_connect import connect_contours

    t = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    ring = np.stack([10 + 5 * np.cos(t), 10 + 5 * np.sin(t)], axis=1)
    for method in ("dp", "greedy"):
        connect_contours([[ring], [ring]], method=method)


STEPS = (("marching cubes (int16)", lambda: _marching(np.int16)),
         ("marching cubes (float32)", lambda: _marching(np.float32)),
         ("multi-label marching cubes", _multilabel),
         ("vertex normals", _normals),
         ("contour connecting", _contours))


def warm_up(*, progress: Progress | None = None) -> None:
    """Compile (or load from numba's disk cache) every kernel meshing uses.

    Safe to call from a background thread and to call again (the second call returns at
    once). ``progress(done, total, message)`` names the kernel being compiled.
    """
    global _done
    with _lock:
        if _done:
            return
        for i, (name, step) in enumerate(STEPS):
            report(progress, i, len(STEPS), f"compiling {name}")
            step()
        report(progress, len(STEPS), len(STEPS), "kernels ready")
        _done = True


if __name__ == "__main__":  # python -m ctui.engine.mesh.warm
    warm_up()
