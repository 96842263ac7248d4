"""`ctui web`: the TUI in headless Chromium (Debian's chromium over its DevTools protocol) on a
real CT: the page shows the slice ctui renders (correlation >= 0.95 in the slice region of a
screenshot), a key steps the slice, the server listens on 127.0.0.1 only and stops cleanly;
and, without a browser, the guard (Host, Origin, token) and web mode's graphics choice."""

from __future__ import annotations

import asyncio
import importlib.util

import numpy as np
import pytest

from support import shared

WEB_LIBS = ("textual_serve_asgi", "uvicorn", "aiohttp")


def _need_web():
    missing = [m for m in WEB_LIBS if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"the web extra is not installed ({', '.join(missing)}): pip install -e '.[test]'")


def expected_slice(ct, z: int, size: tuple[int, int], out_png) -> np.ndarray:
    """The axial slice ``z`` as ctui renders it (display frame, the series' window), written as a PNG
    and fitted into ``size`` (w, h) as the slice view fits it."""
    from PIL import Image

    from ctui.engine.core.windows import apply_window
    from ctui.engine.io.series import load
    from ctui.screens import cells, planes

    vol = load(ct)
    pv = planes.plane_view(vol, "axial")
    gray = apply_window(planes.take(vol.data, pv, z), vol.window)
    Image.fromarray(gray).save(out_png)
    grid, _ = cells.render_view(np.asarray(Image.open(out_png)), size, spacing_yx=pv.spacing_yx)
    return grid.mean(axis=2) if grid.ndim == 3 else grid.astype(float)


def slice_region(shot: np.ndarray, layer: dict) -> np.ndarray:
    """The screenshot's pixels under the slice image (the image layer's opaque box), grey."""
    alpha = layer["rgba"][..., 3] > 0
    ys, xs = np.nonzero(alpha)
    sx, sy = layer["w"] / layer["cw"], layer["h"] / layer["ch"]  # canvas px -> CSS px (1 at DPR 1)
    x0, x1 = int(round(layer["x"] + xs.min() * sx)), int(round(layer["x"] + (xs.max() + 1) * sx))
    y0, y1 = int(round(layer["y"] + ys.min() * sy)), int(round(layer["y"] + (ys.max() + 1) * sy))
    return shot[y0:y1, x0:x1, :3].astype(float).mean(axis=2)


def correlation(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])


async def _session(web, exe, profile, ct, tmp_path) -> dict:
    from web_browser import Browser

    async with Browser(exe, profile) as b:
        await b.open(web.url)
        layer, _ = await b.wait_image(120)
        await asyncio.sleep(1.0)  # the side panel's range finishes: the image stays
        layer = await b.image_layer()
        shot = await b.screenshot()
        seen = slice_region(shot, layer)
        h, w = seen.shape
        z0 = 15  # the workspace opens on the middle slice: 30 // 2
        first = {z: correlation(seen, expected_slice(ct, z, (w, h), tmp_path / f"z{z}.png")) for z in (z0, z0 + 1)}
        await b.press("PageUp", "PageUp", 33)
        layer2, _ = await b.wait_image(60, differs_from=layer["rgba"])
        await asyncio.sleep(0.5)
        layer2 = await b.image_layer()
        seen2 = slice_region(await b.screenshot(), layer2)
        second = {z: correlation(seen2, expected_slice(ct, z, (w, h), tmp_path / f"z{z}.png"))
                  for z in (z0, z0 + 1)} if seen2.shape == seen.shape else {}
        return {"first": first, "second": second, "shape": seen.shape}


@pytest.mark.slow
def test_web_page_shows_the_slice_and_a_key_steps_it(tmp_path):
    _need_web()
    from web_browser import CtuiWeb, chromium

    exe = chromium()
    if exe is None:
        pytest.skip("chromium is not installed (apt-get install chromium)")
    import psutil

    ct = shared("totalseg_example") / "ct_abdomen_3mm.nii.gz"
    web = CtuiWeb(str(ct))
    try:
        listening = {c.laddr for c in psutil.Process(web.proc.pid).net_connections(kind="inet")
                     if c.status == psutil.CONN_LISTEN}
        assert {(a.ip, a.port) for a in listening} == {("127.0.0.1", web.port)}
        res = asyncio.run(_session(web, exe, tmp_path / "profile", ct, tmp_path))
        kids = psutil.Process(web.proc.pid).children(recursive=True)
        assert kids, "no TUI process behind the page"
    finally:
        rc = web.stop()
    first, second = res["first"], res["second"]
    assert first[15] >= 0.95, res  # the page shows ctui's slice 15 in its window
    assert first[15] > first[16], res
    assert second and second[16] >= 0.95 and second[16] > second[15], res  # PageUp: slice 16
    assert rc == 0, web.lines
    _, alive = psutil.wait_procs(kids, timeout=5)
    assert not alive, f"TUI processes left after stop: {alive}"


# ------------------------------------------------------------------ without a browser
def _call(app, scope):
    sent = []

    async def receive():
        return {"type": "websocket.connect"} if scope["type"] == "websocket" else {"type": "http.request"}

    async def send(message):
        sent.append(message)

    asyncio.run(app(scope, receive, send))
    return sent


def _scope(kind="http", host="127.0.0.1:8000", query=b"", **headers):
    hs = [(b"host", host.encode())] + [(k.replace("_", "-").encode(), v.encode()) for k, v in headers.items()]
    return {"type": kind, "path": "/", "query_string": query, "headers": hs}


def test_guard_host_origin_and_token():
    from ctui.commands.web import _allowed_hosts, guard, is_loopback

    reached = []

    async def inner(scope, receive, send):
        reached.append(scope["type"])
        await send({"type": "http.response.start", "status": 200, "headers": []})

    loop_guard = guard(inner, token=None, hosts=_allowed_hosts("127.0.0.1", 8000))
    assert _call(loop_guard, _scope())[0]["status"] == 200 and reached == ["http"]
    assert _call(loop_guard, _scope(host="evil.example:8000"))[0]["status"] == 403  # DNS rebinding
    ws = _call(loop_guard, _scope("websocket", origin="http://evil.example"))  # another site's page
    assert ws == [{"type": "websocket.close", "code": 1008}] and reached == ["http"]
    _call(loop_guard, _scope("websocket", origin="http://127.0.0.1:8000"))
    assert reached == ["http", "websocket"]

    assert not is_loopback("0.0.0.0") and is_loopback("127.0.0.1") and is_loopback("::1")
    public = guard(inner, token="s3cret", hosts=_allowed_hosts("0.0.0.0", 8000))
    assert _call(public, _scope(host="10.0.0.5:8000"))[0]["status"] == 403
    assert _call(public, _scope(host="10.0.0.5:8000", query=b"token=wrong"))[0]["status"] == 403
    ok = _call(public, _scope(host="10.0.0.5:8000", query=b"token=s3cret"))[0]
    assert ok["status"] == 200 and (b"set-cookie", b"ctui_token=s3cret; Path=/; HttpOnly; SameSite=Strict") in ok["headers"]
    n = len(reached)
    _call(public, _scope("websocket", host="10.0.0.5:8000", origin="http://10.0.0.5:8000", cookie="ctui_token=s3cret"))
    assert len(reached) == n + 1
    assert _call(public, _scope("websocket", host="10.0.0.5:8000", cookie="ctui_token=nope"))[0]["code"] == 1008


def test_web_mode_draws_sixel_capped(monkeypatch):
    from ctui.screens import graphics

    monkeypatch.setenv(graphics.WEB_ENV, "1")
    for mode in ("kitty", "auto", "sixel"):
        assert graphics.prepare_graphics(mode) == "sixel"
    assert graphics.pixel_cap() == graphics.WEB_MAX_PIXELS
    monkeypatch.delenv(graphics.WEB_ENV)
    assert graphics.pixel_cap() is None and graphics.prepare_graphics("halfblock") == "halfblock"


def test_served_command_opens_the_path(tmp_path):
    import shlex
    import sys

    from ctui.commands.web import served_command

    argv = shlex.split(served_command(str(tmp_path / "a b.nii.gz")))
    assert argv[:4] == [sys.executable, "-m", "ctui.cli", "open"] and argv[4].endswith("a b.nii.gz")


def test_web_without_the_extra_or_with_a_missing_path(monkeypatch, capsys, tmp_path):
    import sys

    from ctui.cli import main

    assert main(["web", str(tmp_path / "nothing")]) == 2
    assert "no such file or folder" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "uvicorn", None)  # "import uvicorn" -> ImportError
    assert main(["web"]) == 2
    assert "pip install 'ctui[web]'" in capsys.readouterr().err
