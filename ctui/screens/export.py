"""Export (``e``): the menu lists the engine's export formats
(:data:`ctui.engine.actions.formats.FORMATS`, what ``ctui export --format`` offers), those
the input cannot take greyed with the reason, plus the current slice view as a PNG. Every
file but the PNG is written by :func:`ctui.engine.actions.export.export`, in a worker."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ctui.engine.actions.export import ExportResult, available_formats, export
from ctui.engine.actions.formats import FORMATS, output_name
from ctui.engine.core.atomic import check_output, write_bytes
from ctui.screens.cells import physical_image
from ctui.screens.dialogs import ChoiceScreen, PromptScreen
from ctui.screens.projects import opened_of
from ctui.screens.session import Session, safe_cwd
from ctui.screens.ws_host import WorkspaceHost

#: Menu ids the screen adds to the engine's formats: a format's surfaces for the current
#: object only (``<format>:current``) and the slice view as shown.
CURRENT = ":current"
IMAGE = ("image", "Current slice view: PNG", ".png")


def menu_items(session: Session) -> tuple[list[tuple[str, str]], str]:
    """The export menu for this session: (id, label) of every export it can write (each
    registered format the input supports, in registry order, its current-object variant
    when it writes surfaces, then the slice view PNG), and a note saying why the other
    formats are not offered ("" when all are)."""
    items: list[tuple[str, str]] = []
    missing: dict[str, list[str]] = {}
    for fmt, why in available_formats(opened_of(session)):
        if why:
            missing.setdefault(why, []).append(fmt.title)
            continue
        items.append((fmt.name, fmt.label))
        if fmt.per_object:
            items.append((fmt.name + CURRENT, f"{fmt.title}: surface of the current object"))
    items.append(IMAGE[:2])
    note = "\n".join(f"Not offered: {', '.join(titles)} ({why})" for why, titles in missing.items())
    return items, note


def default_name(session: Session, kind: str) -> str:
    """Where an export goes by default: named from the input's stem in the folder ctui
    started from (``ct.nii.gz`` -> ``ct-labels.nii.gz``, ``ct-object2.stl``, ``ct-slice40.png``)."""
    source = session.project_path or session.source_path
    if kind == IMAGE[0]:
        name = output_name(source, IMAGE[2], tag=f"slice{session.z}")
    elif kind.endswith(CURRENT):
        name = output_name(source, FORMATS[kind[: -len(CURRENT)]].suffix, tag=f"object{session.current}")
    else:
        fmt = FORMATS[kind]
        name = output_name(source, fmt.suffix, tag=fmt.tag)
    return str(safe_cwd() / name)


def export_session(session: Session, kind: str, path: str, *, progress=None) -> ExportResult:
    """Write the session's objects (``kind``: a format name, or ``<format>:current`` for the
    current object only) through the export action ``ctui export`` calls."""
    name, current = (kind[: -len(CURRENT)], True) if kind.endswith(CURRENT) else (kind, False)
    return export(opened_of(session), format=name, out=path, objects=int(session.current) if current else None,
                  progress=progress)


def export_image(rgb: np.ndarray, path: str):
    import cv2  # OpenCV: loaded when a PNG is written, not when the TUI starts


    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[:, :, ::-1]) if rgb.ndim == 3 else rgb)
    if not ok:
        raise ValueError("PNG encoding failed")
    write_bytes(path, buf.tobytes())
    return Path(path)


def run_export(ws: WorkspaceHost, kind: str, path: str, *, shown: tuple | None = None) -> str:
    """Do one export (called in a worker thread); returns a message. ``shown``: the slice view's
    (RGB image, spacing yx) taken on the UI thread (the worker reads no widget); None: read them here."""
    if kind == IMAGE[0]:
        check_output(path, inputs=[ws.s.source_path, ws.s.project_path], label="the image")  # as every export
        rgb, spacing_yx = shown if shown is not None else (ws.main_view.rgb, ws.main_view.spacing_yx)
        if rgb is None:
            raise ValueError("no image shown")

        rgb = physical_image(rgb, spacing_yx)  # the physical aspect, as on screen
        export_image(rgb if rgb.ndim == 3 else np.repeat(rgb[:, :, None], 3, axis=2), path)
        return f"Wrote {path}"
    res = export_session(ws.s, kind, path)
    names = ", ".join(o["name"] for o in res.objects[:3]) + (", ..." if len(res.objects) > 3 else "")
    return f"Wrote {path}: {len(res.objects)} object(s) ({names})" + "".join(f"; {w}" for w in res.warnings[:1])


def export_dialog(ws: WorkspaceHost) -> None:
    app = ws.app
    items, note = menu_items(ws.s)
    suffixes = {k: (IMAGE[2] if k == IMAGE[0] else FORMATS[k.split(":")[0]].suffix) for k, _ in items}

    def chose(kind: str | None) -> None:
        if not kind:
            return

        def got_path(path: str | None) -> None:
            if not path:
                return
            path = str(Path(path.strip()).expanduser())

            shown = (ws.main_view.rgb, ws.main_view.spacing_yx)  # on the UI thread: the worker touches no widget
            ws.work.run(lambda: run_export(ws, kind, path, shown=shown), what="Export", name=f"export {kind}")

        app.push_screen(PromptScreen(f"Export to ({suffixes[kind]})", default_name(ws.s, kind)), got_path)

    app.push_screen(ChoiceScreen("Export", items, note=note), chose)
