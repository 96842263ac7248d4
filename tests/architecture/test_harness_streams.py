"""The test harness's guard on Textual's stream redirection (tests/conftest.py ``_Redirect``)."""
from __future__ import annotations

import io
import sys


def _app_loop(capture: io.StringIO):
    import textual.app

    with textual.app.redirect_stdout(capture):
        yield  # the app's loop, left pending when its test's event loop closed


def test_a_stale_app_loop_closed_later_leaves_the_current_streams_alone():
    stale = _app_loop(io.StringIO())
    next(stale)  # an earlier test's app: it replaced sys.stdout with its capture
    earlier = sys.stdout
    sys.stdout = current = io.StringIO()  # pytest gives the next test its own stream
    try:
        stale.close()  # the garbage collector closes the stale loop in the middle of the later test
        assert sys.stdout is current
    finally:
        sys.stdout = earlier


def test_an_app_loop_that_ends_normally_puts_the_stream_back():
    before = sys.stdout
    loop = _app_loop(capture := io.StringIO())
    next(loop)
    assert sys.stdout is capture
    loop.close()
    assert sys.stdout is before
