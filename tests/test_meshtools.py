"""Mesh report and repair tools against meshes with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.meshdata import Mesh
from ctui.engine.meshtools import (
    components,
    decimate,
    drop_small,
    keep_largest,
    merge,
    mesh_report,
    repair_orientation,
    smooth_taubin,
    vertex_normals,
    weld,
)


def cube(size=10.0, offset=(0.0, 0.0, 0.0)) -> Mesh:
    v = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float) * size + offset
    # corners index x + 2y + 4z; faces CCW from outside
    f = np.array([
        [0, 2, 1], [1, 2, 3],  # z = 0 (normal -z)
        [4, 5, 6], [5, 7, 6],  # z = 1
        [0, 1, 4], [1, 5, 4],  # y = 0
        [2, 6, 3], [3, 6, 7],  # y = 1
        [0, 4, 2], [2, 4, 6],  # x = 0
        [1, 3, 5], [3, 7, 5],  # x = 1
    ])
    return Mesh(v.astype(np.float32), f.astype(np.int32))


def sphere(r=20.0, noise=0.0, seed=0) -> Mesh:
    from ctui.engine.surface import isosurface

    z, y, x = np.mgrid[:50, :50, :50].astype(np.float32)
    d = np.sqrt((x - 24.5) ** 2 + (y - 24.3) ** 2 + (z - 24.7) ** 2)
    m = isosurface((r - d).astype(np.float32), 0.0)
    if noise:
        rng = np.random.default_rng(seed)
        m.vertices = m.vertices + rng.normal(0, noise, m.vertices.shape).astype(np.float32)
    return m


def test_report_closed_cube():
    rep = mesh_report(cube())
    assert rep == {**rep, "triangles": 12, "vertices": 8, "watertight": True, "non_manifold_edges": 0,
                   "boundary_edges": 0, "euler": 2, "components": 1, "closed_components": 1,
                   "winding_consistent": True}
    assert rep["volume_ml"] == pytest.approx(1.0)
    assert rep["area_mm2"] == pytest.approx(600.0)


def test_report_open_and_non_manifold():
    c = cube()
    open_c = Mesh(c.vertices, c.faces[1:])
    rep = mesh_report(open_c)
    assert not rep["watertight"] and rep["boundary_edges"] == 3 and rep["volume_ml"] == 0.0
    # a third face on edge (0, 1): non-manifold
    v = np.vstack([c.vertices, [[5.0, -5.0, -5.0]]]).astype(np.float32)
    nm = Mesh(v, np.vstack([c.faces, [[0, 1, 8]]]))
    rep = mesh_report(nm)
    assert rep["non_manifold_edges"] == 1 and not rep["watertight"]


def test_report_two_components_volume_only_closed_ones():
    a, b = cube(10), cube(5, offset=(30, 0, 0))
    b_open = Mesh(b.vertices, b.faces[2:])
    rep = mesh_report(merge([a, b_open]))
    assert rep["components"] == 2 and rep["closed_components"] == 1
    assert rep["volume_ml"] == pytest.approx(1.0)
    rep2 = mesh_report(merge([a, b]))
    assert rep2["volume_ml"] == pytest.approx(1.125) and rep2["euler"] == 4


def test_taubin_smooths_without_shrinking():
    noisy = sphere(noise=0.3)
    exact = 4 / 3 * np.pi * 20.0**3
    sm = smooth_taubin(noisy, iterations=20)

    def roughness(m):
        r = np.linalg.norm(m.vertices - m.vertices.mean(0), axis=1)
        return float(np.std(r))

    assert roughness(sm) < 0.5 * roughness(noisy)
    assert abs(sm.volume_mm3() / exact - 1) < 0.01
    assert mesh_report(sm)["watertight"]
    # plain Laplacian (mu = 0) would shrink: Taubin must beat it
    lap = smooth_taubin(noisy, iterations=20, mu=0.0)
    assert abs(sm.volume_mm3() / exact - 1) < abs(lap.volume_mm3() / exact - 1)


def test_decimate_to_target_keeps_closed_and_volume():
    s = sphere()
    d = decimate(s, 2000)
    rep = mesh_report(d)
    assert 1800 <= rep["triangles"] <= 2000
    assert rep["watertight"]
    assert abs(d.volume_mm3() / s.volume_mm3() - 1) < 0.01
    assert decimate(s, 10**9).n_faces == s.n_faces


def test_components_keep_largest_drop_small():
    m = merge([cube(2, (50, 0, 0)), cube(10), cube(4, (-30, 0, 0))])
    parts = components(m)
    assert [p.n_faces for p in parts] == [12, 12, 12]
    big = keep_largest(m)
    assert mesh_report(big)["volume_ml"] == pytest.approx(1.0)
    kept = drop_small(m, min_volume_ml=0.05)
    assert mesh_report(kept)["volume_ml"] == pytest.approx(1.0 + 0.064)


def test_repair_orientation():
    s = sphere(r=12)
    f = s.faces.copy()
    f[::3] = f[::3, ::-1]  # a third of the faces flipped
    bad = Mesh(s.vertices, f)
    assert not mesh_report(bad)["winding_consistent"]
    fixed = repair_orientation(bad)
    rep = mesh_report(fixed)
    assert rep["winding_consistent"] and fixed.volume_mm3() > 0
    inside_out = Mesh(s.vertices, s.faces[:, ::-1].copy())
    assert repair_orientation(inside_out).volume_mm3() == pytest.approx(s.volume_mm3(), rel=1e-6)


def test_weld_and_normals():
    c = cube()
    soup = Mesh(c.vertices[c.faces.ravel()], np.arange(36).reshape(12, 3).astype(np.int32))
    assert not mesh_report(soup)["watertight"]
    w = weld(soup)
    assert w.n_vertices == 8 and mesh_report(w)["watertight"]
    n = vertex_normals(c.vertices, c.faces)
    ctr = c.vertices.mean(0)
    assert (np.sum((c.vertices - ctr) * n, axis=1) > 0).all()
