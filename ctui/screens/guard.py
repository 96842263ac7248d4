"""Errors as notifications, never tracebacks.

Textual ends the app on any unhandled exception in a handler, action or worker and
prints a traceback. ctui keeps running instead: the failing step is reported in one
line as an error notification (full traceback kept in ``app.internal_errors`` and
shown by the ``Show last internal error`` command), the work in memory stays intact.
Screens mix in :class:`GuardMixin` so a failing event handler does not stop their
message loop.
"""

from __future__ import annotations

import traceback

from textual import events
from textual.screen import Screen


def report_internal_error(app, exc: BaseException) -> None:
    tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    getattr(app, "internal_errors", []).append(tb)
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    where = ""
    if exc.__traceback__ is not None:
        last = traceback.extract_tb(exc.__traceback__)[-1]
        where = f" in {last.name}"
    try:
        app.notify(f"Internal error{where}: {type(exc).__name__}: {msg[:200]} (ctui keeps running; your work is intact)",
                   severity="error", timeout=12)
    except Exception:
        pass


class GuardMixin:
    """Catch exceptions of this node's own event handlers and report them.

    On a screen it also tags each key with the screen it was sent to, so the app can
    hand keys typed in a burst after a key that opened (or closed) a screen to the
    screen now on top instead of dropping them (see ``CtuiApp._on_key``).
    """

    async def _dispatch_message(self, message) -> None:
        if isinstance(message, events.Key) and isinstance(self, Screen) and getattr(message, "ctui_screen", None) is None:
            message.ctui_screen = self  # type: ignore[attr-defined]  # ctui's mark on Textual's Key event: the screen it was typed at
        try:
            await super()._dispatch_message(message)  # type: ignore[misc]  # a mixin: Textual's Screen follows it in the MRO
        except Exception as exc:
            report_internal_error(self.app, exc)  # type: ignore[attr-defined]  # a mixin: self is a Screen, whose app is the CtuiApp
