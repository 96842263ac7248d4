"""The segment action: seeds (and background seeds) + a range -> objects, as ``ctui segment`` and the TUI do it.

:func:`segment` validates every seed first (a seed off the volume or the box, out of its
range, or a background seed inside a foreground seed's own region raises one-line
:class:`CtuiError` before anything is written: nothing is lost). For each seed it then
decides, from the data, what the user did not give (:mod:`ctui.engine.segment.seeding`):

* the range, when none is given: the seed's neighbourhood, median +- 2 robust sd;
* the leak guard's neck width, unless ``neck_mm`` forces one: a sweep of widths on a box
  around the seed, keeping the widest result before the volume jumps
  (:mod:`ctui.engine.segment.autoneck`); the result says what it chose and where it cut;

and runs the method by name from the registry :data:`ctui.engine.segment.methods.METHODS`
(``fill`` default, ``grow``, ``levelset``), then the clean-ups (``keep_largest``,
``min_island``, ``interpolate``). Results that are probably wrong (collapsed, many times
the size the seed suggests, a guard that cut nothing, a background seed that cannot act)
carry warnings; an empty result raises. Each object is one or a few undo steps of the
:class:`Segmentation`. Slices are numbered from 0 (the lowest along the slice normal), in
the CLI and the TUI alike. Coordinates: seeds are (x, y, z) = (column, row, slice).

A method whose registry ``options`` hold ``"prompts"`` (``nninteractive``: a model on a server)
takes another path: no range and no seed fill; every seed is a positive point, every background
seed a negative one, the box a box prompt, for one object, refined from what the segmentation
already holds (:mod:`ctui.engine.segment.nninteractive`).

Memory: the fill works on crops and the sweep on a box of at most 300 mm; 3D mode and
``grow`` without the guard hold one bool in-range volume (1 byte a voxel) plus crop-sized
work arrays, checked against the memory available before they are allocated.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.actions.segment_start import SNAP_MM, box_mask2d, box_text, in_region, snap, sub_grid_neck
from ctui.engine.actions.segment_checks import (body_check, check_background, leak_check, mixed_check, own_measures, sanity,
                                               tissue_check, wrap_check)
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.progress import Progress, report
from ctui.engine.segment.pipeline import Pipeline
from ctui.engine.segment.autoneck import NeckChoice, cut_2d
from ctui.engine.segment import nninteractive
from ctui.engine.segment.methods import METHODS, Job
from ctui.engine.segment.propagate import PropagationSettings
from ctui.engine.segment.seeding import RangeChoice, auto_width, denoised, seed_depth, seed_range, seed_voxels
from ctui.engine.segment.selection import (
    Segmentation,
    fill_range,
    in_range,
    label_counts,
    neck_fill,
    seeded_components,
)

Seed = tuple[int, int, int]
#: A range (low, high), a tolerance (seed value +- t), or None: from the seed's neighbourhood.
Threshold = tuple[float, float] | float | None
#: A box of inclusive voxel ranges ((z0, z1), (y0, y1), (x0, x1)).
Box = tuple[tuple[int, int], tuple[int, int], tuple[int, int]]


@dataclass
class SegmentOptions:
    """How to segment (keyword defaults = the CLI's defaults)."""

    method: str = defaults.SEGMENT_METHOD
    mode: str = defaults.PROPAGATION_MODE
    direction: str = defaults.DIRECTION
    connectivity: int = defaults.CONNECTIVITY
    neighbourhood: int = defaults.NEIGHBOURHOOD
    min_area: int = defaults.MIN_AREA
    leak_factor: float | None = defaults.LEAK_FACTOR
    neck_mm: float | None = None  # None: chosen from the data (autoneck); a number forces it; 0: off
    fill_holes: bool = True  # holes enclosed in each slice of the object are part of it (renal sinus, vessels)
    box: Box | None = None  # fills, propagation and growing stay inside this box
    slices: tuple[int, int] | None = None
    keep_largest: bool = False
    min_island: int = defaults.MIN_ISLAND_VOXELS
    interpolate: bool = False
    curvature: float = defaults.LEVELSET_CURVATURE_MM  # level set: mm; smooths corners sharper than this, blocks necks under ~2x
    overwrite: bool = False
    server: str = ""  # nninteractive: the server's URL (else CTUI_NNI_SERVER); never saved
    api_key: str = field(default="", repr=False)  # nninteractive: the server's key (else CTUI_NNI_KEY); never saved

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
            (z0, z1), (y0, y1), (x0, x1) = self.box
            self.box = ((int(z0), int(z1)), (int(y0), int(y1)), (int(x0), int(x1)))
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
    denoise: str = ""  # what the fill ran on besides the pipeline: "median 3x3" on a noisy series
    shell_range: tuple[float, float] | None = None  # wrap_check's range holding the object and its brighter shell

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "voxels": self.voxels, "volume_ml": round(self.volume_ml, 4),
                "slices": None if self.slices is None else list(self.slices), "warnings": list(self.warnings),
                "seed": list(self.seed), "range": [round(float(v), 3) for v in self.range],
                "range_source": "auto" if self.auto_range is not None else "given", "auto_range": self.auto_range,
                "stops": dict(self.stops), "neck": dict(self.neck), "cuts": list(self.cuts),
                "neck_cut_slices": list(self.necks), "denoise": self.denoise}

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
        noise = (f", filled on a {self.denoise} (noise)" if self.denoise else "") + "".join(f", leak at slice {k['slice']}" for k in self.neck.get("leaks", [])[:3])
        return f"object {self.id}: {self.volume_ml:.1f} mL{sl}, range {rng}{noise}, {guard}{where}"


@dataclass
class PromptedResult(ObjectResult):
    """An object a model made from prompts (``nninteractive``): no range or leak guard; ``stops`` says what
    was sent and how the server answered."""

    def to_dict(self) -> dict[str, Any]:
        return super().to_dict() | {"range": None, "range_source": "model"}

    def message(self) -> str:
        sl = "" if self.slices is None else f", slices {self.slices[0]}..{self.slices[1]}"
        lic = f"; the server's model licence: {self.stops['licence']}" if self.stops.get("licence") else ""
        return f"object {self.id}: {self.volume_ml:.1f} mL{sl}, {self.stops.get('nninteractive', '')}{lic}"


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
    pipe: Pipeline  # what the fill thresholds: the user's pipeline, or a median of it on a noisy series
    denoise: str = ""  # what was added for noise ("median 3x3"), empty when nothing
    seed: Seed | None = None  # the voxel the fill starts from: the given seed, or its in-range neighbour
    moved: str = ""  # why the fill starts beside the given seed (a noise pixel outside the range)
    depth_mm: float = 0.0  # the region's half-thickness at the seed (the size check's ball)


def _limit(opts: SegmentOptions, shape: tuple[int, ...]) -> tuple[slice, slice, slice] | None:
    if opts.box is None:
        return None
    return tuple(slice(max(a, 0), min(b, n - 1) + 1) for (a, b), n in zip(opts.box, shape))  # type: ignore[return-value]  # tuple() of a generator: mypy sees any length, the length is fixed by construction


def _seed_fill(volume: Any, pipe: Pipeline, seg: Segmentation, oid: int, seed: Seed, th: Threshold,
               opts: SegmentOptions) -> _Start:
    """The seed slice's object, the range and the neck width; raises CtuiError when the seed fails."""
    x, y, z = seed
    spacing_yx = (float(volume.spacing[1]), float(volume.spacing[2]))
    final = pipe.final_slice(volume, z)
    box = _limit(opts, volume.data.shape)
    if box is not None and not all(b.start <= c < b.stop for b, c in zip(box, (z, y, x))):
        raise CtuiError(f"seed {x},{y},{z} is outside the box {box_text(opts.box)}")
    auto = None
    if th is None:
        auto = seed_range(volume, pipe, seed)
        lo, hi = auto.low, auto.high
    elif isinstance(th, tuple):
        lo, hi = fill_range(0.0, low=th[0], high=th[1])
    else:
        lo, hi = fill_range(float(final[y, x]), tolerance=float(th))
    smooth = denoised(volume, pipe, seed, lo, hi)
    if smooth is not None:
        pipe, final = smooth, smooth.final_slice(volume, z)
    value = float(final[y, x])
    moved = ""
    if not lo <= value <= hi:
        near = snap(final, x, y, lo, hi, spacing_yx)
        if near is None:
            how = (", after a 3x3 median for the noise" if smooth is not None
                   else ", after the filters" if pipe.active_steps() else "")
            raise CtuiError(f"seed {x},{y},{z}: its value {value:g} (the value fills use{how}) "
                            f"is outside the range [{lo:g}, {hi:g}], and so is most of what lies within "
                            f"{SNAP_MM:g} mm of it")
        moved = (f"seed {x},{y},{z}: its value {value:g} is outside the range [{lo:g}, {hi:g}] (noise: the "
                 f"median within {SNAP_MM:g} mm is {near[2]:g}), so the fill starts at {near[0]},{near[1]},{z}")
        x, y = near[0], near[1]
        seed = (x, y, z)
    labels = None if opts.overwrite else seg.labels
    if opts.neck_mm is None:
        choice = auto_width(volume, pipe, seed, lo, hi, labels=labels, object_id=oid, limit=box)
        if sub_grid_neck(choice, tuple(volume.spacing)):  # the region bounds the leak: no cut at full resolution
            choice.reason, choice.width_mm = f"bounded: {choice.reason}, under one sweep voxel (no cut)", 0.0
        width = choice.width_mm
        inr = in_range(final, lo, hi).view(bool)
        if labels is not None:
            inr &= (labels[z] == 0) | (labels[z] == oid)
        if box is not None:
            inr = inr & box_mask2d(box, inr.shape)
        pts = seed_voxels(inr[None], (0, y, x))[:, 1:]
        start = np.zeros(inr.shape, bool)
        start[tuple(pts.T)] = True
        comp = seeded_components(inr, start, connectivity=opts.connectivity)
        if choice.region is not None and (start & comp).any():
            comp = in_region(comp, start, choice.region, z, width, spacing_yx, opts.connectivity)
        mask, _st = cut_2d(comp, start, width_mm=width, spacing_yx=spacing_yx, fill_holes=opts.fill_holes,
                           connectivity=opts.connectivity)
    else:
        choice, width = None, float(opts.neck_mm)
        depth = seed_depth(volume, pipe, seed, lo, hi, labels=labels, object_id=oid)
        mask = neck_fill(final, x, y, low=lo, high=hi, connectivity=opts.connectivity, neck_mm=width,
                         spacing_yx=spacing_yx)
        if box is not None:
            mask &= box_mask2d(box, mask.shape)
    if not mask.any():
        raise CtuiError(f"seed {x},{y},{z}: nothing to fill in the range [{lo:g}, {hi:g}]")
    if int(mask.sum()) < opts.min_area:
        raise CtuiError(f"seed {x},{y},{z}: the fill of {int(mask.sum())} px is smaller than the minimum area "
                        f"{opts.min_area} px")
    return _Start(mask=mask, rng=(lo, hi), auto_range=auto, neck=choice, width=width, pipe=pipe,
                  denoise="median 3x3" if smooth is not None else "", seed=seed, moved=moved,
                  depth_mm=choice.depth_mm if choice is not None else depth)


SHELL_GROWTH = 3.0  # the object with its shell may be at most this many times the object alone


def segment(volume: Any, seeds: Sequence[Sequence[int]], thresholds: Sequence[Threshold], *,
            background: Sequence[Sequence[int]] = (), options: SegmentOptions | None = None,
            pipeline: Pipeline | None = None, segmentation: Segmentation | None = None,
            names: Sequence[str] | None = None, progress: Progress | None = None,
            object_ids: Sequence[int] | None = None) -> SegmentResult:
    """Segment one object per seed; see the module docstring and :func:`_segment`.

    One seed with the automatic range whose object is wrapped in a brighter shell (``wrap_check``: a kidney's
    medulla in its cortex, an arterial phase) is tried once more with the range that holds both; that result is
    kept when it carries no warning of its own (but the values' shift, which the shell makes) and is at most ``SHELL_GROWTH`` times the first (the shell was
    the rest of the organ, not a neighbour), else the first stays with its warning. With a range given, the result
    stays and the same trial only checks the warning: dropped when the range holding both runs into the tissue
    around (a dark compartment in brighter tissue, not half an organ)."""
    seg = segmentation if segmentation is not None else Segmentation(tuple(volume.data.shape))
    before = len(seg.undo_labels())
    known = set(seg.objects)
    res = _segment(volume, seeds, thresholds, background=background, options=options, pipeline=pipeline,
                   segmentation=seg, names=names, progress=progress, object_ids=object_ids)
    r = res.objects[0]
    if len(res.objects) != 1 or r.shell_range is None:
        return res
    trial = Segmentation(seg.labels.shape)
    trial.labels[:] = np.where(seg.labels == r.id, 0, seg.labels)
    try:
        got = _segment(volume, [r.seed], [r.shell_range], background=background, options=options, pipeline=pipeline,
                       segmentation=trial, object_ids=[r.id]).objects[0]
    except CtuiError:
        return res
    # its values centre above the seed's by design (the shell is brighter): that check alone does not count
    warned = [w for w in got.warnings if not w.startswith("the object's values")]
    if r.auto_range is None:  # a range the user gave stays; the warning stays only when the shell may be the organ's
        k = next(i for i, w in enumerate(r.warnings) if w.startswith("the object is wrapped"))
        if warned or got.voxels > SHELL_GROWTH * r.voxels:
            # the range holding both runs into the tissue around (the MR brain's lateral ventricles in white
            # matter, Dice 0.91 with 11:39): the object is a compartment of darker values, not half an organ
            del r.warnings[k]
        else:
            r.warnings[k] += f" (tried: {got.volume_ml:.0f} mL, {got.voxels / max(r.voxels, 1):.1f}x the object, no leak)"
        return res
    if warned or got.voxels > SHELL_GROWTH * r.voxels:
        k = next(i for i, w in enumerate(r.warnings) if w.startswith("the object is wrapped"))
        r.warnings[k] += (f" (tried: {got.volume_ml:.0f} mL, {got.voxels / max(r.voxels, 1):.1f}x the object, "
                          f"{'with warnings' if warned else 'too large'}: kept the first)")
        return res
    while len(seg.undo_labels()) > before:
        seg.undo()
    for oid in set(seg.objects) - known:
        seg.objects.pop(oid, None)
    out = _segment(volume, [r.seed], [r.shell_range], background=background, options=options, pipeline=pipeline,
                   segmentation=seg, names=names, progress=progress, object_ids=[r.id])
    o = out.objects[0]
    o.warnings = [w for w in o.warnings if not w.startswith("the object's values")]  # the shell's, by design
    o.auto_range = dict(r.auto_range)
    o.auto_range["why"] = (f"{r.auto_range.get('why', '')}; the object ({r.volume_ml:.0f} mL) was wrapped in brighter "
                           f"tissue of the same organ, so the range was widened to {o.range[0]:.0f}:{o.range[1]:.0f} "
                           f"to hold both ({o.volume_ml:.0f} mL, no leak)")
    o.auto_range["low"], o.auto_range["high"] = round(o.range[0], 3), round(o.range[1], 3)
    if o.id in seg.objects:
        seg.objects[o.id].settings["range_source"] = "auto"
    return out


def _segment(volume: Any, seeds: Sequence[Sequence[int]], thresholds: Sequence[Threshold], *,
             background: Sequence[Sequence[int]] = (), options: SegmentOptions | None = None,
             pipeline: Pipeline | None = None, segmentation: Segmentation | None = None,
             names: Sequence[str] | None = None, progress: Progress | None = None,
             object_ids: Sequence[int] | None = None) -> SegmentResult:
    """Segment one object per seed, one pass.

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
    if "prompts" in METHODS[opts.method].options:  # a model answers the prompts: no range, no seed fill
        return _prompted(volume, seeds, background, opts, pipe, segmentation, names, progress, object_ids)
    if not seeds:
        raise CtuiError("give at least one seed X,Y,Z")
    fg = [_check_seed(s, shape, "seed") for s in seeds]
    bg = [_check_seed(s, shape, "background seed") for s in background]
    ths = _ranges(thresholds, len(fg))
    seg = segmentation if segmentation is not None else Segmentation(shape)
    free = [i for i in range(1, 11) if i not in seg.objects] if object_ids is None else [int(i) for i in object_ids]
    if len(fg) > len(free):
        raise CtuiError(f"at most 10 objects: {len(fg)} seeds but {len(free)} free object ids")
    spacing = tuple(float(v) for v in volume.spacing)
    fills = []
    for i, (seed, th) in enumerate(zip(fg, ths)):  # validate everything before the first change
        report(progress, 0, 1, f"seed {i + 1}: range and leak guard")
        fills.append(_seed_fill(volume, pipe, seg, free[i], seed, th, opts))
    notes = check_background(volume, fg, bg, fills, same_region_ok=opts.method == "grow")
    results, settings = [], []
    for i, (seed, start) in enumerate(zip(fg, fills)):
        oid = free[i]
        sub = _scaled(progress, i, len(fg))
        if oid not in seg.objects:
            seg.add_object(names[i] if names and i < len(names) else f"object {oid}", object_id=oid)
        res, st = _one(volume, start.pipe, seg, oid, start.seed or seed, start, bg, opts, sub)
        res.warnings[:0] = notes + ([start.moved] if start.moved else [])
        results.append(res)
        settings.append(st)
    vox_ml = float(np.prod(spacing)) / 1000.0
    geo = Geometry.of(volume)
    for r, start in zip(results, fills):
        box = seg.object_bbox(r.id)  # one pass for the count and the slices (not a whole-volume histogram)
        r.voxels = 0 if box is None else int(np.count_nonzero(seg.labels[box] == r.id))
        r.volume_ml = r.voxels * vox_ml
        r.slices = None if box is None else (box[0].start, box[0].stop - 1)
        r.cuts = [{"slice": c["slice"], "voxels": c["voxels"],
                   "mm": [round(float(v), 1) for v in geo.index_to_mm((c["slice"], c["y"], c["x"]))]} for c in r.cuts]
        r.warnings.extend(sanity(r, start, spacing, opts, own=lambda o, b=box, st=start: own_measures(volume, seg, o, st, b, spacing)))
        r.warnings.extend(tissue_check(volume, seg, r, start, box))
        r.warnings.extend(wrap_check(volume, seg, r, start, box))
        r.warnings.extend(body_check(volume, seg, r, box) + leak_check(seg, r, start, box, spacing))
        r.warnings.extend(mixed_check(volume, seg, r, start, box))
        info = seg.objects.get(r.id)
        if info is not None:  # what the guard chose and where it cut goes into the project with the object
            info.settings["cuts"] = [dict(c) for c in r.cuts[:50]]
            info.settings["range_source"] = "auto" if r.auto_range is not None else "given"
    empty = [r for r in results if r.voxels == 0]
    if empty:
        for r in empty:
            seg.remove_object(r.id)
        raise CtuiError(f"seed {','.join(map(str, empty[0].seed))}: the result is empty "
                        f"({'; '.join(empty[0].warnings) or 'nothing in range joins the seed'})")
    report(progress, 1, 1, "")
    return SegmentResult(segmentation=seg, pipeline=pipe, settings=settings, objects=results, method=opts.method)


def _clip_box(box: Box, shape: Sequence[int]) -> Box:
    """``box`` ((z0, z1), (y0, y1), (x0, x1)) voxels, clipped to a volume of ``shape``."""
    (z0, z1), (y0, y1), (x0, x1) = box
    nz, ny, nx = (int(n) for n in shape)
    return (max(z0, 0), min(z1, nz - 1)), (max(y0, 0), min(y1, ny - 1)), (max(x0, 0), min(x1, nx - 1))


def _prompted(volume: Any, seeds: Sequence[Sequence[int]], background: Sequence[Sequence[int]],
              opts: SegmentOptions, pipe: Pipeline, segmentation: Segmentation | None, names: Sequence[str] | None,
              progress: Progress | None, object_ids: Sequence[int] | None) -> SegmentResult:
    """One object from prompts (``nninteractive``): every seed a positive point, every background seed a
    negative one, the box a box prompt; the object already in ``segmentation`` is refined."""
    shape = tuple(volume.data.shape)
    fg = [_check_seed(s, shape, "seed") for s in seeds]
    bg = [_check_seed(s, shape, "background seed") for s in background]
    seg = segmentation if segmentation is not None else Segmentation(shape)
    oid = int(object_ids[0]) if object_ids else next((i for i in range(1, 11) if i not in seg.objects), 0)
    if not oid:
        raise CtuiError("at most 10 objects: no free object id")
    seg.add_object(names[0] if names else f"object {oid}", object_id=oid)
    roi = None if opts.box is None else _clip_box(opts.box, shape)
    if roi is not None and any(a > b for a, b in roi):
        raise CtuiError(f"the box {box_text(opts.box)} lies outside the volume", option="box")
    rep = nninteractive.run_prompts(volume, seg, oid, nninteractive.Prompts(fg, bg, roi), server=opts.server,
                                    api_key=opts.api_key or None, progress=progress)
    box = seg.object_bbox(oid)
    res = PromptedResult(id=oid, seed=fg[0] if fg else bg[0] if bg else (0, 0, 0), range=(float("nan"),) * 2,
                       stops={"nninteractive": rep.summary()}, neck={"mode": "off"})
    res.voxels = 0 if box is None else int(np.count_nonzero(seg.labels[box] == oid))
    res.volume_ml = res.voxels * float(np.prod(volume.spacing)) / 1000.0
    res.slices = None if box is None else (box[0].start, box[0].stop - 1)
    if rep.licence_new:  # once a session: the message says it
        res.stops["licence"] = rep.licence
    settings = {"method": opts.method, "prompts": rep.to_dict(), "box": roi,
                "seeds": [list(s) for s in fg], "background": [list(b) for b in bg]}
    info = seg.objects[oid]
    info.seeds.extend(s for s in fg if s not in info.seeds)
    info.settings.update({"method": opts.method, "prompts": len(fg) + len(bg) + (opts.box is not None)})
    report(progress, 1, 1, "")
    return SegmentResult(segmentation=seg, pipeline=pipe, settings=[settings], objects=[res], method=opts.method)


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
    res = ObjectResult(id=oid, seed=seed, range=start.rng, neck=_neck_report(opts, start),
                       auto_range=None if start.auto_range is None else start.auto_range.to_dict(),
                       denoise=start.denoise)
    s = _settings(opts, start, volume.data.shape)
    dz, dy, dx = (float(v) for v in volume.spacing)
    spacing = (dz, dy, dx)
    info = seg.objects[oid]
    info.seeds.append(seed)
    info.settings.update({"low": start.rng[0], "high": start.rng[1], "connectivity": opts.connectivity,
                          "method": opts.method, "neck": res.neck, "fill_holes": opts.fill_holes,
                          "denoise": start.denoise})
    if bg:
        info.settings["background"] = [list(b) for b in bg]
    job = Job(volume=volume, pipe=pipe, seg=seg, oid=oid, seed=seed, start=start.mask, settings=s, background=bg,
              region=start.neck.region if start.neck is not None else None, curvature=opts.curvature,
              progress=progress)
    METHODS[opts.method].run(job)
    res.stops, res.necks, res.cuts = dict(job.stops), list(job.necks), list(job.cuts)
    res.warnings.extend(job.warnings)
    if job.neck_status == "thin" and start.width > 0:
        res.warnings.append(f"the neck width {start.width:g} mm is wider than the object around the seed, so "
                            "the leak guard cut nothing: use the automatic width or a smaller one")
    _clean(seg, oid, opts, spacing)
    info.settings["propagation"] = res.stops
    return res, s.to_dict()


def suggest_range(volume: Any, seed: Sequence[int], *, pipeline: Pipeline | None = None) -> RangeChoice:
    """The range a seed (x, y, z) would get with no range given (its neighbourhood's median +- 2 robust sd,
    in the pipeline's domain) and the neighbourhood's histogram: what the TUI shows before a fill."""
    x, y, z = _check_seed(seed, tuple(volume.data.shape), "seed")
    return seed_range(volume, pipeline or Pipeline(), (x, y, z))


def _clean(seg: Segmentation, oid: int, opts: SegmentOptions, spacing: tuple[float, float, float]) -> None:
    if opts.keep_largest:
        seg.keep_largest_island(oid)
    if opts.min_island:
        seg.remove_islands(oid, opts.min_island)
    if opts.interpolate:
        seg.fill_between_slices(oid, slices=opts.slices, spacing=spacing)


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
