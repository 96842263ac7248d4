"""ctui: terminal-first CT/MRI slice series to measured 3D models."""

import os as _os

__version__ = "0.1.0"

# numba formats its compile-time errors through colorama when colorama is installed: each message swaps
# sys.stdout/sys.stderr for colorama's copies of the streams of the moment numba first used it, and
# back (numba.core.errors.ColorShell: init/reinit/deinit). Under the TUI (Textual redirects the streams)
# or any caller that redirects them, a kernel compiling in a worker thread then put back stale streams:
# in the test suite, CLI error lines reached an earlier test's capture. Plain messages need no swap.
_os.environ.setdefault("NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING", "1")
