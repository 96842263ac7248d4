"""numba is imported only when a compiled kernel runs, and its start-up without the BLAS
probe leaves numba's linear algebra working (issue 27). Fresh interpreters, so the import
state is known; no timing."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from ctui.engine.core.meshdata import Mesh
from ctui.engine.mesh import meshtools

from support import ROOT


def _python(code: str, **env_extra: str) -> str:
    env = dict(os.environ, CTUI_NO_BACKGROUND_COMPILE="1", **env_extra)
    env.pop("CTUI_KERNELS", None)
    env.update(env_extra)
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_small_label_mesh_and_report_import_no_numba():
    out = _python("""
        import sys
        import numpy as np
        from ctui.engine.actions.mesh import label_meshes
        from ctui.engine.core.geometry import Geometry
        from ctui.engine.mesh.meshtools import mesh_report
        z, y, x = np.mgrid[:12, :20, :20]
        lab = (((x - 10) ** 2 + (y - 10) ** 2 + 4 * (z - 6) ** 2) < 49).astype(np.uint8)
        g = Geometry(shape=lab.shape, spacing=(2.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), direction=np.eye(3))
        m = label_meshes(lab, g, [1])[1]
        rep = mesh_report(m)
        print(rep["watertight"], "numba" in sys.modules)
    """)
    assert out.split() == ["True", "False"]


@pytest.mark.slow
def test_target_started_without_blas_probe_keeps_linear_algebra():
    out = _python("""
        import sys
        import numpy as np
        from ctui.engine.mesh import jit
        jit.start_target()
        print("scipy.linalg" in sys.modules, sys.modules.get("scipy.linalg.cython_blas", 0) is None, jit.target_ready())
        import numba

        @numba.njit
        def solve(a, b):
            return np.dot(np.linalg.inv(a), b)

        print(solve(np.array([[2.0, 0.0], [0.0, 4.0]]), np.array([2.0, 4.0])).tolist())
    """)
    first, second = out.strip().splitlines()
    assert first.split() == ["False", "False", "True"]
    assert second == "[1.0, 1.0]"


def test_compiled_report_equals_numpy_report(monkeypatch):
    """The one-pass compiled report and the numpy one agree on odd meshes: open, flipped,
    a fin (non-manifold edge), two components and unused vertices."""
    rng = np.random.default_rng(3)
    v = rng.normal(size=(12, 3)).astype(np.float32)
    tet = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    flipped = np.array([[0, 2, 1], [0, 1, 3], [1, 3, 2], [0, 3, 2]])
    meshes = [Mesh(v[:4], tet), Mesh(v[:4], tet[:3]), Mesh(v[:4], flipped),
              Mesh(v[:5], np.concatenate([tet, [[0, 1, 4]]])), Mesh(v, np.concatenate([tet, tet + 4]))]
    for m in meshes:
        monkeypatch.setenv("CTUI_KERNELS", "numpy")
        a = meshtools.mesh_report(m)
        monkeypatch.setenv("CTUI_KERNELS", "compiled")
        b = meshtools.mesh_report(m)
        counts = [k for k in a if not isinstance(a[k], float)]
        assert {k: a[k] for k in counts} == {k: b[k] for k in counts}
        assert abs(a["volume_ml"] - b["volume_ml"]) < 1e-12 and abs(a["area_mm2"] - b["area_mm2"]) < 1e-9


def test_face_components_equal_scipy():
    """The numpy components (no scipy import) equal scipy's csgraph on sparse random meshes
    (many components, unused vertices, long chains numbered against the hooking order)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(5)
    chain = np.array([[k, k + 1, k + 1] for k in range(300)])[::-1] * 7 % 2101  # a path visited backwards
    for f in (rng.integers(0, 400, (150, 3)), rng.integers(0, 3000, (2500, 3)), chain):
        nv = int(f.max()) + 5
        n, flab = meshtools.face_components(Mesh(np.zeros((nv, 3), np.float32), f))
        rows, cols = np.concatenate([f[:, 0], f[:, 1]]), np.concatenate([f[:, 1], f[:, 2]])
        _, vlab = connected_components(coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(nv, nv)), directed=False)
        uniq, ref = np.unique(vlab[f[:, 0]], return_inverse=True)
        assert n == len(uniq)
        np.testing.assert_array_equal(flab, ref)
    assert meshtools._vertex_roots(chain, 2200, max_rounds=1) is None  # not settled: scipy's path then


def test_cold_cache_isosurface_imports_no_numba(tmp_path):
    """An empty numba cache: a big isosurface takes the numpy path without importing numba
    to learn that nothing is compiled (jit.cache_lacks), and gives the mesh."""
    out = _python("""
        import sys
        import numpy as np
        from ctui.engine.mesh.marching import marching_cubes
        z, y, x = np.mgrid[:170, :160, :160]
        vol = (((z - 85) ** 2 + (y - 80) ** 2 + (x - 80) ** 2) < 60 ** 2).astype(np.int16) * 1000
        v, f, n = marching_cubes(vol, 500)
        print(len(f) > 0, "numba" in sys.modules)
    """, NUMBA_CACHE_DIR=str(tmp_path))
    assert out.split() == ["True", "False"]


def test_cache_probe_looks_where_numba_writes(tmp_path):
    """cache_lacks looks for the index files numba itself names (folder and file), in a given
    NUMBA_CACHE_DIR: absent -> lacks; present -> does not lack."""
    out = _python("""
        from pathlib import Path
        from ctui.engine.mesh import jit
        names = ("_pass_rows", "_pass_count")
        print(jit.cache_lacks("mc_kernels", names))
        from ctui.engine.mesh import mc_kernels as k  # imports numba: its own cache paths
        for name in names:
            index = Path(getattr(k, name)._cache._cache_file._index_path)
            index.parent.mkdir(parents=True, exist_ok=True)
            index.write_bytes(b"")
        import sys
        del sys.modules["numba"]  # cache_lacks answers False while numba is imported
        print(jit.cache_lacks("mc_kernels", names), jit.cache_lacks("mc_kernels", names + ("_pass_generate",)))
    """, NUMBA_CACHE_DIR=str(tmp_path))
    assert out.split() == ["True", "False", "True"]
