"""A fresh install (empty numba cache) meshes without compiling, and gives the same mesh.

No timing: the checks are that the first ``ctui mesh --iso`` with an empty cache writes
the same triangles as the compiled kernels, that it compiled nothing (the vectorised
path ran), and that the vectorised marching cubes equals the compiled one on awkward
inputs (float data, anisotropic and oblique affines, objects touching the border).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from ctui.engine.io.meshes import load_mesh
from ctui.engine.mesh import jit
from ctui.engine.mesh.marching import marching_cubes
from ctui.engine.mesh.surface import affine_from

from support import ROOT, SAMPLE_DATA, shared


def _mesh_cmd(out, env_extra):
    env = dict(os.environ, CTUI_NO_BACKGROUND_COMPILE="1", CTUI_NO_PROGRESS="1", **env_extra)
    return subprocess.run([sys.executable, "-m", "ctui.cli", "mesh", str(SAMPLE_DATA / "phantom"), "--iso", "300",
                           "--out", str(out), "--json"], env=env, cwd=ROOT, capture_output=True, text=True,
                          timeout=600)


@pytest.mark.slow
def test_fresh_cache_mesh_equals_compiled(tmp_path):
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    cold = _mesh_cmd(tmp_path / "cold.stl", {"NUMBA_CACHE_DIR": str(cache), "CTUI_KERNELS": "auto"})
    assert cold.returncode == 0, cold.stderr
    # nothing was compiled for marching cubes: the numpy path ran
    assert not list(cache.rglob("mc_kernels*.nbi")), "a fresh install compiled the marching cubes kernels"
    warm = _mesh_cmd(tmp_path / "warm.stl", {"CTUI_KERNELS": "compiled"})
    assert warm.returncode == 0, warm.stderr
    a, b = load_mesh(tmp_path / "cold.stl"), load_mesh(tmp_path / "warm.stl")
    assert a.n_faces == b.n_faces > 1000
    np.testing.assert_allclose(a.vertices[a.faces], b.vertices[b.faces], atol=1e-4)
    assert cold.stdout.strip() == warm.stdout.strip().replace("warm.stl", "cold.stl")


def _both(data, level, affine=None):
    old = os.environ.get("CTUI_KERNELS")
    try:
        os.environ["CTUI_KERNELS"] = "compiled"
        c = marching_cubes(data, level, affine=affine)
        os.environ["CTUI_KERNELS"] = "numpy"
        n = marching_cubes(data, level, affine=affine)
    finally:
        if old is None:
            os.environ.pop("CTUI_KERNELS", None)
        else:
            os.environ["CTUI_KERNELS"] = old
    return c, n


@pytest.mark.parametrize("kind", ["int16", "float32", "bool", "oblique"])
def test_numpy_path_equals_compiled(kind):
    rng = np.random.default_rng(7)
    aff = None
    if kind == "int16":
        data = rng.integers(-3, 4, (7, 19, 23)).astype(np.int16)
        level = 0.0
    elif kind == "float32":
        z, y, x = np.mgrid[:15, :18, :21]
        data = (30 - np.sqrt((x - 10.3) ** 2 + (y - 8.7) ** 2 + 2 * (z - 6.1) ** 2)).astype(np.float32)
        level = 22.5
        aff = affine_from((2.5, 0.7, 0.6), (10.0, -5.0, 3.0))
    elif kind == "bool":
        data = rng.random((9, 10, 11)) > 0.6  # touches every border
        level = 0.5
    else:
        data = rng.normal(size=(8, 12, 9)).astype(np.float32)
        level = 0.3
        th = 0.4
        rot = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1.0]])
        aff = affine_from((1.5, 1.0, 0.8), (1.0, 2.0, 3.0), rot)
    (vc, fc, nc), (vn, fn, nn) = _both(data, level, aff)
    assert len(fc) > 50
    np.testing.assert_array_equal(fc, fn)
    np.testing.assert_allclose(vc, vn, atol=1e-5, rtol=1e-6)
    np.testing.assert_allclose(nc, nn, atol=1e-5)


def test_is_compiled_reads_the_cache_without_compiling(tmp_path):
    from ctui.engine.mesh.mc_kernels import _pass_rows

    # in this process the kernel may or may not be compiled; either way the answer comes
    # without compiling (no new signature appears)
    before = list(_pass_rows.signatures)
    jit.is_compiled(_pass_rows, np.dtype(np.int16))
    assert list(_pass_rows.signatures) == before


def test_warm_up_twice_is_cheap():
    from ctui.engine.mesh import warm

    warm.warm_up()
    calls = []
    warm.warm_up(progress=lambda d, t, m="": calls.append(m))
    assert calls == []  # the second call did nothing


def _contour_mesh(out, labels, env_extra):
    env = dict(os.environ, CTUI_NO_BACKGROUND_COMPILE="1", CTUI_NO_PROGRESS="1", **env_extra)
    if "CTUI_KERNELS" not in env_extra:
        env.pop("CTUI_KERNELS", None)
    return subprocess.run([sys.executable, "-m", "ctui.cli", "mesh", str(labels), "--object", "3",
                           "--method", "contours", "--out", str(out), "--json"], env=env, cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


@pytest.mark.slow
def test_kidney_contours_cold_cache_equal_warm(tmp_path):
    """The issue's case: the first contour mesh after an install (a fresh NUMBA_CACHE_DIR)
    tiled greedily (117.9 mL, 1 non-manifold edge) while the minimum-area kernel compiled;
    now the plain-Python twin of the kernel runs and the surface is the same triangles."""
    labels = shared("totalseg_example") / "ct_abdomen_3mm_labels.nii.gz"
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    cold = _contour_mesh(tmp_path / "cold.stl", labels, {"NUMBA_CACHE_DIR": str(cache)})
    assert cold.returncode == 0, cold.stderr
    assert not list(cache.rglob("contour_tiling*.nbi")), "the cold run compiled the tiling kernel"
    warm = _contour_mesh(tmp_path / "warm.stl", labels, {"CTUI_KERNELS": "compiled"})
    assert warm.returncode == 0, warm.stderr
    a, b = load_mesh(tmp_path / "cold.stl"), load_mesh(tmp_path / "warm.stl")
    assert a.n_faces == b.n_faces > 1000
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    assert cold.stdout.strip() == warm.stdout.strip().replace("warm.stl", "cold.stl")
    assert "greedy" not in cold.stdout
    assert json.loads(cold.stdout)["watertight"] is True


@pytest.mark.parametrize("use_dp", [True, False])
def test_python_tiling_equals_kernel_on_a_real_kidney(use_dp):
    """Every band/table/greedy branch of the tiling: the plain-Python twin gives the kernel's triangles."""
    import nibabel as nib
    from ctui.engine.core.borders import object_borders
    from ctui.engine.mesh import contour_connect as cc

    lab = np.asarray(nib.load(shared("totalseg_example") / "ct_abdomen_3mm_labels.nii.gz").dataobj)
    mask = np.transpose(lab == 2, (2, 1, 0)).astype(np.uint8)
    b = object_borders(mask, 1)
    method = "dp" if use_dp else "greedy"
    old = os.environ.get("CTUI_KERNELS")
    try:
        os.environ["CTUI_KERNELS"] = "compiled"
        k = cc.connect_contours(b, spacing=(3.0, 3.0, 3.0), method=method, band=3 if use_dp else 0)
        os.environ["CTUI_KERNELS"] = "numpy"
        p = cc.connect_contours(b, spacing=(3.0, 3.0, 3.0), method=method, band=3 if use_dp else 0)
    finally:
        os.environ.pop("CTUI_KERNELS", None) if old is None else os.environ.__setitem__("CTUI_KERNELS", old)
    assert len(k.faces) > 1000
    np.testing.assert_array_equal(k.faces, p.faces)
    np.testing.assert_array_equal(k.vertices, p.vertices)


def test_every_kernel_fallback_equals_the_kernel_on_a_real_kidney():
    """Marching cubes, the mesh report and vertex normals: the numpy path (what a cold cache
    runs) against the compiled kernels on the real kidney. Triangles and counts bit for bit;
    summed floats (volume, area, normals) within 1e-9 relative (another summation order)."""
    import nibabel as nib
    from ctui.engine.mesh.meshtools import mesh_report, vertex_normals
    from ctui.engine.core.meshdata import Mesh

    lab = np.asarray(nib.load(shared("totalseg_example") / "ct_abdomen_3mm_labels.nii.gz").dataobj)
    mask = np.ascontiguousarray(np.transpose(lab == 2, (2, 1, 0)))
    aff = affine_from((3.0, 3.0, 3.0), (-10.0, 20.0, 5.0))
    (vc, fc, nc), (vn, fn, nn) = _both(mask, 0.5, aff)
    assert len(fc) > 1000
    np.testing.assert_array_equal(fc, fn)
    np.testing.assert_array_equal(vc, vn)
    np.testing.assert_allclose(nc, nn, atol=1e-6)
    mesh = Mesh(vertices=vc.astype(np.float32), faces=fc.astype(np.int32))
    reports, normals = [], []
    old = os.environ.get("CTUI_KERNELS")
    try:
        for m in ("compiled", "numpy"):
            os.environ["CTUI_KERNELS"] = m
            reports.append(mesh_report(mesh))
            normals.append(vertex_normals(mesh.vertices, mesh.faces))
    finally:
        os.environ.pop("CTUI_KERNELS", None) if old is None else os.environ.__setitem__("CTUI_KERNELS", old)
    a, b = reports
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], float):
            assert a[k] == pytest.approx(b[k], rel=1e-9), k
        else:
            assert a[k] == b[k], k
    np.testing.assert_allclose(normals[0], normals[1], atol=1e-6)
