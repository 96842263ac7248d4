"""The TUI tests' harness: every test here runs in its own folder with its own autosave folder and the
half-block renderer (the public ``using_graphics`` switch, given back after the test).

The fixture takes no ``monkeypatch`` (it uses a MonkeyPatch of its own), so that it is set up before a
test's ``monkeypatch`` and torn down after it: a test that patches the graphics mode itself gets the
mode it found back first, then this fixture puts back the mode from before the test.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import pytest

from ctui.screens import graphics


@pytest.fixture(autouse=True)
def tui_env(tmp_path: Path) -> Iterator[Path]:
    """cwd = ``tmp_path``, ``CTUI_AUTOSAVE_DIR`` = ``tmp_path/autosave``, graphics ``halfblock``."""
    with pytest.MonkeyPatch.context() as mp, graphics.using_graphics("halfblock"):
        mp.setenv("CTUI_AUTOSAVE_DIR", str(tmp_path / "autosave"))
        mp.chdir(tmp_path)
        yield tmp_path
