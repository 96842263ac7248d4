"""The workspace's segmentation runner (:class:`SegmentRunner`): ``S`` segments the current object
from the cursor, ``p``/``<``/``>`` from its seed (an object drawn by hand: propagated from its drawn
slice), ``G`` sets the options, ``a``/``x`` accept or reject the proposal, Escape cancels the run.

The runner owns the run (:class:`ctui.screens.ws_state.Jobs` tracks it), the proposal waiting for
``a`` or ``x`` (:class:`ctui.screens.ws_state.ProposalState`) and its worker (in
:mod:`ctui.screens.propagation`, loaded with the first run: the engine's segmentation and scipy),
which posts :class:`ctui.screens.messages.ProposalReady` or ``SegmentationFailed`` back."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from ctui.engine.core.errors import CtuiError
from ctui.screens.ws_host import Owner
from ctui.screens.ws_state import describe

if TYPE_CHECKING:
    from ctui.screens.propagation import PropagationRun


class SegmentRunner(Owner):
    """Starts and ends the workspace's segmentation runs; holds nothing the screen's state does not."""

    def idle(self) -> bool:
        """Whether no segmentation runs; otherwise says so. A pending proposal does not block: segmenting
        again (after a background seed in its leak, a new range, a new option) replaces it, no x first."""
        if self.ws.jobs.segmenting:
            self.app.notify("A segmentation is already running (Escape cancels it)", severity="warning")
            return False
        return True

    def start_segment(self, direction: str = "both", *, seed: tuple[int, int, int] | None = None) -> None:
        """Segment the current object from ``seed`` (default: the cursor) through ``actions.segment``."""
        from ctui.screens.propagation import PropagationRun, segment_work  # the segmentation engine loads here
        from ctui.screens.segpanel import options_for  # with the segmentation engine

        ws, s = self.ws, self.s
        if not self.idle():
            return
        seed = seed or (int(s.x), int(s.y), int(s.z))
        try:
            opts, th = options_for(s, direction)
        except (CtuiError, ValueError) as exc:
            self.app.notify(str(exc), severity="error")
            return
        run = PropagationRun(ws, direction)
        replaced = ws.pending.clear() is not None
        ws.jobs.segmentation_started(run)
        if replaced:
            ws.refresh_view()  # the old proposal's hatching goes while the new one is computed
        ws.show_progress(f"Segmenting object {s.current} from {seed[0]},{seed[1]},{seed[2]} ({describe(s)})"
                         f"{'; it replaces the pending proposal' if replaced else ''}", 0, 100)
        ws.run_worker(lambda: segment_work(run, seed, opts, th), thread=True, exclusive=True, group="propagate",
                      name="segment")

    def start_propagation(self, direction: str) -> None:
        """``p``/``<``/``>``: segment the current object from its seed (actions.segment); an object drawn by
        hand (no seed) is propagated from its drawn slice."""
        from ctui.screens.propagation import PropagationRun, object_seed, propagate_work, settings_for  # the segmentation engine loads here

        ws, s = self.ws, self.s
        # a pending proposal's seed first: p again (after a background seed in its leak) segments from the same seed
        seed = ws.pending.seed if ws.pending.proposal is not None and ws.pending.seed is not None else object_seed(s)
        if seed is not None:
            self.start_segment(direction, seed=seed)
            return
        if not self.idle():
            return
        try:
            settings = settings_for(s, direction)
            if not (s.seg.labels[s.z] == s.current).any():
                raise CtuiError(f"object {s.current} has no pixels on slice {s.z}: fill it here first (Enter)")
        except (CtuiError, ValueError) as exc:
            self.app.notify(str(exc), severity="error")
            return
        run = PropagationRun(ws, direction)
        ws.pending.clear()
        ws.jobs.segmentation_started(run)
        ws.show_progress(f"Propagating object {s.current} {direction}", 0, s.shape[0])
        ws.run_worker(lambda: propagate_work(run, settings), thread=True, exclusive=True, group="propagate",
                      name="propagate")

    def finished(self, run: PropagationRun) -> None:
        """A run's ``ProposalReady``: the proposal waits for ``a`` or ``x``."""
        ws = self.ws
        ws.jobs.segmentation_ended()
        ws.show_progress(None)
        p = run.proposal
        if p is None:  # done() always gives one; a run that ended without is a SegmentationFailed
            return
        ws.pending.show(p, seed=run.seed, object_settings=run.object_settings)
        rng = p.slices
        secs = time.perf_counter() - run.started
        where = f"slices {rng[0]}..{rng[1]}" if rng else "no slices"
        rep = run.report
        # warnings are advisory: notes in the side panel (and counted on the status line), never a toast
        # over the image, the proposal line or the review strip
        notes = list(rep.warnings) if rep is not None else list(p.warnings())
        ws.pending.notes = notes
        said = f" ({len(notes)} note{'s' if len(notes) != 1 else ''} in the panel)" if notes else ""
        if rep is not None:
            ws.set_status(f"Proposal: {rep.message()} in {secs:.1f} s{said}. a accepts, x rejects")
        else:
            ws.set_status(f"Proposal (hatched): {p.voxels} voxels, {where} in {secs:.1f} s{said}. a accepts, x rejects")
        ws.refresh_view()

    def failed(self, what: str, reason: str) -> None:
        """A run's ``SegmentationFailed``: no proposal."""
        self.ws.jobs.segmentation_ended()
        self.work_failed(what, reason)

    def accept(self) -> None:
        """``a``: the pending proposal goes into the segmentation (one undo step)."""
        ws = self.ws
        if ws.pending.proposal is None:
            self.app.notify("No pending propagation", timeout=2)
            return
        n, p = ws.pending.accept(self.s.seg)
        ws.labels_changed()
        ws.set_status(f"Accepted: {n} voxels added to object {p.object_id} (u undoes)")
        ws.refresh_view()

    # ------------------------------------------------------------------ keys
    def action_propagate(self, direction: str) -> None:
        self.start_propagation(direction)

    def action_segment_here(self) -> None:
        """S: the current object from the cursor, with the segmentation panel's options (actions.segment)."""
        self.start_segment("both")

    def action_segment_panel(self) -> None:
        from ctui.screens.segpanel import SegmentPanel  # the segmentation engine (scipy) loads with the first segmentation

        def done(ok: bool | None) -> None:
            if ok:
                self.set_status(f"Segmentation: {describe(self.s)}. S segments from the cursor")
                self.update_panel()

        self.app.push_screen(SegmentPanel(self.s), done)

    def action_accept(self) -> None:
        if not self.ws.edit.busy():
            self.accept()

    def action_reject(self) -> None:
        """``x``: the pending proposal is dropped."""
        if self.ws.pending.clear() is None:
            self.app.notify("No pending propagation", timeout=2)
            return
        self.set_status("Propagation rejected")
        self.refresh_view()

    def action_cancel(self) -> None:
        ws = self.ws
        cancelled = ws.jobs.cancel()
        if cancelled == "segmentation":
            self.set_status("Cancelling propagation...")
        elif cancelled == "job":
            ws.show_progress(None)
            self.set_status("Cancelled")
        elif ws.edit_tools.lift():
            self.set_status("Brush lifted")
            self.update_panel()
