"""The workspace's vessel tool: ``D`` marks the cursor as the vessel's start, then as waypoints;
``O`` marks the end and extracts the vessel (``actions.vessel.vessel``, the function ``ctui vessel``
calls) in a worker, with progress and cancel (Escape). The vessel comes back as a proposal for the
current object, hatched on every plane, accepted (``a``) or rejected (``x``) like a segmentation.
With the mouse: click, ``D``, click (in the arch), ``D``, click, ``O``, ``a``.

Hooked into :class:`ctui.screens.workspace.WorkspaceScreen` by its bases (:class:`VesselMixin`) and
its bindings (:data:`VESSEL_BINDINGS`)."""

from __future__ import annotations

import weakref

from textual.worker import get_current_worker

from ctui.engine.core.progress import Cancelled
from ctui.screens.keytable import keys
from ctui.screens.messages import SegmentationFailed, Status

VESSEL_BINDINGS = keys("""
D                    vessel_point     Vessel: the cursor is its start, then a waypoint  hidden
O                    vessel_end       Vessel: the cursor is its end; extract it         hidden
""")

_POINTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # workspace -> [(x, y, z), ...]


def points_of(ws) -> list:
    """The points marked so far in workspace ``ws`` (voxels x, y, z: the start, then waypoints)."""
    return _POINTS.setdefault(ws, [])


class VesselMixin:
    """``D`` and ``O`` of the workspace (module docstring)."""

    def action_vessel_point(self) -> None:
        pts = points_of(self)
        s = self.s
        pts.append((int(s.x), int(s.y), int(s.z)))
        what = "start" if len(pts) == 1 else f"waypoint {len(pts) - 1}"
        self.set_status(f"Vessel {what} at {pts[-1][0]},{pts[-1][1]},{pts[-1][2]}. D adds a waypoint, "
                        "O marks the end and extracts the vessel")

    def action_vessel_end(self) -> None:
        from ctui.screens.propagation import PropagationRun  # the segmentation engine loads with the first run

        pts = points_of(self)
        s = self.s
        end = (int(s.x), int(s.y), int(s.z))
        if not pts:
            self.app.notify("Vessel: mark its start first (D at the cursor)", severity="warning")
            return
        if self.jobs.segmenting or self.pending.proposal is not None:
            self.app.notify("Wait for the running segmentation, or accept (a) / reject (x) the proposal first",
                            severity="warning")
            return
        start, vias = pts[0], list(pts[1:])
        _POINTS[self] = []
        run = PropagationRun(self, "vessel")
        self.jobs.segmentation_started(run)
        self.show_progress(f"Vessel from {start[0]},{start[1]},{start[2]} to {end[0]},{end[1]},{end[2]}", 0, 100)
        self.run_worker(lambda: _work(run, start, vias, end), thread=True, exclusive=True, group="propagate",
                        name="vessel")


def _work(run, start, vias, end) -> None:
    """The worker: ``actions.vessel.vessel`` on the session's volume, its proposal to the workspace."""
    from ctui.engine.actions.vessel import vessel, vessel_proposal  # the vessel engine loads with the first vessel

    ws = run.ws
    s = ws.s
    progress = run.progress(get_current_worker(), "Vessel")

    try:
        res = vessel(s.volume, start=start, ends=[end], vias=vias, progress=progress)
        proposal = vessel_proposal(res, s.current)
    except Cancelled:
        ws.post_message(SegmentationFailed("Vessel", "cancelled"))
        return
    except Exception as exc:  # shown as a notification; the session is untouched
        ws.post_message(SegmentationFailed("Vessel", str(exc)))
        return
    run.done(proposal, seed=start)
    big = max(res.maxima, key=lambda m: m["max_diameter_mm"]) if res.maxima else None
    text = (f"Vessel proposal: path {res.path_length_mm[0]:.0f} mm, {res.volume_ml:.1f} ml"
            + (f", max diameter {big['max_diameter_mm']:.1f} mm at {big['at_mm']:.0f} mm" if big else "")
            + ". a accepts, x rejects" + ("; " + "; ".join(res.warnings) if res.warnings else ""))
    ws.post_message(Status(text))
