"""``measure`` and ``export --format dicom-seg`` without whole-volume temporaries (issue 40):
the ids present counted in slabs, the object's box found slab by slab, DICOM-SEG frames packed
one by one; each equals the whole-volume computation it replaces."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.io.labels import present_ids
from ctui.engine.io.segwriter import _packed
from ctui.engine.measure.stats import _bounds, object_stats


def _labels(shape=(37, 29, 23), seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lab = np.zeros(shape, np.uint8)
    lab[3:30, 5:17, 2:9] = 4
    lab[rng.random(shape) < 0.002] = 200
    lab[36, 28, 22] = 9
    return lab


def test_present_ids_equal_unique():
    lab = _labels()
    assert present_ids(lab) == [int(v) for v in np.unique(lab) if v]
    assert present_ids(np.zeros((3, 4, 5), np.uint8)) == []


def test_bounds_equal_those_of_the_whole_mask():
    lab = _labels()
    for oid in (4, 9, 200):
        nz = np.nonzero(lab == oid)
        lo, hi = _bounds(lab, oid, slab=5)
        assert lo.tolist() == [int(i.min()) for i in nz] and hi.tolist() == [int(i.max()) for i in nz]
    assert _bounds(lab, 77) is None


def test_object_stats_in_the_box_equal_a_whole_volume_count():
    lab = _labels()
    st = object_stats(lab, 200, spacing=(2.0, 0.5, 0.7), mesh=False)
    zz, yy, xx = np.nonzero(lab == 200)
    assert st["voxels"] == zz.size
    assert np.allclose(st["centroid_mm"], [xx.mean() * 0.7, yy.mean() * 0.5, zz.mean() * 2.0])


@pytest.mark.parametrize("ny,nx", [(8, 6), (5, 3)])  # whole bytes per frame, and frames sharing bytes
def test_frames_packed_one_by_one_equal_the_whole_stack(ny, nx):
    seg = np.random.default_rng(ny).integers(0, 3, (6, ny, nx)).astype(np.uint8)
    frames = [(s, k) for s in (1, 2) for k in range(6) if (seg[k] == s).any()]
    planes = np.stack([seg[k] == s for s, k in frames])
    want = np.packbits(planes.ravel(), bitorder="little").tobytes()
    assert _packed(seg, frames) == want + b"\0" * (len(want) % 2)
    four = np.stack([seg == 1, seg == 2], axis=-1)
    assert _packed(four, frames) == want + b"\0" * (len(want) % 2)


def test_stl_weld_equals_numpy_unique():
    """``_weld_triangles`` (lexsort) gives ``np.unique(axis=0)``'s vertices and faces, ties and
    -0.0 == 0.0 included."""
    from ctui.engine.io.meshes import _weld_triangles

    rng = np.random.default_rng(3)
    tri = rng.integers(-3, 3, (400, 3, 3)).astype(np.float32)
    tri[0, 0] = (-0.0, 0.0, 1.0)
    tri[1, 1] = (0.0, -0.0, 1.0)
    u, inv = np.unique(tri.reshape(-1, 3), axis=0, return_inverse=True)
    v, f = _weld_triangles(tri)
    assert v.dtype == np.float32 and f.dtype == np.int32
    assert np.array_equal(v, u) and np.array_equal(f, inv.reshape(-1, 3))
    assert np.array_equal(v[f], tri)
