"""Helpers shared by the tests of every folder: ``from support import shared, ROOT``.

The folders of ``tests/`` mirror the code (``engine/<stage>/``, ``cli/``, ``tui/``, ``fuzz/``,
``architecture/``) and are all on ``sys.path`` (:func:`put_test_folders_on_path`), so a test
imports this module, or another test module's helpers, by its bare name: test module names are
unique across the folders (tests/architecture/test_test_layout.py checks it). Fixtures live in
the conftest.py of the folder that uses them; what is not a fixture lives here (a conftest is
not imported by name: each folder's is module ``conftest`` in turn).

``SHARED_DATA`` is ``../shared/data`` next to the repository (real public data sets; override
with ``CTUI_SHARED_DATA``); tests that need it skip with a reason when it is absent.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
from pathlib import Path

import numpy as np
import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
SHARED_DATA = Path(os.environ.get("CTUI_SHARED_DATA", ROOT.parent / "shared" / "data"))
SAMPLE_DATA = ROOT / "sample_data"


def python_folders() -> list[Path]:
    """``tests/`` and every folder below it that holds Python files (not data: ``__snapshots__``,
    ``regression_corpus``)."""
    return [TESTS] + sorted(d for d in TESTS.rglob("*") if d.is_dir() and "__" not in d.name and any(d.glob("*.py")))


def put_test_folders_on_path() -> None:
    """Every test folder on ``sys.path``, so that test modules and helper scripts import each other by bare
    name wherever they live (the root conftest calls it; so do scripts run as subprocesses)."""
    for folder in python_folders():
        if str(folder) not in sys.path:
            sys.path.append(str(folder))


def shared(name: str) -> Path:
    """Path of one data set in ../shared/data, or skip the test with a reason."""
    p = SHARED_DATA / name
    if not p.exists():
        pytest.skip(f"real data set {p} is missing")
    return p


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
