"""Shared test fixtures.

``shared_data`` points at ``../shared/data`` (real public data sets); tests that need
it skip with a reason when it is absent. ``egl_ok`` tells whether an EGL context can
be created.
"""

from __future__ import annotations

import contextlib
import gc
import io
import os
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("CTUI_SHARED_DATA", ROOT.parent / "shared" / "data"))
SAMPLE_DATA = ROOT / "sample_data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder {SHARED_DATA} is missing")
    return SHARED_DATA


def shared(name: str) -> Path:
    """Path of one data set in ../shared/data, or skip the test with a reason."""
    p = SHARED_DATA / name
    if not p.exists():
        pytest.skip(f"real data set {p} is missing")
    return p


@pytest.fixture(scope="session")
def sample_dir() -> Path:
    return SAMPLE_DATA


def lobster() -> np.ndarray:
    """The volvis lobster from ../shared/data as (56, 324, 301) uint8, or skip."""
    path = shared("lobster") / "lobster_301x324x56_uint8.raw"
    if not path.is_file():
        pytest.skip(f"{path} missing")
    return np.fromfile(path, np.uint8).reshape(56, 324, 301)


def cli_streams(args: list[str]) -> tuple[int, str, str]:
    """``ctui ARGS`` in this process: its exit status, stdout and stderr, caught by redirecting the streams for
    the call (capsys read nothing once in the full suite under load: an earlier app's teardown had put
    back its own streams)."""
    from ctui.cli import main as cli_main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = cli_main(args)
    return rc, out.getvalue(), err.getvalue()


class _Redirect:
    """``contextlib.redirect_stdout``/``redirect_stderr`` for Textual's app loop, which puts the old stream
    back only when the stream is still the one it set. A Textual app runs its message loop inside
    ``redirect_stdout``/``redirect_stderr``; an app coroutine left pending when its test's event loop
    closed (a worker still blocked under load) is closed whenever the garbage collector reaches it, and
    its ``with`` blocks then put back the streams of *its* test in the middle of a later test, whose
    capsys then reads nothing (CI: ``test_bad_input_gives_one_line_naming_the_file[info dir/missing-0]``,
    ``test_failure_is_one_line``). A full collection after each test hid it at the cost of ten minutes
    of the suite, and still missed a coroutine that became garbage only later."""

    def __init__(self, name: str, new: object) -> None:
        self._name, self._new, self._old = name, new, None

    def __enter__(self) -> object:
        self._old = getattr(sys, self._name)
        setattr(sys, self._name, self._new)
        return self._new

    def __exit__(self, *exc: object) -> None:
        if getattr(sys, self._name) is self._new:
            setattr(sys, self._name, self._old)


def _guard_textual_redirects() -> None:
    import textual.app

    textual.app.redirect_stdout = lambda new: _Redirect("stdout", new)  # type: ignore[assignment]
    textual.app.redirect_stderr = lambda new: _Redirect("stderr", new)  # type: ignore[assignment]


_guard_textual_redirects()


_APPS_MADE = [0]


def _count_apps() -> None:
    """Count every Textual app made, so that only the tests that made one pay for a full collection."""
    from textual.app import App

    init = App.__init__

    def counting_init(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        _APPS_MADE[0] += 1
        init(self, *args, **kwargs)

    App.__init__ = counting_init  # type: ignore[method-assign]


_count_apps()


@pytest.fixture(autouse=True)
def _collect_after_apps():
    """After a test that made a Textual app, collect what it left in reference cycles (an app coroutine
    left pending), so that it ends inside that test (see ``_Redirect``)."""
    made = _APPS_MADE[0]
    yield
    if _APPS_MADE[0] != made:
        gc.collect()
