"""Progress and cancellation, the same for the CLI (a bar on stderr) and the TUI (a worker).

An engine function that can take more than a second takes ``progress: Progress | None``
and calls ``progress(done, total, message)`` now and then; the callback may raise
:class:`Cancelled` (or return ``False``) to stop the work. :func:`report` wraps both
conventions, and :data:`NULL` is a callback that does nothing.
"""

from __future__ import annotations

from typing import Callable, Optional

from ctui.engine.core.errors import CtuiError

Progress = Callable[..., Optional[bool]]


class Cancelled(CtuiError):
    """The user cancelled the work (Esc in the TUI, Ctrl+C in the CLI)."""

    def __init__(self, message: str = "cancelled") -> None:
        super().__init__(message)


def report(progress: Progress | None, done: float, total: float, message: str = "") -> None:
    """Call ``progress(done, total, message)``; raise :class:`Cancelled` when it returns False."""
    if progress is None:
        return
    try:
        rv = progress(done, total, message)
    except TypeError:  # an older two-argument callback
        rv = progress(done, total)
    if rv is False:
        raise Cancelled()


def scaled(progress: Progress | None, start: float, stop: float) -> Progress | None:
    """A callback mapping a sub-task's 0..total onto start..stop of a 0..1 parent."""
    if progress is None:
        return None

    def sub(done: float, total: float, message: str = "") -> bool | None:
        frac = (done / total) if total else 1.0
        return progress(start + (stop - start) * frac, 1.0, message)

    return sub


def NULL(done: float, total: float, message: str = "") -> None:  # noqa: N802 - a constant-like callback
    return None
