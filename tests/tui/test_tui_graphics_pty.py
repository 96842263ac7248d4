"""Sixel and kitty graphics from the real ``ctui`` binary in a pseudo-terminal: the
bytes a sixel or kitty terminal would receive hold a real image of the slice (tmux
3.3 here has no sixel passthrough to read back, so the stream itself is checked)."""

from __future__ import annotations

import base64
import io
import os
import re
import select
import signal
import struct
import sys
import time

import pytest

pytestmark = pytest.mark.slow

pty = pytest.importorskip("pty")


def _run(mode: str, tmp_path, seconds: float = 90.0, stop: bytes | None = None) -> bytes:
    import fcntl
    import termios

    pid, fd = pty.fork()
    if pid == 0:  # child: the real program, as a user would start it
        os.environ.update(TERM="xterm-256color", COLORTERM="truecolor",
                          CTUI_AUTOSAVE_DIR=str(tmp_path / "autosave"))
        os.chdir(tmp_path)
        os.execv(sys.executable, [sys.executable, "-m", "ctui", "--graphics", mode])
    fcntl.ioctl(fd, termios.TIOCSWINSZ, struct.pack("HHHH", 50, 160, 1600, 1000))
    buf = b""
    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end:
            r, _, _ = select.select([fd], [], [], 0.2)
            if r:
                try:
                    buf += os.read(fd, 1 << 16)
                except OSError:
                    break
            if stop is not None and re.search(stop, buf):
                time.sleep(1.0)
                try:
                    buf += os.read(fd, 1 << 20)
                except OSError:
                    pass
                break
    finally:
        try:
            os.write(fd, b"\x11")  # ctrl+q
            time.sleep(0.5)
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
        os.waitpid(pid, 0)
        os.close(fd)
    return buf


def test_sixel_stream_holds_the_slice_image(tmp_path):
    buf = _run("sixel", tmp_path, stop=rb"\x1bP[0-9;]*q.*?\x1b\\")
    assert b"Traceback" not in buf
    m = re.search(rb"\x1bP[0-9;]*q\"1;1;(\d+);(\d+)(.*?)\x1b\\", buf, re.S)
    assert m, "no sixel image in the output"
    w, h = int(m.group(1)), int(m.group(2))
    # the first slice on screen in a 160x50 terminal with 10x20 pixel cells (the loading screen's
    # preview or the workspace's slice panel): hundreds of pixels each way
    assert w > 300 and h > 300
    body = m.group(3)
    colours = re.findall(rb"#(\d+);2;(\d+);(\d+);(\d+)", body)
    # a grey CT slice: many grey levels (r = g = b), not a blank or one-colour image
    greys = {c for c in colours if c[1] == c[2] == c[3]}
    assert len(greys) > 8
    assert len(body) > 10_000


def test_kitty_stream_holds_a_png_of_the_slice(tmp_path):
    import numpy as np
    from PIL import Image

    buf = _run("kitty", tmp_path, stop=rb"\x1b_G[^;]*m=0[^;]*;[^\x1b]*\x1b\\")
    assert b"Traceback" not in buf
    # chunked transmission: f=100 (PNG), m=1 ... m=0, base64 payloads
    chunks = re.findall(rb"\x1b_G([^;]*);([^\x1b]*)\x1b\\", buf)
    data = b""
    started = False
    for ctrl, payload in chunks:
        if b"f=100" not in ctrl:
            continue
        started = True
        data += payload
        if b"m=0" in ctrl:
            break
    assert started, "no kitty PNG transmission in the output"
    img = np.asarray(Image.open(io.BytesIO(base64.b64decode(data))).convert("RGB"))
    assert img.shape[0] > 300 and img.shape[1] > 300
    grey = img[(img[..., 0] == img[..., 1]) & (img[..., 1] == img[..., 2])]
    assert len(np.unique(grey[:, 0])) > 8  # a grey CT slice, not a blank image
