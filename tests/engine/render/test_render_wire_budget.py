"""A wire view of a dense mesh draws a decimated copy (issue 26, item 16: a 5 M-face wire turntable ran for
minutes): the scene holds at most defaults.WIRE_MAX_FACES triangles, keeps each object's id, and says so."""

from __future__ import annotations

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.actions.opened import open_input
from ctui.engine.actions.render import build_scene
from ctui.engine.io.meshes import save_mesh
from ctui.engine.mesh.surface import isosurface


def test_dense_wire_view_is_decimated(tmp_path, monkeypatch):
    monkeypatch.setattr(defaults, "WIRE_MAX_FACES", 20_000)
    zz, yy, xx = np.mgrid[-40:41, -40:41, -40:41]
    ball = (np.sqrt(zz**2 + yy**2 + xx**2) <= 38).astype(np.float32)
    mesh = isosurface(ball, 0.5, spacing=(1.0, 1.0, 1.0))
    assert mesh.n_faces > 40_000
    path = tmp_path / "ball.stl"
    save_mesh(str(path), mesh)
    opened = open_input(str(path))
    scene, mode = build_scene(opened, mode="wire")
    faces = sum(m.mesh.n_faces for m in scene.meshes)
    assert mode == "wire" and 0 < faces <= 20_000
    assert any("decimated copy" in n for n in opened.notes)
    # the copy keeps the shape: its extent is the ball's within a voxel
    v = np.concatenate([m.mesh.vertices for m in scene.meshes])
    assert np.all(np.abs(v.max(axis=0) - v.min(axis=0) - 76) < 2.0)
    surface, _ = build_scene(open_input(str(path)), mode="surface")  # other modes draw the mesh as it is
    assert sum(m.mesh.n_faces for m in surface.meshes) == mesh.n_faces
