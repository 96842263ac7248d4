"""Fuzz mesh inputs (ctui.engine.io.meshes.load_mesh, used by `ctui render` and `ctui
measure`): binary/ASCII STL, PLY (binary and ASCII), OBJ: truncations, flips, huge
counts, random/hypothesis mutations and structured header/face edits. A mesh that
loads must be usable: finite vertices and face indices within range."""

from __future__ import annotations

import pytest

import numpy as np

from test_fuzz_harness import assert_clean, fuzz_examples, run_campaign, standard_campaign

try:
    import ctui.engine.io.meshes  # noqa: F401

    HAVE_MESHIO = True
except ImportError:  # pragma: no cover
    HAVE_MESHIO = False


def warm_up() -> None:
    import tempfile
    from pathlib import Path

    import hypothesis  # noqa: F401
    import trimesh  # noqa: F401

    d = Path(tempfile.mkdtemp(prefix="ctui-fuzz-warm-"))
    for name, data in seeds().items():
        (d / name).write_bytes(data)
        try:
            checked_load(d / name)
        except Exception:  # noqa: BLE001 - warm-up only
            pass


def checked_load(p):
    from ctui.engine.io.meshes import load_mesh

    m = load_mesh(p)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    if not np.isfinite(v).all():
        raise AssertionError("load_mesh returned non-finite vertices")
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise AssertionError("load_mesh returned face indices out of range")
    if f.ndim != 2 or (len(f) and f.shape[1] != 3):
        raise AssertionError(f"load_mesh returned faces of shape {f.shape}")
    return m


def seeds() -> dict[str, bytes]:
    import tempfile
    from pathlib import Path

    import trimesh

    from ctui.engine.core.meshdata import Mesh
    from ctui.engine.io.meshes import save_mesh

    s = trimesh.creation.icosphere(subdivisions=0, radius=5.0)
    mesh = Mesh(vertices=np.asarray(s.vertices, np.float64), faces=np.asarray(s.faces))
    d = Path(tempfile.mkdtemp(prefix="ctui-fuzz-seed-"))
    out = {}
    for name, ascii in (("b.stl", False), ("a.stl", True), ("b.ply", False), ("a.ply", True), ("m.obj", False)):
        out[name] = save_mesh(d / name, mesh, ascii=ascii).read_bytes()
    return out


def campaign(ctx) -> None:
    s = seeds()
    for name, data in s.items():
        step = max(1, len(data) // (60 if name.endswith(".obj") else 150))
        standard_campaign(ctx, checked_load, data, name=name, tag="mesh-" + name.replace(".", ""), flips_every=step, trunc_limit=200)
    import struct

    # binary STL triangle counts
    b = s["b.stl"]
    for count in (0, 1, 19, 21, 2**31 - 1, 2**32 - 1):
        x = bytearray(b)
        struct.pack_into("<I", x, 80, count)
        ctx.check(checked_load, bytes(x), name="x.stl", tag="stl-count")
    x = bytearray(b)
    struct.pack_into("<f", x, 84 + 12, float("nan"))
    ctx.check(checked_load, bytes(x), name="x.stl", tag="stl-nan")
    # ASCII STL with bad numbers
    a = s["a.stl"].decode()
    first = a.split("vertex", 2)
    for bad in ("nan 0 0", "inf 1 2", "1e999 0 0", "1 2", "1 2 3 4", "x y z", "0x10 0 0"):
        t = a.replace(first[1].split("\n")[0], " " + bad, 1)
        ctx.check(checked_load, t.encode(), name="x.stl", tag="stl-ascii-bad")
    # PLY header counts
    for ply in ("a.ply", "b.ply"):
        head, sep, body = s[ply].partition(b"end_header\n")
        for old, new in ((b"element vertex 12", b"element vertex 999999999"), (b"element vertex 12", b"element vertex -1"),
                         (b"element vertex 12", b"element vertex 0"), (b"element face 20", b"element face 2147483647"),
                         (b"element face 20", b"element face -5"), (b"element face 20", b"element face 0"),
                         (b"format ", b"format nonsense "), (b"float", b"double"), (b"uchar", b"uint")):
            if old in head:
                ctx.check(checked_load, head.replace(old, new, 1) + sep + body, name="x.ply", tag="ply-header")
    # OBJ faces and vertices
    o = s["m.obj"].decode()
    for bad in ("f 1 2 99999", "f 0 1 2", "f -1 -2 -3", "f -999 1 2", "f 1 2", "f a b c", "f 1/1/1 2/2/2 3/3/3",
                "v nan 0 0", "v 1e999 0 0", "v 1 2", "f 1 2 3 4 5 6 7", "f 2147483648 1 2"):
        ctx.check(checked_load, (o + "\n" + bad + "\n").encode(), name="x.obj", tag="obj-line", note=bad)
    # not files / wrong extension
    d = ctx.tmp("dir.stl")
    d.mkdir(exist_ok=True)
    ctx.check(checked_load, d, tag="mesh-dir", size_hint=0)
    ctx.check(checked_load, b"", name="empty.stl", tag="mesh-empty")
    ctx.check(checked_load, b"", name="empty.obj", tag="mesh-empty")
    ctx.check(checked_load, b"", name="empty.ply", tag="mesh-empty")
    ctx.check(checked_load, s["b.stl"], name="x.vtk", tag="mesh-ext")


@pytest.mark.slow
def test_fuzz_mesh():
    import pytest

    if not HAVE_MESHIO:
        pytest.skip("ctui.engine.io.meshes not available yet")
    res = run_campaign("test_fuzz_mesh", "campaign", examples=fuzz_examples(150))
    assert_clean("mesh", res, min_cases=2500)
