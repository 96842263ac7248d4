"""Fixtures and guards for every test; helpers that are not fixtures are in ``support.py``.

``shared_data`` points at ``../shared/data`` (real public data sets); tests that need
it skip with a reason when it is absent. Each folder's conftest.py holds that folder's fixtures.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from support import SAMPLE_DATA, SHARED_DATA, put_test_folders_on_path

put_test_folders_on_path()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder {SHARED_DATA} is missing")
    return SHARED_DATA


@pytest.fixture(scope="session")
def sample_dir() -> Path:
    return SAMPLE_DATA


class _Redirect:
    """``contextlib.redirect_stdout``/``redirect_stderr`` for Textual's app loop, which puts the old stream
    back only when the stream is still the one it set. A Textual app runs its message loop inside
    ``redirect_stdout``/``redirect_stderr``; an app coroutine left pending when its test's event loop
    closed (a worker still blocked under load) is closed whenever the garbage collector reaches it, and
    its ``with`` blocks then put back the streams of *its* test in the middle of a later test, whose
    capsys then reads nothing (CI: ``test_bad_input_gives_one_line_naming_the_file[info dir/missing-0]``,
    ``test_failure_is_one_line``). A full collection after each test hid it at the cost of ten minutes
    of the suite, and still missed a coroutine that became garbage only later. (A collection after each
    test that made an app was dropped too: the streams' other thief was numba's error highlighting,
    now off in ctui/__init__.py; tests/architecture/test_harness_streams.py and test_numba_streams.py
    check both guards.)"""

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
