"""Propagation from the workspace: a thread worker driving
``ctui.engine.segment.propagate.propagate_object`` with a progress bar and cancel (Escape),
then a pending proposal shown (hatched, outlined in yellow) on every plane until accepted
(``a``) or rejected (``x``). The worker talks to the workspace through messages."""

from __future__ import annotations

import threading
import time

from textual.worker import get_current_worker

from ctui.engine.core.errors import CtuiError
from ctui.engine.segment import propagate
from ctui.screens.messages import JobDone, JobFailed, JobProgress


class PropagationRun:
    def __init__(self, ws, direction: str) -> None:
        self.ws = ws
        self.direction = direction
        self.event = threading.Event()
        self.proposal = None
        self.started = time.perf_counter()

    def cancel(self) -> None:
        self.event.set()


def settings_for(session, direction: str):
    """PropagationSettings from the current object's fill range (or the session's) and
    the session's slice limits (``s`` stops at a slice, ``i`` sets a range)."""
    s = session
    info = s.seg.objects.get(s.current) if s.seg is not None else None
    st = dict(info.settings) if info is not None else {}
    if "low" in st and "high" in st:
        lo, hi = float(st["low"]), float(st["high"])
    elif s.range_ is not None:
        lo, hi = s.range_
    else:
        raise CtuiError(f"object {s.current} has no fill yet: press Enter on it first")
    kw = {}
    lim = s.limits.slices
    if lim is not None:
        if not lim[0] <= s.z <= lim[1]:
            raise CtuiError(f"slice {s.z} is outside the limits {lim[0]}..{lim[1]} (i changes them)")
        kw["slices"] = (int(lim[0]), int(lim[1]))
    return propagate.PropagationSettings(low=lo, high=hi, direction=direction, mode=s.prop_mode,
                                         connectivity=int(st.get("connectivity", s.connectivity)), **kw)


def clip_to_slices(proposal, limits: tuple[int, int] | None) -> None:
    """Drop the proposal's slices outside ``limits`` (first, last) in place."""
    if limits is None:
        return
    for z in [z for z in proposal.masks if not limits[0] <= z <= limits[1]]:
        proposal.masks.pop(z, None)
        proposal.areas.pop(z, None)


def start_propagation(ws, direction: str) -> None:
    app = ws.app
    s = ws.s
    if ws._prop is not None:
        app.notify("A propagation is already running (Escape cancels it)", severity="warning")
        return
    if getattr(ws, "proposal", None) is not None:
        app.notify("Accept (a) or reject (x) the pending propagation first", severity="warning")
        return
    try:
        settings = settings_for(s, direction)
        if not (s.seg.labels[s.z] == s.current).any():
            raise CtuiError(f"object {s.current} has no pixels on slice {s.z}: fill it here first (Enter)")
    except (CtuiError, ValueError) as exc:
        app.notify(str(exc), severity="error")
        return
    run = PropagationRun(ws, direction)
    ws._prop = run
    ws.show_progress(f"Propagating object {s.current} {direction}", 0, s.shape[0])
    ws.run_worker(lambda: _work(run, settings), thread=True, exclusive=True, group="propagate", name="propagate")


def _work(run: PropagationRun, settings) -> None:
    """The worker: progress and the result go to the workspace as messages."""
    ws = run.ws
    s = ws.s
    worker = get_current_worker()
    last = [0.0]

    def progress(ev) -> bool:
        if worker.is_cancelled or run.event.is_set() or not ws.is_attached:
            return False  # cancelled, or the app is gone
        now = time.perf_counter()
        if now - last[0] > 0.05:
            last[0] = now
            ws.post_message(JobProgress(f"Propagating {ev.direction}: slice {ev.z}", ev.done, max(ev.total, 1)))
        return True

    try:
        with s._lock:
            proposal = propagate.propagate_object(s.seg, s.volume, s.pipeline, s.current, s.z, settings,
                                                  progress=progress, cancel=run.event)
        clip_to_slices(proposal, s.limits.slices)
    except Exception as exc:
        ws.post_message(JobFailed("Propagation", str(exc)))
        return
    run.proposal = proposal
    ws.post_message(JobDone("propagation", run))


def finished(ws, run: PropagationRun) -> None:
    ws._prop = None
    ws.show_progress(None)
    p = run.proposal
    ws.proposal = p
    rng = p.slices
    secs = time.perf_counter() - run.started
    extra = "; ".join(p.warnings())
    where = f"slices {rng[0]}..{rng[1]}" if rng else "no slices"
    ws.set_status(f"Proposal (hatched): {p.voxels} voxels, {where} in {secs:.1f} s. a accepts, x rejects. {extra}")
    if p.warnings():
        ws.app.notify(extra, severity="warning", timeout=8)
    ws.refresh_view()


def accept(ws) -> None:
    p = getattr(ws, "proposal", None)
    if p is None:
        ws.app.notify("No pending propagation", timeout=2)
        return
    n = p.accept(ws.s.seg)
    ws.proposal = None
    ws.labels_changed()
    ws.set_status(f"Accepted: {n} voxels added to object {p.object_id} (u undoes)")
    ws.refresh_view()


def reject(ws) -> None:
    if getattr(ws, "proposal", None) is None:
        ws.app.notify("No pending propagation", timeout=2)
        return
    ws.proposal = None
    ws.set_status("Propagation rejected")
    ws.refresh_view()
