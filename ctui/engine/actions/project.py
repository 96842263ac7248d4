"""Save a project: :func:`new_project`, :func:`propagation_record` and :func:`save_project`, the
one constructor and writer of ``.ctui`` files for ``ctui segment --project``, ``ctui drift
--project``, ``ctui batch`` and the TUI (Ctrl+S, autosave). A project records the source
series' geometry and identity, so it stands on its own."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Sequence

from ctui.engine.core.atomic import check_output
from ctui.engine.core.volume import Volume
from ctui.engine.io import project as projectio
from ctui.engine.io.project import (Project, autosave, find_autosave, load_project, remove_autosave,
                                    source_load_options)

# the project file's own functions, re-exported for the TUI's open and autosave path
__all__ = ["Project", "autosave", "find_autosave", "load_project", "new_project", "propagation_record",
           "remove_autosave", "save_project", "source_load_options"]


def propagation_record(settings: Sequence[dict] = (), **state: Any) -> dict:
    """The one shape of a project's ``propagation`` (keys in ``io.projectschema.PROPAGATION_KEYS``):
    the first object's settings at the top level, ``per_object`` (one dict per object) when
    there are several, and the editor's ``state`` (``current`` object, propagation ``mode``).
    ``ctui segment``, ``ctui drift``, ``ctui batch`` and the TUI all write it through here."""
    prop = dict(settings[0]) if settings else {}
    if len(settings) > 1:
        prop["per_object"] = [dict(s) for s in settings]
    prop.update({k: v for k, v in state.items() if v is not None})
    return prop


def new_project(volume: Volume | None, *, source_path: str | os.PathLike = "", source_options: dict | None = None,
                labels: Any = None, objects: list | None = None, pipeline: dict | None = None,
                propagation: dict | None = None, drift: dict | None = None, window: Any = None,
                meta: dict | None = None, data: Any = None, identity: dict | None = None) -> Project:
    """A Project of ``volume``'s segmentation (geometry, modality, series UID and voxel hash
    recorded from ``volume``, the hash of ``data`` when given: the voxels as loaded). ``source_path``
    is stored absolute ("" = no series). ``identity``: the recorded identity of a series that
    is not loaded (a labels-only session), kept instead of ``volume``'s."""
    src = os.path.abspath(os.fspath(source_path)) if str(source_path).strip() else ""
    if window is None and volume is not None and volume.window:
        window = tuple(volume.window)
    proj = Project(source_path=src, source_options=dict(source_options or {}), pipeline=dict(pipeline or {}),
                   labels=labels, objects=list(objects or []), propagation=dict(propagation or {}),
                   drift=dict(drift or {}), window=tuple(window) if window is not None else None, meta=dict(meta or {}))
    if identity:
        for key, value in identity.items():
            setattr(proj, key, value)
    elif volume is not None:
        proj.set_source(volume, data=data)
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
