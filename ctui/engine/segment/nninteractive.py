"""The ``nninteractive`` method: prompts sent to an nnInteractive server, its answers written back.

ctui holds no model: a GPU box runs ``nninteractive-server`` and ctui talks to it with the
PyPI client ``nninteractive-client`` (torch-free: numpy, httpx, blosc2; the optional extra
``ctui[ai]``). The protocol (the client's ``nnInteractiveRemoteInferenceSession``): claim a
session (a lease token; HTTP 503 when the server is full), read its capabilities (the
model's licence among them), upload the image once (``set_image``, a (1, nz, ny, nx) array:
the client compresses it with blosc2), declare the target buffer (uint8 (nz, ny, nx)), then
each prompt (a point, positive or negative; a box; the current object as the initial
segmentation) returns the bounding box it changed and that box's voxels, which the client
writes into its copy of the buffer. A background thread sends heartbeats; a session the
server dropped (idle timeout, restart) answers HTTP 410, and ctui claims a new one, sends
the image again and the object as it stands, then goes on.

ctui keeps one session per server (and API key) for the process, so the TUI's clicks reuse
the uploaded image and the server's interaction history: every prompt refines the same
object. An object that differs from the server's copy (the user edited it, undid, switched
objects, or ``--refine`` opened it from a project) is sent first as the initial
segmentation. Each prompt's answer is written into the :class:`Segmentation` as one undo
step, and only inside the box the server returned: voxels outside it are never touched.
Coordinates: seeds (x, y, z) = (column, row, slice); the server gets (z, y, x) index
coordinates of the array it was sent, boxes as half-open [start, stop) per axis.

The server's URL and API key come from the caller or the environment (``CTUI_NNI_SERVER``,
``CTUI_NNI_KEY``) and are never stored in a project or a report; ``CTUI_NNI_TIMEOUT`` (seconds,
default 60) bounds a prediction (the image upload gets ten times as long).
"""

from __future__ import annotations

import atexit
import os
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.core.progress import Progress, report

ENV_SERVER = "CTUI_NNI_SERVER"
ENV_KEY = "CTUI_NNI_KEY"
ENV_TIMEOUT = "CTUI_NNI_TIMEOUT"
INSTALL = "pip install 'ctui[ai]' (the nninteractive-client package)"
TIMEOUT_S = 60.0  # a prediction; the image upload gets 10x this
CONNECT_TIMEOUT_S = 5.0

Point = tuple[int, int, int]
#: A box of inclusive voxel ranges ((z0, z1), (y0, y1), (x0, x1)), as ``SegmentOptions.box``.
Box = tuple[tuple[int, int], tuple[int, int], tuple[int, int]]


@dataclass
class Prompts:
    """What the user gave for one object: positive and negative points (x, y, z) and a box (inclusive)."""

    positive: list[Point] = field(default_factory=list)
    negative: list[Point] = field(default_factory=list)
    box: Box | None = None

    def items(self) -> list[tuple[str, Any]]:
        """The prompts in the order they are sent: the box first (it frames the object), then the points."""
        out: list[tuple[str, Any]] = [("box", self.box)] if self.box is not None else []
        return out + [("point", p) for p in self.positive] + [("negative", p) for p in self.negative]


@dataclass
class PromptReport:
    """What one call sent and got: prompts sent, the boxes the server changed ((z0, z1), ... half-open),
    the server's licence (``licence_new``: first time this session), re-established sessions, seconds."""

    prompts: int = 0
    boxes: list[list[list[int]]] = field(default_factory=list)
    licence: str = ""
    licence_new: bool = False
    reconnects: int = 0
    image_sent: bool = False
    refined: bool = False
    seconds: float = 0.0

    def summary(self) -> str:
        """One line: prompts sent, what else was sent, the boxes changed, seconds."""
        extra = [w for w, on in (("image sent", self.image_sent), ("object sent to refine", self.refined),
                                 (f"session re-established {self.reconnects}x", self.reconnects)) if on]
        return (f"nnInteractive: {self.prompts} prompt{'s' if self.prompts != 1 else ''}"
                + (f" ({', '.join(extra)})" if extra else "") + f", {len(self.boxes)} box(es) changed in "
                f"{self.seconds:.2f} s")

    def to_dict(self) -> dict[str, Any]:
        return {"prompts": self.prompts, "boxes": self.boxes, "licence": self.licence, "reconnects": self.reconnects,
                "image_sent": self.image_sent, "refined": self.refined, "seconds": round(self.seconds, 4)}


def server_of(server: str | None = None, api_key: str | None = None) -> tuple[str, str]:
    """(url, key): the given ones, else ``CTUI_NNI_SERVER`` / ``CTUI_NNI_KEY``; CtuiError without a URL."""
    url = (server or os.environ.get(ENV_SERVER, "")).strip()
    key = (api_key if api_key is not None else os.environ.get(ENV_KEY, "")).strip()
    if not url:
        raise CtuiError(f"no nnInteractive server: give its URL (e.g. http://127.0.0.1:8000 through an ssh -L "
                        f"tunnel) or set {ENV_SERVER}", option="server")
    if not url.startswith(("http://", "https://")):
        raise CtuiError(f"the server URL {url!r} must start with http:// or https://", option="server")
    return url.rstrip("/"), key


def timeout_of(timeout: float | None) -> float:
    """Seconds a prediction may take: ``timeout``, else ``CTUI_NNI_TIMEOUT``, else 60."""
    if timeout is None:
        text = os.environ.get(ENV_TIMEOUT, "").strip()
        try:
            timeout = float(text) if text else TIMEOUT_S
        except ValueError:
            raise CtuiError(f"{ENV_TIMEOUT}={text!r}: expected seconds, e.g. 60") from None
    if not 0 < timeout < 1e6:
        raise CtuiError(f"the server timeout must be a positive number of seconds, got {timeout:g}")
    return float(timeout)


def client_library() -> Any:
    """The nnInteractive remote client module (imported here: an optional extra, and httpx/blosc2 are
    needed only by this method); CtuiError saying what to install when it is missing."""
    try:
        from nnInteractive.inference import remote  # optional: pip install 'ctui[ai]'
    except ImportError:
        raise CtuiError(f"the nninteractive method needs the nnInteractive client: {INSTALL}") from None
    return remote


class Remote:
    """One claimed session on a server: the client, the image it holds and the licence shown."""

    def __init__(self, url: str, key: str, timeout: float) -> None:
        lib = client_library()
        self.url = url
        self.client = lib.nnInteractiveRemoteInferenceSession(
            url, api_key=key or None, connect_timeout=CONNECT_TIMEOUT_S, read_timeout=timeout,
            set_image_read_timeout=timeout * 10, write_timeout=timeout * 10)
        self.licence = str(self.client.license or "")
        self.licence_shown = False
        self.image_key: tuple | None = None
        self.buffer: np.ndarray | None = None
        self.object_id = 0
        self.sent: set[tuple[str, Any]] = set()
        self.region: list[list[int]] | None = None  # the box outside which the buffer is zero (None: all zero)
        self.fresh = False  # the image was just sent: the server holds no interactions

    def ensure_image(self, data: np.ndarray, spacing: tuple[float, ...]) -> bool:
        """Upload ``data`` (nz, ny, nx) unless the server holds it; True when it was sent."""
        key = _image_key(data)
        if key == self.image_key:
            return False
        self.image_key = None
        self.client.set_image(np.asarray(data)[None], {"spacing": [float(v) for v in spacing]})
        self.buffer = np.zeros(data.shape, np.uint8)
        self.client.set_target_buffer(self.buffer)
        self.image_key, self.object_id, self.sent, self.region, self.fresh = key, 0, set(), None, True
        return True

    def sync_object(self, seg: Any, oid: int) -> bool:
        """Make the server's object equal object ``oid`` of ``seg``: nothing when it does and is the same
        object; else its interactions are reset and a non-empty object sent as the initial segmentation.
        True when an object was sent. The check reads only the box holding both (the buffer is zero
        outside ``region``, the object outside its bounding box): no whole-volume comparison."""
        assert self.buffer is not None
        ob = seg.object_bbox(oid)
        box = _union(self.region, None if ob is None else [[b.start, b.stop] for b in ob])
        if oid == self.object_id:
            sl = None if box is None else tuple(slice(a, b) for a, b in box)
            if sl is None or np.array_equal(seg.labels[sl] == oid, self.buffer[sl].view(bool)):
                return False
        if not self.fresh:  # a new image holds no interactions: nothing to reset (a minimal server may lack it)
            self.client.reset_interactions()
        self.object_id, self.sent, self.region, self.fresh = oid, set(), None, False
        if ob is None:
            return False
        self.client.add_initial_seg_interaction((seg.labels == oid).view(np.uint8), run_prediction=False)
        self.region = [[b.start, b.stop] for b in ob]
        return True

    def written(self, box: list[list[int]]) -> None:
        """The server wrote ``box`` (half-open (z, y, x)) of the buffer: it may hold the object there."""
        self.region = _union(self.region, box)

    def send(self, kind: str, value: Any) -> list[list[int]] | None:
        """One prompt; returns the box the server changed ([[z0, z1], [y0, y1], [x0, x1]], half-open) or None."""
        c = self.client
        if kind == "box":
            (z0, z1), (y0, y1), (x0, x1) = value
            got = c.add_bbox_interaction([[z0, z1 + 1], [y0, y1 + 1], [x0, x1 + 1]], include_interaction=True)
        else:
            x, y, z = value
            got = c.add_point_interaction((z, y, x), include_interaction=kind == "point")
        self.sent.add((kind, value))
        self.fresh = False
        return None if got is None else [[int(a), int(b)] for a, b in got]

    def close(self) -> None:
        self.client.close()


_SESSIONS: dict[tuple[str, str], Remote] = {}
_LOCK = threading.Lock()


def _union(a: list[list[int]] | None, b: list[list[int]] | None) -> list[list[int]] | None:
    """The box holding boxes ``a`` and ``b`` ([[start, stop], ...] per axis; None: empty)."""
    if a is None or b is None:
        return b if a is None else a
    return [[min(p[0], q[0]), max(p[1], q[1])] for p, q in zip(a, b)]


def _image_key(data: np.ndarray) -> tuple:
    """Identifies the array the server holds: object, shape, dtype and a middle slice's sum (cheap)."""
    mid = data[data.shape[0] // 2]
    return id(data), tuple(data.shape), str(data.dtype), float(np.asarray(mid, np.float64).sum())


def close_sessions() -> None:
    """Release every claimed session (at exit; the TUI when it closes)."""
    with _LOCK:
        while _SESSIONS:
            _, r = _SESSIONS.popitem()
            try:
                r.close()
            except Exception:  # noqa: BLE001 - releasing is best effort: the server reaps idle leases
                pass


atexit.register(close_sessions)


def run_prompts(volume: Any, seg: Any, oid: int, prompts: Prompts, *, server: str | None = None,
                api_key: str | None = None, timeout: float | None = None, progress: Progress | None = None
                ) -> PromptReport:
    """Send ``prompts`` for object ``oid`` and write each answer into ``seg`` (one undo step a prompt).

    ``volume``: a Volume (data (nz, ny, nx), spacing (dz, dy, dx) mm); ``seg``: the Segmentation whose
    object ``oid`` (possibly empty) is the starting point. Errors (no server, refused key, server full,
    a session lost twice, timeouts, a malformed answer) raise one-line CtuiError; the prompts written
    before an error stay as undo steps (the caller's scratch segmentation is what the TUI drops).
    """
    url, key = server_of(server, api_key)
    timeout = timeout_of(timeout)
    lib = client_library()
    import httpx  # the client's HTTP library (installed with it): its exceptions name what failed

    rep = PromptReport()
    t0 = time.perf_counter()
    todo = prompts.items()
    if not todo:
        raise CtuiError("nninteractive needs a prompt: a seed, a background seed or a box", option="seeds")
    with _LOCK:
        for attempt in range(2):
            try:
                _exchange(volume, seg, oid, todo, url, key, timeout, rep, progress)
                break
            except lib.SessionExpiredError as exc:
                _drop(url, key)
                if attempt:
                    raise CtuiError(f"the nnInteractive server at {url} lost the session twice ({exc}): "
                                    "is it restarting?") from None
                rep.reconnects += 1
            except lib.ServerAtCapacityError as exc:
                _drop(url, key)
                raise CtuiError(f"the nnInteractive server at {url} is full ({exc}): try again when a user "
                                "leaves, or ask for more sessions (--max-sessions)") from None
            except httpx.InvalidURL as exc:
                _drop(url, key)
                raise CtuiError(f"the server URL {url!r} is not valid: {exc}", option="server") from None
            except httpx.HTTPError as exc:
                _drop(url, key)
                raise CtuiError(_http_message(httpx, exc, url, timeout)) from None
            except (ValueError, KeyError, TypeError) as exc:
                _drop(url, key)
                raise CtuiError(f"the nnInteractive server at {url} gave an answer ctui cannot read: {exc}") from None
    rep.seconds = time.perf_counter() - t0
    return rep


def _drop(url: str, key: str) -> None:
    r = _SESSIONS.pop((url, key), None)
    if r is not None:
        try:
            r.close()
        except Exception:  # noqa: BLE001 - a dead session is dropped whatever its release says
            pass


def _exchange(volume: Any, seg: Any, oid: int, todo: list[tuple[str, Any]], url: str, key: str, timeout: float,
              rep: PromptReport, progress: Progress | None) -> None:
    """Claim (or reuse) the session, upload the image when needed, sync the object, send the prompts not
    yet sent and write each answer's box."""
    remote = _SESSIONS.get((url, key))
    if remote is None:
        report(progress, 0, len(todo) + 2, f"claiming a session on {url}")
        remote = Remote(url, key, timeout)
        _SESSIONS[(url, key)] = remote
    if remote.licence and not remote.licence_shown:
        rep.licence, rep.licence_new, remote.licence_shown = remote.licence, True, True
    else:
        rep.licence = remote.licence
    data = volume.data
    report(progress, 1, len(todo) + 2, "sending the image")
    rep.image_sent |= remote.ensure_image(data, tuple(volume.spacing))
    rep.refined |= remote.sync_object(seg, oid)
    fresh = [(k, v) for k, v in todo if (k, v) not in remote.sent]
    for i, (kind, value) in enumerate(fresh):
        report(progress, i + 2, len(fresh) + 2, f"{kind} prompt {i + 1}/{len(fresh)}")
        box = remote.send(kind, value)
        rep.prompts += 1
        if box is not None:
            remote.written(box)
            _write_box(seg, oid, remote.buffer, box, f"nninteractive {kind} {_text(value)} -> object {oid}")
            rep.boxes.append(box)


def _write_box(seg: Any, oid: int, buffer: np.ndarray | None, box: list[list[int]], label: str) -> None:
    """The object inside ``box`` (half-open (z, y, x)) becomes the server's answer there; one undo step.
    Voxels of other objects stay theirs (the Segmentation's rule for every method)."""
    assert buffer is not None
    shape = seg.labels.shape
    if any(not 0 <= a <= b <= n for (a, b), n in zip(box, shape)):
        raise ValueError(f"the box {box} it returned is outside the image {tuple(shape)}")
    sl = tuple(slice(a, b) for a, b in box)
    region = seg.labels[sl]
    want = buffer[sl] != 0
    new = np.where((region == oid) & ~want, np.uint8(0), region)
    new = np.where(want & ((region == 0) | (region == oid)), np.uint8(oid), new)
    seg.add_object(object_id=oid)
    seg.apply_region(sl, new, label=label)


def _text(value: Any) -> str:
    if value and isinstance(value[0], tuple):
        (z0, z1), (y0, y1), (x0, x1) = value
        return f"{x0},{y0},{z0}..{x1},{y1},{z1}"
    return ",".join(str(v) for v in value)


def _http_message(httpx: Any, exc: Exception, url: str, timeout: float) -> str:
    """One line for a failed request: unreachable, refused key, timeout, or the server's status and detail."""
    if isinstance(exc, httpx.ConnectError | httpx.ConnectTimeout):
        return (f"cannot reach the nnInteractive server at {url} ({type(exc).__name__}): is it running, "
                "and is the ssh -L tunnel open?")
    if isinstance(exc, httpx.TimeoutException):
        return f"the nnInteractive server at {url} did not answer within {timeout:g} s ({type(exc).__name__})"
    if isinstance(exc, httpx.HTTPStatusError):
        code = exc.response.status_code
        if code in (401, 403):
            return (f"the nnInteractive server at {url} refused the API key (HTTP {code}): give the server's key "
                    f"({ENV_KEY}, or the key option)")
        detail = _detail(exc.response)
        return f"the nnInteractive server at {url} answered HTTP {code}" + (f": {detail}" if detail else "")
    return f"the nnInteractive server at {url} failed: {type(exc).__name__}: {exc}"


def _detail(resp: Any) -> str:
    try:
        d = resp.json()
    except ValueError:
        return resp.text[:200].strip()
    return str(d.get("detail", ""))[:200] if isinstance(d, dict) else str(d)[:200]


def run_job(job: Any) -> None:
    """The registry's entry (``methods.Job``): the job's seed as a positive point, its background seeds
    as negative ones and its box; the server from the environment. ``actions.segment.segment`` takes the
    prompted path before a job is built (no range or seed fill is needed), so this serves callers that
    build jobs themselves."""
    box = job.settings.box
    rep = run_prompts(job.volume, job.seg, job.oid, Prompts([tuple(job.seed)], list(job.background), box),
                      progress=job.progress)
    job.stops["nninteractive"] = f"{rep.prompts} prompt(s)"
