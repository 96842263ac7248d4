"""The workspace's state, in small objects that own it (the :class:`Session` holds what a
project saves: volume, labels, cursor, window, tools).

- :class:`ViewState`: which layout shows the volume (one plane, the pipeline's 2x2, the
  planes' 2x2), where a zoomed view is panned, the window preset chosen, the newest
  request for the pipeline's views.
- :class:`EditTools`: the pen, click-to-fill, the box corner and the scissors polygon.
- :class:`Jobs`: the running work (one cancellable worker, one segmentation run).
- :class:`ProposalState`: the pending proposal of a segmentation (hatched until ``a`` or
  ``x``), with its full-volume mask for the other planes.
- :class:`ObjectVolumes`: the labels' version and each object's volume (ml) for the side panel.
- :class:`SeedRange`: the side panel's range at the cursor, computed in a thread.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from ctui.engine.actions.series import label_counts
from ctui.screens import planes
from ctui.screens.session import Session


class ViewState:
    """Layout, pan and window choice of the workspace's views."""

    def __init__(self) -> None:
        self.zoom = 1.0  # 1 (the whole plane) to 16
        self.grid_mode = False  # the pipeline's four views of the file's slice
        self.ortho_mode = False  # axial, sagittal, coronal and 3D in 2x2
        self.pan_center: tuple[float, float] | None = None  # (x, y) image pixel of a zoomed main view
        self.token = 0  # the newest request for the pipeline's views (older answers are dropped)
        self.last_views = None  # the pipeline's views (SliceViews) shown last
        self.window_index = -1  # the preset ``w`` chose last (index in Session.window_presets())
        self.window_name: str | None = None  # its name, or "custom" (W)
        self.painted = False  # the workspace has been painted once (work that can wait for it waits)
        self.zoomed_at: tuple[int, int, int] | None = None  # the cursor a zoom about a point kept in view

    def set_layout(self, *, grid: bool = False, ortho: bool = False) -> None:
        """One plane (both False), the pipeline's 2x2 (``grid``) or the planes' 2x2 (``ortho``); the pan resets."""
        self.grid_mode, self.ortho_mode = grid, ortho
        self.pan_center = None

    def zoom_by(self, d: int) -> float:
        """Zoom in (``d`` > 0: x2) or out (/2), from 1 to 16; the pan resets at 1. Returns the zoom."""
        self.zoom = min(max(self.zoom * (2.0 if d > 0 else 0.5), 1.0), 16.0)
        if self.zoom == 1.0:
            self.pan_center = None
        return self.zoom

    def next_token(self) -> int:
        """A new request for the pipeline's views: answers to older ones are dropped."""
        self.token += 1
        return self.token

    def center(self, session, plane: str) -> tuple[float, float]:
        """(x, y) image pixel the view of ``plane`` centres on: the cursor, or (zoomed, the
        session's plane) the pan centre, moved so that the cursor stays visible and the
        view inside the image."""
        s = session
        pv = planes.plane_view(s.volume, plane)
        cx0, cy0 = planes.cursor_in(pv, s.zyx, s.shape)
        if self.zoom <= 1.0 or plane != s.plane:
            return (cx0, cy0)
        if self.pan_center is None:
            self.pan_center = (float(cx0), float(cy0))
        ny, nx = s.shape[pv.rows], s.shape[pv.cols]
        half_w, half_h = nx / self.zoom / 2.0, ny / self.zoom / 2.0
        cx, cy = self.pan_center
        moved = self.zoomed_at != s.zyx  # a zoom on the pointer put the cursor in view: leave the pan be
        if moved and (abs(cx0 - cx) > half_w * 0.9 or abs(cy0 - cy) > half_h * 0.9):  # keep the cursor visible
            cx, cy = float(cx0), float(cy0)
        self.pan_center = (min(max(cx, half_w), nx - half_w), min(max(cy, half_h), ny - half_h))
        return self.pan_center

    def pan_by(self, session, dx: float, dy: float) -> tuple[int, int]:
        """Move the pan centre by (dx, dy) quarters of the zoomed view; returns the step in
        pixels (x, y) the cursor moves along so that it stays visible."""
        s = session
        pv = planes.plane_view(s.volume, s.plane)
        ny, nx = s.shape[pv.rows], s.shape[pv.cols]
        cx, cy = self.pan_center or self.center(s, s.plane)
        step_x, step_y = nx / self.zoom / 4, ny / self.zoom / 4
        self.pan_center = (cx + dx * step_x, cy + dy * step_y)
        return int(round(dx * step_x)), int(round(dy * step_y))

    def pan_to(self, center: tuple[float, float] | None, *, cursor: tuple[int, int, int] | None = None) -> None:
        """The pan centre (x, y) image pixel, or None: centred on the cursor. ``cursor``: the
        cursor (z, y, x) this pan keeps in view (a zoom about it): not re-centred while it stays there."""
        self.pan_center = center
        self.zoomed_at = cursor

    def next_window(self, presets: list) -> tuple[str, tuple[float, float]]:
        """The preset after the last one chosen: (name, (centre, width))."""
        self.window_index = (self.window_index + 1) % len(presets)
        name, win = presets[self.window_index]
        self.window_name = name
        return name, (float(win[0]), float(win[1]))


class EditTools:
    """The edit tools between keys: the pen (brush or eraser down: moving paints), whether a
    click fills, the first corner of an ROI box being set and the scissors polygon. (The
    ROI box itself is ``Session.roi_box``: fills, segmentation and edits read it.)"""

    def __init__(self) -> None:
        self.pen: str | None = None  # "brush" / "eraser" while down
        self.pen_painted = False  # the pen has painted since it went down (the first move paints its start too)
        self.click_fills = False  # a left click on a view fills there (as Enter) instead of only moving the cursor
        self.box_corner: tuple[int, int, int] | None = None  # (z, y, x) first corner of a box being set
        self.polygon: list[tuple[int, int]] = []  # scissors polygon, (x, y) voxels on the file's slices
        self.polygon_mode = False  # clicks add polygon points (P starts it; Y clears box and polygon)
        self.box_drawn_on: int | None = None  # the one slice the ROI box was drawn on (it spans more: asked)
        self.enter_guard = False  # a save with no dialog just happened: the next key, if Enter, fills nothing
        self.doomed = None  # (z, y, x) bool: what an edit waiting for its confirmation would remove (drawn red)

    def toggle_pen(self, tool: str) -> bool:
        """``tool`` ("brush"/"eraser") down, or lifted when it was down; True when down."""
        self.pen = None if self.pen == tool else tool
        self.pen_painted = False
        return self.pen is not None

    def lift(self) -> bool:
        """Lift the pen; True when it was down."""
        down, self.pen = self.pen is not None, None
        return down

    def toggle_click_fills(self) -> bool:
        self.click_fills = not self.click_fills
        return self.click_fills

    def take_corner(self) -> tuple[int, int, int] | None:
        """The first corner of the box being set (None when none), which is then forgotten."""
        corner, self.box_corner = self.box_corner, None
        return corner

    def add_point(self, x: int, y: int) -> int:
        """A polygon point (voxel x, y); the first one starts a new polygon. Returns the count."""
        if not self.polygon_mode:
            self.polygon, self.polygon_mode = [], True
        self.polygon.append((int(x), int(y)))
        return len(self.polygon)

    def clear_shapes(self) -> None:
        """No box corner, no polygon."""
        self.box_corner = self.box_drawn_on = None
        self.polygon, self.polygon_mode = [], False


class Jobs:
    """The workspace's running work: at most one cancellable worker (the 3D cell, an
    export...) and one segmentation run (``screens.propagation.PropagationRun``)."""

    def __init__(self) -> None:
        self.worker = None
        self.segmentation = None

    def track(self, worker, *, replace: bool = False):
        """Make ``worker`` the running cancellable job (Escape cancels it; ``replace``: the
        one running is cancelled first); returns it."""
        if replace and self.worker is not None:
            self.worker.cancel()
        self.worker = worker
        return worker

    def worker_ended(self) -> None:
        self.worker = None

    def segmentation_started(self, run) -> None:
        self.segmentation = run

    def segmentation_ended(self) -> None:
        self.segmentation = None

    @property
    def segmenting(self) -> bool:
        """Whether a segmentation runs (it reads the labels: edits wait)."""
        return self.segmentation is not None

    def cancel(self) -> str | None:
        """Escape: cancel the segmentation, else the worker; returns which ("segmentation",
        "job") or None when nothing ran."""
        if self.segmentation is not None:
            self.segmentation.cancel()  # its worker ends with a SegmentationFailed("cancelled")
            return "segmentation"
        if self.worker is not None:
            self.worker.cancel()
            self.worker = None
            return "job"
        return None


class ProposalState:
    """The pending proposal (``engine.segment.propagate.Proposal``), the seed (x, y, z) and
    settings its object keeps when it is accepted, and its full-volume mask."""

    def __init__(self) -> None:
        self.proposal: Any = None  # a Proposal (engine.segment.proposal; the screens reach it through actions only)
        self.notes: list[str] = []
        self.seed: tuple[int, int, int] | None = None
        self.object_settings: dict = {}
        self._full: tuple[int, np.ndarray] | None = None  # (id of the proposal, its (z, y, x) mask)

    def show(self, proposal, *, seed: tuple[int, int, int] | None = None, object_settings: dict | None = None) -> None:
        """``proposal`` becomes the pending one (hatched on every plane until accepted or
        rejected); ``seed`` and ``object_settings`` go to its object when it is accepted."""
        self.proposal = proposal
        self.seed = seed
        self.object_settings = dict(object_settings or {})
        self.notes = []  # the run's warnings: shown in the side panel while it waits

    def replace(self, proposal) -> None:
        """A cut or shortened version of the pending proposal takes its place (same seed and settings)."""
        self.proposal = proposal

    def clear(self):
        """No pending proposal; returns the one there was (or None)."""
        p, self.proposal = self.proposal, None
        self.seed, self.object_settings, self.notes = None, {}, []
        self._full = None
        return p

    @property
    def object_id(self) -> int:
        return self.proposal.object_id if self.proposal is not None else 0

    def plane(self, pv: planes.PlaneView, index: int, shape: tuple[int, int, int]) -> np.ndarray | None:
        """The proposal's mask on plane ``pv`` at ``index`` (display orientation), or None."""
        p = self.proposal
        if p is None:
            return None
        if pv.normal == 0:  # the file's slice plane (axial for an axial acquisition)
            return planes.orient(p.slice_mask(index), pv)
        if self._full is None or self._full[0] != id(p):
            full = np.zeros(shape, bool)
            got = p.mask3d()
            if got is not None:
                (z0, y0, x0), m = got
                full[z0:z0 + m.shape[0], y0:y0 + m.shape[1], x0:x0 + m.shape[2]] = m
            self._full = (id(p), full)
        return planes.take(self._full[1], pv, index)

    def accept(self, seg) -> tuple[int, Any]:
        """Write the proposal into the segmentation ``seg`` (one undo step); a proposal from a
        seed registers its object with the seed and settings (as a fill does). Returns
        (voxels added, the proposal). No proposal: ValueError."""
        p = self.proposal
        if p is None:
            raise ValueError("no pending proposal")
        n = p.accept(seg)
        if self.seed is not None:  # from a seed: the object keeps it and its settings, as after a fill (Enter)
            seg.add_object(object_id=p.object_id)
            info = seg.objects[p.object_id]
            if self.seed not in [tuple(v) for v in info.seeds]:
                info.seeds.append(self.seed)
            info.settings.update(self.object_settings)
        self.clear()
        return n, p


def describe(session: Session) -> str:
    """One line of the current segmentation settings, for the side panel and messages."""
    o = session.segment_options
    neck = o.get("neck")
    rng = o.get("range", "given")
    rtxt = "auto" if rng == "auto" else ("T's, else auto" if rng == "given" else f"{rng[0]:g}:{rng[1]:g}")
    bg = len(session.background_seeds)
    return (f"{o.get('method', 'fill')} {session.prop_mode}, neck {'auto' if neck is None else f'{neck:g} mm'}, "
            f"range {rtxt}{', holes filled' if o.get('fill_holes', True) else ''}"
            + (f", {bg} background seed{'s' if bg != 1 else ''}" if bg else ""))


class SeedRange:
    """The range ``S`` would use at the cursor (``actions.segment.suggest_range``), computed
    in a thread once per cursor position and pipeline: the ``key`` last asked for and its
    ``result`` (None while it is computed)."""

    def __init__(self) -> None:
        self.key = None
        self.result = None
        self.painted = False  # the workspace has been painted once (the engine may load now)
        self.first_end: float | None = None  # a histogram bar clicked: one end of the range being picked

    def pick(self, bar: int | None) -> tuple[float, float] | None:
        """A click on the panel's histogram: ``bar`` None (the text) takes the seed range; a bar
        gives one end of the range, a second bar the other (returned then, ordered; None
        while waiting for it)."""
        rc = self.result
        if rc is None:
            return None
        width = float(rc.edges[1] - rc.edges[0]) if len(rc.edges) > 1 else 1.0
        # the ends to a tenth of a bar at most (10.7459..38.9153 -> 11..39): what the panel then says is readable
        nd = max(0, -int(np.floor(np.log10(width / 10)))) if width > 0 else 3

        def nice(a: float, b: float) -> tuple[float, float]:
            return float(round(a, nd)), float(round(b, nd))

        if bar is None or not 0 <= bar < len(rc.hist):
            self.first_end = None
            return nice(float(rc.low), float(rc.high))
        lo, hi = float(rc.edges[bar]), float(rc.edges[bar + 1])
        if self.first_end is None:
            self.first_end = lo
            return None
        first, self.first_end = self.first_end, None
        return nice(min(first, lo), max(first + (hi - lo), hi))

    def wants(self, key) -> bool:
        """True when ``key`` is new (its range is to be computed; the old one is forgotten)."""
        if key == self.key:
            return False
        self.key, self.result = key, None
        return True

    def store(self, key, result) -> bool:
        """The range computed for ``key``; False (dropped) when the cursor moved on meanwhile."""
        if key != self.key:
            return False
        self.result = result
        return True


class ObjectVolumes:
    """The labels' version (one more per edit) and each object's volume, counted once per version.

    After edits made through the Segmentation (brush, erase, undo, redo: its ``changes_since``
    journal), the counts are updated from the voxels those edits changed, not recounted over the
    whole label volume (166 ms per side-panel update at 1,000 x 512 x 512); any other change of
    the labels (more versions than journalled changes, another label array) recounts them."""

    def __init__(self) -> None:
        self.version = 0
        self._cache: tuple[int, dict[int, float]] | None = None
        self._counts: tuple | None = None  # version, seg and labels (weak references), revision, counts

    def changed(self) -> None:
        self.version += 1

    def counts(self, seg) -> np.ndarray:
        """int64 (256,): voxels per label value of ``seg.labels`` at this version."""
        c = self._counts
        rev = int(getattr(seg, "revision", -1))
        if c is not None and c[1]() is seg and c[2]() is seg.labels:
            since = seg.changes_since(c[3]) if hasattr(seg, "changes_since") and rev >= 0 else None
            # each journalled change is one version at most: more versions mean a write outside it
            if since is not None and self.version - c[0] <= rev - c[3]:
                counts = c[4] + since[0]
                self._counts = (self.version, c[1], c[2], rev, counts)
                return counts
        counts = label_counts(seg.labels)
        self._counts = (self.version, weakref.ref(seg), weakref.ref(seg.labels), rev, counts)
        return counts

    def of(self, session) -> dict[int, float]:
        """Volume (ml) per object id of ``session``'s labels; recounted only when they changed."""
        if self._cache is not None and self._cache[0] == self.version:
            return self._cache[1]
        counts = self.counts(session.seg)
        vox_ml = session.volume.voxel_volume_mm3() / 1000.0
        vols = {i: float(counts[i]) * vox_ml for i in range(1, len(counts)) if counts[i]}
        self._cache = (self.version, vols)
        return vols


def mm(v: float | None) -> str:
    """A length for people: one decimal, none when whole (3.22266 -> "3.2", 3.0 -> "3"); None: "0"."""
    return f"{float(v or 0.0):.1f}".removesuffix(".0")


def value_unit(s: Session) -> str:
    """The unit of the values a range or tolerance is in: HU on CT, the signal on MR and
    other modalities, 0..255 after a pipeline that leaves the HU domain."""
    if s.pipeline is not None and s.pipeline.domain != "hu":
        return "(0..255)"
    return "HU" if s.volume.modality == "CT" else "(signal)"
