"""The real ``ctui`` binary in tmux: start it, send keys, read the screen with
capture-pane (as a person over SSH would see it). Skips when tmux is missing."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import uuid

import pytest

pytestmark = pytest.mark.slow

TMUX = shutil.which("tmux")
# a private server (own socket) for these tests: they pass inside tmux and beside a
# server the user already runs (the default socket is never touched)
SOCKET = f"ctui-test-{os.getpid()}-{uuid.uuid4().hex[:6]}"


def _tmux(*args: str) -> list[str]:
    return ["tmux", "-L", SOCKET, *args]


def _env(**extra: str) -> dict[str, str]:
    """The child's environment: never the caller's tmux (TMUX, TMUX_PANE)."""
    env = {k: v for k, v in os.environ.items() if k not in ("TMUX", "TMUX_PANE")}
    env.update(extra)
    return env


def _cap(session: str, *, escapes: bool = False) -> str:
    args = _tmux("capture-pane", "-p", "-t", session) + (["-e"] if escapes else [])
    return subprocess.run(args, capture_output=True, text=True, timeout=10, env=_env()).stdout


def _wait(session: str, text: str, timeout: float = 60.0) -> str:
    end = time.monotonic() + timeout
    screen = ""
    while time.monotonic() < end:
        screen = _cap(session)
        if text in screen:
            return screen
        time.sleep(0.2)
    raise AssertionError(f"{text!r} never appeared on screen:\n{screen}")


def _keys(session: str, *keys: str) -> None:
    subprocess.run(_tmux("send-keys", "-t", session, *keys), check=True, timeout=10, env=_env())


@pytest.fixture
def tmux_session(tmp_path):
    if TMUX is None:
        pytest.skip("tmux is not installed")
    name = f"ctui-test-{uuid.uuid4().hex[:8]}"
    yield name
    subprocess.run(_tmux("kill-session", "-t", name), capture_output=True, timeout=10, env=_env())
    # the private server ends with its last session; make sure
    subprocess.run(_tmux("kill-server"), capture_output=True, timeout=10, env=_env())


@pytest.mark.parametrize("size", [(160, 50), (80, 24)], ids=["160x50", "80x24"])
def test_real_binary_in_tmux(tmux_session, tmp_path, size):
    w, h = size
    env = _env(CTUI_AUTOSAVE_DIR=str(tmp_path / "autosave"), COLORTERM="truecolor")
    env.pop("TEXTUAL_COLOR_SYSTEM", None)
    cmd = f"cd {tmp_path} && {sys.executable} -m ctui --graphics halfblock; echo CTUI-EXIT=$?; sleep 30"
    subprocess.run(_tmux("new-session", "-d", "-s", tmux_session, "-x", str(w), "-y", str(h), cmd),
                   check=True, env=env, timeout=10)
    screen = _wait(tmux_session, "Slice")
    assert "Traceback" not in screen
    # the slice is drawn with half blocks in truecolor
    esc = _cap(tmux_session, escapes=True)
    assert "\u2580" in screen and "38;2;" in esc
    start = int(screen.split("Slice ")[1].split("/")[0])
    _keys(tmux_session, "PageUp")
    _keys(tmux_session, "PageUp")
    screen = _wait(tmux_session, f"Slice {start + 2}/")
    # move the cursor and read the value under it in the side panel
    _keys(tmux_session, "l")
    screen = _wait(tmux_session, "Cursor x 65")
    assert "HU" in screen
    # help lists the bindings
    _keys(tmux_session, "?")
    screen = _wait(tmux_session, "ctui help")
    assert "Keys on this screen" in screen and "Segment" in screen and "Fill" in screen  # by task, main keys first
    _keys(tmux_session, "Escape")
    # resize the window: still alive and redrawn
    subprocess.run(_tmux("resize-window", "-t", tmux_session, "-x", "60", "-y", "20"), capture_output=True, timeout=10, env=_env())
    time.sleep(1.0)
    subprocess.run(_tmux("resize-window", "-t", tmux_session, "-x", str(w), "-y", str(h)), capture_output=True, timeout=10, env=_env())
    _wait(tmux_session, "Slice")
    # quit (nothing unsaved: exits at once)
    _keys(tmux_session, "q")
    screen = _wait(tmux_session, "CTUI-EXIT=")
    assert "CTUI-EXIT=0" in screen, screen
    assert "Traceback" not in screen


def test_tmux_without_colorterm_tells_how_to_fix(tmux_session, tmp_path):
    """Over SSH COLORTERM is usually not forwarded: Rich drops to 256 colours and grey
    slices band. ctui says once how to fix it."""
    env = {k: v for k, v in _env().items() if k not in ("COLORTERM", "TEXTUAL_COLOR_SYSTEM")}
    env.update({"CTUI_AUTOSAVE_DIR": str(tmp_path / "autosave"), "SSH_CONNECTION": "10.0.0.1 5555 10.0.0.2 22"})
    cmd = (f"cd {tmp_path} && unset COLORTERM TEXTUAL_COLOR_SYSTEM && TERM=screen-256color "
           f"SSH_CONNECTION='10.0.0.1 5555 10.0.0.2 22' {sys.executable} -m ctui --graphics halfblock; sleep 30")
    subprocess.run(_tmux("new-session", "-d", "-s", tmux_session, "-x", "160", "-y", "50", cmd),
                   check=True, env=env, timeout=10)
    screen = _wait(tmux_session, "SendEnv")
    assert "TEXTUAL_COLOR_SYSTEM=truecolor" in screen.replace("\n", " ") or "TEXTUAL_COLOR_SYSTEM" in screen
    assert "Traceback" not in screen


def test_paint_and_erase_in_tmux_voxel_counts(tmux_session, tmp_path):
    """The real binary: brush a dab (space), a stroke (b, moves, b), erase (E, space, E), switch to
    the sagittal view (orientation letters), save the project and count its voxels."""
    import numpy as np

    from ctui.engine.io.project import load_project

    env = _env(CTUI_AUTOSAVE_DIR=str(tmp_path / "autosave"), COLORTERM="truecolor")
    cmd = f"cd {tmp_path} && {sys.executable} -m ctui --graphics halfblock; echo CTUI-EXIT=$?; sleep 30"
    subprocess.run(_tmux("new-session", "-d", "-s", tmux_session, "-x", "160", "-y", "50", cmd),
                   check=True, env=env, timeout=10)
    _wait(tmux_session, "Slice")
    # the sample is 128x128: the cursor starts at its centre (x 64, y 64); brush radius 3 -> 29 px
    _keys(tmux_session, "space")
    _wait(tmux_session, "Painted 29 voxels")
    _keys(tmux_session, "b")
    for _ in range(4):
        _keys(tmux_session, "l")
    _keys(tmux_session, "b")
    _wait(tmux_session, "Brush lifted")
    _keys(tmux_session, ",", ",")  # radius 1: a 5-px eraser
    _wait(tmux_session, "Brush radius 2 mm")
    _keys(tmux_session, "E")
    _wait(tmux_session, "Eraser down")  # putting it down erases nothing: Space erases a dab
    _keys(tmux_session, "space")
    _wait(tmux_session, "Erased 5 voxels")
    _keys(tmux_session, "E")
    _keys(tmux_session, "2")
    screen = _wait(tmux_session, "sagittal")
    assert all(f" {c} " in screen or f"{c}◀" in screen or f"▶{c}" in screen or f"{c}▲" in screen or f"▼{c}" in screen
               for c in "APSI")
    _keys(tmux_session, "C-s")
    _wait(tmux_session, "Save project as")
    proj = tmp_path / "painted.ctui"
    _keys(tmux_session, "C-u", str(proj), "Enter")
    _wait(tmux_session, "Project saved")
    labels = load_project(str(proj)).labels
    # dab 29 + a stroke of 4 one-pixel steps (7 new pixels each) - the eraser's 5 px
    assert int(np.count_nonzero(labels == 1)) == 29 + 4 * 7 - 5
    _keys(tmux_session, "q")
    screen = _wait(tmux_session, "CTUI-EXIT=")
    assert "CTUI-EXIT=0" in screen and "Traceback" not in screen
