"""The numpy STL and PLY writers (issue 27: no trimesh import, no float64 cross products)
write what a reader expects: STL facet normals equal the float64 unit normals, and a
binary PLY reads back through trimesh with the same vertices, faces and normals."""

from __future__ import annotations

import numpy as np

from ctui.engine.core.meshdata import Mesh
from ctui.engine.io.meshes import _STL_DTYPE, load_mesh, save_mesh


def _sphere() -> Mesh:
    from ctui.engine.mesh.surface import isosurface

    z, y, x = np.mgrid[:14, :16, :18]
    d = (9.0 - np.sqrt((x - 8.6) ** 2 + (y - 7.2) ** 2 + (z - 6.9) ** 2)).astype(np.float32)
    return isosurface(d, 3.0, spacing=(1.5, 0.8, 0.7), origin=(-20.0, 5.0, 100.0))


def test_stl_normals_and_vertices(tmp_path):
    m = _sphere()
    save_mesh(tmp_path / "s.stl", m)
    rec = np.fromfile(tmp_path / "s.stl", dtype=_STL_DTYPE, offset=84)
    v = np.asarray(m.vertices, np.float64)
    f = np.asarray(m.faces)
    np.testing.assert_array_equal(rec["v"], m.vertices[f])
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    np.testing.assert_allclose(rec["normal"], n, atol=2e-5)  # float32 cross products: ~1e-5 of a unit vector
    assert not rec["attr"].any()
    back = load_mesh(tmp_path / "s.stl")
    assert back.n_faces == m.n_faces and abs(back.volume_mm3() - m.volume_mm3()) < 1e-6 * abs(m.volume_mm3())


def test_binary_ply_round_trip(tmp_path):
    import trimesh

    m = _sphere()
    for normals in (m.normals, None):
        mesh = Mesh(m.vertices, m.faces, normals)
        save_mesh(tmp_path / "s.ply", mesh)
        head = (tmp_path / "s.ply").read_bytes().split(b"end_header\n")[0].decode()
        assert ("property float nx" in head) == (normals is not None)
        tm = trimesh.load(tmp_path / "s.ply", process=False)
        np.testing.assert_array_equal(np.asarray(tm.vertices, np.float32), m.vertices)
        np.testing.assert_array_equal(tm.faces, m.faces)
        if normals is not None:
            np.testing.assert_allclose(tm.vertex_normals, m.normals, atol=1e-6)
        assert load_mesh(tmp_path / "s.ply").n_faces == m.n_faces
