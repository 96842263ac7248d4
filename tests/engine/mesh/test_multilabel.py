"""One-pass multi-label marching cubes: one closed surface per object, identical to
meshing each object's mask on its own, whatever the thread count."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.meshdata import Mesh
from ctui.engine.mesh.meshtools import mesh_report
from ctui.engine.mesh.multilabel import multilabel_marching_cubes
from ctui.engine.mesh.surface import affine_from, label_surfaces, mask_surface

SPACING = (2.0, 0.8, 0.6)  # (dz, dy, dx) mm


def _labels():
    """Two touching balls, a ball inside a shell (nested objects), a box on the
    volume's corner, a one-voxel object and random speckle inside a block (ambiguous
    faces everywhere)."""
    lab = np.zeros((60, 70, 80), np.uint8)
    z, y, x = np.mgrid[:60, :70, :80]
    lab[(x - 20) ** 2 + (y - 20) ** 2 + (z - 15) ** 2 <= 10 ** 2] = 1
    lab[(x - 38) ** 2 + (y - 20) ** 2 + (z - 15) ** 2 <= 9 ** 2] = 2  # overwrites a cap of 1: they touch
    r = np.sqrt((x - 55) ** 2 + (y - 50) ** 2 + (z - 40) ** 2)
    lab[(r >= 8) & (r <= 12)] = 3
    lab[r < 5] = 4  # inside the shell's cavity
    lab[:4, :5, :6] = 5  # touches three faces of the volume
    lab[30, 10, 70] = 6
    rng = np.random.default_rng(7)
    blk = lab[40:58, 5:30, 5:30]
    blk[rng.random(blk.shape) < 0.45] = 9
    return lab


def test_each_object_closed_and_equal_to_its_own_mask_surface():
    lab = _labels()
    aff = affine_from(SPACING, (10.0, -5.0, 3.0))
    out = multilabel_marching_cubes(lab, affine=aff)
    assert sorted(out) == [1, 2, 3, 4, 5, 6, 9]
    for k, (v, f) in out.items():
        rep = mesh_report(Mesh(v, f))
        assert rep["watertight"] and rep["non_manifold_edges"] == 0 and rep["boundary_edges"] == 0, k
        ref = mask_surface(lab == k, spacing=SPACING, origin=(10.0, -5.0, 3.0), smooth=False)
        # the same triangles as a marching cubes of the object's mask alone
        assert len(f) == len(ref.faces) and len(v) == len(ref.vertices), k
        assert Mesh(v, f).volume_mm3() == pytest.approx(ref.volume_mm3(), rel=1e-5, abs=1e-4), k
        assert np.allclose(np.sort(v, axis=0), np.sort(ref.vertices, axis=0), atol=1e-3), k
    # the shell is a closed surface with a cavity: two components, Euler characteristic 4
    assert mesh_report(Mesh(*out[3]))["euler"] == 4
    # outward orientation: positive volume close to the voxel volume for a big smooth object
    v1 = Mesh(*out[1]).volume_mm3()
    assert v1 > 0 and v1 == pytest.approx((lab == 1).sum() * np.prod(SPACING), rel=0.03)


@pytest.mark.parametrize("threads", [1, 2, 3, 7])
def test_thread_count_does_not_change_the_result(threads):
    lab = _labels()
    a = multilabel_marching_cubes(lab, threads=1)
    b = multilabel_marching_cubes(lab, threads=threads)
    assert sorted(a) == sorted(b)
    for k in a:
        assert np.array_equal(a[k][0], b[k][0]) and np.array_equal(a[k][1], b[k][1])


def test_label_surfaces_terraced_uses_one_pass_and_objects_filter():
    lab = _labels()
    out = label_surfaces(lab, spacing=SPACING, smooth=False, objects=[2, 4])
    assert sorted(out) == [2, 4]
    for k, m in out.items():
        assert m.object_id == k and m.meta["method"] == "mask-binary-multilabel"
        assert m.normals is not None and m.normals.shape == m.vertices.shape
        # normals point outwards: away from the object's centroid on a ball
        c = m.vertices.mean(axis=0)
        assert np.mean(np.sum((m.vertices - c) * m.normals, axis=1) > 0) > 0.95
    assert multilabel_marching_cubes(np.zeros((4, 4, 4), np.uint8)) == {}


@pytest.mark.slow
def test_any_integer_ids_keep_their_ids():
    lab = _labels().astype(np.int64)
    ref = multilabel_marching_cubes(lab)
    odd = np.where(lab == 1, -7, np.where(lab == 2, 1_000_000, lab))
    out = multilabel_marching_cubes(odd)
    assert sorted(out) == sorted([-7, 1_000_000] + [k for k in ref if k not in (1, 2)])
    assert np.array_equal(out[-7][1], ref[1][1]) and np.array_equal(out[1_000_000][0], ref[2][0])
    only = multilabel_marching_cubes(odd, objects=[-7])
    assert list(only) == [-7]
    with pytest.raises(ValueError, match="whole numbers"):
        multilabel_marching_cubes(lab.astype(np.float32) + 0.5)
