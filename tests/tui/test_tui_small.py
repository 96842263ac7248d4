"""80x24 is a first-class size: the real binary in tmux shows every footer key and a
proposal message in full (wrapped, not cut), and ``\\`` hides the side panel. The cursor
glyph scales with the zoom (ticks that leave a small view's anatomy visible)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from ctui.screens import cells
from test_tui_tmux import _cap, _env, _keys, _tmux, _wait, tmux_session  # noqa: F401  (fixture)


def _flat(screen: str) -> str:
    return " ".join(" ".join(line.split()) for line in screen.splitlines())


@pytest.mark.slow
def test_80x24_footer_and_proposal_read_in_full(tmux_session, tmp_path):  # noqa: F811
    env = _env(CTUI_AUTOSAVE_DIR=str(tmp_path / "autosave"), COLORTERM="truecolor")
    cmd = f"cd {tmp_path} && {sys.executable} -m ctui --graphics halfblock; echo CTUI-EXIT=$?; sleep 30"
    subprocess.run(_tmux("new-session", "-d", "-s", tmux_session, "-x", "80", "-y", "24", cmd),
                   check=True, env=env, timeout=10)
    screen = _wait(tmux_session, "Slice")
    flat = _flat(screen)
    for pair in ("PgUp Slice +1", "Enter Fill", "t Edit tools", "n New object", "u Undo", "p Propagate",
                 "r 3D", "M Measure", "e Export", "\\ Side panel on/off"):
        assert pair in flat, (pair, screen)
    # a proposal's message, whole: what it is and how to accept or reject it
    _keys(tmux_session, "Enter")
    _wait(tmux_session, "Filled")
    _keys(tmux_session, "p")
    screen = _wait(tmux_session, "rejects", timeout=90)
    flat = _flat(screen)
    assert "Proposal: object 1" in flat and "a accepts, x rejects" in flat, screen
    assert all(len(line) <= 80 for line in screen.splitlines())
    # \ hides the side panel (and shows it again)
    _keys(tmux_session, "x")
    subprocess.run(_tmux("send-keys", "-t", tmux_session, "-l", "\\"), check=True, timeout=10, env=_env())
    screen = _wait(tmux_session, "Side panel hidden")
    assert "Cursor x" not in screen
    subprocess.run(_tmux("send-keys", "-t", tmux_session, "-l", "\\"), check=True, timeout=10, env=_env())
    _wait(tmux_session, "Cursor x")
    _keys(tmux_session, "q")
    _wait(tmux_session, "Quit without saving")
    _keys(tmux_session, "Down")
    _keys(tmux_session, "Enter")
    screen = _wait(tmux_session, "CTUI-EXIT=")
    assert "Traceback" not in screen
    # the line written before anything heavy is imported (something on screen at once)
    assert "ctui: opening the bundled sample series" in screen


def test_cursor_glyph_scales_with_zoom():
    img_shape = (100, 100)
    small = np.zeros((40, 40, 3), np.uint8)
    _, vm = cells.fit_view(img_shape, (40, 40))  # 0.4 display px per image pixel: a small view
    cells.draw_cursor(small, vm, 50, 50)
    red = np.all(small == (255, 40, 40), axis=2)
    cy, cx = np.argwhere(red).mean(axis=0).round().astype(int)
    assert red[cy, cx] and red.sum() <= 9  # the dot and four short ticks
    assert not red[cy - 1, cx] and not red[cy, cx + 1]  # a gap: the neighbours stay visible
    big = np.zeros((400, 400, 3), np.uint8)
    _, vm = cells.fit_view(img_shape, (400, 400), zoom=4.0, center=(50, 50))  # 16 px per image pixel
    cells.draw_cursor(big, vm, 50, 50)
    red = np.all(big == (255, 40, 40), axis=2)
    ys, xs = np.nonzero(red)
    assert xs.max() - xs.min() >= 2 * 16  # a ring around the magnified pixel, bigger than it
