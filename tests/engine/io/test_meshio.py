"""Mesh export and import: round trips, privacy of the STL header, clear errors on bad files."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.core.errors import CtuiError, FormatError
from ctui.engine.io.meshes import load_mesh, save_mesh
from ctui.engine.mesh.meshtools import mesh_report
from ctui.engine.mesh.surface import mask_surface


@pytest.fixture(scope="module")
def mesh():
    z, y, x = np.mgrid[:20, :40, :40]
    m = ((x - 20) * 0.8) ** 2 + ((y - 19) * 0.8) ** 2 + ((z - 10) * 2.0) ** 2 <= 12.0**2
    return mask_surface(m, spacing=(2.0, 0.8, 0.8), origin=(-120.5, 33.0, 250.0))


@pytest.mark.parametrize("ext,ascii", [("stl", False), ("stl", True), ("ply", False), ("ply", True), ("obj", False)])
def test_round_trip(tmp_path, mesh, ext, ascii):
    p = tmp_path / f"m.{ext}"
    save_mesh(p, mesh, ascii=ascii)
    back = load_mesh(p)
    a, b = mesh_report(mesh), mesh_report(back)
    assert b["triangles"] == a["triangles"] and b["vertices"] == a["vertices"]
    assert b["watertight"]
    assert b["volume_ml"] == pytest.approx(a["volume_ml"], rel=1e-5)
    assert np.allclose(np.sort(back.vertices, axis=0), np.sort(mesh.vertices, axis=0), atol=1e-3)
    assert not list(tmp_path.glob(".*tmp*"))  # no temporary file left behind


def test_stl_header_is_ctui_only(tmp_path, mesh):
    p = tmp_path / "m.stl"
    mesh.meta["PatientName"] = "DOE^JOHN"  # must never reach the file
    save_mesh(p, mesh)
    raw = p.read_bytes()
    assert raw[:80] == b"ctui".ljust(80, b" ")
    assert int(np.frombuffer(raw[80:84], "<u4")[0]) == mesh.n_faces
    assert len(raw) == 84 + 50 * mesh.n_faces
    assert b"DOE" not in raw
    del mesh.meta["PatientName"]


def test_truncated_and_inconsistent_stl(tmp_path, mesh):
    p = tmp_path / "m.stl"
    save_mesh(p, mesh)
    raw = p.read_bytes()
    bad = tmp_path / "trunc.stl"
    bad.write_bytes(raw[:-13])
    with pytest.raises(FormatError, match="truncated"):
        load_mesh(bad)
    huge = tmp_path / "huge.stl"  # header claims 4 billion triangles: refused before allocating
    huge.write_bytes(raw[:80] + np.uint32(4_000_000_000).tobytes() + raw[84:200])
    with pytest.raises(FormatError, match="4000000000 triangles"):
        load_mesh(huge)
    tiny = tmp_path / "tiny.stl"
    tiny.write_bytes(b"abc")
    with pytest.raises(FormatError):
        load_mesh(tiny)


def test_bad_ply_obj_and_extension(tmp_path):
    p = tmp_path / "bad.ply"
    p.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 100\nend_header\n\x00\x01")
    with pytest.raises(FormatError) as e:
        load_mesh(p)
    assert "bad.ply" in str(e.value) and "\n" not in str(e.value)
    o = tmp_path / "bad.obj"
    o.write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    with pytest.raises(FormatError):
        load_mesh(o)
    with pytest.raises(FormatError, match="unknown mesh format"):
        load_mesh(tmp_path / "x.vtk")
    with pytest.raises(FormatError, match="no such file"):
        load_mesh(tmp_path / "missing.stl")


def test_write_into_missing_folder_is_a_clear_error(tmp_path, mesh):
    with pytest.raises(CtuiError):
        save_mesh(tmp_path / "nope" / "m.stl", mesh)


@pytest.mark.parametrize("encoding", ["latin-1", "utf-8", "utf-8-sig"])
def test_obj_in_latin1_or_utf8(tmp_path, encoding):
    """OBJ text with non-ASCII comments, object and material names (older exporters write
    latin-1): read, not a UnicodeDecodeError traceback."""
    text = ("# exporté par un logiciel ancien, ©\no Rein_gauche_é\nusemtl matériau\n"
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    p = tmp_path / "t.obj"
    p.write_bytes(text.encode(encoding))
    m = load_mesh(p)
    assert m.vertices.shape == (4, 3) and m.faces.shape == (4, 3)
    assert np.allclose(np.sort(m.vertices.sum(axis=1)), [0, 1, 1, 1])


def test_mesh_over_the_memory_limit_refused(tmp_path, mesh, monkeypatch):
    """CTUI_MEMORY_LIMIT stands in for RLIMIT_AS / cgroup memory.max: one line naming the
    file instead of a MemoryError traceback."""
    p = save_mesh(tmp_path / "m.stl", mesh)
    monkeypatch.setenv("CTUI_MEMORY_LIMIT", str(p.stat().st_size))
    with pytest.raises(CtuiError) as exc:
        load_mesh(p)
    assert "\n" not in str(exc.value) and "m.stl" in str(exc.value) and "memory" in str(exc.value)
