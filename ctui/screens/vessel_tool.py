"""The workspace's vessel tool: ``D`` marks the cursor as the vessel's start, then as waypoints;
``O`` marks the end and extracts the vessel (``actions.vessel.vessel``, the function ``ctui vessel``
calls) in a worker, with progress and cancel (Escape). The vessel comes back as a proposal for the
current object, hatched on every plane, accepted (``a``) or rejected (``x``) like a segmentation.
With the mouse: click, ``D``, click (in the arch), ``D``, click, ``O``, ``a``.

Every slice view draws the vessels' paths (:meth:`VesselOwner.draw`, from the workspace's overlay): the
points marked so far, and the path of the pending proposal and of each vessel object (its
settings' "vessel" record, :func:`ctui.engine.actions.vessel.vessel_record`): the whole path
projected on the plane in a dim line, the part within a slice of the plane in a bright one, the
start green, the waypoints white, the ends red (filled on their slice). The measure screen shows
a vessel object's report (:func:`report_lines`).

Composed by :class:`ctui.screens.workspace.WorkspaceScreen` (:class:`VesselOwner`, its ``vessel``) with
its bindings (:data:`VESSEL_BINDINGS`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np
from textual.worker import get_current_worker

from ctui.engine.core.progress import Cancelled
from ctui.screens.keytable import keys
from ctui.screens.messages import SegmentationFailed, Status
from ctui.screens.ws_host import Owner, WorkspaceHost

if TYPE_CHECKING:
    from ctui.screens.propagation import PropagationRun

VESSEL_BINDINGS = keys(via="do", table="""
D                    vessel_point     Vessel: the cursor is its start, then a waypoint  hidden
O                    vessel_end       Vessel: the cursor is its end; extract it         hidden
""")

PATH_COLOR = (255, 64, 200)  # the path within a slice of the plane
PATH_FAR_COLOR = (140, 40, 110)  # the rest of the path, projected on the plane
START_COLOR, VIA_COLOR, END_COLOR = (60, 255, 60), (255, 255, 255), (255, 60, 60)
NEAR_VOXELS = 1.0  # path points this close to the plane (voxels along its normal) are on it

class VesselOwner(Owner):
    """``D`` and ``O`` of the workspace and the vessels' paths on its views (module docstring)."""

    def __init__(self, ws: WorkspaceHost) -> None:
        super().__init__(ws)
        self.points: list[tuple[int, int, int]] = []  # marked so far (voxels x, y, z): the start, then waypoints

    def action_vessel_point(self) -> None:
        pts = self.points
        s = self.s
        pts.append((int(s.x), int(s.y), int(s.z)))
        what = "start" if len(pts) == 1 else f"waypoint {len(pts) - 1}"
        self.set_status(f"Vessel {what} at {pts[-1][0]},{pts[-1][1]},{pts[-1][2]}. D adds a waypoint, "
                        "O marks the end and extracts the vessel")
        self.refresh_view()  # the mark on the views

    def action_vessel_end(self) -> None:
        from ctui.screens.propagation import PropagationRun  # the segmentation engine loads with the first run

        ws, pts, s = self.ws, self.points, self.s
        end = (int(s.x), int(s.y), int(s.z))
        if not pts:
            self.app.notify("Vessel: mark its start first (D at the cursor)", severity="warning")
            return
        if ws.jobs.segmenting or ws.pending.proposal is not None:
            self.app.notify("Wait for the running segmentation, or accept (a) / reject (x) the proposal first",
                            severity="warning")
            return
        start, vias = pts[0], list(pts[1:])
        self.points = []
        run = PropagationRun(ws, "vessel")
        ws.jobs.segmentation_started(run)
        ws.show_progress(f"Vessel from {start[0]},{start[1]},{start[2]} to {end[0]},{end[1]},{end[2]}", 0, 100)
        ws.run_worker(lambda: _work(run, start, vias, end), thread=True, exclusive=True, group="propagate",
                      name="vessel")

    def records(self) -> list[dict]:
        """The vessel records to draw: the pending proposal's, then each object's."""
        ws = self.ws
        out = []
        if ws.pending.proposal is not None and "vessel" in ws.pending.object_settings:
            out.append(ws.pending.object_settings["vessel"])
        seg = ws.s.seg
        for info in (seg.objects.values() if seg is not None else ()):
            rec = (getattr(info, "settings", None) or {}).get("vessel")
            if rec and rec.get("path"):
                out.append(rec)
        return out

    def draw(self, pv, idx: int, grid, disp) -> None:
        """The vessels' paths and points on one plane's display grid (module docstring); ``pv`` the
        plane's view, ``idx`` its slice index along ``pv.normal``, ``disp`` voxel (z, y, x) -> display (x, y)."""
        n = pv.normal
        for rec in self.records():
            path = np.asarray(rec.get("path") or [], dtype=float).reshape(-1, 3)
            if len(path) >= 2:
                xy = np.array([disp(tuple(int(v) for v in np.rint(p))) for p in path], dtype=float)
                near = np.abs(path[:, n] - idx) <= NEAR_VOXELS
                pts = np.rint(xy).astype(np.int32)
                cv2.polylines(grid, [pts.reshape(-1, 1, 2)], False, PATH_FAR_COLOR, 1)
                for a, b in zip(range(len(pts) - 1), range(1, len(pts))):
                    if near[a] or near[b]:
                        cv2.line(grid, tuple(int(v) for v in pts[a]), tuple(int(v) for v in pts[b]), PATH_COLOR, 2)
            marks = [(rec.get("start"), START_COLOR)] + [(v, VIA_COLOR) for v in rec.get("vias") or []]
            for p, color in marks + [(e, END_COLOR) for e in rec.get("ends") or []]:
                if p:
                    zyx = (int(p[2]), int(p[1]), int(p[0]))
                    _mark(grid, disp(zyx), color, abs(zyx[n] - idx) <= NEAR_VOXELS)
        for k, (x, y, z) in enumerate(self.points):  # marked, not yet extracted
            _mark(grid, disp((z, y, x)), START_COLOR if k == 0 else VIA_COLOR, (z, y, x)[n] == idx)


def _work(run: PropagationRun, start, vias, end) -> None:
    """The worker: ``actions.vessel.vessel`` on the session's volume, its proposal to the workspace."""
    from ctui.engine.actions.vessel import vessel, vessel_proposal, vessel_record  # loads with the first vessel

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
    run.done(proposal, seed=start, object_settings={"vessel": vessel_record(res, s.volume)})
    big = max(res.maxima, key=lambda m: m["max_diameter_mm"]) if res.maxima else None
    text = (f"Vessel proposal: path {res.path_length_mm[0]:.0f} mm, {res.volume_ml:.1f} ml"
            + (f", max diameter {big['max_diameter_mm']:.1f} mm at {big['at_mm']:.0f} mm" if big else "")
            + ". a accepts, x rejects" + ("; " + "; ".join(res.warnings) if res.warnings else ""))
    ws.post_message(Status(text))


def _mark(grid, xy, color, filled: bool) -> None:
    x, y = (int(round(v)) for v in xy)
    cv2.rectangle(grid, (x - 2, y - 2), (x + 2, y + 2), color, -1 if filled else 1)


def report_lines(rec: dict) -> list[str]:
    """The vessel's report for the measure screen: arc length, area, diameters, the largest max
    diameter per segment and where (``rec``: a vessel record)."""
    rep = rec.get("report") or {}
    lengths = rep.get("length_mm") or []
    ml = f", {rep['volume_ml']:.1f} ml" if "volume_ml" in rep else ""
    out = [f"[b]Vessel[/b] ({rec.get('lumen', 'contrast')}): path " + ", ".join(f"{v:.0f}" for v in lengths) + " mm" + ml]
    if rep.get("sections"):
        a, eq = rep["area_mm2"], rep["eq_diameter_mm"]
        out += [f"{rep['sections']} sections, area {a[0]:.0f}..{a[1]:.0f} mm²",
                f"eq. diameter {eq[0]:.1f}..{eq[2]:.1f} mm (median {eq[1]:.1f})",
                f"min diameter {rep['min_diameter_mm']:.1f} mm, inscribed up to {rep['inscribed_diameter_mm']:.1f} mm",
                f"max diameter {rep['max_diameter_mm']:.1f} mm at {rep['max_at_mm']:.0f} mm"]
    maxima = rep.get("maxima") or []
    if maxima:
        out.append("[b]max diameter per segment[/b]")
        out += [f" {m['from_mm']:.0f}-{m['to_mm']:.0f} mm: {m['max_diameter_mm']:.1f} at {m['at_mm']:.0f}"
                + (f" (branch {m['branch']})" if m.get("branch") else "") for m in maxima]
    return out
