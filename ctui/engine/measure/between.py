"""Volume of an object between two planes normal to a path (thesis ch. 7.2).

The planes normal to the path at arc lengths s1 < s2 bound a slab; the region is grown
(26-connectivity) from the path voxels between the two points through object voxels
inside the slab only, so parallel structures the planes also cut are excluded; the
function ``max(sdf, psi1, psi2)`` (psi = signed distances to the half-spaces, mm)
restricted to that region is meshed at its zero level with the mesh stage's
``isosurface`` (flat, exact caps) and the volume is measured by the Gauss theorem.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.measure.fields import ObjectField, object_field
from ctui.engine.measure.paths import index_matrix, path_points, path_spline
from ctui.engine.measure.sections import sections_along_path
from ctui.engine.measure.stats import mesh_stats
from ctui.engine.mesh.surface import isosurface


def _slab_region(field: ObjectField, spl, s1, s2, p1, n1, p2, n2):
    """(psi1, psi2, obj, region): signed distances (mm, negative on the kept side) of the
    crop's voxel centres to the two planes, the object, and its part between the planes
    that the path runs through (26-connected)."""
    from scipy import ndimage as ndi

    shape = field.sdf.shape
    mfwd = index_matrix(field.spacing, field.direction)
    o = field.crop_origin
    zz, yy, xx = (np.arange(n, dtype=np.float32) for n in shape)

    def plane_dist(p, nrm, sign):
        # signed distance (mm) of voxel centres to the plane, negative on the kept side
        a = sign * (mfwd.T @ nrm)  # per-index-axis slope
        b = sign * float((o - p) @ nrm)
        return (b + a[0] * zz[:, None, None] + a[1] * yy[None, :, None] + a[2] * xx[None, None, :]).astype(np.float32)

    psi1 = plane_dist(p1, n1, -1.0)  # kept: beyond p1 along the path
    psi2 = plane_dist(p2, n2, 1.0)  # kept: before p2
    obj = field.mask | (field.sdf < 0)
    cand = obj & (psi1 <= 0) & (psi2 <= 0)
    ss = np.linspace(s1, s2, max(int((s2 - s1) / (0.25 * min(field.spacing))) + 2, 2))
    seeds = np.rint(field.to_index(spl(ss))).astype(int)
    inb = np.all((seeds >= 0) & (seeds < np.array(shape)), axis=1)
    seeds = seeds[inb]
    seeds = seeds[cand[seeds[:, 0], seeds[:, 1], seeds[:, 2]]] if len(seeds) else seeds
    if len(seeds) == 0:
        raise CtuiError("the path does not run inside the object between the two planes")
    lab, _ = ndi.label(cand, structure=np.ones((3, 3, 3)))
    keep = np.unique(lab[seeds[:, 0], seeds[:, 1], seeds[:, 2]])
    keep = keep[keep > 0]
    return psi1, psi2, obj, np.isin(lab, keep)


def _pv_volume(field: ObjectField, obj, region, psi1, psi2, n1, n2) -> float:
    """Cross-check (mm3): partial-volume integral of the smoothed indicator over the
    region's blur footprint (voxels nearer the region than any excluded structure),
    weighted by each voxel's fraction on the kept side of both planes."""
    from scipy import ndimage as ndi

    others = obj & ~region
    tail = math.ceil(3.3 * field.sigma_vox) + 1
    foot = ndi.binary_dilation(region, structure=np.ones((3, 3, 3)), iterations=tail)
    if others.any():
        d_reg = ndi.distance_transform_edt(~region, sampling=field.spacing)
        d_oth = ndi.distance_transform_edt(~others, sampling=field.spacing)
        foot &= d_reg < d_oth
    sp_xyz = np.asarray(field.spacing)[::-1]
    ext = [float(np.abs(field.direction.T @ nn) @ sp_xyz) for nn in (n1, n2)]  # voxel extent along each normal
    w = np.clip(0.5 - psi1 / ext[0], 0, 1) * np.clip(0.5 - psi2 / ext[1], 0, 1)
    return float((field.indicator * w)[foot].sum()) * float(np.prod(field.spacing))


def volume_between(
    mask: np.ndarray | None,
    path_mm: np.ndarray,
    s1: float,
    s2: float,
    *,
    spacing=(1.0, 1.0, 1.0),
    origin=(0.0, 0.0, 0.0),
    direction=None,
    field: ObjectField | None = None,
    return_mesh: bool = False,
) -> dict[str, Any]:
    """Volume of the object between the planes normal to a path at arc lengths s1, s2.

    Parameters
    ----------
    mask : ndarray (z, y, x) or None
        The object (ignored when ``field`` is given).
    path_mm : ndarray (n, 3)
        The path, patient mm (x, y, z).
    s1, s2 : float
        Arc lengths (mm) of the two planes (any order).
    return_mesh : bool
        Add the region's surface (:class:`~ctui.engine.core.meshdata.Mesh`) as ``"mesh"``.

    Returns
    -------
    dict with ``volume_mm3``, ``volume_ml`` (Gauss theorem on the region's surface),
    ``volume_pv_mm3`` (cross-check: partial-volume integral of the smoothed mask over
    the region, weighted by the planes), ``area1_mm2``, ``area2_mm2`` (sections at
    the planes), ``s1_mm``, ``s2_mm``, ``voxels`` (region voxel count),
    ``closed`` (mesh closed), ``warnings``.
    """
    if field is None:
        if mask is None:
            raise CtuiError("volume_between needs a mask or a field")
        field = object_field(mask, spacing=spacing, origin=origin, direction=direction)
    spl, total = path_spline(path_mm)
    s1, s2 = sorted((float(s1), float(s2)))
    if s1 < -1e-6 or s2 > total + 1e-6:
        raise CtuiError(f"plane positions must lie on the path (0 to {total:.1f} mm), got {s1:g}, {s2:g}")
    if s2 - s1 <= 0:
        raise CtuiError("the two planes must be at different positions along the path")
    from scipy import ndimage as ndi

    (p1, p2), (n1, n2) = path_points(path_mm, [s1, s2])
    psi1, psi2, obj, region = _slab_region(field, spl, s1, s2, p1, n1, p2, n2)
    shape = field.sdf.shape
    mfwd = index_matrix(field.spacing, field.direction)
    o = field.crop_origin
    near = ndi.binary_dilation(region, structure=np.ones((3, 3, 3)))
    F = np.maximum(np.maximum(field.sdf, psi1), psi2)
    pos = float(max(field.spacing))
    F = np.where(near, F, np.maximum(F, pos))
    # crop to the region for meshing
    idx = np.nonzero(near)
    lo = np.array([max(int(i.min()) - 1, 0) for i in idx])
    hi = np.array([min(int(i.max()) + 2, n) for i, n in zip(idx, shape)])
    sub = F[tuple(slice(a, b) for a, b in zip(lo, hi))]
    sub = np.pad(sub, 1, constant_values=pos)  # closed surface even at the crop edge
    sub_origin = o + mfwd @ (lo.astype(np.float64) - 1.0)
    mesh = isosurface(-sub, 0.0, spacing=tuple(field.spacing), origin=tuple(sub_origin), direction=field.direction)
    st = mesh_stats(mesh)
    vol_pv = _pv_volume(field, obj, region, psi1, psi2, n1, n2)
    areas = sections_along_path(None, path_mm, field=field, at_s=[s1, s2], flags=False)
    out = {
        "volume_mm3": st["volume_mm3"],
        "volume_ml": st["volume_mm3"] / 1000.0,
        "volume_pv_mm3": vol_pv,
        "area1_mm2": areas[0]["area_mm2"],
        "area2_mm2": areas[1]["area_mm2"],
        "s1_mm": s1,
        "s2_mm": s2,
        "voxels": int(region.sum()),
        "closed": st["closed"],
        "warnings": st["warnings"],
    }
    if return_mesh:
        out["mesh"] = mesh
    return out
