"""Export (``e``): mesh (STL/PLY/OBJ), label map (NIfTI/NRRD), MRIC contours, or the
current image (PNG). Each writer is the engine's (atomic); the TUI asks what and where,
runs it in a worker and reports the file written."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ctui.engine.actions.mesh import mesh_objects
from ctui.engine.core import borders
from ctui.engine.io import labels as labelio
from ctui.engine.io import meshes as meshio
from ctui.engine.io import mric
from ctui.screens.projects import opened_of
from ctui.screens.session import safe_cwd
from ctui.screens.ws_jobs import run_job

KINDS = [
    ("mesh-stl", "Mesh of the current object: STL", ".stl"),
    ("mesh-ply", "Mesh of the current object: PLY", ".ply"),
    ("mesh-obj", "Mesh of the current object: OBJ", ".obj"),
    ("meshall-stl", "Meshes of all objects in one file: STL", ".stl"),
    ("meshall-ply", "Meshes of all objects in one file: PLY", ".ply"),
    ("meshall-obj", "Meshes of all objects in one file: OBJ", ".obj"),
    ("labels-nii", "Label map: NIfTI (.nii.gz)", ".nii.gz"),
    ("labels-nrrd", "Label map: NRRD (.seg.nrrd, 3D Slicer segmentation)", ".seg.nrrd"),
    ("mric", "Contours: MRIC", ".mric"),
    ("dicom-seg", "All objects: DICOM-SEG over the series (PACS, 3D Slicer)", ".dcm"),
    ("rtstruct", "All objects: DICOM RTSTRUCT contours (radiotherapy planning)", ".dcm"),
    ("csv", "Measurements of all objects: CSV", ".csv"),
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


def export_mesh(session, path: str, object_id: int):
    """Smoothed surface of one object written with ``meshio.save_mesh``; returns the Mesh."""
    labels = session.labels()
    if labels is None or not (labels == object_id).any():
        raise ValueError(f"object {object_id} is empty: nothing to export")
    mesh = mesh_objects(opened_of(session), objects=int(object_id)).mesh  # the action `ctui mesh` calls
    mesh.object_id = int(object_id)
    meshio.save_mesh(path, mesh)
    return mesh


def export_all_meshes(session, path: str):
    """Smoothed surfaces of every object (each closed on its own) written as one mesh
    file; returns (Mesh, number of objects)."""
    labels = session.labels()
    if labels is None or not labels.any():
        raise ValueError("no objects to export")
    res = mesh_objects(opened_of(session))  # the action `ctui mesh` calls: the same surfaces
    meshio.save_mesh(path, res.mesh)
    return res.mesh, len(res.meshes)


def export_labels(session, path: str):
    labels = session.labels()
    if labels is None or not labels.any():
        raise ValueError("no objects to export")
    names = {i: o.name for i, o in session.seg.objects.items()} if session.seg is not None else None
    return labelio.save_labels(path, labels, session.volume, names=names)


def export_mric(session, path: str):
    labels = session.labels()
    if labels is None or not labels.any():
        raise ValueError("no objects to export")
    slices = borders.borders_for_mric(labels)
    ny, nx = labels.shape[1:]
    from ctui.engine.core.windows import apply_window

    image = apply_window(session.volume.data[session.z], session.window)
    v = session.volume  # the sidecar <name>.mric.json keeps the true voxel size
    return mric.write_mric(path, slices, width=nx, height=ny, image=image, spacing=v.spacing, origin=v.origin,
                           direction=v.direction)


def export_image(rgb: np.ndarray, path: str):
    import cv2

    from ctui.engine.core.atomic import write_bytes

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[:, :, ::-1]) if rgb.ndim == 3 else rgb)
    if not ok:
        raise ValueError("PNG encoding failed")
    write_bytes(path, buf.tobytes())
    return Path(path)


def run_export(ws, kind: str, path: str) -> str:
    """Do one export (called in a worker thread); returns a message."""
    s = ws.s
    if kind.startswith("meshall"):
        mesh, n = export_all_meshes(s, path)
        return f"Wrote {path}: {n} objects, {len(mesh.faces)} triangles, {mesh.volume_mm3() / 1000:.2f} ml"
    if kind.startswith("mesh"):
        mesh = export_mesh(s, path, s.current)
        return f"Wrote {path}: {len(mesh.faces)} triangles, {mesh.volume_mm3() / 1000:.2f} ml"
    if kind.startswith("labels"):
        export_labels(s, path)
        return f"Wrote label map {path}"
    if kind == "mric":
        export_mric(s, path)
        return f"Wrote MRIC contours {path}"
    if kind in ("dicom-seg", "rtstruct", "csv"):  # the action `ctui export` calls
        from ctui.engine.actions.export import export

        res = export(opened_of(s), format=kind, out=path)
        return f"Wrote {path}: {len(res.objects)} objects" + "".join(f"; {w}" for w in res.warnings[:1])
    if kind == "image":
        iv = ws.main_view
        rgb = iv.rgb
        if rgb is None:
            raise ValueError("no image shown")
        export_image(rgb if rgb.ndim == 3 else np.repeat(rgb[:, :, None], 3, axis=2), path)
        return f"Wrote {path}"
    raise ValueError(f"unknown export {kind}")


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
                msg = run_export(ws, kind, path)
                ws.last_export = path
                return msg

            run_job(ws, work, what="Export", name=f"export {kind}")

        app.push_screen(PromptScreen(f"Export to ({suffix})", default_name(ws.s, suffix, kind)), got_path)

    app.push_screen(ChoiceScreen("Export", [(k, label) for k, label, _ in KINDS]), chose)
