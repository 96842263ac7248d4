"""A headless Chromium driven through its DevTools protocol (CDP), for tests/tui/test_web.py and
benchmarks/web.py: start ``ctui web``, open the page, press keys, take screenshots, read the
slice image xterm.js drew (its image layer canvas). Needs Debian's ``chromium`` and aiohttp
(the web extra brings it)."""

from __future__ import annotations

import asyncio
import base64
import io
import itertools
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

#: the slice image layer (xterm.js image addon): its box in CSS pixels and its pixels as a PNG data URL
IMAGE_LAYER_JS = """(() => {
  const c = document.querySelector('canvas.xterm-image-layer');
  if (!c || !c.width) return null;
  const r = c.getBoundingClientRect();
  return {x: r.x, y: r.y, w: r.width, h: r.height, cw: c.width, ch: c.height, png: c.toDataURL('image/png')};
})()"""


def chromium() -> str | None:
    """The Chromium executable, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        exe = shutil.which(name)
        if exe:
            return exe
    return None


def decode_png(data: str | bytes) -> np.ndarray:
    """RGBA (h, w, 4) uint8 of a PNG (bytes, base64 or a data URL)."""
    from PIL import Image

    if isinstance(data, str):
        data = base64.b64decode(data.split(",", 1)[1] if data.startswith("data:") else data)
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))


class CtuiWeb:
    """``ctui web PATH --port 0`` as a subprocess: its URL, its pid; :meth:`stop` sends SIGINT."""

    def __init__(self, path: str | None, *extra: str, env: dict | None = None) -> None:
        cmd = [sys.executable, "-m", "ctui.cli", "web", *([path] if path else []), "--port", "0", *extra]
        full_env = {**os.environ, "PYTHONPATH": str(ROOT), **(env or {})}
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=full_env,
                                     start_new_session=True)
        self.url = ""
        self.lines: list[str] = []
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                break
            self.lines.append(line)
            if line.startswith("ctui web: open "):
                self.url = line.split()[3]
                break
        if not self.url:
            self.proc.kill()
            raise RuntimeError("ctui web did not start: " + "".join(self.lines)[-2000:])

    @property
    def port(self) -> int:
        return int(self.url.split(":")[2].split("/")[0])

    def stop(self, timeout: float = 20.0) -> int:
        """SIGINT (Ctrl+C), then its exit status (SIGKILL after ``timeout`` s: returns -9)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
            return -9


class Browser:
    """One headless Chromium page over CDP (aiohttp's websocket client)."""

    def __init__(self, exe: str, profile: Path, *, width: int = 1280, height: int = 800) -> None:
        self.exe, self.profile, self.size = exe, Path(profile), (width, height)
        self.proc: subprocess.Popen | None = None
        self._ids = itertools.count(1)
        self.events: list[dict] = []

    async def __aenter__(self) -> Browser:
        import aiohttp

        self.profile.mkdir(parents=True, exist_ok=True)
        (self.profile / "DevToolsActivePort").unlink(missing_ok=True)  # a previous run's
        self.proc = subprocess.Popen(
            [self.exe, "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run", "--hide-scrollbars",
             "--disable-extensions", "--disable-background-networking", f"--user-data-dir={self.profile}",
             "--remote-debugging-port=0", "--remote-debugging-address=127.0.0.1",
             f"--window-size={self.size[0]},{self.size[1]}", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        self.http = aiohttp.ClientSession()
        try:
            await self._connect()
        except BaseException:
            await self.__aexit__()
            raise
        return self

    async def _connect(self) -> None:
        active = self.profile / "DevToolsActivePort"
        for _ in range(600):
            if active.is_file() and active.read_text().strip():
                break
            await asyncio.sleep(0.1)
        port = int(active.read_text().split()[0])
        async with self.http.get(f"http://127.0.0.1:{port}/json/list") as r:
            pages = [t for t in json.loads(await r.text()) if t.get("type") == "page"]
        self.ws = await self.http.ws_connect(pages[0]["webSocketDebuggerUrl"], max_msg_size=0)
        await self.call("Page.enable")
        await self.call("Runtime.enable")

    async def __aexit__(self, *exc) -> None:
        try:
            if getattr(self, "ws", None) is not None:
                await self.ws.close()
            await self.http.close()
        finally:
            if self.proc is not None:
                os.killpg(self.proc.pid, signal.SIGTERM)
                try:
                    self.proc.wait(10)
                except subprocess.TimeoutExpired:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                    self.proc.wait()

    async def call(self, method: str, **params) -> dict:
        n = next(self._ids)
        await self.ws.send_str(json.dumps({"id": n, "method": method, "params": params}))
        while True:
            msg = json.loads((await self.ws.receive()).data)
            if msg.get("id") == n:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            self.events.append(msg)

    async def evaluate(self, expression: str):
        res = await self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        return res.get("result", {}).get("value")

    async def open(self, url: str) -> None:
        await self.call("Page.navigate", url=url)

    async def screenshot(self) -> np.ndarray:
        res = await self.call("Page.captureScreenshot", format="png")
        return decode_png(res["data"])

    async def press(self, key: str, code: str, key_code: int) -> None:
        for kind in ("rawKeyDown", "keyUp"):
            await self.call("Input.dispatchKeyEvent", type=kind, key=key, code=code, windowsVirtualKeyCode=key_code,
                            nativeVirtualKeyCode=key_code)

    async def image_layer(self) -> dict | None:
        """The slice image xterm.js drew: {x, y, w, h (CSS px), rgba (h, w, 4)}, or None before the first."""
        v = await self.evaluate(IMAGE_LAYER_JS)
        if not v:
            return None
        v["rgba"] = decode_png(v.pop("png"))
        return v

    async def wait_image(self, timeout: float = 60.0, *, differs_from: np.ndarray | None = None) -> tuple[dict, float]:
        """The image layer once it holds an image (different from ``differs_from``), and the seconds it took."""
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < timeout:
            v = await self.image_layer()
            if v is not None and v["rgba"][..., 3].any():
                if differs_from is None or v["rgba"].shape != differs_from.shape or \
                        np.abs(v["rgba"].astype(int) - differs_from).mean() > 0.5:
                    return v, time.perf_counter() - t0
            await asyncio.sleep(0.05)
        raise TimeoutError("no slice image in the page")
