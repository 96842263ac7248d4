"""Segmentation from the workspace: a thread worker calling ``ctui.engine.actions.segment.segment``
(the function ``ctui segment`` calls, with the panel's options: :mod:`ctui.screens.segpanel`)
from the cursor (``S``) or from the object's seed (``p``, ``<``, ``>``), with a progress bar and
cancel (Escape), then a pending proposal shown (hatched, outlined in yellow) on every plane
until accepted (``a``: the object becomes the proposal, one undo step) or rejected (``x``).
An object drawn by hand (no seed) is propagated from its drawn slice instead. The worker
talks to the workspace through messages. The runs are started and ended by the workspace's
:class:`ctui.screens.ws_segment.SegmentRunner`; this module (the engine's segmentation, scipy)
loads with the first run."""

from __future__ import annotations

import threading
import time
from typing import Any

from textual.worker import get_current_worker

from ctui.engine.actions.segment import METHODS, segment as segment_action
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.progress import Cancelled
from ctui.engine.segment import propagate
from ctui.engine.segment.selection import Segmentation
from ctui.screens.messages import JobProgress, ProposalReady, SegmentationFailed
from ctui.screens.session import Session
from ctui.screens.ws_host import RunHost


class PropagationRun:
    """One segmentation or propagation of the workspace ``ws`` (all the worker sees of it: its session and
    its message box, :class:`ctui.screens.ws_host.RunHost`): its cancel event and, when it
    ends, its proposal, the segmentation's report (``actions.segment``'s object result, None
    for a propagation), the seed (x, y, z) and the settings the object keeps when accepted."""

    def __init__(self, ws: RunHost, direction: str) -> None:
        self.ws = ws
        self.direction = direction
        self.event = threading.Event()
        self.proposal: propagate.Proposal | None = None
        self.report: Any = None  # the segment action's ObjectResult (None: a propagation)
        self.seed: tuple[int, int, int] | None = None
        self.object_settings: dict = {}
        self.started = time.perf_counter()

    def cancel(self) -> None:
        self.event.set()

    def done(self, proposal, *, report=None, seed=None, object_settings: dict | None = None) -> None:
        """The worker's result, posted to the workspace (``ProposalReady``)."""
        self.proposal, self.report = proposal, report
        self.seed = None if seed is None else (int(seed[0]), int(seed[1]), int(seed[2]))
        self.object_settings = dict(object_settings or {})
        self.ws.post_message(ProposalReady(self))

    def progress(self, worker, label: str):
        """The engine's ``progress(done, total, message)`` for this run's thread ``worker``: False (stop) once
        the worker, the run or the workspace is gone; a ``JobProgress`` "<label>: message" at most every
        50 ms."""
        last = [0.0]

        def callback(done: float, total: float, message: str = "") -> bool:
            if worker.is_cancelled or self.event.is_set() or not self.ws.is_attached:
                return False
            now = time.perf_counter()
            if now - last[0] > 0.05:
                last[0] = now
                self.ws.post_message(JobProgress(f"{label}: {message}", int(100 * done / max(total, 1e-9)), 100))
            return True

        return callback


def settings_for(session: Session, direction: str) -> propagate.PropagationSettings:
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
    kw: dict[str, Any] = {}
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


def object_seed(session: Session) -> tuple[int, int, int] | None:
    """The current object's last seed (x, y, z) (set by Enter, S or ctui segment), or None."""
    info = session.seg.objects.get(session.current)
    if info is None or not info.seeds:
        return None
    x, y, z = info.seeds[-1]
    return int(x), int(y), int(z)


def segment_work(run: PropagationRun, seed, opts, th) -> None:
    ws = run.ws
    s = ws.s
    progress = run.progress(get_current_worker(), "Segmenting")
    oid = s.current
    try:
        with s._lock:
            labels = s.seg.labels.copy()
            if "prompts" not in METHODS[opts.method].options:  # a model's prompts refine the object as it is
                labels[labels == oid] = 0
            scratch = Segmentation(s.seg.shape, labels=labels)
            res = segment_action(s.volume, [seed], th, background=list(s.background_seeds),
                                 options=opts, pipeline=s.pipeline, segmentation=scratch, progress=progress,
                                 object_ids=[oid])
        obj = res.objects[0]
        mask = scratch.labels == oid
        del scratch, labels
        proposal = propagate.Proposal.of_mask(oid, seed[2], mask, stops=dict(obj.stops), necks=list(obj.necks),
                                              settings=dict(res.settings[0]))
        proposal.cuts = list(obj.cuts)
        proposal.leak_entries = list(obj.neck.get("leaks", []))  # where leaks enter: the review strip's L marks
        settings = res.segmentation.objects[oid].settings
    except Cancelled:
        ws.post_message(SegmentationFailed("Segmentation", "cancelled"))
        return
    except Exception as exc:
        ws.post_message(SegmentationFailed("Segmentation", str(exc)))
        return
    run.done(proposal, report=obj, seed=seed, object_settings=settings)


def propagate_work(run: PropagationRun, settings) -> None:
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
        ws.post_message(SegmentationFailed("Propagation", str(exc)))
        return
    run.done(proposal)
