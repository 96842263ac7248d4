"""Leaks found where they enter: the pieces of a result that hang on its body by a narrow contact.

A leak through a vessel or a thin bridge (a kidney's renal vein into the vena cava, a liver into the vena cava,
the portal vein or vertebral marrow, a spleen into the liver) is a piece of the result joined to the seed's
"core" only through a neck much narrower than the piece itself. :func:`find_leaks` compares the object with
its core (the object opened by a ball of ``CORE_FRAC`` of the seed's depth, the part joined to the seed) and
reports, for each piece outside the core of meaningful volume that touches it through a narrow contact:

* ``slice``: the slice where it enters (the contact's centre), ``at``: that voxel (x, y, z);
* ``volume_ml``: the piece's volume, ``neck_mm``: the contact's equivalent diameter, ``depth_mm`` the piece's;
* ``click``: the piece's deepest voxel (x, y, z), the background seed that removes it.

The segment action turns each into a warning and a review mark ("leak enters here"); the TUI's strip draws it.
Runs on the object's bounding box (a box over ``MAX_VOXELS`` is sampled every 2nd, 3rd ... voxel first: a box
134 x 512 x 512 full in 0.3 s, 2.7 s halved).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

__all__ = ["Leak", "find_leaks"]

CORE_FRAC = 0.5  # the core: the object opened by a ball of this fraction of the seed's depth
MIN_ML = 2.0  # pieces smaller than this (mL) ...
MIN_SHARE = 0.04  # ... or than this share of the object are not reported
NARROW = 0.65  # a contact thinner (the object's depth there) than this many times the piece's depth is a neck
MIN_DEPTH_VOX = 1.5  # a piece shallower (depth in its largest spacings) is a rind the opening shaved off
MAX_VOXELS = 2_000_000


@dataclass(frozen=True)
class Leak:
    """One piece joined to the object's core through a narrow contact (see the module docstring)."""

    slice: int
    at: tuple[int, int, int]
    volume_ml: float
    neck_mm: float
    depth_mm: float
    click: tuple[int, int, int]

    def to_dict(self) -> dict:
        return {"slice": self.slice, "at": list(self.at), "volume_ml": round(self.volume_ml, 1),
                "neck_mm": round(self.neck_mm, 1), "depth_mm": round(self.depth_mm, 1), "click": list(self.click)}

    def message(self) -> str:
        return (f"a leak of {self.volume_ml:.0f} mL enters at slice {self.slice} (x {self.at[0]}, y {self.at[1]}) "
                f"through a neck of {self.neck_mm:.0f} mm: add a background seed at {self.click[0]},{self.click[1]},"
                f"{self.click[2]} (deep in it) to remove it, if it is not part of the object")


def _edt(mask: np.ndarray, spacing, cut=((False, False),) * 3) -> np.ndarray:
    """Distance (mm) to the object's edge; a face in ``cut`` ((before, after) per axis: the volume ends
    there) is no edge: an organ cut off by the field of view is not thin there."""
    pad = np.pad(mask, 1)
    for ax, (a, b) in enumerate(cut):
        for on, src, dst in ((a, 1, 0), (b, -2, -1)):
            if on:
                idx_s, idx_d = [slice(None)] * 3, [slice(None)] * 3
                idx_s[ax], idx_d[ax] = src, dst
                pad[tuple(idx_d)] = pad[tuple(idx_s)]
    return edt(pad, spacing)[1:-1, 1:-1, 1:-1]


EDT_SLAB = 8  # slices a step when turning the feature transform into distances


def edt(mask: np.ndarray, spacing, *, at_most: float | None = None) -> np.ndarray:
    """``scipy.ndimage.distance_transform_edt(mask, sampling=spacing)`` bit for bit (float64 mm), computed from its
    feature transform slab by slab: about 20 bytes a voxel at the peak instead of scipy's 48 (its distances
    go through int32 and float64 copies of all three offsets). ``at_most``: bool (distance <= at_most) instead,
    12 bytes a voxel. ``mask`` (z, y, x), ``spacing`` (dz, dy, dx)."""
    ft = ndimage.distance_transform_edt(mask, sampling=spacing, return_distances=False, return_indices=True)
    sp = np.asarray(spacing, np.float64).reshape(-1)
    sp = np.broadcast_to(sp, (mask.ndim,)) if sp.size == 1 else sp
    out = np.empty(mask.shape, bool if at_most is not None else np.float64)
    for z0 in range(0, mask.shape[0], EDT_SLAB):
        f = ft[:, z0:z0 + EDT_SLAB]
        idx = np.indices(f.shape[1:], dtype=ft.dtype)
        idx[0] += z0
        dt = (f - idx).astype(np.float64)  # the same operations, in the same order, as scipy's
        for ii in range(len(sp)):
            dt[ii, ...] *= sp[ii]
        np.multiply(dt, dt, dt)
        d = np.sqrt(np.add.reduce(dt, axis=0))
        out[z0:z0 + EDT_SLAB] = d if at_most is None else d <= at_most
    return out


def _core(mask: np.ndarray, dt: np.ndarray, spacing, seed: tuple[int, int, int], r: float) -> np.ndarray:
    """The object opened by a ball of radius ``r`` mm (erosion and dilation by distance), the part at the seed
    (else the largest part)."""
    eroded = dt >= r
    opened = edt(~eroded, spacing, at_most=r) & mask
    lab, n = ndimage.label(opened)
    if n == 0:
        return opened
    at = int(lab[seed])
    if at == 0:
        at = int(np.argmax(np.bincount(lab.ravel())[1:])) + 1
    return lab == at


def find_leaks(mask: np.ndarray, spacing, seed_zyx, *, origin=(0, 0, 0), shape=None) -> list[Leak]:
    """The leaks of a bool (z, y, x) object ``mask`` (its bounding box; ``origin`` the box's first voxel in the
    volume, ``shape`` the volume's: the box's faces on the volume's are no edge) seeded at ``seed_zyx`` (box
    coordinates), ``spacing`` (dz, dy, dx) mm. Voxels in the result are volume coordinates (x, y, z). Sorted by
    volume, largest first."""
    sp = np.asarray(spacing, np.float64)
    step = max(1, int(np.ceil(np.cbrt(mask.size / MAX_VOXELS))))
    m = mask[::step, ::step, ::step] if step > 1 else mask
    sp_m = sp * step
    seed = tuple(min(int(v) // step, s - 1) for v, s in zip(seed_zyx, m.shape))
    if not m.any():
        return []
    cut = ((False, False),) * 3 if shape is None else tuple(
        (int(o) == 0, int(o) + n >= int(full)) for o, n, full in zip(origin, mask.shape, shape))
    dt = _edt(m, sp_m, cut)
    depth = float(dt[seed]) if m[seed] else float(dt.max())
    if depth < 2.0 * float(sp_m.max()):
        return []  # too thin a seed neighbourhood for a core
    r = max(CORE_FRAC * depth, 1.5 * float(sp_m.max()))
    core = _core(m, dt, sp_m, seed, r)
    rest = m & ~core
    if not rest.any():
        return []
    vox_ml = float(np.prod(sp_m)) / 1000.0
    total_ml = float(np.count_nonzero(m)) * vox_ml
    parts, n = ndimage.label(rest)
    sizes = np.bincount(parts.ravel(), minlength=n + 1)
    touch = ndimage.binary_dilation(core) & rest
    found = []
    for pid in np.flatnonzero(sizes >= max(MIN_ML, MIN_SHARE * total_ml) / vox_ml):
        if pid == 0:
            continue
        sl = ndimage.find_objects((parts == pid).astype(np.int8))[0]
        piece = parts[sl] == pid
        contact = touch[sl] & piece
        if not contact.any():
            continue
        pdt = dt[sl] * piece  # the object's depth inside the piece: a blob behind a neck is deep
        pdepth = float(pdt.max())
        if pdepth < MIN_DEPTH_VOX * float(sp_m.max()):
            continue
        neck_r = float(dt[sl][contact].max())  # how thick the object is where the piece meets the core
        if neck_r >= NARROW * pdepth:
            continue
        pts = np.argwhere(contact)
        mid = pts[int(np.argmin(((pts - pts.mean(axis=0)) ** 2 * sp_m ** 2).sum(axis=1)))]
        deep = np.unravel_index(int(np.argmax(pdt)), piece.shape)
        off = np.array([s.start for s in sl])
        at_v = (mid + off) * step + np.asarray(origin)
        cl_v = (np.array(deep) + off) * step + np.asarray(origin)
        found.append(Leak(slice=int(at_v[0]), at=(int(at_v[2]), int(at_v[1]), int(at_v[0])),
                          volume_ml=float(sizes[pid]) * vox_ml, neck_mm=2.0 * neck_r, depth_mm=pdepth,
                          click=(int(cl_v[2]), int(cl_v[1]), int(cl_v[0]))))
    return sorted(found, key=lambda lk: -lk.volume_ml)
