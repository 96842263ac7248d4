"""Progress bars: drawn on stderr when it is a terminal, never with --json or into a pipe.

The command runs in a subprocess whose stderr is a pseudo-terminal (``pty.openpty``);
``CTUI_PROGRESS_DELAY=0`` draws the bar at the first report (no timing involved).
"""

from __future__ import annotations

import os
import select
import subprocess
import sys

import pytest

from support import ROOT, SAMPLE_DATA

pty = pytest.importorskip("pty")


def _run_with_tty_stderr(args: list[str], tmp_path) -> tuple[int, str, str]:
    master, slave = pty.openpty()
    env = dict(os.environ, CTUI_PROGRESS_DELAY="0", CTUI_NO_BACKGROUND_COMPILE="1", COLUMNS="100", TERM="xterm")
    env.pop("CTUI_NO_PROGRESS", None)
    proc = subprocess.Popen([sys.executable, "-m", "ctui.cli", *args], cwd=tmp_path, env=env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave)
    os.close(slave)
    chunks = []
    while True:
        r, _, _ = select.select([master], [], [], 0.2)
        if r:
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        elif proc.poll() is not None:
            # drain what is left
            try:
                while select.select([master], [], [], 0.1)[0]:
                    data = os.read(master, 65536)
                    if not data:
                        break
                    chunks.append(data)
            except OSError:
                pass
            break
    out = proc.stdout.read().decode() if proc.stdout else ""
    rc = proc.wait(timeout=600)
    os.close(master)
    return rc, out, b"".join(chunks).decode(errors="replace")


def _mesh_args(tmp_path, *extra):
    return ["mesh", str(SAMPLE_DATA / "phantom"), "--iso", "300", "--out", str(tmp_path / "bone.stl"), *extra]


def test_mesh_draws_a_bar_on_a_terminal(tmp_path):
    rc, out, tty = _run_with_tty_stderr(_mesh_args(tmp_path), tmp_path)
    assert rc == 0, tty
    assert "meshing" in tty  # the bar's description
    assert "%" in tty  # its percentage column
    assert "triangles" in out  # the result on stdout, untouched by the bar


def test_json_draws_nothing(tmp_path):
    rc, out, tty = _run_with_tty_stderr(_mesh_args(tmp_path, "--json"), tmp_path)
    assert rc == 0, tty
    assert tty.strip() == ""
    assert out.strip().startswith("{")


def test_no_bar_into_a_pipe(tmp_path):
    env = dict(os.environ, CTUI_PROGRESS_DELAY="0", CTUI_NO_BACKGROUND_COMPILE="1")
    res = subprocess.run([sys.executable, "-m", "ctui.cli", *_mesh_args(tmp_path)], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert "meshing" not in res.stderr and "\x1b[" not in res.stderr
