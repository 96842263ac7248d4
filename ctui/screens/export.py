"""Export (``e``): meshes (STL/PLY/OBJ), label maps (NIfTI, NRRD, DICOM-SEG, RTSTRUCT), the
objects table (CSV), MRIC contours (all by :func:`ctui.engine.actions.export.export`, what
``ctui export`` runs), or the current image (PNG). The TUI asks what and where, runs it in
a worker (progress row, Esc cancels) and reports the file written."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ctui.engine.actions.mesh import mesh_objects
from ctui.engine.actions.opened import Opened
from ctui.engine.core import borders
from ctui.engine.io import labels as labelio
from ctui.engine.io import meshes as meshio
from ctui.engine.io import mric
from ctui.engine.io.project import Project
from ctui.screens.session import safe_cwd
from ctui.screens.ws_jobs import job_progress, run_job

KINDS = [
    ("mesh-stl", "Mesh of the current object: STL", ".stl"),
    ("mesh-ply", "Mesh of the current object: PLY", ".ply"),
    ("mesh-obj", "Mesh of the current object: OBJ", ".obj"),
    ("meshall-stl", "Meshes of all objects in one file: STL", ".stl"),
    ("meshall-ply", "Meshes of all objects in one file: PLY", ".ply"),
    ("meshall-obj", "Meshes of all objects in one file: OBJ", ".obj"),
    ("labels-nii", "Label map: NIfTI (.nii.gz)", ".nii.gz"),
    ("labels-nrrd", "Label map: NRRD (.seg.nrrd, 3D Slicer segmentation)", ".seg.nrrd"),
    ("labels-dicom-seg", "DICOM-SEG over the source DICOM series", ".dcm"),
    ("labels-rtstruct", "DICOM RTSTRUCT over the source DICOM series", ".dcm"),
    ("table-csv", "Objects table: CSV (volumes, areas, centroids)", ".csv"),
    ("mric", "Contours: MRIC", ".mric"),
    ("image", "Current slice view: PNG", ".png"),
]


def default_name(session, suffix: str, kind: str) -> str:
    stem = Path(session.source_path or "ctui").name.replace(" ", "_") or "ctui"
    if kind.startswith("meshall"):
        stem += "-objects"
    elif kind.startswith("mesh"):
        stem += f"-object{session.current}"
    elif kind == "image":
        stem += f"-slice{session.z}"
    return str(safe_cwd() / f"{stem}{suffix}")


def export_image(rgb: np.ndarray, path: str):
    import cv2

    from ctui.engine.core.atomic import write_bytes

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[:, :, ::-1]) if rgb.ndim == 3 else rgb)
    if not ok:
        raise ValueError("PNG encoding failed")
    write_bytes(path, buf.tobytes())
    return Path(path)


def run_export(ws, kind: str, path: str, *, progress=None) -> str:
    """Do one export (called in a worker thread) with :func:`ctui.engine.actions.export.export`,
    the action ``ctui export`` calls; returns a message."""
    s = ws.s
    if kind == "image":
        rgb = ws.main_view.rgb
        if rgb is None:
            raise ValueError("no image shown")
        export_image(rgb if rgb.ndim == 3 else np.repeat(rgb[:, :, None], 3, axis=2), path)
        return f"Wrote {path}"
    fmt = {"labels-nii": "nifti", "table-csv": "csv"}.get(kind, kind.split("-", 1)[-1])
    objects = s.current if kind.startswith("mesh-") else None
    series = s.source_path if fmt in ("dicom-seg", "rtstruct") else None
    res = export(opened_of(s), format=fmt, out=path, objects=objects, series=series, progress=progress)
    names = ", ".join(str(o["id"]) for o in res.objects)
    extra = f" ({'; '.join(res.warnings)})" if res.warnings else ""
    return f"Wrote {path}: {fmt}, object(s) {names}{extra}"


def export_dialog(ws) -> None:
    from ctui.screens.dialogs import ChoiceScreen, PromptScreen

    app = ws.app

    def chose(kind: str | None) -> None:
        if not kind:
            return
        suffix = dict((k, sfx) for k, _, sfx in KINDS)[kind]

        def got_path(path: str | None) -> None:
            if not path:
                return
            path = str(Path(path.strip()).expanduser())

            def work() -> str:
                msg = run_export(ws, kind, path, progress=job_progress(ws, f"Export {kind}"))
                ws.last_export = path
                return msg

            run_job(ws, work, what="Export", name=f"export {kind}")

        app.push_screen(PromptScreen(f"Export to ({suffix})", default_name(ws.s, suffix, kind)), got_path)

    app.push_screen(ChoiceScreen("Export", [(k, label) for k, label, _ in KINDS]), chose)
