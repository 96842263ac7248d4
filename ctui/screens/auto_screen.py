"""The workspace's AI first draft (``Z``; Ctrl+P "AI first draft"): TotalSegmentator, where the user
installed it, run on the open series by ``actions.auto.auto_segment`` (the function ``ctui auto``
calls) in a worker with progress (Escape cancels: the subprocess is killed), its classes imported
as named objects into the open segmentation as one undo step.

The dialog offers the task (``auto.TASKS``), a subset of classes (``auto.ROI_SETS``, or names
typed), the merge policy (``auto.MERGE``), ``--fast`` and the device. The TUI edits at most
``core.colors.MAX_OBJECTS`` objects: a subset that would need more new objects than are free is
refused in the dialog with the count. A missing executable or weights is one line, before the
dialog opens.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Checkbox, Input, Label, Select
from textual.worker import get_current_worker

from ctui.engine.actions import auto
from ctui.engine.core.colors import MAX_OBJECTS
from ctui.engine.core.progress import Cancelled
from ctui.screens.guard import GuardMixin
from ctui.screens.messages import AutoReady, JobFailed, JobProgress
from ctui.screens.ws_host import WorkspaceHost

WHAT = "AI first draft"


def new_objects(names: Sequence[str], merge: str, existing: Sequence[str]) -> int:
    """How many new objects ``names`` make under ``merge`` beside objects named ``existing``
    (``replace`` reuses the object of a class's name, ``keep`` skips it)."""
    if merge == "add":
        return len(set(names))
    return len(set(names) - set(existing))


def fit_problem(names: Sequence[str], merge: str, objects: dict[int, str]) -> str:
    """"" when ``names`` fit beside ``objects`` (id -> name) in the TUI's MAX_OBJECTS, else one line."""
    if not names:
        return "pick a set of classes or type their names"
    need = new_objects(names, merge, list(objects.values()))
    free = MAX_OBJECTS - len(objects)
    if need > free:
        return (f"{need} classes need {need} new objects and {free} of {MAX_OBJECTS} are free: "
                "pick fewer, or merge replace/keep")
    return ""


class AutoScreen(GuardMixin, ModalScreen[dict | None]):
    """The draft's options; dismisses with {task, roi_subset, merge, fast, device} or None."""

    DEFAULT_CSS = """
    AutoScreen { align: center middle; }
    AutoScreen > Vertical { width: 90%; max-width: 100; height: auto; max-height: 100%; border: round $accent;
                            background: $surface; padding: 0 1; }
    AutoScreen Horizontal { height: auto; }
    AutoScreen .name { width: 9; padding: 1 0 0 0; }
    AutoScreen Select { width: 1fr; }
    AutoScreen #au-device { width: 12; }
    AutoScreen #au-names { width: 1fr; }
    AutoScreen Checkbox { width: auto; }
    AutoScreen #au-note { width: 1fr; color: $warning; }
    AutoScreen Button { margin: 0 1; }
    """
    BINDINGS = [Binding("escape", "cancel", "Cancel")]

    def __init__(self, objects: dict[int, str]) -> None:
        super().__init__()
        self.objects = dict(objects)

    def compose(self) -> ComposeResult:
        first = next(iter(auto.ROI_SETS))
        with Vertical():
            yield Label(f"[b]{WHAT}[/b]: TotalSegmentator's classes as objects (at most {MAX_OBJECTS})")
            with Horizontal():
                yield Label("Task", classes="name")
                yield Select([(f"{k}: {v}", k) for k, v in auto.TASKS.items()], value="total", allow_blank=False,
                             id="au-task")
                yield Checkbox("fast (3 mm)", id="au-fast")
            with Horizontal():
                yield Label("Classes", classes="name")
                yield Select([(f"{k}: {', '.join(v)}", k) for k, v in auto.ROI_SETS.items()], value=first,
                             allow_blank=False, id="au-set")
            with Horizontal():
                yield Label("or", classes="name")
                yield Input(placeholder="class names, e.g. liver,spleen (replace the set)", id="au-names")
            with Horizontal():
                yield Label("Merge", classes="name")
                yield Select([(f"{k}: {v.split(';')[0]}", k) for k, v in auto.MERGE.items()], value="add",
                             allow_blank=False, id="au-merge")
                yield Select([(d, d) for d in auto.DEVICES], value="cpu", allow_blank=False, id="au-device")
            yield Label("", id="au-note")
            with Horizontal():
                yield Button("Run", id="au-run", variant="primary")
                yield Button("Cancel", id="au-cancel")

    def on_mount(self) -> None:
        self.query_one("#au-run", Button).focus()
        self._check()

    def names(self) -> list[str]:
        typed = [n.strip() for n in self.query_one("#au-names", Input).value.split(",") if n.strip()]
        return typed or list(auto.ROI_SETS[str(self.query_one("#au-set", Select).value)])

    def choice(self) -> dict[str, Any]:
        return {"task": str(self.query_one("#au-task", Select).value), "roi_subset": self.names(),
                "merge": str(self.query_one("#au-merge", Select).value),
                "fast": bool(self.query_one("#au-fast", Checkbox).value),
                "device": str(self.query_one("#au-device", Select).value)}

    def _check(self) -> str:
        c = self.choice()
        problem = fit_problem(c["roi_subset"], c["merge"], self.objects)
        self.query_one("#au-note", Label).update(problem)
        self.query_one("#au-run", Button).disabled = bool(problem)
        return problem

    def on_select_changed(self, _event: Select.Changed) -> None:
        self._check()

    def on_input_changed(self, _event: Input.Changed) -> None:
        self._check()

    def on_input_submitted(self, _event: Input.Submitted) -> None:
        self._run()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "au-run":
            self._run()
        else:
            self.dismiss(None)

    def _run(self) -> None:
        if not self._check():
            self.dismiss(self.choice())

    def action_cancel(self) -> None:
        self.dismiss(None)


def open_auto(ws: WorkspaceHost) -> None:
    """``Z``: say what is missing in one line, else ask the options and start the worker."""
    if ws.edit.busy():
        return
    why = auto.missing("total")
    if why:
        ws.set_status(why)
        ws.app.notify(why, severity="error", timeout=10)
        return
    objects = {i: o.name for i, o in ws.s.seg.objects.items()}
    def chosen(choice: dict | None) -> None:
        if choice is not None:
            start(ws, choice)

    ws.app.push_screen(AutoScreen(objects), chosen)


def start(ws: WorkspaceHost, choice: dict[str, Any]):
    """Run the draft in a thread (Escape cancels it); its result comes back as ``AutoReady``."""
    snapshot = ws.s.seg.labels.copy()
    objects = ws.s.seg.object_list()

    def body() -> None:
        worker = get_current_worker()
        ws.post_message(JobProgress(f"{WHAT}: starting TotalSegmentator", 0, 100))
        try:
            res = auto.auto_segment(ws.s.volume, labels=snapshot, objects=objects, max_id=MAX_OBJECTS,
                                    progress=ws.work.progress(WHAT), **choice)
        except Cancelled:
            ws.post_message(JobFailed(WHAT, "cancelled"))
            return
        except Exception as exc:  # one line, the segmentation untouched
            ws.post_message(JobFailed(WHAT, str(exc).splitlines()[0] if str(exc) else type(exc).__name__))
            return
        if not worker.is_cancelled:
            ws.post_message(AutoReady(res, snapshot))

    return ws.jobs.track(ws.run_worker(body, thread=True, group="job", name=WHAT))


def apply_result(ws: WorkspaceHost, res, snapshot: np.ndarray) -> None:
    """Write what the draft changed (voxels where its labels differ from ``snapshot``: edits made while
    it ran stay) as one undo step, name and colour its objects, say what came in."""
    ws.jobs.worker_ended()
    ws.show_progress(None)
    seg = ws.s.seg
    changed = res.labels != snapshot
    if not changed.any() and not res.added:
        ws.set_status(f"{WHAT}: TotalSegmentator found none of the classes asked for"
                      + (f" ({'; '.join(res.skipped)})" if res.skipped else ""))
        return
    if changed.any():
        idx = [np.flatnonzero(changed.any(axis=a)) for a in ((1, 2), (0, 2), (0, 1))]
        box = (slice(int(idx[0][0]), int(idx[0][-1]) + 1), slice(int(idx[1][0]), int(idx[1][-1]) + 1),
               slice(int(idx[2][0]), int(idx[2][-1]) + 1))
        seg.apply_region(box, np.where(changed[box], res.labels[box], seg.labels[box]),
                         label=f"TotalSegmentator {res.task}")
    for o in res.added:
        obj = next(x for x in res.objects if int(x["id"]) == int(o["id"]))
        oid = seg.add_object(obj["name"], color=tuple(obj["color"]), object_id=int(obj["id"]))
        seg.objects[oid].name, seg.objects[oid].color = str(obj["name"]), (int(obj["color"][0]), int(obj["color"][1]), int(obj["color"][2]))
    if res.added:
        ws.s.current = int(res.added[0]["id"])
    names = ", ".join(f"{o['name']} {o['volume_ml']:.1f} mL" for o in res.added)
    notes = [f"skipped {s}" for s in res.skipped] + list(res.warnings)
    ws.edit.edited(f"{WHAT}: {len(res.added)} object(s) from TotalSegmentator {res.task} in {res.seconds:.0f} s: "
               f"{names}" + (f" ({'; '.join(notes)})" if notes else "") + "; u undoes")
