"""numba's error highlighting must not swap the process's standard streams (ctui/__init__.py).

With colorama installed, numba formats each compile-time error message inside a ``ColorShell``: it
saves ``sys.stderr``/``sys.stdout`` as they are when the shell is made, and puts those back when it is
left (colorama's init/reinit/deinit, whose saved streams are shared by every thread). A kernel compiling in
a worker thread while the main thread redirects the streams (the TUI under Textual, a caller capturing
output, a test's capture) then puts back stale streams."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys

import pytest

SWAP = (
    "import io, sys\n"
    "from numba.core import errors\n"
    "first = sys.stderr = io.StringIO()\n"
    "shell = errors.ColorShell()  # made while the first stream is set (a worker thread's message)\n"
    "later = sys.stderr = io.StringIO()  # meanwhile the main thread redirects stderr\n"
    "with shell:\n"
    "    pass\n"
    "print('same' if sys.stderr is later else 'swapped', file=sys.__stdout__)\n"
)


def _run(code: str, env: dict) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_ctui_turns_numbas_stream_swapping_off():
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING"}
    code = ("import ctui, numba.core.errors as e\n"
            "print('nop' if not hasattr(e, 'ColorShell') and type(e.termcolor()).__name__ == 'NOPColorScheme'"
            " else 'colour', file=__import__('sys').__stdout__)\n")
    assert _run(code, env) == "nop"


def test_numbas_colour_shell_swaps_the_streams_when_on():
    """The reason for the setting (so the check above can fail): the swap, reproduced without ctui."""
    if importlib.util.find_spec("colorama") is None:
        pytest.skip("colorama is not installed: numba has no colour shell")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING"}
    assert _run(SWAP, env) == "swapped"
