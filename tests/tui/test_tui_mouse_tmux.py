"""The real ``ctui`` binary in tmux with the mouse: SGR mouse reports (as a terminal with
mouse reporting sends them, e.g. tmux with ``mouse on`` or xterm over SSH) typed into the
pane with ``send-keys -l``: a click moves the cursor readout, the wheel changes the slice,
a drag with the brush down paints (voxels counted in the saved project)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
import uuid

import pytest

pytestmark = pytest.mark.slow

SOCKET = f"ctui-mouse-{os.getpid()}-{uuid.uuid4().hex[:6]}"


def _tmux(*args: str) -> list[str]:
    return ["tmux", "-L", SOCKET, *args]


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("TMUX", "TMUX_PANE")}
    env.update(extra)
    return env


def _cap(session: str) -> str:
    return subprocess.run(_tmux("capture-pane", "-p", "-t", session), capture_output=True, text=True, timeout=10,
                          env=_env()).stdout


def _wait(session: str, pattern: str, timeout: float = 60.0) -> str:
    end = time.monotonic() + timeout
    screen = ""
    while time.monotonic() < end:
        screen = _cap(session)
        if re.search(pattern, screen):
            return screen
        time.sleep(0.2)
    raise AssertionError(f"{pattern!r} never appeared on screen:\n{screen}")


def _keys(session: str, *keys: str) -> None:
    subprocess.run(_tmux("send-keys", "-t", session, *keys), check=True, timeout=10, env=_env())


def _sgr(session: str, button: int, col: int, row: int, release: bool = False) -> None:
    """One SGR mouse report (1-based column and row), typed into the pane."""
    seq = f"\x1b[<{button};{col};{row}{'m' if release else 'M'}"
    subprocess.run(_tmux("send-keys", "-t", session, "-l", seq), check=True, timeout=10, env=_env())
    time.sleep(0.15)


@pytest.fixture
def tmux_session():
    if shutil.which("tmux") is None:
        pytest.skip("tmux is not installed")
    name = f"ctui-mouse-{uuid.uuid4().hex[:8]}"
    yield name
    subprocess.run(_tmux("kill-session", "-t", name), capture_output=True, timeout=10, env=_env())
    subprocess.run(_tmux("kill-server"), capture_output=True, timeout=10, env=_env())


# terminal size -> (a cell up-left of the image centre, the drag's row and columns)
LAYOUTS = {(160, 50): ((40, 15), 30, range(40, 75, 5)), (80, 24): ((15, 8), 12, range(10, 34, 4))}


@pytest.mark.parametrize("size", list(LAYOUTS), ids=lambda s: f"{s[0]}x{s[1]}")
def test_mouse_click_wheel_drag_in_tmux(tmux_session, tmp_path, size):
    import numpy as np

    from ctui.engine.io.project import load_project

    env = _env(CTUI_AUTOSAVE_DIR=str(tmp_path / "autosave"), COLORTERM="truecolor")
    cmd = f"cd {tmp_path} && {sys.executable} -m ctui --graphics halfblock; echo CTUI-EXIT=$?; sleep 30"
    (cc, cr), drag_row, drag_cols = LAYOUTS[size]
    subprocess.run(_tmux("new-session", "-d", "-s", tmux_session, "-x", str(size[0]), "-y", str(size[1]), cmd),
                   check=True, env=env, timeout=10)
    subprocess.run(_tmux("set-option", "-t", tmux_session, "mouse", "on"), capture_output=True, timeout=10, env=_env())
    screen = _wait(tmux_session, r"Slice \d+/")
    start = int(screen.split("Slice ")[1].split("/")[0])
    assert "Cursor x 64  y 64" in screen
    # the sample (128x128) fills the main view's height left of the side panel: a click left
    # of and above the centre moves the cursor there
    _sgr(tmux_session, 0, cc, cr)
    _sgr(tmux_session, 0, cc, cr, release=True)
    # wait for the readout to change (under load the click is handled a moment later)
    screen = _wait(tmux_session, r"Cursor x (?!64  y 64\b)\d+  y \d+")
    x, y = (int(v) for v in re.search(r"Cursor x (\d+)  y (\d+)", screen).groups())
    assert x < 60 and y < 60, screen
    # the wheel: up one slice, then down two
    _sgr(tmux_session, 64, cc, cr)
    _wait(tmux_session, f"Slice {start + 1}/")
    _sgr(tmux_session, 65, cc, cr)
    _sgr(tmux_session, 65, cc, cr)
    _wait(tmux_session, f"Slice {start - 1}/")
    # brush down (b paints nothing), then a drag 30 columns to the right paints (its press: a 29-px dab)
    _keys(tmux_session, "b")
    _wait(tmux_session, "Brush down")
    cols = list(drag_cols)
    _sgr(tmux_session, 0, cols[0], drag_row)
    for c in cols[1:]:
        _sgr(tmux_session, 32, c, drag_row)  # motion with the left button held
    _sgr(tmux_session, 0, cols[-1], drag_row, release=True)
    _wait(tmux_session, "Painted along the drag")
    _keys(tmux_session, "b")
    _keys(tmux_session, "C-s")
    _wait(tmux_session, "Save project as")
    proj = tmp_path / "drag.ctui"
    _keys(tmux_session, "C-u", str(proj), "Enter")
    _wait(tmux_session, "Project saved")
    labels = load_project(str(proj)).labels
    z = start - 1
    painted = labels[z] == 1
    ys, xs = np.nonzero(painted)
    # the dab (29 px) plus a 7-px-wide band along the drag, well over 20 columns long
    assert painted.sum() > 29 + 7 * 15 and xs.max() - xs.min() > 20, painted.sum()
    assert set(np.unique(np.nonzero(labels)[0])) == {z}
    _keys(tmux_session, "q")
    screen = _wait(tmux_session, "CTUI-EXIT=")
    assert "CTUI-EXIT=0" in screen and "Traceback" not in screen
