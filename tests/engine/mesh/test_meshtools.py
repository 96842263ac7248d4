"""Mesh report and repair tools against meshes with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.meshdata import Mesh
from ctui.engine.mesh.meshtools import (
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
    from ctui.engine.mesh.surface import isosurface

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


def _edge_touching_cubes() -> Mesh:
    """Two unit-10 cubes that share only the edge x = 10, y = 10 (welded): a
    non-manifold edge with four faces, and two non-manifold vertices."""
    return weld(merge([cube(), cube(offset=(10.0, 10.0, 0.0))]))


def test_report_volume_of_a_closed_surface_with_a_non_manifold_edge():
    m = _edge_touching_cubes()
    rep = mesh_report(m)
    assert rep["non_manifold_edges"] == 1 and rep["boundary_edges"] == 0 and not rep["watertight"]
    # still a closed surface: it encloses both cubes
    assert rep["volume_ml"] == pytest.approx(2.0)


def test_split_non_manifold_cuts_touching_solids_apart():
    from ctui.engine.mesh.meshtools import split_non_manifold

    m = _edge_touching_cubes()
    s = split_non_manifold(m)
    rep = mesh_report(s)
    assert rep["watertight"] and rep["non_manifold_edges"] == 0 and rep["winding_consistent"]
    assert rep["components"] == 2 and rep["volume_ml"] == pytest.approx(2.0)
    assert rep["euler"] == 4  # two spheres
    assert s.n_vertices == m.n_vertices + 2  # the shared edge's two ends, one copy each
    assert np.array_equal(s.faces.shape, m.faces.shape)
    # nothing to cut: the mesh is returned with the same vertex count
    c = split_non_manifold(cube())
    assert c.n_vertices == 8 and mesh_report(c)["watertight"]


def test_drop_opposite_twins_removes_fins_only():
    from ctui.engine.mesh.meshtools import drop_opposite_twins

    c = cube()
    fin = np.array([[0, 3, 5], [0, 5, 3]])  # a zero-thickness fin inside the cube
    m = Mesh(c.vertices, np.vstack([c.faces, fin]).astype(np.int32))
    out = drop_opposite_twins(m)
    assert out.n_faces == 12 and mesh_report(out)["watertight"]
    same = Mesh(c.vertices, np.vstack([c.faces, fin[:1], fin[:1]]).astype(np.int32))
    assert drop_opposite_twins(same).n_faces == 14  # same-winding duplicates are not a fin


def test_decimated_lobster_keeps_its_volume_and_cuts_most_non_manifold_edges():
    """The lobster (../shared/data) at 100, decimated 10x: quadric collapses make thin
    walls meet along edges; the report's volume stays the enclosed volume (it was
    reported as almost nothing when such components counted as open), no hole
    appears, and the cut leaves far fewer non-manifold edges than the raw decimator."""
    import fast_simplification

    from support import lobster

    from ctui.engine.mesh.meshtools import edge_counts
    from ctui.engine.mesh.surface import isosurface

    data = lobster()
    m = isosurface(data, 100, spacing=(1.4, 1.0, 1.0))
    rep0 = mesh_report(m)
    target = m.n_faces // 10
    d = decimate(m, target)
    rep = mesh_report(d)
    assert rep["boundary_edges"] == 0
    assert rep["closed_components"] == rep["components"]
    assert rep["volume_ml"] == pytest.approx(rep0["volume_ml"], rel=0.03)
    big = components(m)[0]
    v, f = fast_simplification.simplify(big.vertices.astype(np.float32), big.faces.astype(np.int32),
                                        target_reduction=0.9, agg=7)
    raw_nonman = int(np.count_nonzero(edge_counts(f, len(v))[1] > 2))
    assert raw_nonman > 50  # the raw decimator does make sheets meet here
    assert rep["non_manifold_edges"] * 4 < raw_nonman
