"""The segment action's checks: the warnings that keep a wrong result from passing silently.

They read the action's ObjectResult, _Start and SegmentOptions (typed Any here: no import cycle).

A result that collapsed, grew many times past the ball that fits at the seed, took in a
neighbouring tissue (its values centre away from the seed's), is wrapped in a brighter shell
that is probably part of the same organ (a kidney's medulla inside its cortex), a guard that turned itself off,
a neighbourhood that mixes tissues, background seeds that cannot act. Each says what happened
and what to try (``ctui segment`` prints them, ``--json`` lists them, the TUI notifies them).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage

from ctui.engine.core.errors import CtuiError
from ctui.engine.segment.autoneck import coarse, resample_factors
from ctui.engine.segment.leaks import find_leaks
from ctui.engine.segment.seeding import seed_range

Seed = tuple[int, int, int]


def check_background(volume: Any, fg: list[Seed], bg: list[Seed], fills: list[Any], *,
                      same_region_ok: bool = False) -> list[str]:
    """Refuse a background seed inside a seed's own slice object (unless the method shares a region along
    its edges: ``grow``); warn about one that cannot act."""
    notes = []
    for seed, start in zip(fg, fills if not same_region_ok else []):
        for b in bg:
            if b[2] == seed[2] and start.mask[b[1], b[0]]:
                raise CtuiError(f"background seed {b[0]},{b[1]},{b[2]} lies inside the region of seed "
                                f"{seed[0]},{seed[1]},{seed[2]} on its slice (same range, no neck between): "
                                "move it outside the object")
    lo = min(f.rng[0] for f in fills)
    hi = max(f.rng[1] for f in fills)
    for b in bg:
        vals = [float(f.pipe.final_slice(volume, b[2])[b[1], b[0]]) for f in fills]
        if not any(f.rng[0] <= v <= f.rng[1] for f, v in zip(fills, vals)):
            v = vals[0]
            notes.append(f"background seed {b[0]},{b[1]},{b[2]} (value {v:g}) is outside the range "
                         f"[{lo:g}, {hi:g}], so it cannot stop anything: place it in the neighbour the object leaks into")
    return notes


# an automatic range whose neighbourhood spreads more than this many times the image noise mixes tissues
# (real CT, benchmarks/organs.py seeds: kidneys, spleen, liver 1.0-1.2x unenhanced; a kidney's cortex and
# medulla in a contrast phase 1.8x, the aorta's lumen beside its thrombus 3.8x)
MIXED_NEIGHBOURHOOD = 1.5
# ... but up to this many times the noise it is a note on the range (``auto_range["why"]``, the TUI's panel), not a
# warning: the range was widened from the seed's own value (autorange's plateau rule) and the results are right
# (benchmarks/organs_sets.py: the msd spleen 1.52-1.54x, Dice 0.95; a parotid 1.52x, Dice 0.84); the results it
# alone warned about outside 0.5-2x the reference (a stomach's and two mandibles' seeds) were at 14-16x
MIXED_WARN = 2.0


# an object many times the ball at its seed is a leak only when it is also many times the ball at its own deepest
# point (the shared abdomen's liver from a seed 20 mm deep: 37-39x the seed's ball, 8.4x its own, Dice 0.90; the
# stomach's leaks 18-37x their own, the right kidney's and the spleen's 15-17x)
OWN_BALLS = 12.0


# ... and when it is not a closed dark compartment: this share of its face brighter than its range (the MR brain's
# lateral ventricles in white matter, 0.88-0.98 (fill, levelset), 31-34x the seed's ball and as many of their own: a
# thin structure; the abdomen's leaks 0.01-0.32)
CLOSED = 0.85


LEAK_BODY = 0.25  # ... or holding this share of the body on its slices (the abdomen's liver at 1.22x from a seed 20 mm
# deep: 0.20; the aorta CTA's seed with its reference's 5-95th percentile range run into the heart and bone: 0.32,
# 9.9x its own ball)


def leak_like(r: Any, seed_ball_ml: float, own_ml: float, closed: float, body: float | None) -> bool:
    """Whether an object many times the seed's ball (``seed_ball_ml``) also looks like a leak: many times the ball
    at its own deepest point (``own_ml``) or holding much of the body on its slices (``body``: its share, None off
    CT), and not closed by brighter tissue (``closed``: the share of its face)."""
    return (r.volume_ml > OWN_BALLS * own_ml or (body or 0.0) > LEAK_BODY) and closed < CLOSED


def own_measures(volume: Any, seg: Any, r: Any, start: Any, box: tuple[slice, slice, slice] | None,
                 spacing: tuple[float, ...]) -> tuple[float, float, float | None]:
    """(the ball's mL at the object's own deepest point, the share of its face above its range, its share of the
    body on its slices or None off CT)."""
    if box is None or r.voxels == 0:
        return 0.0, 0.0, 0.0
    v = face_values(volume, seg, r, start, box)
    return (own_ball_ml(seg, r, box, spacing), float(np.count_nonzero(v > start.rng[1])) / max(v.size, 1),
            body_share(volume, seg, r))


def own_ball_ml(seg: Any, r: Any, box: tuple[slice, slice, slice] | None, spacing: tuple[float, ...]) -> float:
    """The volume (mL) of the ball at the object's own deepest point (its distance map on the sweep's coarse grid,
    about 2 mm: 0.1-0.3 s a liver); 0 when the object is empty."""
    if box is None:
        return 0.0
    f = resample_factors(tuple(float(s) for s in spacing))  # type: ignore[arg-type]  # three floats
    obj = coarse(seg.labels[box] == r.id, f)
    sp = tuple(float(s) * k for s, k in zip(spacing, f))
    depth = float(ndimage.distance_transform_edt(np.pad(obj, 1), sampling=sp).max()) if obj.any() else 0.0
    return 4.0 / 3.0 * np.pi * depth ** 3 / 1000.0


def sanity(r: Any, start: Any, spacing: tuple[float, ...], opts: Any, own: Any = None) -> list[str]:
    """Warnings for results that are probably wrong: collapsed, or many times what the seed suggests (and what
    its own deepest point does: ``own(r)`` gives (the ball's mL there, the share of its face above the range))."""
    out = []
    seed_px = int(start.mask.sum())
    if 0 < r.voxels < max(27, seed_px // 4):
        out.append(f"the object collapsed to {r.voxels} voxels (its seed slice had {seed_px} px): widen the range, "
                   "move the seed deeper into the object, or check the background seeds")
    if start.neck is not None and start.width <= 0 and not start.neck.reason.startswith(("no leak", "bounded")):
        out.append(f"the leak guard is off for this object ({start.neck.reason}): check it for leaks, or force "
                   "a neck width")
    depth = start.depth_mm
    ball_ml = 4.0 / 3.0 * np.pi * depth ** 3 / 1000.0
    big = depth > 0 and r.volume_ml > 25 * ball_ml
    leaky = big and (own is None or leak_like(r, ball_ml, *own(r)))
    rc = start.auto_range
    if rc is not None and rc.noise > 0 and rc.sd > MIXED_NEIGHBOURHOOD * rc.noise:
        text = (f"the seed's neighbourhood is not uniform (spread {rc.sd:.0f}, {rc.sd / rc.noise:.1f}x the image "
                f"noise), so the automatic range [{rc.low:.0f}, {rc.high:.0f}] may take in several tissues")
        if rc.sd > MIXED_WARN * rc.noise or big:  # or the result is many times what the seed suggests
            out.append(text + ": give a range, or move the seed into the object's even part")
        elif isinstance(r.auto_range, dict):  # a note on the range, not a warning (unless: mixed_check)
            r.auto_range["why"] = f"{r.auto_range.get('why', '')}; note: {text}".lstrip("; ")
            r.mixed_note = text + ": give a range, or move the seed into the object's even part"
    if leaky:
        out.append(f"the object ({r.volume_ml:.0f} mL) is {r.volume_ml / ball_ml:.0f}x the ball that fits at the "
                   f"seed ({ball_ml:.1f} mL): it probably leaked into a neighbour; add background seeds there, "
                   "narrow the range, or draw a box" + (", or let the leak guard find its width (neck auto)"
                                                        if opts.neck_mm is not None else ""))
    return out


# an object whose median lies more than this many (range width / 4) from its seed's neighbourhood median is mostly
# another tissue (benchmarks/organs.py: the 16 kidney/spleen/liver rows and the aorta with defaults 0-0.56;
# the right kidney run into the liver on a noisy 1 x 1 x 3 mm grid 0.90-1.17, the aorta into bone with its range 2.3)
TISSUE_SHIFT = 0.8
TISSUE_SLICES = 16  # the object's values are sampled on at most this many of its slices


# a result whose own values spread more than this many times the noise holds the mixed neighbourhood's tissues
# (benchmarks/organs_sets.py, seeds at 1.5-2x: the msd spleen's right results 1.41-1.54; a parotid in fat at
# -84:0, 2.4x its reference, 2.07)
MIXED_RESULT = 1.8


def mixed_check(volume: Any, seg: Any, r: Any, start: Any, box: tuple[slice, slice, slice] | None) -> list[str]:
    """The not-uniform note as a warning when the result shows the mixing: another check says it is wrong (it took
    in another tissue, fills the body, leaked through a neck), or its own values spread more than MIXED_RESULT x
    the image noise."""
    note = getattr(r, "mixed_note", "")
    if not note:
        return []
    wrong = ("the object's values", "the object fills", "a leak of", "the ball that fits")
    if any(w.startswith(wrong) or wrong[3] in w for w in r.warnings):
        return [note]
    if r.slices is None or r.voxels == 0 or start.auto_range is None:
        return []
    ys, xs = (box[1], box[2]) if box is not None else (slice(None), slice(None))
    z0, z1 = r.slices
    v = np.concatenate([np.asarray(start.pipe.final_slice(volume, int(z))[ys, xs], np.float64)[seg.labels[int(z), ys, xs] == r.id]
                        for z in np.unique(np.linspace(z0, z1, TISSUE_SLICES).round().astype(int))])
    spread = 1.4826 * float(np.median(np.abs(v - np.median(v)))) if v.size else 0.0
    return [note] if spread > MIXED_RESULT * start.auto_range.noise else []


def near_seed_value(volume: Any, seg: Any, r: Any, start: Any, mm: float = 10.0) -> float:
    """The median of the object's own values within ``mm`` of its seed (x, y, z) in the pipeline's final view."""
    x, y, z = start.seed
    sp = [float(v) for v in volume.spacing]
    k = [max(1, int(np.ceil(mm / v))) for v in sp]
    nz, ny, nx = volume.data.shape
    y0, y1, x0, x1 = max(y - k[1], 0), min(y + k[1] + 1, ny), max(x - k[2], 0), min(x + k[2] + 1, nx)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    window = start.pipe.window_for(volume)
    vals = []
    for zz in range(max(z - k[0], 0), min(z + k[0] + 1, nz)):
        ball = ((zz - z) * sp[0]) ** 2 + ((yy - y) * sp[1]) ** 2 + ((xx - x) * sp[2]) ** 2 <= mm * mm
        keep = ball & (seg.labels[zz, y0:y1, x0:x1] == r.id)
        if keep.any():
            img = start.pipe.final_region(volume, zz, y0, y1, x0, x1, window=window)
            vals.append(np.asarray(img, np.float64)[keep])
    return float(np.median(np.concatenate(vals))) if vals else float("nan")


def tissue_check(volume: Any, seg: Any, r: Any, start: Any, box: tuple[slice, slice, slice] | None = None) -> list[str]:
    """A warning when the object's values are centred away from its seed's: it took in a neighbouring tissue
    whose values overlap the range (a leak no neck separates, or a range spanning two tissues). ``box``: the
    object's bounding box (z, y, x), when known."""
    if r.slices is None or r.voxels == 0 or start.seed is None:
        return []
    lo, hi = start.rng
    unit = (hi - lo) / 4.0
    if unit <= 0:
        return []
    seed_med = start.auto_range.median if start.auto_range is not None else seed_range(volume, start.pipe, start.seed).median
    if not lo <= seed_med <= hi:
        # the seed's ball is mostly its neighbours (a structure thinner than the ball: the MR brain's lateral
        # ventricles, ball median 53 in white matter, range 11:39, the object 19): the seed's own tissue is
        # then the object's values in that ball
        near = near_seed_value(volume, seg, r, start)
        seed_med = near if np.isfinite(near) else seed_med
    z0, z1 = r.slices
    ys, xs = (box[1], box[2]) if box is not None else (slice(None), slice(None))
    vals = [start.pipe.final_slice(volume, int(z))[ys, xs][seg.labels[int(z), ys, xs] == r.id]
            for z in np.unique(np.linspace(z0, z1, TISSUE_SLICES).round().astype(int))]
    obj_med = float(np.median(np.concatenate(vals)))
    shift = (obj_med - seed_med) / unit
    if abs(shift) <= TISSUE_SHIFT:
        return []
    return [f"the object's values (median {obj_med:.0f}) lie {abs(shift):.1f} quarter-ranges "
            f"{'above' if shift > 0 else 'below'} its seed's (median {seed_med:.0f}): it probably took in a "
            "neighbouring tissue; narrow the range towards the seed's values, add background seeds there, or "
            "draw a box"]


# an object whose outer face borders values above the range on more than this share of it is wrapped in a
# brighter shell (a kidney's medulla seeded in an arterial phase: 0.65-0.98 of the face is cortex; the 16
# kidney/spleen/liver rows of benchmarks/organs.py, random seeds in them, the aorta and the nephrographic
# kidneys 0.00-0.15; leaks into a neighbour 0.28-0.30) ...
WRAPPED = 0.5
WRAP_GAP = 3.0  # ... when the shell's median lies within this many range widths above the range (not bone
WRAP_STEP = 0.25  # around the brain) and at least this many (another tissue, not the same one past a narrow
# range: air in a head phantom's insert, range 6 HU wide, its face 1 HU above: 0.17; the medulla in its
# cortex 0.55-1.15)
WRAP_SLICES = 32  # the face is sampled on at most this many of the object's slices


def face_values(volume: Any, seg: Any, r: Any, start: Any, box: tuple[slice, slice, slice]) -> np.ndarray:
    """The values (float64, 1D) just outside the object's faces, on at most ``WRAP_SLICES`` of its slices."""
    labels = seg.labels
    nz, ny, nx = labels.shape
    ys = slice(max(box[1].start - 1, 0), min(box[1].stop + 1, ny))
    xs = slice(max(box[2].start - 1, 0), min(box[2].stop + 1, nx))
    cross = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)
    window = start.pipe.window_for(volume)  # the box's values only, not whole slices (16 -> 5 ms, 512 x 512)
    vals = []
    for z in np.unique(np.linspace(box[0].start, box[0].stop - 1, WRAP_SLICES).round().astype(int)):
        obj = labels[z, ys, xs] == r.id
        # slice z's pixels that are 6-neighbours of the object: beside it in-plane, or above or below it
        face = ndimage.binary_dilation(obj, structure=cross)
        for dz in (-1, 1):
            if 0 <= z + dz < nz:
                face |= labels[z + dz, ys, xs] == r.id
        face &= ~obj
        img = start.pipe.final_region(volume, int(z), ys.start, ys.stop, xs.start, xs.stop, window=window)
        vals.append(np.asarray(img, np.float64)[face])
    return np.concatenate(vals) if vals else np.zeros(0)


def wrap_check(volume: Any, seg: Any, r: Any, start: Any, box: tuple[slice, slice, slice] | None) -> list[str]:
    """A warning when the object is wrapped in a brighter shell, probably the rest of the same organ: seeded
    in a kidney's medulla in an arterial (corticomedullary) phase, a range from the seed gives the medulla
    alone, half the kidney, with nothing else amiss. ``box``: the object's bounding box (z, y, x)."""
    if box is None or r.voxels == 0:
        return []
    lo, hi = start.rng
    if hi <= lo:
        return []
    v = face_values(volume, seg, r, start, box)
    above = v[v > hi]
    if not v.size or above.size < WRAPPED * v.size:
        return []
    med = float(np.median(above))
    if not WRAP_STEP * (hi - lo) <= med - hi <= WRAP_GAP * (hi - lo):
        return []
    sd = max(1.4826 * float(np.median(np.abs(above - med))),
             start.auto_range.noise if start.auto_range is not None else 0.0)
    r.shell_range = (float(lo), float(med + 2 * sd))  # what the segment action may try once (a range holding both)
    return [f"the object is wrapped in brighter tissue: {above.size / v.size:.0%} of its surface borders values "
            f"above the range (median {med:.0f}); if that shell is part of the same organ (a kidney's cortex "
            f"around its medulla in an arterial phase), give a range that holds both, about {lo:.0f}:{med + 2 * sd:.0f}"]


# an object holding more than this share of the body (voxels above BODY_HU) on its slices ran into the tissue around
# it (measured: the abdomen's kidneys, spleen, liver and the contrast spleen 0.02-0.18; leaks of a spinal cord, a
# parotid, a brainstem or a mandible seed into the neck and head 0.2-0.9 on the openkbp head-and-neck CTs)
BODY_SHARE = 0.3
# ... or more than this share of the body's cross-section on any one slice (benchmarks/organs_sets.py, every result
# 0.8-1.25x its reference: the abdomen's kidneys 0.03-0.04, spleen 0.05-0.06, liver 0.25-0.32, the msd spleen's crop
# 0.30-0.31; the head-and-neck results that passed silently, a spinal cord or a brainstem seed filling the neck or
# the brain, 5-16x to 120x: 0.44-0.79)
SLICE_SHARE = 0.4
SLICE_BODY_CM2 = 50.0  # both on slices where the body's cross-section is at least this (openkbp pt_5's field of
# view is cropped to 9-13 cm^2 around its larynx and brainstem: a correct larynx held 76% of that "body")
BODY_HU = -400.0
BODY_SLICES = 16


def _slice_share(volume: Any, seg: Any, r: Any, box: tuple[slice, slice, slice] | None) -> tuple[float, int]:
    """The largest share of the body's cross-section (voxels above BODY_HU) the object holds on one of its slices
    (slices whose body is at least SLICE_BODY_CM2), and that slice."""
    z0, z1 = r.slices
    ys, xs = (box[1], box[2]) if box is not None else (slice(None), slice(None))
    obj = np.count_nonzero(seg.labels[z0:z1 + 1, ys, xs] == r.id, axis=(1, 2))
    px_cm2 = float(volume.spacing[1]) * float(volume.spacing[2]) / 100.0
    best, at = 0.0, z0
    for k in np.flatnonzero(obj):
        body = int(np.count_nonzero(volume.data[z0 + k] > BODY_HU))
        if body * px_cm2 >= SLICE_BODY_CM2 and obj[k] / body > best:
            best, at = float(obj[k]) / body, int(z0 + k)
    return best, at


def body_share(volume: Any, seg: Any, r: Any) -> float | None:
    """The share of the body (voxels above BODY_HU) the object holds on up to BODY_SLICES of its slices (those whose
    body is at least SLICE_BODY_CM2); None when the series is not a CT in HU."""
    if r.slices is None or r.voxels == 0:
        return 0.0
    zs = np.unique(np.linspace(r.slices[0], r.slices[1], BODY_SLICES).round().astype(int))
    data = volume.data[zs]
    if getattr(volume, "modality", "") != "CT" and not float(data.min()) < -500:
        return None
    areas = np.count_nonzero(data > BODY_HU, axis=(1, 2))
    full = areas * float(volume.spacing[1]) * float(volume.spacing[2]) / 100.0 >= SLICE_BODY_CM2
    body = int(areas[full].sum())  # a cropped field of view's slices (a larynx's 10 cm^2 of it) say nothing
    obj = int(np.count_nonzero(seg.labels[zs[full]] == r.id))
    return obj / body if body else 0.0


def body_check(volume: Any, seg: Any, r: Any, box: tuple[slice, slice, slice] | None = None) -> list[str]:
    """A warning when the object fills much of the body on its slices, or of one slice's cross-section (CT in HU
    only: the body is what lies above BODY_HU): a structure without an edge at this range (a spinal cord, a parotid
    or the brainstem in the tissue around it) whose result is the surrounding tissue, many times the structure.
    ``box``: the object's bounding box (z, y, x), when known."""
    if r.slices is None or r.voxels == 0:
        return []
    share = body_share(volume, seg, r)
    if share is None:
        return []
    what = ""
    if share > BODY_SHARE:
        what = f"fills {share:.0%} of the body on its slices"
    else:
        share, at = _slice_share(volume, seg, r, box)
        if share <= SLICE_SHARE:
            return []
        what = f"fills {share:.0%} of the body's cross-section on slice {at}"
    return [f"the object {what}: the structure probably has no edge at the range {r.range[0]:.0f}:{r.range[1]:.0f} "
            "(its values overlap the tissue around it), so the result is that tissue; draw a box around the "
            "structure, add background seeds in what it ran into, or give a narrower range"]


def leak_check(seg: Any, r: Any, start: Any, box: tuple[slice, slice, slice] | None, spacing: tuple[float, ...]) -> list[str]:
    """Warnings for the pieces that hang on the object by a narrow neck (:mod:`ctui.engine.segment.leaks`): each
    names the slice and voxel where it enters and the background seed that removes it. The leaks go into
    ``r.neck["leaks"]`` ({"slice", "at": [x, y, z], "volume_ml", "neck_mm", "depth_mm", "click": [x, y, z]}),
    which ``--json`` lists, and into the object's settings, which the review strip marks."""
    if box is None or r.voxels == 0 or start.seed is None:
        return []
    x, y, z = start.seed
    seed = (z - box[0].start, y - box[1].start, x - box[2].start)
    found = find_leaks(seg.labels[box] == r.id, spacing, seed, origin=tuple(b.start for b in box),
                       shape=seg.labels.shape)
    r.neck["leaks"] = [lk.to_dict() for lk in found]
    info = seg.objects.get(r.id)
    if info is not None:  # kept with the object: the review strip marks them
        info.settings["leaks"] = [dict(d) for d in r.neck["leaks"]]
    return [lk.message() for lk in found]
