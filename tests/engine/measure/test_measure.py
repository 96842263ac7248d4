"""Volumes, areas and shape figures: voxel and Gauss-theorem mesh volumes against
analytic spheres and ellipsoids, mesh components and open meshes, principal axes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ctui.engine.core.meshdata import Mesh
from ctui.engine.measure.stats import (
    label_stats,
    mesh_components,
    mesh_stats,
    object_stats,
    principal_axes,
    stats_json,
)
from ctui.engine.measure.summary import measure_object


def _ellipsoid(sp, semi, centre_jitter=(0.17, -0.23, 0.31), rot=None):
    """Binary ellipsoid mask; semi-axes (x, y, z) mm; returns mask, analytic volume mm^3."""
    semi = np.asarray(semi, float)
    ext = semi.max() + 3 * max(sp)
    shape = [int(2 * ext / s) + 1 for s in sp]
    c = np.array([shape[2] * sp[2], shape[1] * sp[1], shape[0] * sp[0]]) / 2 + np.asarray(centre_jitter)
    zz, yy, xx = np.meshgrid(*[np.arange(n) * s for n, s in zip(shape, sp)], indexing="ij")
    p = np.stack([xx, yy, zz], -1) - c
    if rot is not None:
        p = p @ rot  # coordinates in the ellipsoid frame
    m = ((p / semi) ** 2).sum(-1) <= 1.0
    return m, 4.0 / 3.0 * math.pi * semi.prod(), c


def _sdf_sphere_mesh(c, r, h=0.5):
    """A closed sphere mesh by scikit-image marching cubes on an analytic distance (test helper)."""
    from skimage.measure import marching_cubes

    n = int(2 * (r + 2) / h) + 1
    g = (np.arange(n) * h) - (r + 2)
    zz, yy, xx = np.meshgrid(g, g, g, indexing="ij")
    d = np.sqrt(xx**2 + yy**2 + zz**2) - r
    v, f, _, _ = marching_cubes(-d, 0.0, spacing=(h, h, h))
    xyz = v[:, ::-1] + (np.asarray(c) - (r + 2))
    return Mesh(vertices=xyz, faces=f[:, ::-1].astype(np.int64))


def test_mesh_stats_per_component_and_open_mesh_warning():
    a = _sdf_sphere_mesh((0, 0, 0), 5.0)
    b = _sdf_sphere_mesh((20, 0, 0), 3.0)
    both = Mesh(vertices=np.vstack([a.vertices, b.vertices]), faces=np.vstack([a.faces, b.faces + len(a.vertices)]))
    n, lab = mesh_components(both)
    assert n == 2 and set(np.unique(lab)) == {0, 1}
    st = mesh_stats(both)
    assert st["closed"] and st["n_components"] == 2 and not st["warnings"]
    vols = sorted(c["volume_mm3"] for c in st["components"])
    assert vols[0] == pytest.approx(4 / 3 * math.pi * 27, rel=0.02)
    assert vols[1] == pytest.approx(4 / 3 * math.pi * 125, rel=0.02)
    assert st["volume_mm3"] == pytest.approx(sum(vols))
    assert st["area_mm2"] == pytest.approx(4 * math.pi * (25 + 9), rel=0.03)
    # inward orientation gives the same positive volume
    flipped = Mesh(vertices=both.vertices, faces=both.faces[:, ::-1])
    assert mesh_stats(flipped)["volume_mm3"] == pytest.approx(st["volume_mm3"])
    # remove a few faces: the component is not closed any more and a warning says so
    holed = Mesh(vertices=both.vertices, faces=both.faces[5:])
    sh = mesh_stats(holed)
    assert not sh["closed"]
    assert any("not closed" in w for w in sh["warnings"])
    assert sum(not c["closed"] for c in sh["components"]) == 1


def _has_mask_surface() -> bool:
    try:
        from ctui.engine.mesh.surface import mask_surface  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.mark.parametrize(
    "sp,semi",
    [
        ((1.0, 1.0, 1.0), (10.5, 10.5, 10.5)),
        ((1.5, 0.5, 0.5), (16.0, 13.0, 15.0)),
        ((3.0, 1.0, 1.0), (34.0, 40.0, 31.0)),
    ],
    ids=["sphere-iso", "ellipsoid-1:3", "ellipsoid-3:1"],
)
def test_object_stats_volumes_against_analytic(sp, semi):
    """Spheres/ellipsoids with radius >= 10 voxels along every axis, spacing up to 1:3:
    voxel volume and Gauss mesh volume (MESH's mask_surface) within 0.5%."""
    m, v_true, c = _ellipsoid(sp, semi)
    labels = m.astype(np.uint8) * 3
    st = object_stats(labels, 3, spacing=sp, mesh=_has_mask_surface())
    assert st["volume_voxels_mm3"] == pytest.approx(v_true, rel=0.005)
    assert np.allclose(st["centroid_mm"], c, atol=0.05 * max(sp))
    lo, hi = st["bbox_mm"]
    assert np.allclose(lo, c - semi, atol=max(sp)) and np.allclose(hi, c + semi, atol=max(sp))
    assert sorted(st["principal_axes_mm"]) == pytest.approx(sorted(2 * np.asarray(semi)), rel=0.02)
    if not _has_mask_surface():
        pytest.skip("ctui.engine.mesh.surface.mask_surface (MESH) not available yet: voxel figures checked only")
    assert st["mesh_closed"]
    assert st["volume_mesh_mm3"] == pytest.approx(v_true, rel=0.005)
    assert abs(st["volume_difference_percent"]) < 1.0
    # surface area of a sphere / ellipsoid (Knud Thomsen's approximation, 1% accurate)
    a, b, cc = semi
    p = 1.6075
    area = 4 * math.pi * (((a * b) ** p + (a * cc) ** p + (b * cc) ** p) / 3) ** (1 / p)
    assert st["area_mm2"] == pytest.approx(area, rel=0.02)


def test_principal_axes_of_a_rotated_ellipsoid():
    ang = math.radians(30)
    rot = np.array([[math.cos(ang), -math.sin(ang), 0], [math.sin(ang), math.cos(ang), 0], [0, 0, 1]])
    m, _, _ = _ellipsoid((1.0, 0.5, 0.5), (15.0, 8.0, 5.0), rot=rot)
    pa = principal_axes(m, spacing=(1.0, 0.5, 0.5))
    assert pa["lengths_mm"] == pytest.approx([30.0, 16.0, 10.0], rel=0.02)
    # the major axis is the ellipsoid's x axis rotated by 30 degrees in the x-y plane
    assert abs(pa["axes"][0] @ rot[:, 0]) > 0.999


def test_object_stats_geometry_and_json():
    m, _, _ = _ellipsoid((2.0, 1.0, 1.0), (12.0, 12.0, 12.0))
    labels = np.zeros(m.shape, np.uint8)
    labels[m] = 1
    labels[:3, :3, :3] = 2
    origin = (-50.0, 20.0, 100.0)
    direction = np.array([[-1.0, 0, 0], [0, -1.0, 0], [0, 0, 1.0]])
    st = label_stats(labels, spacing=(2.0, 1.0, 1.0), origin=origin, direction=direction, mesh=False)
    assert set(st) == {1, 2}
    assert st[2]["voxels"] == 27 and st[2]["volume_voxels_mm3"] == pytest.approx(27 * 2.0)
    # object 2 sits at indices 0..2: its centroid is origin + direction @ (1, 1, 2) mm
    assert np.allclose(st[2]["centroid_mm"], np.asarray(origin) + direction @ np.array([1.0, 1.0, 2.0]))
    lo, hi = st[2]["bbox_mm"]
    assert np.allclose(hi - lo, [3.0, 3.0, 6.0])
    import json

    doc = stats_json(st[1])
    json.dumps(doc)
    assert doc["volume_mesh_ml"] is None and doc["voxels"] == int(m.sum())
    from ctui.engine.core.errors import CtuiError

    with pytest.raises(CtuiError):
        object_stats(labels, 7, spacing=(1, 1, 1))


def test_measure_object_report_for_the_tui():
    """measure_object: the CLI's JSON keys plus drawable rows; voxel path points."""
    sp = (0.5, 0.5, 0.5)
    shape = (24, 24, 60)
    zz, yy, xx = np.meshgrid(*[np.arange(n) * 0.5 for n in shape], indexing="ij")
    labels = np.zeros(shape, np.uint8)
    labels[((yy - 6.1) ** 2 + (zz - 5.9) ** 2 <= 2.5**2) & (xx > 2) & (xx < 27)] = 4
    res = measure_object(labels, 4, spacing=sp, path="4,6.1,5.9;25,6.1,5.9", step_mm=1.0, between=(5, 15), mesh=False)
    for k in ("volume_ml", "area_mm2", "path_length_mm", "sections", "between", "rows", "path_mm"):
        assert k in res
    assert res["path_length_mm"] == pytest.approx(21.0, abs=1e-6)
    assert len(res["sections"]) == 22 and len(res["rows"]) == 22
    mid = res["rows"][10]
    assert mid["area_mm2"] == pytest.approx(math.pi * 2.5**2, rel=0.03)
    # the drawn contour lies on the cylinder (patient mm)
    c = mid["contour_mm"]
    assert np.abs(np.hypot(c[:, 1] - 6.1, c[:, 2] - 5.9) - 2.5).max() < 0.3
    assert res["between"]["volume_ml"] == pytest.approx(math.pi * 2.5**2 * 10 / 1000, rel=0.03)
    # the same path as voxel indices (z, y, x)
    res2 = measure_object(labels, 4, spacing=sp, path=[[11.8, 12.2, 8], [11.8, 12.2, 50]], path_voxels=True,
                          step_mm=1.0, mesh=False)
    assert res2["path_length_mm"] == pytest.approx(21.0, abs=1e-6)
    assert res2["sections"][10]["area_mm2"] == pytest.approx(res["sections"][10]["area_mm2"], rel=1e-3)
