"""A small nnInteractive server for the tests and the benchmark, written from the client's protocol.

It speaks what ``nninteractive-client`` 2.6 (``nnInteractive.inference.remote``) sends: ``POST /claim``
(a lease token; 503 when ``max_sessions`` are out), ``GET /capabilities`` (the model's licence
among them), ``POST /set_image`` (a packed (1, nz, ny, nx) array, metadata in ``X-Meta``),
``/set_target_buffer`` (JSON shape and dtype), ``/reset_interactions``, ``/add_point_interaction``,
``/add_bbox_interaction`` (JSON), ``/add_initial_seg_interaction`` (a packed uint8 array),
``/heartbeat``, ``/lease_status``, ``/release``, ``GET /healthz``. Requests other than claim,
capabilities and health carry the lease in ``X-Lease-Token``; an unknown lease answers 410. With
``api_key`` set, a request without ``Authorization: Bearer KEY`` answers 401.

The "model" is deterministic so a test knows every answer: a positive point adds the ball of
``POS_MM`` voxels around it where the image is above ``THRESHOLD``; a negative point removes the
ball of ``NEG_R`` voxels; a box adds the ellipsoid inscribed in it; the initial segmentation
replaces the object. Each prompt answers the ball's (or box's) bounding box, clipped to the image,
and the object's voxels there (``X-Meta`` ``{"ran_prediction": true, "bbox": [[z0, z1], ...]}``,
the body a packed uint8 array), as the real server answers with the patch it pasted.

Failure injection: ``expire_next`` (a path: the next request to it answers 410 and drops the
lease, as after the idle reaper or a restart), ``delay_s`` (each prompt sleeps first).
Counters: bytes in and out, requests by path, claims, images received, answers sent.
"""

from __future__ import annotations

import json
import sys
import threading
import time
import uuid
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import numpy as np
from nnInteractive.inference.remote.serialization import pack_array, unpack_array

POS_R = 6  # voxels: a positive point's ball
NEG_R = 3  # voxels: a negative point's ball
THRESHOLD = 0.0  # a positive ball keeps only voxels of the image above this
LICENCE = "CC BY-NC-SA 4.0 (test model)"


def ball(shape: tuple[int, ...], centre: tuple[int, int, int], r: int) -> tuple[tuple[slice, ...], np.ndarray]:
    """(box, bool mask on the box) of the ball of radius ``r`` voxels at ``centre`` (z, y, x), clipped."""
    box = tuple(slice(max(c - r, 0), min(c + r + 1, n)) for c, n in zip(centre, shape))
    zz, yy, xx = np.ogrid[box[0], box[1], box[2]]
    return box, (zz - centre[0]) ** 2 + (yy - centre[1]) ** 2 + (xx - centre[2]) ** 2 <= r * r


def ellipsoid(box: tuple[slice, ...]) -> np.ndarray:
    """bool mask on ``box`` (half-open slices) of the ellipsoid inscribed in it."""
    axes = [np.arange(b.start, b.stop) + 0.5 for b in box]
    c = [(b.start + b.stop) / 2 for b in box]
    h = [max((b.stop - b.start) / 2, 0.5) for b in box]
    zz, yy, xx = np.meshgrid(*axes, indexing="ij")
    return ((zz - c[0]) / h[0]) ** 2 + ((yy - c[1]) / h[1]) ** 2 + ((xx - c[2]) / h[2]) ** 2 <= 1.0


class _QuietServer(ThreadingHTTPServer):
    """A client that gave up (a timeout test) leaves the answer unwritten: no traceback on stderr, which a
    test reading its own stderr (capsys) would otherwise catch from a request still asleep."""

    def handle_error(self, request, client_address):  # noqa: ANN001
        if not isinstance(sys.exc_info()[1], (BrokenPipeError, ConnectionResetError)):
            super().handle_error(request, client_address)


class Lease:
    def __init__(self) -> None:
        self.image: np.ndarray | None = None
        self.mask: np.ndarray | None = None
        self.prompts: list[tuple[str, Any]] = []


class PromptServer:
    """The server on 127.0.0.1 (an ephemeral port); ``url``; ``close()`` stops it."""

    def __init__(self, *, api_key: str = "", max_sessions: int = 4, liveness_s: float = 0.0) -> None:
        self.api_key = api_key
        self.max_sessions = max_sessions
        self.liveness_s = liveness_s
        self.leases: dict[str, Lease] = {}
        self.expire_next: set[str] = set()
        self.delay_s = 0.0
        self.expire_all = False  # every request with a lease answers 410 (a server that loses every session)
        self.bytes_in = self.bytes_out = 0
        self.requests: list[str] = []
        self.claims = self.images = 0
        self.answers: list[tuple[list[list[int]], np.ndarray]] = []  # every prompt's (bbox, voxels) sent
        self.log: list[tuple[str, Any]] = []  # every prompt received: ("point"|"negative", (z, y, x)), ("box", ...)
        self.model_s = 0.0  # time spent in the model and packing
        self.lock = threading.Lock()
        self.httpd = _QuietServer(("127.0.0.1", 0), _handler(self))
        self.httpd.daemon_threads = True
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.httpd.server_address[1]}"

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()

    def forget(self) -> None:
        """Drop every lease (a restart): the next request of a client answers 410."""
        with self.lock:
            self.leases.clear()

    def returned(self, shape: tuple[int, ...]) -> np.ndarray:
        """The object a client holds after applying every answer sent, in order (uint8 (nz, ny, nx))."""
        out = np.zeros(shape, np.uint8)
        for bbox, arr in self.answers:
            out[tuple(slice(a, b) for a, b in bbox)] = arr
        return out

    # ------------------------------------------------------------------ the model
    def prompt(self, lease: Lease, path: str, body: dict[str, Any]) -> tuple[list[list[int]], np.ndarray]:
        assert lease.mask is not None and lease.image is not None
        shape = lease.mask.shape
        if path == "/add_point_interaction":
            centre = tuple(int(round(v)) for v in body["coordinates"])
            if not all(0 <= c < n for c, n in zip(centre, shape)):
                raise ValueError(f"point {centre} outside the image {shape}")
            pos = bool(body["include_interaction"])
            box, m = ball(shape, centre, POS_R if pos else NEG_R)  # type: ignore[arg-type]
            region = lease.mask[box]
            if pos:
                region[m & (lease.image[0][box] > THRESHOLD)] = 1
            else:
                region[m] = 0
            lease.prompts.append(("point" if pos else "negative", centre))
            self.log.append(lease.prompts[-1])
        else:
            coords = [[int(a), int(b)] for a, b in body["bbox_coords"]]
            box = tuple(slice(max(a, 0), min(b, n)) for (a, b), n in zip(coords, shape))
            lease.mask[box][ellipsoid(box)] = 1 if body["include_interaction"] else 0
            lease.prompts.append(("box", coords))
            self.log.append(lease.prompts[-1])
        bbox = [[b.start, b.stop] for b in box]
        return bbox, lease.mask[box].copy()


def _handler(server: PromptServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"
        disable_nagle_algorithm = True  # headers and body go out as two writes: no 40 ms Nagle wait

        def log_message(self, *args: Any) -> None:  # quiet
            pass

        def _send(self, code: int, body: bytes = b"", *, meta: dict | None = None, ctype: str = "application/json"):
            self.send_response(code)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            if meta is not None:
                self.send_header("X-Meta", json.dumps(meta))
            self.end_headers()
            self.wfile.write(body)
            with server.lock:
                server.bytes_out += len(body) + 200

        def _json(self, code: int, obj: Any) -> None:
            self._send(code, json.dumps(obj).encode())

        def do_GET(self) -> None:  # noqa: N802 - http.server's name
            self._route(b"")

        def do_POST(self) -> None:  # noqa: N802 - http.server's name
            n = int(self.headers.get("Content-Length") or 0)
            self._route(self.rfile.read(n) if n else b"")

        def _route(self, raw: bytes) -> None:
            path = self.path.split("?")[0]
            with server.lock:
                server.bytes_in += len(raw) + 200
                server.requests.append(path)
            if path == "/healthz":
                return self._json(200, {"status": "ok"})
            if server.api_key and self.headers.get("Authorization") != f"Bearer {server.api_key}":
                return self._json(401, {"detail": "invalid or missing API key"})
            if path == "/claim":
                with server.lock:
                    if len(server.leases) >= server.max_sessions:
                        return self._json(503, {"detail": f"server at capacity ({server.max_sessions} sessions)"})
                    token = uuid.uuid4().hex
                    server.leases[token] = Lease()
                    server.claims += 1
                return self._json(200, {"lease_token": token, "idle_timeout_seconds": 600.0,
                                        "liveness_timeout_seconds": server.liveness_s})
            if path == "/capabilities":
                return self._json(200, _CAPS)
            token = self.headers.get("X-Lease-Token", "")
            with server.lock:
                if server.expire_all:
                    server.leases.pop(token, None)
                if path in server.expire_next:
                    server.expire_next.discard(path)
                    server.leases.pop(token, None)
                lease = server.leases.get(token)
            if lease is None:
                return self._json(410, {"detail": "lease expired or unknown"})
            try:
                self._lease_call(path, raw, lease, token)
            except (ValueError, KeyError, TypeError) as exc:
                self._json(400, {"detail": str(exc)})

        def _lease_call(self, path: str, raw: bytes, lease: Lease, token: str) -> None:
            if path == "/set_image":
                lease.image = unpack_array(raw)
                with server.lock:
                    server.images += 1
                return self._json(200, {"original_image_shape": list(lease.image.shape)})
            if path == "/set_target_buffer":
                body = json.loads(raw)
                lease.mask = np.zeros(tuple(body["shape"]), np.dtype(body["dtype"]))
                return self._json(200, {})
            if path == "/reset_interactions":
                if lease.mask is not None:
                    lease.mask[:] = 0
                lease.prompts.clear()
                return self._json(200, {})
            if path == "/add_initial_seg_interaction":
                meta = json.loads(self.headers.get("X-Meta") or "{}")
                seg = unpack_array(raw)
                assert lease.mask is not None
                lease.mask[:] = seg
                lease.prompts.append(("initial", int(np.count_nonzero(seg))))
                server.log.append(lease.prompts[-1])
                return self._send(200, b"", meta={"ran_prediction": bool(meta.get("run_prediction")), "bbox": None})
            if path in ("/add_point_interaction", "/add_bbox_interaction"):
                if server.delay_s:
                    time.sleep(server.delay_s)
                t0 = time.perf_counter()
                bbox, arr = server.prompt(lease, path, json.loads(raw))
                body = pack_array(arr.astype(np.uint8))
                with server.lock:
                    server.answers.append((bbox, arr.astype(np.uint8)))
                    server.model_s += time.perf_counter() - t0
                return self._send(200, body, meta={"ran_prediction": True, "bbox": bbox},
                                  ctype="application/octet-stream")
            if path == "/heartbeat":
                return self._json(200, {"remaining_seconds": 600.0})
            if path == "/lease_status":
                return self._json(200, {"remaining_seconds": 600.0, "idle_timeout_seconds": 600.0})
            if path == "/release":
                with server.lock:
                    server.leases.pop(token, None)
                return self._json(200, {})
            return self._json(404, {"detail": f"no endpoint {path}"})

    return Handler


_CAPS = {
    "supported_interactions": {"point": True, "bbox": True, "scribble": True, "lasso": True, "initial_seg": True},
    "channel_mapping": {"point": [1, 2], "bbox": [3, 4]},
    "num_interaction_channels": 8,
    "supports_initial_label": True,
    "supports_zero_shot_label_refinement": True,
    "preferred_scribble_thickness": [2, 2, 2],
    "interaction_decay": 0.9,
    "inference_session_version": "test",
    "license": LICENCE,
    "supports_undo": False,
    "do_autozoom": True,
}
