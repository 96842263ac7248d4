"""Contour connecting: closed, oriented surfaces with the right volume; branching, holes, ends."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.actions.mesh import connect_mric
from ctui.engine.mesh.contour_connect import (
    connect_contours,
    offset_pixel_boundary,
    tile_dp,
    tile_greedy,
)
from ctui.engine.mesh.meshtools import mesh_report

SPACING = (2.5, 0.7, 0.7)


@pytest.fixture(autouse=True)
def _compiled_kernels(monkeypatch):
    """The compiled kernels (DP tiling), whatever the state of numba's cache: the
    first-use fallbacks are tested in test_cold_start.py."""
    monkeypatch.setenv("CTUI_KERNELS", "compiled")


def borders(mask):
    from ctui.engine.core.borders import object_borders

    return object_borders(np.asarray(mask, np.uint8), 1)


def ellipsoid(axes_xyz, shape=(36, 110, 110), spacing=SPACING):
    nz, ny, nx = shape
    z, y, x = np.mgrid[:nz, :ny, :nx]
    c = [nx / 2 * spacing[2] + 0.3, ny / 2 * spacing[1] - 0.2, nz / 2 * spacing[0] + 0.4]
    q = ((x * spacing[2] - c[0]) / axes_xyz[0]) ** 2 + ((y * spacing[1] - c[1]) / axes_xyz[1]) ** 2 \
        + ((z * spacing[0] - c[2]) / axes_xyz[2]) ** 2
    return q <= 1.0, 4.0 / 3.0 * np.pi * np.prod(axes_xyz)


@pytest.mark.parametrize("method", ["dp", "greedy"])
@pytest.mark.parametrize("axes", [(25.0, 25.0, 25.0), (30.0, 20.0, 35.0)])
def test_ellipsoids_volume_and_closed(axes, method):
    mask, analytic = ellipsoid(axes)
    m = connect_contours(borders(mask), spacing=SPACING, origin=(5.0, -7.0, 100.0), method=method)
    rep = mesh_report(m)
    assert rep["watertight"] and rep["winding_consistent"]
    assert rep["components"] == 1 and rep["euler"] == 2
    assert abs(rep["volume_ml"] * 1000 / analytic - 1) < 0.01
    assert m.volume_mm3() > 0  # outward
    lo, hi = m.bounds()
    assert lo[2] >= 100.0 - 1e-6  # placed through the origin


def test_offset_gives_pixel_count_area():
    yy, xx = np.mgrid[:80, :80]
    disk = (xx - 40.3) ** 2 + (yy - 39.6) ** 2 <= 25.0**2
    from ctui.engine.core.borders import slice_borders

    b = slice_borders(disk)[0]
    centre_area = abs(b.signed_area)
    p = offset_pixel_boundary(b.points)
    x, y = p[:, 0], p[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    assert centre_area < 0.97 * disk.sum()  # the centre polygon loses half a pixel all round
    assert abs(area / disk.sum() - 1) < 0.005
    sq = offset_pixel_boundary(np.array([[3.0, 4.0]]))
    assert len(sq) == 4


def test_branching_two_into_one():
    yy, xx = np.mgrid[:100, :100]
    m = np.zeros((24, 100, 100), bool)
    for k in range(24):
        if k < 12:
            m[k] = ((xx - 30) ** 2 + (yy - 50) ** 2 < 15**2) | ((xx - 70) ** 2 + (yy - 50) ** 2 < 15**2)
        else:
            m[k] = (xx - 50) ** 2 + (yy - 50) ** 2 < 34**2
    res = {}
    for method in ("dp", "greedy"):
        mesh = connect_contours(borders(m), spacing=(2.0, 1.0, 1.0), method=method)
        rep = mesh_report(mesh)
        assert rep["watertight"] and rep["winding_consistent"], method
        assert rep["components"] == 1 and rep["euler"] == 2
        assert abs(rep["volume_ml"] * 1000 / (m.sum() * 2.0) - 1) < 0.01
        res[method] = rep
    # the minimum-area tiling is never larger than the greedy one
    assert res["dp"]["area_mm2"] <= res["greedy"]["area_mm2"] + 1e-6


def test_tube_with_hole_and_objects_that_appear_and_vanish():
    yy, xx = np.mgrid[:90, :90]
    m = np.zeros((30, 90, 90), bool)
    r = np.hypot(xx - 45, yy - 45)
    m[2:20] = (r < 30) & (r >= 12)  # a thick-walled tube: a torus topologically
    m[24:28, 5:15, 5:15] = True  # a small block appearing and vanishing above
    mesh = connect_contours(borders(m), spacing=(2.0, 1.0, 1.0))
    rep = mesh_report(mesh)
    assert rep["watertight"] and rep["winding_consistent"]
    assert rep["components"] == 2
    assert rep["euler"] == 0 + 2  # torus (0) + block (2)
    assert abs(rep["volume_ml"] * 1000 / (m.sum() * 2.0) - 1) < 0.01


def test_hole_that_closes_inside_the_object():
    # a cup: a solid base, then a tube whose hole ends at the top lid -> a closed cavity
    yy, xx = np.mgrid[:70, :70]
    r = np.hypot(xx - 35, yy - 35)
    m = np.zeros((16, 70, 70), bool)
    m[1:15] = r < 25
    m[4:11] &= ~(r < 10)  # internal cavity
    mesh = connect_contours(borders(m), spacing=(2.0, 1.0, 1.0))
    rep = mesh_report(mesh)
    assert rep["watertight"] and rep["winding_consistent"]
    assert rep["components"] == 2  # outer surface and the cavity's inward-facing surface
    assert abs(rep["volume_ml"] * 1000 / (m.sum() * 2.0) - 1) < 0.01


def test_plain_arrays_and_pairs_accepted():
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    ring = lambda r: np.column_stack([50 + r * np.cos(t), 50 + r * np.sin(t)])  # noqa: E731
    stack_arrays = [[ring(20)], [ring(21)], [ring(20)]]
    stack_pairs = [[(ring(20), False), (ring(8)[::-1], True)]] * 3
    for st in (stack_arrays, stack_pairs):
        rep = mesh_report(connect_contours(st, pixel_centres=False))
        assert rep["watertight"] and rep["winding_consistent"] and rep["volume_ml"] > 0


def test_tilings_cover_both_loops_once():
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    P = np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)]) * [10, 10, 1]
    t2 = np.linspace(0, 2 * np.pi, 57, endpoint=False) + 0.3
    Q = np.column_stack([12 * np.cos(t2) + 3, 8 * np.sin(t2), np.ones_like(t2)])
    pid, qid = np.arange(40), np.arange(40, 97)
    for tris in (tile_dp(P, Q, pid, qid, 0), tile_dp(P, Q, pid, qid, 12), tile_greedy(P, Q, pid, qid)):
        assert len(tris) == 97
        d = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
        # every loop edge appears exactly once, in the loop's direction (P) / reversed (Q)
        for i in range(40):
            assert ((d[:, 0] == i) & (d[:, 1] == (i + 1) % 40)).sum() == 1
        for j in range(57):
            assert ((d[:, 0] == 40 + (j + 1) % 57) & (d[:, 1] == 40 + j)).sum() == 1
    V = np.vstack([P, Q])

    def area(tr):
        a, b, c = V[tr[:, 0]], V[tr[:, 1]], V[tr[:, 2]]
        return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()

    assert area(tile_dp(P, Q, pid, qid, 0)) <= area(tile_greedy(P, Q, pid, qid)) + 1e-9


def test_mric_file(tmp_path):
    from ctui.engine.core.borders import borders_for_mric
    from ctui.engine.io.mric import write_mric

    mask, _ = ellipsoid((20.0, 15.0, 25.0), shape=(26, 80, 80))
    lab = mask.astype(np.uint8)
    path = tmp_path / "obj.mric"
    write_mric(path, borders_for_mric(lab), width=80, height=80)
    mesh = connect_mric(path, spacing=SPACING)
    rep = mesh_report(mesh)
    assert rep["watertight"]
    assert abs(rep["volume_ml"] * 1000 / (mask.sum() * np.prod(SPACING)) - 1) < 0.01


# --------------------------------------------------------------- real-looking contour stacks (issue 17)


def _disk(ny, nx, cy, cx, r):
    y, x = np.ogrid[:ny, :nx]
    return (y - cy) ** 2 + (x - cx) ** 2 <= r * r


def _stack(kind: str, seed: int = 0) -> np.ndarray:
    """Contour stacks as real segmentations give them (24 x 64 x 64 masks)."""
    from scipy import ndimage as ndi

    rng = np.random.default_rng(seed)
    nz, ny, nx = 24, 64, 64
    m = np.zeros((nz, ny, nx), bool)
    if kind == "holes":  # a hole that appears, wanders and closes
        for z in range(2, 22):
            m[z] = _disk(ny, nx, 32, 32, 20)
            if 6 <= z < 16:
                m[z] &= ~_disk(ny, nx, 32, 32 + (z - 10), 6 + (z % 3))
    elif kind == "islands":  # specks beside the object, slice by slice
        for z in range(2, 22):
            m[z] = _disk(ny, nx, 30, 30, 15)
            for _ in range(rng.integers(0, 4)):
                cy, cx = rng.integers(5, 59, 2)
                m[z] |= _disk(ny, nx, cy, cx, rng.integers(0, 3))
    elif kind in ("split", "merge"):  # one contour becomes two (or two one)
        for z in range(2, 22):
            d = max(z - 9, 0) * 2
            m[z] = _disk(ny, nx, 32, 32, 14) if z < 10 else _disk(ny, nx, 32, 32 - d, 9) | _disk(ny, nx, 32, 32 + d, 9)
        if kind == "merge":
            m = m[::-1].copy()
    elif kind == "noisy":  # a blob with a noisy outline (3D-correlated noise)
        f = ndi.gaussian_filter(rng.normal(size=(nz, ny, nx)), (1.0, 2.5, 2.5))
        zz, yy, xx = np.mgrid[:nz, :ny, :nx]
        m = (((zz - 12) / 10.0) ** 2 + ((yy - 32) / 24.0) ** 2 + ((xx - 32) / 18.0) ** 2 + 3.0 * f) < 1.0
    else:  # kidney-like: a sinus opening to one side, holes, necks and branches, islands
        carve = ndi.gaussian_filter(rng.normal(size=(nz, ny, nx)), (1.0, 2.0, 2.0))
        for z in range(1, 23):
            t = abs(z - 12) / 11
            r = 22 * np.sqrt(max(1 - t * t, 0)) + 1
            s = _disk(ny, nx, 32, 32, r)
            if t < 0.6:
                s &= ~_disk(ny, nx, 32, 32 + r * 0.5, r * 0.5)
            s &= ~(carve[z] > 0.25)
            for _ in range(rng.integers(0, 3)):
                cy, cx = rng.integers(5, 59, 2)
                s |= _disk(ny, nx, cy, cx, rng.integers(0, 2))
            m[z] = s
    return m


@pytest.mark.parametrize("kind,seed", [("holes", 0), ("islands", 0), ("split", 0), ("merge", 0), ("noisy", 0),
                                       ("noisy", 1), ("kidney", 0), ("kidney", 1), ("kidney", 2)])
def test_real_looking_contours_give_closed_surfaces(kind, seed):
    """Before: the noisy blob had 1 non-manifold edge, the kidney-like stacks 13-17 (a
    real kidney 116): a bridge reused from both sides of a slice, and a vertex tiled to
    both copies of a bridge vertex."""
    m = _stack(kind, seed)
    spacing = (2.0, 1.0, 1.0)
    rep = mesh_report(connect_contours(borders(m), spacing=spacing))
    assert rep["watertight"] and rep["non_manifold_edges"] == 0 and rep["boundary_edges"] == 0
    assert rep["winding_consistent"] and rep["closed_components"] == rep["components"]
    voxels_ml = m.sum() * np.prod(spacing) / 1000.0
    assert abs(rep["volume_ml"] / voxels_ml - 1) < 0.02
