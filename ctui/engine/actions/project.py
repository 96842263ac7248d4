"""Save a project: :func:`new_project` and :func:`save_project`, the one writer of ``.ctui``
files for ``ctui segment --project``, ``ctui drift --project`` and the TUI (Ctrl+S, autosave).
Both record the source series' geometry and identity, so the project stands on its own."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Sequence

from ctui.engine.core.atomic import check_output
from ctui.engine.core.volume import Volume
from ctui.engine.io import project as projectio
from ctui.engine.io.project import Project


def new_project(volume: Volume | None, *, source_path: str | os.PathLike = "", source_options: dict | None = None,
                labels: Any = None, objects: list | None = None, pipeline: dict | None = None,
                propagation: dict | None = None, drift: dict | None = None, window: Any = None,
                meta: dict | None = None) -> Project:
    """A Project of ``volume``'s segmentation (geometry, modality, series UID and voxel hash
    recorded from ``volume``). ``source_path`` is stored absolute ("" = no series)."""
    src = os.path.abspath(os.fspath(source_path)) if str(source_path).strip() else ""
    if window is None and volume is not None and volume.window:
        window = tuple(volume.window)
    proj = Project(source_path=src, source_options=dict(source_options or {}), pipeline=dict(pipeline or {}),
                   labels=labels, objects=list(objects or []), propagation=dict(propagation or {}),
                   drift=dict(drift or {}), window=tuple(window) if window is not None else None, meta=dict(meta or {}))
    if volume is not None:
        proj.set_source(volume)
    return proj


def save_project(path: str | os.PathLike, project: Project, *, volume: Volume | None = None,
                 autosave: bool = False, inputs: Sequence[str | os.PathLike] = ()) -> Path:
    """Write ``project`` atomically (its source identity refreshed from ``volume`` when
    given); ``autosave`` writes the recovery file for ``path`` instead. Refuses a
    ``path`` that is (or lies inside) the project's source series or one of ``inputs``."""
    if volume is not None:
        project.set_source(volume)
    if autosave:
        return projectio.autosave(project, path)
    check_output(path, inputs=[project.source_path, *inputs], label="project")
    return projectio.save_project(path, project)
