"""Segmentation methods: one function per method, chosen by name from :data:`METHODS`.

Every method takes a :class:`Job` (the volume, pipeline, segmentation, the object id, its
seed, the seed slice's object and the leak guard's choice, background seeds, propagation
settings) and writes the object into the :class:`Segmentation` as undo steps, filling the
job's report fields (stops, necks, cuts, warnings). The ``segment`` action
(:mod:`ctui.engine.actions.segment`) validates the input, builds the job and calls
``METHODS[name].run(job)``; ``ctui segment --method``, the batch manifest's ``method`` and
the TUI's segmentation panel list :data:`METHODS`. Adding a method is one function and one
:func:`register` call.

* ``fill``: the seed slice's object propagated slice by slice (or in 3D) with the leak
  guard (:mod:`ctui.engine.segment.propagate`); with background seeds the object is then
  split at its narrowest place between the seed and the background seeds it reached.
* ``grow``: the guarded fill, then shared with the background seeds by a marker watershed
  on the smoothed intensity gradient, so the boundary between the object and a
  neighbour of the same range runs along the edge between them (Slicer's "Grow from
  seeds" and the random walker weigh each step by the intensity difference too), not
  half-way between the seeds; with the leak guard off, the competition runs on the whole
  in-range region.
* ``levelset``: the fill refined by a threshold level set with a curvature term.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.core.limits import check_allocation
from ctui.engine.core.progress import Cancelled, Progress, report
from ctui.engine.segment import grow as _grow
from ctui.engine.segment.fill3d import fill3d_seeds
from ctui.engine.segment import nninteractive as _nninteractive
from ctui.engine.segment.propagate import PropagationSettings, propagate_object
from ctui.engine.segment.selection import Segmentation, in_range


@dataclass
class Job:
    """One object to segment. Seeds are (x, y, z); ``start`` is the seed slice's bool (ny, nx) object;
    ``region`` the automatic leak guard's allowed region (autoneck.Region) or None."""

    volume: Any
    pipe: Any
    seg: Segmentation
    oid: int
    seed: tuple[int, int, int]
    start: np.ndarray
    settings: PropagationSettings
    background: list[tuple[int, int, int]] = field(default_factory=list)
    region: Any = None
    curvature: float = 0.5
    progress: Progress | None = None
    stops: dict[str, str] = field(default_factory=dict)
    necks: list[int] = field(default_factory=list)
    cuts: list[dict[str, Any]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    neck_status: str = ""

    @property
    def spacing(self) -> tuple[float, float, float]:
        return tuple(float(v) for v in self.volume.spacing)  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


@dataclass(frozen=True)
class Method:
    """A registered method: its name, the function that runs it, one line of help, and the options it reads."""

    name: str
    run: Callable[[Job], None]
    help: str
    options: tuple[str, ...] = ()


METHODS: dict[str, Method] = {}


BG_LEAST = 0.01  # a competition that gives the background seeds less than this share of the region gave them nothing


def register(name: str, run: Callable[[Job], None], help: str, options: tuple[str, ...] = ()) -> Method:
    """Add a method to :data:`METHODS` (the CLI's --method choices, the batch manifest and the TUI's panel)."""
    m = Method(name, run, help, tuple(options))
    METHODS[name] = m
    return m


def fill(job: Job) -> None:
    """The guarded fill: the seed slice's object, propagated; split at the background seeds it reached."""
    _propagate(job, share=1.0)
    if job.background:
        split_background(job)


def grow(job: Job) -> None:
    """The guarded fill shared with the background seeds at the intensity edges (see the module docstring)."""
    if job.settings.neck_mm > 0:
        _propagate(job, share=0.6)
        box = job.seg.object_bbox(job.oid)
        if box is None:
            return
        region = job.seg.labels[box] == job.oid
    else:
        got = _inrange_candidate(job)
        if got is None:
            return
        box, region = got
    job.stops.setdefault("grow", "in-range region")
    org = np.array([b.start for b in box])
    bg = _grow.inside_seeds(np.array([[b[2], b[1], b[0]] for b in job.background], np.int64).reshape(-1, 3) - org,
                            region.shape)
    bg = bg[region[tuple(bg.T)]] if len(bg) else bg
    unreached(job, box, region)
    x, y, z = job.seed
    if len(bg):
        report(job.progress, 0.8, 1.0, "edges between the seeds")
        image = _values(job, box)
        fg = _seed_ball(region, (z, y, x), org)
        share = _grow.compete_edges(image, region, fg, bg, spacing=job.spacing)
        job.stops["grow"] = "shared with the background seeds along the intensity edges"
        if np.count_nonzero(region) - np.count_nonzero(share) < BG_LEAST * np.count_nonzero(region):
            # the edges gave the background seeds (almost) nothing (a seed on a local edge, swamped by the
            # object's front): cut at the narrowest place between them instead, as ``fill`` does, so a
            # background seed always acts (the stomach's leak, one click: 0.28 -> 0.28 by edges)
            share = _grow.compete(region, fg, bg, spacing=job.spacing, connectivity=job.settings.connectivity)
            job.stops["grow"] = "cut at the narrowest place between the seeds (the edges gave the background nothing)"
    else:
        share = fill3d_seeds(region, np.array([[z, y, x]]) - org, connectivity=job.settings.connectivity)
    job.seg.apply_mask(share, job.oid, offset=tuple(int(v) for v in org), mode="replace",  # type: ignore[arg-type]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
                       overwrite=job.settings.overwrite, label=f"grow object {job.oid} from ({x}, {y}, {z})")


def levelset(job: Job) -> None:
    """The guarded fill refined by a threshold level set with a curvature term."""
    _propagate(job, share=0.5)
    if job.background:
        split_background(job)
    report(job.progress, 1, 2, "level set")
    _levelset_object(job)


register("fill", fill, "threshold fill + propagation with the leak guard (the neck width found from the data)")
register("grow", grow, "the guarded fill shared with the background seeds along the intensity edges",
         options=("background",))
register("levelset", levelset, "the fill refined by a threshold level set with a curvature term",
         options=("curvature",))
register("nninteractive", _nninteractive.run_job, "nnInteractive on a server (pip install 'ctui[ai]'): seeds are "
         "positive points, background seeds negative, the box a box prompt; refines the current object",
         options=("prompts", "server"))


def _propagate(job: Job, *, share: float) -> None:
    x, y, z = job.seed
    s = job.settings
    job.seg.apply_mask(job.start, job.oid, offset=(z, 0, 0), overwrite=s.overwrite,
                       label=f"fill object {job.oid} at ({x}, {y}, {z})")

    def cb(ev: Any) -> bool:
        try:
            report(job.progress, ev.done * share, max(ev.total, 1), f"slice {ev.z}")
        except Cancelled:
            return False
        return True

    prop = propagate_object(job.seg, job.volume, job.pipe, job.oid, z, s,
                            progress=cb if job.progress is not None else None, region=job.region)
    if prop.cancelled:
        job.seg.undo()
        raise Cancelled()
    prop.accept(job.seg)
    job.stops.update(prop.stops)
    job.necks.extend(prop.necks)
    job.cuts.extend(prop.cuts)
    job.warnings.extend(prop.warnings())
    job.neck_status = str(prop.settings.get("neck_status", ""))


def _seed_ball(region: np.ndarray, seed_zyx: tuple[int, int, int], org: np.ndarray) -> np.ndarray:
    z, y, x = (int(a) - int(b) for a, b in zip(seed_zyx, org))
    box = (slice(max(z - 1, 0), z + 2), slice(max(y - 1, 0), y + 2), slice(max(x - 1, 0), x + 2))
    pts = np.argwhere(region[box]) + np.array([b.start for b in box])
    return pts if len(pts) else np.array([[z, y, x]])


def _values(job: Job, box: tuple[slice, slice, slice]) -> np.ndarray:
    """The pipeline's final values in ``box`` (float32, (nz, ny, nx))."""
    shape = tuple(b.stop - b.start for b in box)
    check_allocation(int(np.prod(shape)) * 4, what="the values of the object's box")
    window = job.pipe.window_for(job.volume)
    out = np.empty(shape, np.float32)
    for k, z in enumerate(range(box[0].start, box[0].stop)):
        out[k] = job.pipe.final_region(job.volume, z, box[1].start, box[1].stop, box[2].start, box[2].stop,
                                       window=window)
    return out


def _inrange_candidate(job: Job) -> tuple[tuple[slice, slice, slice], np.ndarray] | None:
    s = job.settings
    inr = inrange_volume(job.volume, job.pipe, s.low, s.high, slices=s.slices,
                         labels=None if s.overwrite else job.seg.labels, object_id=job.oid)
    x, y, z = job.seed
    seeds = np.array([[z, y, x]] + [[b[2], b[1], b[0]] for b in job.background], np.int64)
    got = _grow.candidate(inr, seeds, job.spacing, s.connectivity)
    del inr
    return got


def inrange_volume(volume: Any, pipe: Any, low: float, high: float, *, slices: tuple[int, int] | None = None,
                   labels: np.ndarray | None = None, object_id: int = 0,
                   progress: Progress | None = None) -> np.ndarray:
    """bool (nz, ny, nx): the pipeline's final view in [low, high], slice by slice (1 byte a voxel);
    voxels of other objects in ``labels`` and slices outside ``slices`` are False."""
    nz, ny, nx = volume.data.shape
    check_allocation(nz * ny * nx, what="the in-range mask")
    out = np.zeros((nz, ny, nx), bool)
    z0, z1 = (0, nz - 1) if slices is None else (max(slices[0], 0), min(slices[1], nz - 1))
    window = pipe.window_for(volume)
    for z in range(z0, z1 + 1):
        img = pipe.prepare(volume.data[z], window) if not pipe.active_steps() else pipe.final_region(
            volume, z, 0, ny, 0, nx, window=window)
        out[z] = in_range(img, low, high).view(bool)
        if labels is not None:
            lab = labels[z]
            if lab.any():
                out[z] &= (lab == 0) | (lab == object_id)
        if z % 16 == 0:
            report(progress, z - z0, z1 - z0 + 1, f"threshold slice {z}")
    return out


def unreached(job: Job, box: tuple[slice, ...], region: np.ndarray) -> None:
    """A warning for each background seed in range that the object's region (bool, on ``box``) does not
    hold: it separates nothing, since the object does not run there. (One out of range has its own note
    from the ``segment`` action.)"""
    s = job.settings
    for b in job.background:
        p = (b[2], b[1], b[0])
        if not s.low <= float(job.pipe.final_slice(job.volume, b[2])[b[1], b[0]]) <= s.high:
            continue
        if not (all(box[k].start <= v < box[k].stop for k, v in enumerate(p))
                and region[tuple(v - box[k].start for k, v in enumerate(p))]):
            job.warnings.append(f"background seed {b[0]},{b[1]},{b[2]}: the object does not reach it, so it "
                                "changes nothing; place background seeds in the neighbours the object runs into")


def split_background(job: Job) -> None:
    """Cut the object at its narrowest place between the seed and the background seeds it reached."""
    seg, oid = job.seg, job.oid
    box = seg.object_bbox(oid)
    if box is None:
        return
    origin = np.array([b.start for b in box])
    region = seg.labels[box] == oid
    inside = [b for b in job.background if all(box[k].start <= v < box[k].stop for k, v in enumerate((b[2], b[1], b[0])))
              and region[tuple(np.array([b[2], b[1], b[0]]) - origin)]]
    unreached(job, box, region)
    if not inside:
        return
    x, y, z = job.seed
    fgz = np.array([[z, y, x]]) - origin
    bgz = np.array([[b[2], b[1], b[0]] for b in inside]) - origin
    share = _grow.compete(region, fgz, bgz, spacing=job.spacing, connectivity=job.settings.connectivity)
    seg.apply_mask(region & ~share, oid, offset=tuple(int(v) for v in origin), mode="subtract",  # type: ignore[arg-type]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
                   label=f"cut object {oid} at the background seeds")


def _levelset_object(job: Job) -> None:
    seg, oid, s, spacing = job.seg, job.oid, job.settings, job.spacing
    box = seg.object_bbox(oid)
    if box is None:
        return
    margin = [max(1, int(np.ceil(4.0 / sp))) for sp in spacing]
    nz, ny, nx = seg.labels.shape
    big = tuple(slice(max(b.start - m, 0), min(b.stop + m, n)) for b, m, n in zip(box, margin, (nz, ny, nx)))
    origin = np.array([b.start for b in big])
    check_allocation(int(np.prod([b.stop - b.start for b in big])) * 20, what="the level set of the object's box")
    if not job.pipe.active_steps() and job.pipe.domain == "hu":
        image = job.volume.data[big]  # the series values themselves: a view, no copy
    else:
        image = _values(job, big)  # type: ignore[arg-type]  # big: the box's slices, tuple() of a generator: mypy sees any length, the length is fixed by construction
    init = seg.labels[big] == oid
    if (init.sum(axis=(1, 2)) > 0).sum() < 3:
        return  # the level set needs a body at least 3 slices thick
    bgz = np.array([[b[2], b[1], b[0]] for b in job.background]).reshape(-1, 3) - origin
    off, m = _grow.levelset(image, init, low=s.low, high=s.high, spacing=spacing, background=bgz,
                            curvature=job.curvature, margin_mm=4.0, connectivity=s.connectivity)
    full = np.zeros(init.shape, bool)
    full[off[0]:off[0] + m.shape[0], off[1]:off[1] + m.shape[1], off[2]:off[2] + m.shape[2]] = m
    if s.slices is not None:
        zs = np.arange(big[0].start, big[0].stop)
        full[(zs < s.slices[0]) | (zs > s.slices[1])] = init[(zs < s.slices[0]) | (zs > s.slices[1])]
    seg.apply_mask(full, oid, offset=tuple(int(v) for v in origin), mode="replace", axis=0,  # type: ignore[arg-type]  # tuple() of a generator: mypy sees any length, the length is fixed by construction
                   overwrite=s.overwrite, label=f"level set of object {oid}")
