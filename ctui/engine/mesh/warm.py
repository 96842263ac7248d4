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
    from ctui.engine.mesh.marching import _marching_cubes_compiled, _threshold  # numba kernels

    d = np.zeros((4, 4, 4), dtype)
    d[1:3, 1:3, 1:3] = 2
    m = np.eye(3)
    _marching_cubes_compiled(d, _threshold(d, 1.0), 1.0, m, np.zeros(3), m, True, None)


def _multilabel() -> None:
    from ctui.engine.mesh.multilabel import multilabel_marching_cubes  # numba kernels

    lab = np.zeros((4, 4, 4), np.uint8)
    lab[1:3, 1:3, 1:3] = 1
    multilabel_marching_cubes(lab)


def _normals() -> None:
    from ctui.engine.mesh.tool_kernels import _vertex_normals  # numba kernels

    _vertex_normals(np.eye(3), np.array([[0, 1, 2]], np.int64))


def _report() -> None:
    from ctui.engine.mesh.tool_kernels import _report_kernel  # numba kernels

    _report_kernel(np.eye(3), np.array([[0, 1, 2]], np.int64), np.zeros(3))


def _contours() -> None:
    # the kernels themselves: connect_contours would tile a small stack in plain Python
    from ctui.engine.mesh.contour_tiling import _tile_range  # numba kernels

    t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    ring = np.ascontiguousarray(np.stack([np.cos(t), np.sin(t), np.zeros(12)], axis=1))
    ids = np.arange(12, dtype=np.int64)
    off = np.array([0, 12], np.int64)
    for use_dp in (True, False):
        out = np.empty((24, 3), np.int64)
        _tile_range(ring, off, ids, ring + [0.0, 0.0, 1.0], off, ids + 12, np.zeros(1, np.int64), use_dp,
                    np.array([0, 24], np.int64), out, np.ones(1, np.int64), 0, 1)


STEPS = (("marching cubes (int16)", lambda: _marching(np.int16)),
         ("marching cubes (float32)", lambda: _marching(np.float32)),
         ("multi-label marching cubes", _multilabel),
         ("vertex normals", _normals),
         ("mesh report", _report),
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
