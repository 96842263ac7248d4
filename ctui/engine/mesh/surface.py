"""Surfaces of volumes and segmented objects, in patient mm.

* :func:`isosurface`: marching cubes at a value (HU...), crack-free, welded vertices,
  gradient normals (see :mod:`ctui.engine.mesh.marching`).
* :func:`mask_surface`: a binary mask's surface *without staircase*: the surface is
  the zero level of a smoothed signed-distance field (distances in mm, so anisotropic
  voxels are handled), cropped to the object's bounding box, with the level corrected
  so the enclosed volume equals the mask's voxel volume (to about 0.1 %). Thick
  slices can be refined by shape-based interpolation (signed distances interpolated
  between slices).
* :func:`label_surfaces`: every object of a label map. Terraced (``smooth=False``):
  one pass of a multi-label discrete marching cubes over the label map gives every
  object's closed surface (:mod:`ctui.engine.mesh.multilabel`). Smooth: the signed distance
  is per object, so one scan (``scipy.ndimage.find_objects``) gives every object's
  bounding box and each object is meshed inside its own box only: the cost is the
  sum of the objects' boxes, not one pass over the whole volume per label.

Geometry follows :mod:`ctui.engine.core.volume`: spacing (dz, dy, dx) mm, origin (x, y, z)
of voxel (0, 0, 0)'s centre, direction columns = x, y, z index axes;
``p = origin + direction @ (spacing_xyz * (i, j, k))``.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ctui.engine.core.limits import check_allocation
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.meshdata import Mesh
from ctui.engine.core.progress import Progress, report


def affine_from(spacing: Sequence[float], origin: Sequence[float] = (0.0, 0.0, 0.0),
                direction: np.ndarray | None = None) -> np.ndarray:
    """4x4 matrix mapping homogeneous (x, y, z, 1) indices to patient mm.

    spacing is (dz, dy, dx) mm (ctui's convention); origin (x, y, z) mm.
    """
    return Geometry((1, 1, 1), spacing, origin, direction).affine  # the one voxel<->mm type


def _fix_handedness(faces: np.ndarray, affine: np.ndarray) -> np.ndarray:
    # a left-handed index->mm map mirrors the mesh: swap winding to stay CCW outward
    if np.linalg.det(affine[:3, :3]) < 0:
        return np.ascontiguousarray(faces[:, ::-1])
    return faces


def _touches_border(data: np.ndarray, level: float) -> bool:
    """Whether any voxel on the volume's six faces is inside (value > level)."""
    for ax in range(3):
        for idx in (0, -1):
            face = np.take(data, idx, axis=ax)
            if (face > level).any():
                return True
    return False


def _closing_crop(data: np.ndarray, level: float) -> tuple[tuple[slice, ...], list[tuple[int, int]], list[int]]:
    """The part of the volume a closed isosurface needs, and where to pad it: (slices, pads,
    origin index (z, y, x) of the padded copy).

    The box of the voxels above ``level`` grown by two voxels (the outside neighbours of its
    border voxels and their central-difference gradients), padded by one voxel where it reaches
    the volume's border: the same mesh as padding the whole volume, from a smaller copy (a CT's
    bone at 300 HU: about half the volume; found by two max reductions, no boolean volume)."""
    red = np.fmax.reduce if data.dtype.kind == "f" else np.maximum.reduce  # fmax: NaN is outside
    rows = red(data, axis=2) > level  # (nz, ny)
    zs, ys = np.flatnonzero(rows.any(axis=1)), np.flatnonzero(rows.any(axis=0))
    cols = red(red(data[zs[0]: zs[-1] + 1, ys[0]: ys[-1] + 1], axis=0), axis=0) > level
    xs = np.flatnonzero(cols)
    sls, pads, off = [], [], []
    for n, idx in zip(data.shape, (zs, ys, xs)):
        a, b = max(int(idx[0]) - 2, 0), min(int(idx[-1]) + 3, n)
        pad = (1 if a == 0 else 0, 1 if b == n else 0)
        sls.append(slice(a, b))
        pads.append(pad)
        off.append(a - pad[0])
    return tuple(sls), pads, off


def isosurface(data: np.ndarray, level: float, *, spacing: Sequence[float] = (1.0, 1.0, 1.0),
               origin: Sequence[float] = (0.0, 0.0, 0.0), direction: np.ndarray | None = None,
               normals: bool = True, close: bool = False, progress: Progress | None = None) -> Mesh:
    """Isosurface of a volume at ``level``.

    Parameters
    ----------
    data : ndarray (nz, ny, nx), any numeric dtype (not copied)
        Voxels with value > level are inside.
    level : float
        Iso value in the data's units (HU for CT).
    spacing : (dz, dy, dx) mm; origin : (x, y, z) mm; direction : (3, 3), columns x, y, z axes.
    close : bool
        Close the surface where the object touches the volume's border (the volume is
        padded by one voxel below the level, a copy made only when some border voxel
        is inside, and only of the box that holds the surface). Off by default (like VTK
        and scikit-image).
    progress : callback ``(done, total, message)``, optional (may cancel).

    Returns
    -------
    Mesh
        vertices float32 (n, 3) mm, faces int32 (m, 3) counter-clockwise from outside
        (outside = values <= level), unit normals float32 (n, 3) from the gradient.
        Vertices are shared between cells (one per crossed voxel edge).
    """
    from ctui.engine.mesh.marching import marching_cubes  # numba kernels

    aff = affine_from(spacing, origin, direction)
    data = np.asarray(data)
    if close and _touches_border(data, level):
        lo = data.min()
        fill = lo if lo <= level else level
        if np.issubdtype(data.dtype, np.integer) and fill > level - 1:
            fill = np.floor(level) if np.floor(level) >= np.iinfo(data.dtype).min else fill
        sls, pads, off = _closing_crop(data, level)
        check_allocation(np.prod([s.stop - s.start + a + b for s, (a, b) in zip(sls, pads)]) * data.itemsize,
                         what="a padded copy of the volume")
        padded = np.pad(data[sls], pads, mode="constant", constant_values=fill)
        shift = np.eye(4)
        shift[:3, 3] = off[::-1]  # (x, y, z) index of the copy's first voxel
        aff = aff @ shift
        data = padded
    v, f, n = marching_cubes(data, level, affine=aff, normals=normals, progress=progress)
    f = _fix_handedness(f, aff)
    return Mesh(vertices=v, faces=f, normals=n, meta={"method": "marching-cubes", "level": float(level)})


# --------------------------------------------------------------------------- masks


def _signed_distance(mask: np.ndarray, sampling: Sequence[float]) -> np.ndarray:
    """Signed distance (mm, float32) to the mask's border: negative inside, positive outside."""
    from scipy.ndimage import distance_transform_edt

    d_out = distance_transform_edt(~mask, sampling=sampling).astype(np.float32)
    d_in = distance_transform_edt(mask, sampling=sampling).astype(np.float32)
    return d_out - d_in


def _interp_z(field: np.ndarray, factor: int) -> np.ndarray:
    """Linear interpolation along axis 0: (nz, ...) -> ((nz - 1) * factor + 1, ...)."""
    nz = field.shape[0]
    out = np.empty(((nz - 1) * factor + 1,) + field.shape[1:], np.float32)
    for j in range(out.shape[0]):
        k, r = divmod(j, factor)
        if r == 0:
            out[j] = field[k]
        else:
            t = r / factor
            out[j] = (1 - t) * field[k] + t * field[k + 1]
    return out


def _mask_mesh_crop(crop: np.ndarray, offset_zyx: Sequence[int], spacing: Sequence[float], affine: np.ndarray, *,
                    smooth: bool, sigma_mm: float | None, interpolate_z: int | None,
                    target_mm3: float | None) -> Mesh:
    """Mesh of a binary crop (already padded with background) placed at ``offset_zyx``."""
    from ctui.engine.mesh.marching import marching_cubes  # numba kernels

    sp = np.asarray(spacing, dtype=np.float64)
    oz, oy, ox = (float(o) for o in offset_zyx)
    if not smooth:
        field = crop.view(np.uint8)
        level = 0.5
        step_z = 1.0
    else:
        from scipy.ndimage import gaussian_filter

        phi = -_signed_distance(crop, sp)  # inside positive (marching cubes: inside = value > level)
        step_z = 1.0
        if interpolate_z and int(interpolate_z) > 1 and phi.shape[0] > 1:
            step_z = 1.0 / int(interpolate_z)
            phi = _interp_z(phi, int(interpolate_z))
        sp_f = np.array([sp[0] * step_z, sp[1], sp[2]])
        sig = float(sigma_mm) if sigma_mm is not None else 0.5 * float(max(sp_f.max(), 2 * sp_f.min()))
        if sig > 0:
            phi = gaussian_filter(phi, sigma=sig / sp_f, mode="nearest", truncate=3.0)
        field = phi
        level = 0.0
    # crop index (x, y, z) -> volume index -> mm
    shift = np.eye(4)
    shift[:3, :3] = np.diag([1.0, 1.0, step_z])
    shift[:3, 3] = (ox, oy, oz)
    aff = affine @ shift
    v, f, n = marching_cubes(field, level, affine=aff, normals=True)
    f = _fix_handedness(f, aff)
    mesh = Mesh(vertices=v, faces=f, normals=n)
    if smooth and target_mm3 and len(f):
        # keep the enclosed volume equal to the voxel volume: the smoothed distance moves
        # convex parts inwards (about sigma^2 * mean curvature); move the level by the
        # volume error over the area (phi is a distance in mm), two secant steps.
        lv_prev, vol_prev = level, abs(mesh.volume_mm3())
        lv = level - (target_mm3 - vol_prev) / max(mesh.area_mm2(), 1e-9)
        for _ in range(3):
            v2, f2, n2 = marching_cubes(field, lv, affine=aff, normals=True)
            f2 = _fix_handedness(f2, aff)
            m2 = Mesh(vertices=v2, faces=f2, normals=n2)
            vol = abs(m2.volume_mm3())
            mesh, level = m2, lv
            if abs(vol - target_mm3) <= 2e-4 * target_mm3 or vol == vol_prev:
                break
            lv_new = lv + (target_mm3 - vol) * (lv - lv_prev) / (vol - vol_prev)
            lv_prev, vol_prev, lv = lv, vol, lv_new
    mesh.meta = {"method": "mask-sdf" if smooth else "mask-binary", "level": float(level)}
    return mesh


def _crop_box(shape: Sequence[int], box: tuple[slice, ...], margin: Sequence[int]) -> tuple[tuple[slice, ...], list[tuple[int, int]], list[int]]:
    """Crop slices within the volume, padding still needed, and the crop's origin index (z, y, x)."""
    sls, pads, off = [], [], []
    for n, s, m in zip(shape, box, margin):
        lo, hi = s.start - m, s.stop + m
        sls.append(slice(max(lo, 0), min(hi, n)))
        pads.append((max(0, -lo), max(0, hi - n)))
        off.append(lo)
    return tuple(sls), pads, off


def _margin(spacing: Sequence[float], smooth: bool, sigma_mm: float | None) -> list[int]:
    if not smooth:
        return [1, 1, 1]
    sp = np.asarray(spacing, dtype=np.float64)
    sig = float(sigma_mm) if sigma_mm is not None else 0.5 * float(max(sp.max(), 2 * sp.min()))
    return [int(np.ceil(3.0 * sig / s)) + 2 for s in sp]


def mask_surface(mask: np.ndarray, *, spacing: Sequence[float] = (1.0, 1.0, 1.0),
                 origin: Sequence[float] = (0.0, 0.0, 0.0), direction: np.ndarray | None = None,
                 smooth: bool = True, sigma_mm: float | None = None, interpolate_z: int | None = None,
                 keep_volume: bool = True) -> Mesh:
    """Closed surface of a binary mask, without staircase.

    Parameters
    ----------
    mask : ndarray bool/uint8 (nz, ny, nx)
        Object voxels (non-zero).
    spacing : (dz, dy, dx) mm; origin : (x, y, z) mm; direction : (3, 3).
    smooth : bool
        True: zero level of the Gaussian-smoothed signed distance (mm, computed inside
        and outside with the true anisotropic spacing). False: plain marching cubes of
        the mask at 0.5 (terraced).
    sigma_mm : float, optional
        Gaussian sigma in mm (default: half the largest voxel size, at least one
        smallest voxel size).
    interpolate_z : int, optional
        Shape-based interpolation: signed distances are interpolated linearly to
        ``interpolate_z`` times more slices before smoothing (thick slices).
    keep_volume : bool
        Correct the level so the enclosed volume equals the mask's voxel volume
        (count x voxel volume) to about 0.1 %.

    Returns
    -------
    Mesh
        Closed (the crop is padded, so objects touching the volume border are closed
        too), outward-oriented, in patient mm, normals from the field's gradient.
    """
    from scipy.ndimage import find_objects

    m = np.asarray(mask)
    if m.ndim != 3:
        raise ValueError(f"mask_surface needs a 3D mask, got shape {m.shape}")
    m = m != 0
    boxes = find_objects(m.view(np.uint8))
    if not boxes or boxes[0] is None:
        return Mesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros((0, 3), np.float32))
    aff = affine_from(spacing, origin, direction)
    return _object_mesh(m, boxes[0], None, spacing, aff, smooth=smooth, sigma_mm=sigma_mm,
                        interpolate_z=interpolate_z, keep_volume=keep_volume)


def _object_mesh(arr: np.ndarray, box: tuple[slice, ...], label: int | None, spacing, aff, *, smooth, sigma_mm,
                 interpolate_z, keep_volume) -> Mesh:
    margin = _margin(spacing, smooth, sigma_mm)
    sls, pads, off = _crop_box(arr.shape, box, margin)
    sub = arr[sls]
    if smooth:  # two float64 distance transforms (with their index arrays) and a float32 field
        n_crop = np.prod([s.stop - s.start + p[0] + p[1] for s, p in zip(sls, pads)])
        check_allocation(float(n_crop) * 28 * max(int(interpolate_z or 1), 1),
                         what=f"the signed distance of object {label if label is not None else 1}")
    crop = (sub == label) if label is not None else sub.astype(bool, copy=False)
    crop = np.pad(crop, pads)
    target = float(np.count_nonzero(crop)) * float(np.prod(spacing)) if keep_volume else None
    crop = np.ascontiguousarray(crop)
    mesh = _mask_mesh_crop(crop, off, spacing, aff, smooth=smooth, sigma_mm=sigma_mm,
                           interpolate_z=interpolate_z, target_mm3=target)
    if smooth and mesh.n_faces == 0 and crop.any():
        # a thin object (a line or plate 1-2 voxels across): the Gaussian took its signed
        # distance below zero everywhere. Retry with a quarter-voxel sigma, then with the
        # plain signed distance (the voxels' outline, volume still matched to the voxels)
        for sig in (0.25 * float(min(spacing)), 0.0):
            mesh = _mask_mesh_crop(crop, off, spacing, aff, smooth=True, sigma_mm=sig,
                                   interpolate_z=interpolate_z, target_mm3=target)
            if mesh.n_faces:
                mesh.meta["note"] = f"thin object: smoothed with sigma {sig:g} mm instead of the default"
                break
    return mesh


def _terraced(lab: np.ndarray, aff: np.ndarray, objects: Sequence[int] | None, note: str = "") -> dict[int, Mesh]:
    """Terraced surfaces of ``objects`` (all when None) from one multi-label pass."""
    from ctui.engine.mesh.meshtools import vertex_normals  # numba kernels
    from ctui.engine.mesh.multilabel import multilabel_marching_cubes  # numba kernels

    out = {}
    for k, (v, f) in sorted(multilabel_marching_cubes(lab, affine=aff, objects=objects).items()):
        meta = {"method": "mask-binary-multilabel", "level": 0.5}
        if note:
            meta["note"] = note
        out[k] = Mesh(vertices=v, faces=f, normals=vertex_normals(v, f), object_id=k, meta=meta)
    return out


#: scattered objects (noise, specks): filling under SPARSE_FILL of a bounding box over
#: SPARSE_MIN_BOX voxels with under SPARSE_INNER of their voxels inside (all six
#: neighbours in the object) get a terraced surface from the one-pass multi-label kernel
#: instead of a smoothed signed distance over their whole box (a 255-label noise map:
#: 226 s -> seconds). Thin but compact objects (lines, plates) fill their boxes.
SPARSE_FILL = 0.05
SPARSE_MIN_BOX = 32 ** 3
SPARSE_INNER = 0.1


def _scattered(lab: np.ndarray, box: tuple[slice, ...], k: int) -> bool:
    """Whether object ``k`` is scattered specks in its box (see :data:`SPARSE_FILL`)."""
    box_voxels = int(np.prod([b.stop - b.start for b in box]))
    if box_voxels <= SPARSE_MIN_BOX:
        return False
    m = lab[box] == k
    count = int(np.count_nonzero(m))
    if count >= SPARSE_FILL * box_voxels or min(m.shape) < 3:
        return False
    c = m[1:-1, 1:-1, 1:-1]
    inner = c & m[:-2, 1:-1, 1:-1] & m[2:, 1:-1, 1:-1] & m[1:-1, :-2, 1:-1] & m[1:-1, 2:, 1:-1]
    inner &= m[1:-1, 1:-1, :-2] & m[1:-1, 1:-1, 2:]
    return int(np.count_nonzero(inner)) < SPARSE_INNER * count


def label_surfaces(labels: np.ndarray, *, spacing: Sequence[float] = (1.0, 1.0, 1.0),
                   origin: Sequence[float] = (0.0, 0.0, 0.0), direction: np.ndarray | None = None,
                   smooth: bool = True, objects: Sequence[int] | None = None, sigma_mm: float | None = None,
                   interpolate_z: int | None = None, progress: Progress | None = None) -> dict[int, Mesh]:
    """One surface per object of a label map.

    Parameters
    ----------
    labels : ndarray uint8 (nz, ny, nx)
        0 background, 1..255 objects.
    spacing, origin, direction : geometry as in :func:`isosurface`.
    smooth : bool
        True: smoothed signed-distance surfaces (volume kept equal to the voxel
        volume), one object at a time inside its bounding box (the distance field is
        per object). False: terraced discrete marching cubes of every object in one
        pass over the label map (:mod:`ctui.engine.mesh.multilabel`).
    objects : sequence of int, optional
        Only these object ids.
    progress : callback ``(done, total, message)``, optional; may cancel
        (:class:`~ctui.engine.core.progress.Cancelled`) between objects.

    Returns
    -------
    dict {object id: Mesh}
        Objects with no voxel are absent. Smooth: one scan of the label map finds
        every object's bounding box; each object is then meshed inside its box only.
        Thin objects (1-2 voxels across) are smoothed less so they keep a surface;
        scattered objects (specks filling under 5 % of their box: noise, see
        :data:`SPARSE_FILL`) get a terraced surface from one multi-label pass; both say
        so in ``mesh.meta["note"]``.
    """
    from scipy.ndimage import find_objects

    lab = np.asarray(labels)
    if lab.ndim != 3:
        raise ValueError(f"label_surfaces needs a 3D label map, got shape {lab.shape}")
    if not np.issubdtype(lab.dtype, np.integer):
        check_allocation(lab.size * 4, what="an integer copy of the label map")
        lab = lab.astype(np.int32)
    aff = affine_from(spacing, origin, direction)
    wanted = None if objects is None else {int(o) for o in objects}
    if not smooth:
        report(progress, 0, 1, "terraced surfaces")
        out = _terraced(lab, aff, objects)
        report(progress, 1, 1, "terraced surfaces")
        return out
    boxes = find_objects(lab)
    todo = [(i + 1, box) for i, box in enumerate(boxes)
            if box is not None and (wanted is None or i + 1 in wanted)]
    out: dict[int, Mesh] = {}
    sparse: list[int] = []
    for n, (k, box) in enumerate(todo):
        report(progress, n, len(todo), f"object {k}")
        if _scattered(lab, box, k):
            sparse.append(k)
            continue
        mesh = _object_mesh(lab, box, k, spacing, aff, smooth=smooth, sigma_mm=sigma_mm,
                            interpolate_z=interpolate_z, keep_volume=smooth)
        mesh.object_id = k
        out[k] = mesh
    if sparse:
        report(progress, len(todo) - 1, len(todo), f"{len(sparse)} scattered objects")
        out.update(_terraced(lab, aff, sparse, note="scattered object (specks, under 5 % of its box): terraced surface"))
    report(progress, len(todo), len(todo), "surfaces")
    return dict(sorted(out.items()))
