"""Isosurfaces, mask surfaces without staircase, label maps: volumes against analytic truths."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.mesh.meshtools import mesh_report
from ctui.engine.mesh.surface import isosurface, label_surfaces, mask_surface


@pytest.fixture(autouse=True)
def _compiled_kernels(monkeypatch):
    """The compiled kernels (DP tiling), whatever the state of numba's cache: the
    first-use fallbacks are tested in test_cold_start.py."""
    monkeypatch.setenv("CTUI_KERNELS", "compiled")

SPACING = (2.5, 0.7, 0.7)  # (dz, dy, dx) mm


def ellipsoid_mask(axes_xyz, shape=(36, 110, 110), spacing=SPACING, centre_shift=(0.3, -0.2, 0.4)):
    nz, ny, nx = shape
    z, y, x = np.mgrid[:nz, :ny, :nx]
    c = [nx / 2 * spacing[2] + centre_shift[0], ny / 2 * spacing[1] + centre_shift[1], nz / 2 * spacing[0] + centre_shift[2]]
    q = ((x * spacing[2] - c[0]) / axes_xyz[0]) ** 2 + ((y * spacing[1] - c[1]) / axes_xyz[1]) ** 2 \
        + ((z * spacing[0] - c[2]) / axes_xyz[2]) ** 2
    return q <= 1.0, 4.0 / 3.0 * np.pi * np.prod(axes_xyz)


def _face_normal_error(mesh, axes_xyz, centre):
    """Mean angle (deg) between face normals and the analytic ellipsoid normals."""
    v = mesh.vertices.astype(np.float64)
    f = mesh.faces
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    fn = np.cross(b - a, c - a)
    fn /= np.linalg.norm(fn, axis=1, keepdims=True) + 1e-30
    p = (a + b + c) / 3 - centre
    g = p / np.asarray(axes_xyz, float) ** 2
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    return float(np.degrees(np.arccos(np.clip((fn * g).sum(1), -1, 1))).mean())


@pytest.mark.parametrize("axes", [(25.0, 25.0, 25.0), (30.0, 20.0, 35.0)])
def test_mask_surface_volume_closed_and_smooth(axes):
    mask, analytic = ellipsoid_mask(axes)
    smooth = mask_surface(mask, spacing=SPACING, origin=(-50.0, 12.0, 300.0))
    rep = mesh_report(smooth)
    assert rep["watertight"] and rep["winding_consistent"] and rep["components"] == 1
    assert abs(rep["volume_ml"] * 1000 / analytic - 1) < 0.01
    voxel_ml = mask.sum() * np.prod(SPACING) / 1000
    assert abs(rep["volume_ml"] / voxel_ml - 1) < 0.002  # level corrected to the voxel volume
    # no staircase: normals follow the true surface much better than binary marching cubes
    terraced = mask_surface(mask, spacing=SPACING, smooth=False)
    nz, ny, nx = mask.shape
    centre = np.array([nx / 2 * 0.7 + 0.3, ny / 2 * 0.7 - 0.2, nz / 2 * 2.5 + 0.4])
    e_smooth = _face_normal_error(smooth, axes, centre + [-50.0, 12.0, 300.0])
    e_terraced = _face_normal_error(terraced, axes, centre)
    assert e_smooth < 0.5 * e_terraced
    assert e_smooth < 8.0


def test_shape_based_interpolation_keeps_volume():
    mask, analytic = ellipsoid_mask((20.0, 15.0, 30.0), shape=(30, 80, 80))
    base = mask_surface(mask, spacing=SPACING)
    fine = mask_surface(mask, spacing=SPACING, interpolate_z=3)
    rep = mesh_report(fine)
    assert rep["watertight"]
    assert fine.n_faces > 1.5 * base.n_faces
    assert abs(rep["volume_ml"] * 1000 / analytic - 1) < 0.01


def test_isosurface_of_smooth_field_matches_analytic_volume():
    # a distance-like field at anisotropic spacing, direction with a flip (left-handed)
    nz, ny, nx = 40, 100, 100
    z, y, x = np.mgrid[:nz, :ny, :nx].astype(np.float32)
    r = 22.0
    d = np.sqrt(((x - 50) * 0.7) ** 2 + ((y - 49) * 0.7) ** 2 + ((z - 20) * 2.5) ** 2)
    vol = (r - d).astype(np.float32)
    for direction in (np.eye(3), np.diag([1.0, -1.0, 1.0])):
        m = isosurface(vol, 0.0, spacing=SPACING, origin=(10, 20, 30), direction=direction)
        rep = mesh_report(m)
        assert rep["watertight"] and rep["winding_consistent"]
        assert abs(rep["volume_ml"] * 1000 / (4 / 3 * np.pi * r**3) - 1) < 0.01
        assert m.volume_mm3() > 0
        # normals point outwards (away from the centre)
        ctr = m.vertices.mean(axis=0)
        assert (np.sum((m.vertices - ctr) * m.normals, axis=1) > 0).mean() > 0.99


def test_isosurface_close_option_closes_border_objects():
    a = np.zeros((10, 12, 12), np.int16)
    a[:, 3:9, 3:9] = 500  # a bar through the whole z range
    open_mesh = isosurface(a, 250, spacing=(2, 1, 1))
    assert mesh_report(open_mesh)["boundary_edges"] > 0
    closed = isosurface(a, 250, spacing=(2, 1, 1), close=True)
    rep = mesh_report(closed)
    assert rep["watertight"]
    # box of 6 x 6 voxels over 10 slices: faces halfway between voxel centres (720 mm3),
    # minus marching cubes' chamfers along the 12 box edges
    assert 0.95 * 720 < rep["volume_ml"] * 1000 < 720


def test_label_surfaces_one_mesh_per_object():
    lab = np.zeros((30, 60, 60), np.uint8)
    lab[3:12, 5:25, 5:30] = 1
    lab[15:28, 30:55, 20:50] = 4
    lab[0:5, 40:60, 0:10] = 7  # touches three borders: still closed
    out = label_surfaces(lab, spacing=SPACING, origin=(1, 2, 3))
    assert sorted(out) == [1, 4, 7]
    for k, m in out.items():
        rep = mesh_report(m)
        assert m.object_id == k
        assert rep["watertight"], k
        assert rep["volume_ml"] == pytest.approx((lab == k).sum() * np.prod(SPACING) / 1000, rel=0.01)
    only = label_surfaces(lab, spacing=SPACING, objects=[4], smooth=False)
    assert list(only) == [4]
    assert mesh_report(only[4])["watertight"]


def test_empty_mask_gives_empty_mesh():
    m = mask_surface(np.zeros((5, 5, 5), bool), spacing=SPACING)
    assert m.n_faces == 0


@pytest.fixture(scope="module")
def phantom():
    from ctui.engine.io.phantom import make_phantom

    return make_phantom()


def kidney_mask(volume, truth, name):
    from scipy.ndimage import label

    obj = next(o for o in truth["objects"] if o["name"] == name)
    lo, hi = obj["hu_range"]
    comp, _ = label((volume.data >= lo) & (volume.data <= hi))
    seed = tuple(obj["seed_zyx"])
    assert comp[seed] > 0
    return comp == comp[seed], obj["volume_ml"]


@pytest.mark.parametrize("name", ["kidney_left", "kidney_right"])
def test_phantom_kidneys_both_methods(phantom, name):
    from ctui.engine.core.borders import object_borders
    from ctui.engine.mesh.contour_connect import connect_contours

    volume, truth = phantom
    mask, analytic_ml = kidney_mask(volume, truth, name)
    geo = dict(spacing=volume.spacing, origin=volume.origin, direction=volume.direction)
    sdf = mesh_report(mask_surface(mask, **geo))
    cc = mesh_report(connect_contours(object_borders(mask.astype(np.uint8), 1), **geo))
    for rep in (sdf, cc):
        assert rep["watertight"]
        assert abs(rep["volume_ml"] / analytic_ml - 1) < 0.03
    assert abs(sdf["volume_ml"] / cc["volume_ml"] - 1) < 0.03


def test_lobster_components_all_closed():
    from support import lobster

    data = lobster()
    m = isosurface(data, 100, spacing=(1.4, 1.0, 1.0))
    rep = mesh_report(m)
    assert rep["triangles"] > 100_000
    assert rep["boundary_edges"] == 0 and rep["non_manifold_edges"] == 0
    assert rep["closed_components"] == rep["components"]
    assert rep["winding_consistent"]


@pytest.mark.parametrize("shape", ["line", "line2", "plate", "plate2"])
@pytest.mark.parametrize("spacing", [(1.0, 1.0, 1.0), (3.0, 0.7, 0.7)])
def test_thin_objects_keep_a_closed_surface(shape, spacing):
    lab = np.zeros((16, 18, 18), np.uint8)
    if shape == "line":
        lab[8, 9, 3:15] = 1
    elif shape == "line2":
        lab[8:10, 9:11, 3:15] = 1
    elif shape == "plate":
        lab[8, 3:15, 3:15] = 1
    else:
        lab[8:10, 3:15, 3:15] = 1
    m = label_surfaces(lab, spacing=spacing)[1]
    rep = mesh_report(m)
    assert rep["triangles"] > 0 and rep["watertight"] and rep["components"] == 1
    voxels_ml = lab.sum() * np.prod(spacing) / 1000.0
    assert abs(rep["volume_ml"] / voxels_ml - 1) < 0.06


def test_noise_labels_bounded_with_progress_and_cancel():
    from ctui.engine.core.progress import Cancelled

    rng = np.random.default_rng(3)
    lab = rng.integers(0, 64, (34, 40, 40)).astype(np.uint8)
    lab[2:12, 5:25, 5:25] = 70  # one real object among the noise
    seen = []
    surf = label_surfaces(lab, spacing=(2.0, 1.0, 1.0), progress=lambda d, t, m="": seen.append((d, t)))
    assert sorted(surf) == sorted(int(k) for k in np.unique(lab) if k)
    assert seen and seen[-1][0] == seen[-1][1]
    for k in (1, 33, 63):
        assert "scattered" in surf[k].meta.get("note", "")
        assert mesh_report(surf[k])["watertight"]
    real = mesh_report(surf[70])
    assert real["watertight"] and abs(real["volume_ml"] / (10 * 20 * 20 * 2 / 1000) - 1) < 0.01
    assert "note" not in surf[70].meta
    with pytest.raises(Cancelled):
        label_surfaces(lab, spacing=(2.0, 1.0, 1.0), progress=lambda d, t, m="": d < 3)
