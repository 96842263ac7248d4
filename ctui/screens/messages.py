"""Textual messages between ctui's workers, screens and the app.

Thread workers never touch widgets: they ``post_message`` one of these to the screen
(or app) that started them (``post_message`` is thread-safe). A screen that has been
closed meanwhile no longer runs its message loop, so a late answer is dropped instead
of updating widgets that are gone (the NoMatches '#ms-status' / '#v3-status' races).
"""

from __future__ import annotations

from typing import Any

from textual.message import Message


class JobProgress(Message):
    """A worker's progress: ``label`` with ``done`` of ``total`` (``total`` None: indeterminate);
    ``label`` None hides the progress row."""

    def __init__(self, label: str | None, done: float = 0.0, total: float | None = None) -> None:
        super().__init__()
        self.label = label
        self.done = float(done)
        self.total = None if total is None else float(total)


class Status(Message):
    """One line for the screen's status bar."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.text = text


class JobFailed(Message):
    """A worker failed: ``what`` did not happen because of ``reason`` (shown as an error)."""

    def __init__(self, what: str, reason: str) -> None:
        super().__init__()
        self.what = what
        self.reason = reason


class JobDone(Message):
    """A worker finished: ``kind`` names the job, ``result`` is its value."""

    def __init__(self, kind: str, result: Any = None, **info: Any) -> None:
        super().__init__()
        self.kind = kind
        self.result = result
        self.info = info


class LabelsChanged(Message):
    """The segmentation changed (posted by screens that edit it, to the workspace)."""


class SessionReady(Message):
    """A series or project has loaded: the app opens a workspace on ``session``."""

    def __init__(self, session: Any) -> None:
        super().__init__()
        self.session = session


class LoadFailed(Message):
    """Loading ``path`` failed for ``reasons``."""

    def __init__(self, path: str | None, reasons: list[str], options: dict | None = None) -> None:
        super().__init__()
        self.path = path
        self.reasons = list(reasons)
        self.options = dict(options or {})


class Call(Message, bubble=False):
    """Run ``fn(*args, **kwargs)`` on the UI thread in the screen it is posted to (screens
    mix in :class:`ctui.screens.guard.GuardMixin`, which handles it). Unlike
    ``App.call_from_thread`` it never blocks the worker, and it is dropped when the screen
    has closed meanwhile instead of touching widgets that are gone."""

    def __init__(self, fn: Any, *args: Any, **kwargs: Any) -> None:
        super().__init__()
        self.fn = fn
        self.args = args
        self.kwargs = kwargs
