"""``ctui web [PATH]``: the same TUI served to a browser (textual-serve-asgi under uvicorn).

Every browser tab gets its own ``ctui open PATH`` process, drawn by xterm.js. Slices are sixel
images (``CTUI_WEB=1``: :mod:`ctui.screens.graphics` never picks the kitty protocol there, caps
the image size and debounces redraws). The server binds 127.0.0.1 by default: reach it from
another machine with ``ssh -L 8000:127.0.0.1:8000 host``. Bound to any other address it needs a
token (``--token`` or ``CTUI_WEB_TOKEN``; one is made and printed when neither is given): the
page is opened as ``/?token=...`` once, which sets a cookie for the websocket. Every request
must name this server in its Host header (no DNS rebinding onto a loopback server), and a
websocket must come from a page of this server (its Origin), so another site open in the same
browser cannot drive the TUI.
"""

from __future__ import annotations

import argparse
import hmac
import os
import secrets
import shlex
import sys
from http.cookies import SimpleCookie
from urllib.parse import parse_qs, urlsplit

from ctui.commands._args import command, number
from ctui.engine.core.errors import CtuiError

LOOPBACK = ("127.0.0.1", "localhost", "::1")
COOKIE = "ctui_token"


def register(subparsers: argparse._SubParsersAction) -> None:
    from ctui.engine.actions import defaults  # plain constants: --help stays fast

    p = command(
        subparsers, "web", run,
        help="serve the TUI to a browser (loopback by default; reach it with ssh -L)",
        description="Serve the same TUI to a web browser: every tab runs `ctui open PATH`, its slices drawn "
        "as sixel images at full resolution (capped at 1280x960 pixels, at most one image per 40 ms). Binds 127.0.0.1 "
        "by default; from another machine use `ssh -L 8000:127.0.0.1:8000 HOST` and open "
        "http://127.0.0.1:8000. Bound to any other address, a token is required (--token, CTUI_WEB_TOKEN, "
        "or one printed at start). Needs the web extra: pip install 'ctui[web]'.",
        epilog="Examples: ctui web scan/\n"
        "          ctui web kidney.ctui --port 8080\n"
        "          ctui web scan/ --host 0.0.0.0 --token \"$(openssl rand -hex 16)\"",
        raw=True,
    )
    p.add_argument("path", nargs="?", default=None, help="what `ctui open` would open (default: the sample series)")
    p.add_argument("--host", default=defaults.WEB_HOST, help="address to bind (default %(default)s: this machine only)")
    p.add_argument("--port", type=number("--port", 0, 65535, integer=True), default=defaults.WEB_PORT,
                   help="port (default %(default)s; 0: any free port, printed)")
    p.add_argument("--token", default=None,
                   help="required by the page when bound beyond loopback (default: CTUI_WEB_TOKEN, else made now)")


def is_loopback(host: str) -> bool:
    return host.strip("[]") in LOOPBACK or host.startswith("127.")


def served_command(path: str | None) -> str:
    """The shell command each browser tab runs: this Python's ``ctui open [PATH]``."""
    argv = [sys.executable, "-m", "ctui.cli", "open"] + ([os.path.abspath(path)] if path else [])
    return shlex.join(argv)


def _headers(scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}


def guard(app, *, token: str | None, hosts: set[str] | None):
    """An ASGI wrapper: refuse a Host not in ``hosts`` (None: any), a websocket whose Origin is not
    this server, and, with ``token``, any request without it (``?token=`` sets a cookie)."""

    async def guarded(scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            return await app(scope, receive, send)
        h = _headers(scope)
        host = h.get("host", "")
        ok = hosts is None or host in hosts
        if ok and scope["type"] == "websocket" and "origin" in h:
            ok = urlsplit(h["origin"]).netloc == host
        given = parse_qs(scope.get("query_string", b"").decode("latin-1")).get("token", [""])[0]
        cookie = SimpleCookie(h.get("cookie", ""))
        kept = cookie[COOKIE].value if COOKIE in cookie else ""
        by_query = bool(token) and hmac.compare_digest(given.encode(), token.encode())
        if ok and token:
            ok = by_query or hmac.compare_digest(kept.encode(), token.encode())
        if not ok:
            return await _refuse(scope, receive, send)
        if not by_query or scope["type"] != "http":
            return await app(scope, receive, send)

        async def send_cookie(message):
            if message["type"] == "http.response.start":
                value = f"{COOKIE}={token}; Path=/; HttpOnly; SameSite=Strict"
                message = {**message, "headers": [*message.get("headers", []), (b"set-cookie", value.encode())]}
            await send(message)

        return await app(scope, receive, send_cookie)

    return guarded


async def _refuse(scope, receive, send) -> None:
    if scope["type"] == "websocket":
        await receive()  # websocket.connect
        await send({"type": "websocket.close", "code": 1008})
        return
    body = b"ctui web: this page needs its token (open the address ctui web printed)\n"
    await send({"type": "http.response.start", "status": 403,
                "headers": [(b"content-type", b"text/plain"), (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})


def _allowed_hosts(host: str, port: int) -> set[str] | None:
    if not is_loopback(host):
        return None  # any name may reach a public bind; the token guards it
    names = {"127.0.0.1", "localhost", "[::1]", host if ":" not in host else f"[{host}]"}
    return {f"{n}:{port}" for n in names} | (names if port == 80 else set())


def run(args: argparse.Namespace) -> int:
    try:  # the web extra: pip install 'ctui[web]'
        import socket

        import uvicorn
        from textual_serve_asgi import Server
    except ImportError as exc:
        raise CtuiError(f"ctui web needs the web extra ({exc.name} is missing): pip install 'ctui[web]'") from None
    if args.path and not os.path.exists(args.path):
        raise CtuiError("no such file or folder", path=args.path)
    token = args.token or os.environ.get("CTUI_WEB_TOKEN") or None
    if not is_loopback(args.host) and not token:
        token = secrets.token_urlsafe(18)
    family = socket.AF_INET6 if ":" in args.host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)  # bound here: port 0 gets a free port we can print
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((args.host, args.port))
        sock.listen(128)  # listening when the address is printed
    except OSError as exc:
        sock.close()
        raise CtuiError(f"cannot listen on {args.host}:{args.port} ({exc.strerror or exc})", option="port") from None
    port = sock.getsockname()[1]
    os.environ["CTUI_WEB"] = "1"  # the served TUI draws sixel images (screens/graphics.web_mode)
    os.environ["CTUI_GRAPHICS"] = "sixel"
    class _Server(Server):
        async def on_shutdown(self, app) -> None:  # the tabs' TUIs end while the event loop still runs
            import asyncio

            await asyncio.to_thread(_end_tabs)
            await asyncio.sleep(0.2)  # their pipes' transports close

    server = _Server(served_command(args.path), host=args.host, port=port, title="ctui")
    app = guard(server.asgi_app, token=token, hosts=_allowed_hosts(args.host, port))
    shown = f"[{args.host}]" if ":" in args.host else args.host
    url = f"http://{shown}:{port}/" + (f"?token={token}" if token else "")
    print(f"ctui web: open {url}  (Ctrl+C stops)", flush=True)
    if is_loopback(args.host):
        print(f"from another machine: ssh -L {port}:127.0.0.1:{port} THIS_HOST, then open that address there",
              flush=True)
    config = uvicorn.Config(app, log_level="warning", timeout_graceful_shutdown=3)
    import logging

    for name in ("textual_serve", "textual_serve_asgi", "uvicorn.error"):  # a tab closed while stopping: no trace
        logging.getLogger(name).setLevel(logging.CRITICAL)
    try:
        uvicorn.Server(config).run(sockets=[sock])  # until Ctrl+C / SIGTERM
    except KeyboardInterrupt:  # uvicorn re-raises the signal once it has shut down
        pass
    finally:
        sock.close()
        _end_tabs()
    print("ctui web: stopped", flush=True)
    return 0


def _end_tabs(timeout: float = 5.0) -> None:
    """End the tabs' TUI processes this server started and that outlived it (SIGTERM, then SIGKILL)."""
    import psutil  # listed in HEAVY_LIBRARIES; a dependency

    kids = psutil.Process().children(recursive=True)
    for k in kids:
        try:
            k.terminate()
        except psutil.Error:
            pass
    _, alive = psutil.wait_procs(kids, timeout=timeout)
    for k in alive:
        try:
            k.kill()
        except psutil.Error:
            pass

