"""The segment action: seeds (and background seeds) + an HU range -> objects, as ``ctui segment`` and the TUI do it.

:func:`segment` validates every seed first (a seed off the volume, out of its range, or
a background seed inside a foreground seed's own region raises one-line
:class:`CtuiError` before anything is written: nothing is lost), then for each
foreground seed, in order (object ids 1, 2, ...):

* ``method="fill"`` (default): threshold fill of the seed slice, cut at necks narrower
  than ``neck_mm`` (:mod:`ctui.engine.segment.necks`), propagated slice by slice or in
  3D (``mode``) with the neck-cutting leak guard; with background seeds the object is
  then split at its narrowest place between the seed and any background seed it
  reached (:func:`ctui.engine.segment.grow.compete`);
* ``method="grow"``: competitive region growing inside the range from the seed and the
  background seeds (:func:`ctui.engine.segment.grow.grow`);
* ``method="levelset"``: the fill above, then a threshold level set with a curvature
  term (:func:`ctui.engine.segment.grow.levelset`), cut to the foreground's share when
  background seeds are given.

Then ``keep_largest`` / ``min_island`` clean-ups, and ``interpolate`` fills the empty
slices between key slices. Each object is one or a few undo steps of the
:class:`Segmentation`. Slices are numbered from 0 (the lowest along the slice normal),
in the CLI and the TUI alike. Coordinates: seeds are (x, y, z) = (column, row, slice).

Memory: the fill works on crops; 3D mode, ``grow`` and ``levelset`` hold one bool
in-range volume (1 byte a voxel) plus crop-sized work arrays, checked against the
memory available before they are allocated.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.core.limits import check_allocation
from ctui.engine.core.progress import Cancelled, Progress, report
from ctui.engine.segment import grow as _grow
from ctui.engine.segment.fill3d import fill3d_seeds
from ctui.engine.segment.necks import DEFAULT_NECK_MM, cut_necks_3d
from ctui.engine.segment.pipeline import Pipeline
from ctui.engine.core.geometry import Geometry
from ctui.engine.segment.autoneck import NeckChoice, cut_2d
from ctui.engine.segment.propagate import PropagationSettings, propagate_object
from ctui.engine.segment.seeding import RangeChoice, auto_width, seed_range, seed_voxels
from ctui.engine.segment.selection import (
    Segmentation,
    fill_range,
    in_range,
    label_counts,
    neck_fill,
    seeded_components,
)

METHODS = ("fill", "grow", "levelset")
Seed = tuple[int, int, int]
#: A range (low, high), a tolerance (seed value +- t), or None: from the seed's neighbourhood.
Threshold = tuple[float, float] | float | None
#: A box of inclusive voxel ranges ((z0, z1), (y0, y1), (x0, x1)).
Box = tuple[tuple[int, int], tuple[int, int], tuple[int, int]]


@dataclass
class SegmentOptions:
    """How to segment (keyword defaults = the CLI's defaults)."""

    method: str = "fill"
    mode: str = "slice"
    direction: str = "both"
    connectivity: int = 8
    neighbourhood: int = 2
    min_area: int = 5
    leak_factor: float | None = 2.5
    neck_mm: float | None = None  # None: chosen from the data (autoneck); a number forces it; 0: off
    fill_holes: bool = True  # holes enclosed in each slice of the object are part of it (renal sinus, vessels)
    box: Box | None = None  # fills, propagation and growing stay inside this box
    slices: tuple[int, int] | None = None
    keep_largest: bool = False
    min_island: int = 0
    interpolate: bool = False
    curvature: float = 0.5  # level set: mm; smooths corners sharper than this, blocks necks under ~2x
    overwrite: bool = False

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise CtuiError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        if self.leak_factor is not None and self.leak_factor <= 1:
            raise CtuiError("the leak factor must be > 1")
        if self.neighbourhood < 0 or self.min_area < 1:
            raise CtuiError("the neighbourhood must be >= 0 and the minimum area >= 1")
        if self.neck_mm is not None and (not np.isfinite(self.neck_mm) or not 0 <= self.neck_mm <= 1000):
            raise CtuiError("the neck width must be a number of mm between 0 and 1000, or automatic")
        if self.box is not None:
            self.box = tuple((int(a), int(b)) for a, b in self.box)  # type: ignore[assignment]
            if any(a > b for a, b in self.box):
                raise CtuiError("the box is empty: each of its ranges needs first <= last")
        if self.min_island < 0:
            raise CtuiError("the minimum island size must be >= 0")
        if self.curvature < 0:
            raise CtuiError("the curvature weight must be >= 0 mm")


@dataclass
class ObjectResult:
    """One object: id, seed (x, y, z), range, voxels, volume (mL), slices [first, last], warnings."""

    id: int
    seed: Seed
    range: tuple[float, float]
    voxels: int = 0
    volume_ml: float = 0.0
    slices: tuple[int, int] | None = None
    stops: dict[str, str] = field(default_factory=dict)
    necks: list[int] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    neck: dict[str, Any] = field(default_factory=dict)  # {"mode": "auto" | "fixed" | "off", "width_mm", "reason", ...}
    auto_range: dict[str, Any] | None = None  # the seed's neighbourhood statistics when the range was automatic
    cuts: list[dict[str, Any]] = field(default_factory=list)  # {"slice", "voxels", "mm": [x, y, z] patient LPS}

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "voxels": self.voxels, "volume_ml": round(self.volume_ml, 4),
                "slices": None if self.slices is None else list(self.slices), "warnings": list(self.warnings),
                "seed": list(self.seed), "range": [round(float(v), 3) for v in self.range],
                "range_source": "auto" if self.auto_range is not None else "given", "auto_range": self.auto_range,
                "stops": dict(self.stops), "neck": dict(self.neck), "cuts": list(self.cuts),
                "neck_cut_slices": list(self.necks)}

    def message(self) -> str:
        """One line for the TUI's message bar and the CLI: what was made and how the leak guard chose."""
        rng = f"{self.range[0]:.0f}..{self.range[1]:.0f}" + (" (auto)" if self.auto_range is not None else "")
        sl = "" if self.slices is None else f", slices {self.slices[0]}..{self.slices[1]}"
        neck = self.neck.get("mode", "off")
        guard = (f"neck {self.neck.get('width_mm', 0):g} mm ({neck})" if self.neck.get("width_mm") else f"no neck cut ({neck})")
        where = ""
        if self.cuts:
            zs = sorted({c["slice"] for c in self.cuts})
            where = f", cut at slice{'s' if len(zs) > 1 else ''} " + ",".join(map(str, zs[:6])) + ("..." if len(zs) > 6 else "")
        return f"object {self.id}: {self.volume_ml:.1f} mL{sl}, range {rng}, {guard}{where}"


@dataclass
class SegmentResult:
    """What :func:`segment` made: the segmentation (labels + objects, undoable), the
    pipeline, per-object propagation settings (dicts, for projects) and reports."""

    segmentation: Segmentation
    pipeline: Pipeline
    settings: list[dict[str, Any]]
    objects: list[ObjectResult]
    method: str = "fill"

    def to_dict(self) -> dict[str, Any]:
        return {"method": self.method, "pipeline": self.pipeline.to_dict(), "objects": [o.to_dict() for o in self.objects]}


def _check_seed(seed: Sequence[int], shape: tuple[int, ...], what: str) -> Seed:
    x, y, z = (int(v) for v in seed)
    nz, ny, nx = shape
    if not (0 <= x < nx and 0 <= y < ny and 0 <= z < nz):
        raise CtuiError(f"{what} {x},{y},{z} is outside the volume (x 0..{nx - 1}, y 0..{ny - 1}, "
                        f"slices 0..{nz - 1}, numbered from 0)")
    return x, y, z


def _ranges(thresholds: Sequence[Threshold], n: int) -> list[Threshold]:
    th = list(thresholds)
    if not th:
        th = [None]
    if len(th) == 1:
        th = th * n
    if len(th) != n:
        raise CtuiError(f"{n} seeds but {len(th)} ranges/tolerances: give one for all or one per seed")
    return th


@dataclass
class _Start:
    """The seed slice's object and what was chosen for it before anything is written."""

    mask: np.ndarray  # bool (ny, nx)
    rng: tuple[float, float]
    auto_range: RangeChoice | None
    neck: NeckChoice | None  # the automatic choice; None when the width was given
    width: float  # mm; 0: no neck cut


def _limit(opts: SegmentOptions, shape: tuple[int, ...]) -> tuple[slice, slice, slice] | None:
    if opts.box is None:
        return None
    return tuple(slice(max(a, 0), min(b, n - 1) + 1) for (a, b), n in zip(opts.box, shape))  # type: ignore[return-value]


def _seed_fill(volume: Any, pipe: Pipeline, seg: Segmentation, oid: int, seed: Seed, th: Threshold,
               opts: SegmentOptions) -> _Start:
    """The seed slice's object, the range and the neck width; raises CtuiError when the seed fails."""
    x, y, z = seed
    spacing_yx = (float(volume.spacing[1]), float(volume.spacing[2]))
    final = pipe.final_slice(volume, z)
    box = _limit(opts, volume.data.shape)
    if box is not None and not all(b.start <= c < b.stop for b, c in zip(box, (z, y, x))):
        raise CtuiError(f"seed {x},{y},{z} is outside the box {_box_text(opts.box)}")
    auto = None
    if th is None:
        auto = seed_range(volume, pipe, seed)
        lo, hi = auto.low, auto.high
    elif isinstance(th, tuple):
        lo, hi = fill_range(0.0, low=th[0], high=th[1])
    else:
        lo, hi = fill_range(float(final[y, x]), tolerance=float(th))
    value = float(final[y, x])
    if not lo <= value <= hi:
        raise CtuiError(f"seed {x},{y},{z}: its value {value:g} (the value fills use{', after the filters' if pipe.active_steps() else ''}) "
                        f"is outside the range [{lo:g}, {hi:g}]")
    labels = None if opts.overwrite else seg.labels
    if opts.neck_mm is None:
        choice = auto_width(volume, pipe, seed, lo, hi, labels=labels, object_id=oid, limit=box)
        width = choice.width_mm
        inr = in_range(final, lo, hi).view(bool)
        if labels is not None:
            inr &= (labels[z] == 0) | (labels[z] == oid)
        if box is not None:
            inr = inr & _box_mask2d(box, inr.shape)
        pts = seed_voxels(inr[None], (0, y, x))[:, 1:]
        start = np.zeros(inr.shape, bool)
        start[tuple(pts.T)] = True
        comp = seeded_components(inr, start, connectivity=opts.connectivity)
        mask, _st = cut_2d(comp, start, width_mm=width, spacing_yx=spacing_yx, fill_holes=opts.fill_holes,
                           connectivity=opts.connectivity)
    else:
        choice, width = None, float(opts.neck_mm)
        mask = neck_fill(final, x, y, low=lo, high=hi, connectivity=opts.connectivity, neck_mm=width,
                         spacing_yx=spacing_yx)
        if box is not None:
            mask &= _box_mask2d(box, mask.shape)
    if not mask.any():
        raise CtuiError(f"seed {x},{y},{z}: nothing to fill in the range [{lo:g}, {hi:g}]")
    if int(mask.sum()) < opts.min_area:
        raise CtuiError(f"seed {x},{y},{z}: the fill of {int(mask.sum())} px is smaller than the minimum area "
                        f"{opts.min_area} px")
    return _Start(mask=mask, rng=(lo, hi), auto_range=auto, neck=choice, width=width)


def _box_mask2d(box: tuple[slice, slice, slice], shape: tuple[int, ...]) -> np.ndarray:
    m = np.zeros(shape, bool)
    m[box[1], box[2]] = True
    return m


def _box_text(box: Box | None) -> str:
    if box is None:
        return "(none)"
    (z0, z1), (y0, y1), (x0, x1) = box
    return f"x {x0}..{x1}, y {y0}..{y1}, slices {z0}..{z1}"


def segment(volume: Any, seeds: Sequence[Sequence[int]], thresholds: Sequence[Threshold], *,
            background: Sequence[Sequence[int]] = (), options: SegmentOptions | None = None,
            pipeline: Pipeline | None = None, segmentation: Segmentation | None = None,
            names: Sequence[str] | None = None, progress: Progress | None = None,
            object_ids: Sequence[int] | None = None) -> SegmentResult:
    """Segment one object per seed; see the module docstring.

    Parameters
    ----------
    volume : Volume (data (nz, ny, nx), spacing (dz, dy, dx) mm)
    seeds : foreground seeds (x, y, z), one object each (ids 1, 2, ... or the next free ids)
    thresholds : per seed (or one for all): (low, high) inclusive, or a tolerance t (seed value +- t),
        in the pipeline's domain (HU by default)
    background : background seeds (x, y, z), shared by every object
    options : :class:`SegmentOptions`
    pipeline : the filter pipeline (default: none, HU)
    segmentation : add to this Segmentation (the TUI's); default: a new one
    progress : ``progress(done, total, message)``; returning False cancels (raises Cancelled;
        the segmentation is left as it was before the cancelled object)
    object_ids : the ids to write (the TUI's current object); default the next free ids

    Returns :class:`SegmentResult`. Raises CtuiError on bad input, before any change.
    """
    opts = options or SegmentOptions()
    pipe = pipeline or Pipeline()
    shape = tuple(volume.data.shape)
    if not seeds:
        raise CtuiError("give at least one seed X,Y,Z")
    fg = [_check_seed(s, shape, "seed") for s in seeds]
    bg = [_check_seed(s, shape, "background seed") for s in background]
    ths = _ranges(thresholds, len(fg))
    seg = segmentation if segmentation is not None else Segmentation(shape)  # type: ignore[arg-type]
    free = [i for i in range(1, 11) if i not in seg.objects] if object_ids is None else [int(i) for i in object_ids]
    if len(fg) > len(free):
        raise CtuiError(f"at most 10 objects: {len(fg)} seeds but {len(free)} free object ids")
    spacing = tuple(float(v) for v in volume.spacing)
    fills = []
    for i, (seed, th) in enumerate(zip(fg, ths)):  # validate everything before the first change
        report(progress, 0, 1, f"seed {i + 1}: range and leak guard")
        fills.append(_seed_fill(volume, pipe, seg, free[i], seed, th, opts))
    notes = _check_background(volume, pipe, fg, bg, fills)
    results, settings = [], []
    for i, (seed, start) in enumerate(zip(fg, fills)):
        oid = free[i]
        sub = _scaled(progress, i, len(fg))
        if oid not in seg.objects:
            seg.add_object(names[i] if names and i < len(names) else f"object {oid}", object_id=oid)
        res, st = _one(volume, pipe, seg, oid, seed, start, bg, opts, sub)
        res.warnings[:0] = notes
        results.append(res)
        settings.append(st)
    counts = label_counts(seg.labels)
    vox_ml = float(np.prod(spacing)) / 1000.0
    geo = Geometry.of(volume)
    for r, start in zip(results, fills):
        r.voxels = int(counts[r.id])
        r.volume_ml = r.voxels * vox_ml
        r.slices = seg.slice_range(r.id)
        r.cuts = [{"slice": c["slice"], "voxels": c["voxels"],
                   "mm": [round(float(v), 1) for v in geo.index_to_mm((c["slice"], c["y"], c["x"]))]} for c in r.cuts]
        r.warnings.extend(_sanity(r, start, spacing, opts))
    empty = [r for r in results if r.voxels == 0]
    if empty:
        for r in empty:
            seg.remove_object(r.id)
        raise CtuiError(f"seed {','.join(map(str, empty[0].seed))}: the result is empty "
                        f"({'; '.join(empty[0].warnings) or 'nothing in range joins the seed'})")
    report(progress, 1, 1, "")
    return SegmentResult(segmentation=seg, pipeline=pipe, settings=settings, objects=results, method=opts.method)


def _scaled(progress: Progress | None, i: int, n: int) -> Progress | None:
    if progress is None:
        return None

    def sub(done: float, total: float, message: str = "") -> bool | None:
        frac = (done / total) if total else 1.0
        return progress((i + frac) / n, 1.0, f"object {i + 1}/{n}: {message}" if n > 1 else message)

    return sub


def _settings(opts: SegmentOptions, start: _Start, shape: tuple[int, ...]) -> PropagationSettings:
    slices = opts.slices
    if opts.box is not None:
        z0, z1 = opts.box[0]
        slices = (max(z0, slices[0]), min(z1, slices[1])) if slices is not None else (z0, z1)
        if slices[0] > slices[1]:
            raise CtuiError("the slice limits and the box's slices do not overlap")
    return PropagationSettings(low=start.rng[0], high=start.rng[1], direction=opts.direction,
                               connectivity=opts.connectivity, neighbourhood=opts.neighbourhood,
                               min_area=opts.min_area, leak_factor=opts.leak_factor, mode=opts.mode,
                               neck_mm=start.width, slices=slices, overwrite=opts.overwrite,
                               neck_rule="sweep" if opts.neck_mm is None else "opening", fill_holes=opts.fill_holes,
                               box=opts.box)


def _neck_report(opts: SegmentOptions, start: _Start) -> dict[str, Any]:
    if opts.neck_mm is None and start.neck is not None:
        return {"mode": "auto", "width_mm": round(start.width, 3), "reason": start.neck.reason,
                "sweep": start.neck.to_dict()}
    return {"mode": "fixed" if start.width > 0 else "off", "width_mm": round(start.width, 3)}


def _one(volume: Any, pipe: Pipeline, seg: Segmentation, oid: int, seed: Seed, start: _Start,
         bg: list[Seed], opts: SegmentOptions, progress: Progress | None) -> tuple[ObjectResult, dict[str, Any]]:
    x, y, z = seed
    res = ObjectResult(id=oid, seed=seed, range=start.rng, neck=_neck_report(opts, start),
                       auto_range=None if start.auto_range is None else start.auto_range.to_dict())
    s = _settings(opts, start, volume.data.shape)
    spacing = tuple(float(v) for v in volume.spacing)
    info = seg.objects[oid]
    info.seeds.append(seed)
    info.settings.update({"low": start.rng[0], "high": start.rng[1], "connectivity": opts.connectivity,
                          "method": opts.method, "neck": res.neck, "fill_holes": opts.fill_holes})
    if bg:
        info.settings["background"] = [list(b) for b in bg]
    if opts.method == "grow":
        _grow_object(volume, pipe, seg, oid, seed, bg, s, spacing, progress)  # type: ignore[arg-type]
        res.stops = {"grow": "competition with the background seeds at the edges" if bg else "in-range region"}
    else:
        seg.apply_mask(start.mask, oid, offset=(z, 0, 0), overwrite=opts.overwrite,
                       label=f"fill object {oid} at ({x}, {y}, {z})")

        def cb(ev: Any) -> bool:
            try:
                report(progress, ev.done, max(ev.total, 1) * (2 if opts.method == "levelset" else 1),
                       f"slice {ev.z}")
            except Cancelled:
                return False
            return True

        region = start.neck.region if start.neck is not None else None
        prop = propagate_object(seg, volume, pipe, oid, z, s, progress=cb if progress is not None else None,
                                region=region)
        if prop.cancelled:
            seg.undo()
            raise Cancelled()
        prop.accept(seg)
        res.stops, res.necks, res.cuts = dict(prop.stops), list(prop.necks), list(prop.cuts)
        res.warnings.extend(prop.warnings())
        if prop.settings.get("neck_status") == "thin" and start.width > 0:
            res.warnings.append(f"the neck width {start.width:g} mm is wider than the object around the seed, so "
                                "the leak guard cut nothing: use the automatic width or a smaller one")
        if bg:
            _split_background(seg, oid, seed, bg, spacing, opts.connectivity)  # type: ignore[arg-type]
        if opts.method == "levelset":
            report(progress, 1, 2, "level set")
            _levelset_object(volume, pipe, seg, oid, bg, s, opts, spacing)  # type: ignore[arg-type]
    _clean(seg, oid, opts, spacing)  # type: ignore[arg-type]
    info.settings["propagation"] = res.stops
    return res, s.to_dict()


def _check_background(volume: Any, pipe: Pipeline, fg: list[Seed], bg: list[Seed], fills: list[_Start]) -> list[str]:
    """Refuse a background seed inside a seed's own slice object; warn about one that cannot act."""
    notes = []
    for seed, start in zip(fg, fills):
        for b in bg:
            if b[2] == seed[2] and start.mask[b[1], b[0]]:
                raise CtuiError(f"background seed {b[0]},{b[1]},{b[2]} lies inside the region of seed "
                                f"{seed[0]},{seed[1]},{seed[2]} on its slice (same range, no neck between): "
                                "move it outside the object")
    lo = min(f.rng[0] for f in fills)
    hi = max(f.rng[1] for f in fills)
    for b in bg:
        v = float(pipe.final_slice(volume, b[2])[b[1], b[0]])
        if not lo <= v <= hi:
            notes.append(f"background seed {b[0]},{b[1]},{b[2]} (value {v:g}) is outside the range "
                         f"[{lo:g}, {hi:g}], so it cannot stop anything: place it in the neighbour the object leaks into")
    return notes


def _sanity(r: ObjectResult, start: _Start, spacing: tuple[float, ...], opts: SegmentOptions) -> list[str]:
    """Warnings for results that are probably wrong: collapsed, or many times what the seed suggests."""
    out = []
    seed_px = int(start.mask.sum())
    if 0 < r.voxels < max(27, seed_px // 4):
        out.append(f"the object collapsed to {r.voxels} voxels (its seed slice had {seed_px} px): widen the range, "
                   "move the seed deeper into the object, or check the background seeds")
    depth = start.neck.depth_mm if start.neck is not None else 0.0
    if depth > 0:
        ball_ml = 4.0 / 3.0 * np.pi * depth ** 3 / 1000.0
        if r.volume_ml > 25 * ball_ml:
            out.append(f"the object ({r.volume_ml:.0f} mL) is {r.volume_ml / ball_ml:.0f}x the ball that fits at the "
                       f"seed ({ball_ml:.1f} mL): it probably leaked into a neighbour; add background seeds there, "
                       "narrow the range, or draw a box")
    return out


def _clean(seg: Segmentation, oid: int, opts: SegmentOptions, spacing: tuple[float, float, float]) -> None:
    if opts.keep_largest:
        seg.keep_largest_island(oid)
    if opts.min_island:
        seg.remove_islands(oid, opts.min_island)
    if opts.interpolate:
        seg.fill_between_slices(oid, slices=opts.slices, spacing=spacing)


def inrange_volume(volume: Any, pipe: Pipeline, low: float, high: float, *, slices: tuple[int, int] | None = None,
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


def _grow_object(volume: Any, pipe: Pipeline, seg: Segmentation, oid: int, seed: Seed, bg: list[Seed],
                 s: PropagationSettings, spacing: tuple[float, float, float], progress: Progress | None) -> None:
    inr = inrange_volume(volume, pipe, s.low, s.high, slices=s.slices, labels=None if s.overwrite else seg.labels,
                         object_id=oid, progress=_grow_progress(progress, 0.0, 0.5))
    x, y, z = seed
    fg = np.array([[z, y, x]])
    bgz = np.array([[b[2], b[1], b[0]] for b in bg], np.int64).reshape(-1, 3)
    got = _grow.candidate(inr, np.concatenate([fg, bgz]), spacing, s.connectivity)
    del inr  # only the candidate's box from here on
    if got is None:
        return
    box, region = got
    org = np.array([b.start for b in box])
    report(progress, 0.6, 1.0, "competition" if bg else "necks")
    if bg:
        m = _grow.compete(region, fg - org, _grow.inside_seeds(bgz - org, region.shape), spacing=spacing,
                          connectivity=s.connectivity)
    else:  # nothing to compete with: cut the necks instead
        m = fill3d_seeds(region, fg - org, connectivity=s.connectivity)
        if s.neck_mm > 0:
            m, _status = cut_necks_3d(m, fg - org, neck_mm=s.neck_mm, spacing=spacing, connectivity=s.connectivity,
                                      inplace=True)
    del region
    off, m = _grow.tight(tuple(int(v) for v in org), m)  # type: ignore[arg-type]
    seg.apply_mask(m, oid, offset=off, overwrite=s.overwrite, label=f"grow object {oid} from ({x}, {y}, {z})")


def _grow_progress(progress: Progress | None, a: float, b: float) -> Progress | None:
    if progress is None:
        return None

    def sub(done: float, total: float, message: str = "") -> bool | None:
        return progress(a + (b - a) * (done / total if total else 1.0), 1.0, message)

    return sub


def _split_background(seg: Segmentation, oid: int, seed: Seed, bg: list[Seed], spacing: tuple[float, float, float],
                      connectivity: int) -> None:
    """Cut the object at its narrowest place between the seed and the background seeds it reached."""
    box = seg.object_bbox(oid)
    if box is None:
        return
    origin = np.array([b.start for b in box])
    region = seg.labels[box] == oid
    inside = [b for b in bg if all(box[k].start <= v < box[k].stop for k, v in enumerate((b[2], b[1], b[0])))
              and region[tuple(np.array([b[2], b[1], b[0]]) - origin)]]
    if not inside:
        return
    x, y, z = seed
    fgz = np.array([[z, y, x]]) - origin
    bgz = np.array([[b[2], b[1], b[0]] for b in inside]) - origin
    share = _grow.compete(region, fgz, bgz, spacing=spacing, connectivity=connectivity)
    seg.apply_mask(region & ~share, oid, offset=tuple(int(v) for v in origin), mode="subtract",  # type: ignore[arg-type]
                   label=f"cut object {oid} at the background seeds")


def _levelset_object(volume: Any, pipe: Pipeline, seg: Segmentation, oid: int, bg: list[Seed],
                     s: PropagationSettings, opts: SegmentOptions, spacing: tuple[float, float, float]) -> None:
    box = seg.object_bbox(oid)
    if box is None:
        return
    margin = [max(1, int(np.ceil(4.0 / sp))) for sp in spacing]
    nz, ny, nx = seg.labels.shape
    big = tuple(slice(max(b.start - m, 0), min(b.stop + m, n)) for b, m, n in zip(box, margin, (nz, ny, nx)))
    origin = np.array([b.start for b in big])
    window = pipe.window_for(volume)
    check_allocation(int(np.prod([b.stop - b.start for b in big])) * 20, what="the level set of the object's box")
    if not pipe.active_steps() and pipe.domain == "hu":
        image = volume.data[big]  # the series values themselves: a view, no copy
    else:
        image = np.empty(tuple(b.stop - b.start for b in big), np.float32)  # filled slice by slice: one copy
        for k, z in enumerate(range(big[0].start, big[0].stop)):
            image[k] = pipe.final_region(volume, z, big[1].start, big[1].stop, big[2].start, big[2].stop,
                                         window=window)
    init = seg.labels[big] == oid
    if (init.sum(axis=(1, 2)) > 0).sum() < 3:
        return  # the level set needs a body at least 3 slices thick
    bgz = np.array([[b[2], b[1], b[0]] for b in bg]).reshape(-1, 3) - origin
    off, m = _grow.levelset(image, init, low=s.low, high=s.high, spacing=spacing, background=bgz,
                            curvature=opts.curvature, margin_mm=4.0, connectivity=s.connectivity)
    full = np.zeros(init.shape, bool)
    full[off[0]:off[0] + m.shape[0], off[1]:off[1] + m.shape[1], off[2]:off[2] + m.shape[2]] = m
    if s.slices is not None:
        zs = np.arange(big[0].start, big[0].stop)
        full[(zs < s.slices[0]) | (zs > s.slices[1])] = init[(zs < s.slices[0]) | (zs > s.slices[1])]
    seg.apply_mask(full, oid, offset=tuple(int(v) for v in origin), mode="replace", axis=0,  # type: ignore[arg-type]
                   overwrite=s.overwrite, label=f"level set of object {oid}")


def edit_objects(segmentation: Segmentation, object_ids: Sequence[int] | None = None, *,
                 spacing: tuple[float, float, float] = (1.0, 1.0, 1.0), interpolate: bool = False,
                 keep_largest: bool = False, min_island: int = 0,
                 slices: tuple[int, int] | None = None) -> list[dict[str, Any]]:
    """Clean up existing objects (``ctui segment PROJECT.ctui --interpolate ...``; the TUI's keys).

    In order: keep the largest 3D island, remove islands under ``min_island`` voxels (so
    specks do not become key slices), then fill between slices (signed-distance
    interpolation across the empty slices between the object's slices, key slices
    limited to ``slices``). Each step is one undo step.
    Returns per object ``{id, voxels_before, voxels, added, removed}``.
    """
    counts = label_counts(segmentation.labels)
    present = [int(i) for i in np.flatnonzero(counts[1:]) + 1]
    ids = present if object_ids is None else [int(i) for i in object_ids]
    missing = [i for i in ids if i not in present]
    if missing:
        raise CtuiError(f"no object {', '.join(map(str, missing))} in the label volume (objects: "
                        f"{', '.join(map(str, present)) or 'none'})")
    out = []
    for oid in ids:
        before = int(counts[oid])
        removed = segmentation.keep_largest_island(oid) if keep_largest else 0
        removed += segmentation.remove_islands(oid, min_island) if min_island else 0
        added = segmentation.fill_between_slices(oid, slices=slices, spacing=spacing) if interpolate else 0
        out.append({"id": oid, "voxels_before": before, "voxels": segmentation.voxels(oid), "added": added,
                    "removed": removed})
    return out
