"""User-facing errors.

A :class:`CtuiError` carries a one-line message that names the file and the fault.
The CLI prints it (no traceback) and exits with status 2; the TUI shows it as a
notification.
"""

from __future__ import annotations


class CtuiError(Exception):
    """An error meant for the user: ``str(err)`` is one clear line, in the domain's words.

    ``option``: the keyword of the engine action whose value would fix it (e.g.
    ``"series"``, ``"fit_window"``); each front end names it its own way (the CLI appends
    its flag, ``--series``), so engine messages name no CLI flag.
    """

    def __init__(self, message: str, *, path: object | None = None, option: str | None = None) -> None:
        message = " ".join(str(message).split())  # one line, always
        if path is not None and str(path) not in message:
            message = f"{path}: {message}"
        super().__init__(message)
        self.path = path
        self.option = option


class LoadError(CtuiError):
    """Nothing could be loaded from the given path."""


class FormatError(CtuiError):
    """A file is not in the expected format, or is corrupted/truncated."""
