"""Renderer tests: rendered pixels against geometric truths (EGL needed; skip otherwise)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import numpy as np
import pytest

from ctui.engine.core.meshdata import Mesh
from ctui.engine.render import (Camera, EGLUnavailable, Light, Material, Scene, SceneMesh, SceneVolume, SlicePlane,
                                get_renderer, save_flythrough, save_png, save_turntable, setup_camera)
from ctui.engine.render.gl import vertex_normals

pytestmark = pytest.mark.egl
ROOT = Path(__file__).resolve().parents[3]
BG = (0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def renderer():
    try:
        return get_renderer()
    except EGLUnavailable as exc:
        pytest.skip(f"no EGL context: {exc}")


def icosphere(radius: float, centre=(0.0, 0.0, 0.0), *, subdiv: int = 5, object_id: int = 1) -> Mesh:
    """Icosphere with vertices on the sphere of ``radius`` (no normals: the renderer computes them)."""
    t = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                  [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
                  [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
                  [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(subdiv):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mids = v[uniq].mean(axis=1)
        mids /= np.linalg.norm(mids, axis=1, keepdims=True)
        m = inv.reshape(3, -1).T + len(v)
        v = np.vstack([v, mids])
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        ab, bc, ca = m[:, 0], m[:, 1], m[:, 2]
        f = np.concatenate([np.c_[a, ab, ca], np.c_[b, bc, ab], np.c_[c, ca, bc], np.c_[ab, bc, ca]])
    return Mesh(v * radius + np.asarray(centre, float), f.astype(np.int32), object_id=object_id)


def fg_mask(img: np.ndarray, bg=BG) -> np.ndarray:
    return np.abs(img.astype(int) - np.array(bg) * 255).sum(axis=2) > 12


def test_icosphere_helper_is_closed_and_round():
    m = icosphere(10.0, subdiv=4)
    assert abs(m.volume_mm3() - 4 / 3 * math.pi * 1000) / (4 / 3 * math.pi * 1000) < 0.01
    n = vertex_normals(m.vertices, m.faces)
    assert np.allclose(n, m.vertices / 10.0, atol=0.01)  # outward, unit


@pytest.mark.parametrize("aa", ["none", "fxaa", "msaa"])
def test_sphere_disc_radius_orthographic(renderer, aa):
    r = 20.0
    scene = Scene.from_meshes(icosphere(r, (5.0, -3.0, 12.0)))
    scene.options.background = BG
    scene.options.antialias = aa
    scene.camera = Camera(azimuth=40, elevation=25, extent_mm=100.0)
    size = (400, 400)
    img = renderer.render(scene, size=size)
    mask = fg_mask(img)
    r_px = r * size[1] / 100.0
    assert abs(mask.sum() - math.pi * r_px ** 2) / (math.pi * r_px ** 2) < 0.02
    ys, xs = np.nonzero(mask)
    assert abs(xs.mean() + 0.5 - 200) < 1.0 and abs(ys.mean() + 0.5 - 200) < 1.0  # centred on the axis point


def test_sphere_radius_follows_zoom_and_fit(renderer):
    r = 15.0
    scene = Scene.from_meshes(icosphere(r, (100.0, 50.0, -20.0)))
    scene.options.background = BG
    scene.camera.zoom = 1.7
    size = (300, 200)
    cs = setup_camera(scene, size)
    r_px = r * cs.pixels_per_mm(size)
    mask = fg_mask(renderer.render(scene, size=size))
    assert abs(mask.sum() - math.pi * r_px ** 2) / (math.pi * r_px ** 2) < 0.03
    c = cs.project(np.array([[100.0, 50.0, -20.0]]), size)[0]
    ys, xs = np.nonzero(mask)
    assert abs(xs.mean() + 0.5 - c[0]) < 1.0 and abs(ys.mean() + 0.5 - c[1]) < 1.0


def test_perspective_disc_matches_projection(renderer):
    """Perspective: the sphere's silhouette is a circle of angular radius asin(r/d)."""
    r, d = 10.0, 60.0
    scene = Scene.from_meshes(icosphere(r))
    scene.options.background = BG
    scene.camera = Camera(projection="perspective", fov_deg=40.0, eye=(0.0, -d, 0.0), look_at=(0, 0, 0))
    size = (400, 400)
    mask = fg_mask(renderer.render(scene, size=size))
    ang = math.asin(r / d)
    r_px = math.tan(ang) / math.tan(math.radians(20.0)) * 200
    assert abs(mask.sum() - math.pi * r_px ** 2) / (math.pi * r_px ** 2) < 0.03


@pytest.mark.parametrize("side", [1, -1])
def test_side_facing_light_is_brighter(renderer, side):
    scene = Scene.from_meshes(icosphere(20.0))
    scene.options.background = BG
    scene.options.headlight = 0.0
    scene.light = Light(kind="point", azimuth=80 * side, elevation=0, intensity=1.0)
    img = renderer.render(scene, size=(200, 200)).astype(float).sum(axis=2)
    mask = fg_mask(renderer.render(scene, size=(200, 200)))
    right = img[:, 100:][mask[:, 100:]].mean()
    left = img[:, :100][mask[:, :100]].mean()
    if side > 0:
        assert right > 2.0 * left
    else:
        assert left > 2.0 * right


def test_two_objects_show_their_colours(renderer):
    from ctui.engine.core.colors import object_color

    scene = Scene.from_meshes([icosphere(10.0, (-15, 0, 0), object_id=1), icosphere(10.0, (15, 0, 0), object_id=2)])
    scene.options.background = BG
    scene.material = Material(ambient=0.3, diffuse=0.7, specular=0.0)
    scene.camera.extent_mm = 60.0
    size = (300, 300)
    img = renderer.render(scene, size=size).astype(float)
    cs = setup_camera(scene, size)
    for oid, c in ((1, (-15, 0, 0)), (2, (15, 0, 0))):
        px, py = cs.project(np.array([c], float), size)[0].astype(int)
        got = img[py - 3:py + 4, px - 3:px + 4].reshape(-1, 3).mean(axis=0)
        want = np.array(object_color(oid), float)
        cos = got @ want / np.linalg.norm(got) / np.linalg.norm(want)
        assert cos > 0.995, (oid, got, want)
        assert got.sum() > 0.6 * want.sum()


def test_transparent_outer_object_shows_inner_colour(renderer):
    inner = icosphere(10.0, object_id=2)   # green
    outer = icosphere(20.0, object_id=1)   # red
    scene = Scene.from_meshes([inner, outer])
    scene.options.background = BG
    scene.material = Material(specular=0.0)
    size = (200, 200)
    opaque = renderer.render(scene, size=size).astype(float)[95:105, 95:105].reshape(-1, 3).mean(0)
    scene.meshes[1].opacity = 0.3
    see = renderer.render(scene, size=size).astype(float)
    centre = see[95:105, 95:105].reshape(-1, 3).mean(0)
    assert opaque[1] < 0.4 * opaque[0]            # opaque red outer hides the green
    assert centre[1] > 2.0 * opaque[1] and centre[1] > 40  # green shows through
    ppm = setup_camera(scene, size).pixels_per_mm(size)
    x0 = int(100 - 15 * ppm)                      # between the silhouettes: outer only, over background
    ring = see[98:102, x0 - 2:x0 + 2].reshape(-1, 3).mean(0)
    assert ring[0] > ring[1] and ring.sum() < opaque.sum()
    # mode "transparent" makes opaque meshes see-through too
    scene.meshes[1].opacity = 1.0
    scene.mode = "transparent"
    c2 = renderer.render(scene, size=size).astype(float)[95:105, 95:105].reshape(-1, 3).mean(0)
    assert c2[1] / c2[0] > 2.0 * opaque[1] / opaque[0]


def test_wire_modes_draw_edges(renderer):
    scene = Scene.from_meshes(icosphere(20.0, subdiv=2))
    scene.options.background = BG
    scene.options.antialias = "none"
    full = fg_mask(renderer.render(scene, size=(200, 200))).sum()
    scene.mode = "wire"
    wire = fg_mask(renderer.render(scene, size=(200, 200))).sum()
    assert 0.05 * full < wire < 0.8 * full
    scene.mode = "surface"
    scene.options.wireframe_overlay = True
    scene.options.wire_color = (0.0, 0.0, 1.0)
    img = renderer.render(scene, size=(200, 200))
    blue = (img[..., 2] > 200) & (img[..., 0] < 60)
    assert 0.02 * full < blue.sum() < 0.6 * full


def _volume(shape=(32, 48, 64), seed=0):
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    return ndimage.gaussian_filter(rng.normal(size=shape), 2.0).astype(np.float32)


@pytest.mark.parametrize("mode", ["mip", "minip"])
@pytest.mark.parametrize("skip", [True, False])
def test_axis_aligned_projection_equals_numpy(renderer, mode, skip):
    d = _volume()
    nz, ny, nx = d.shape
    lo, hi = float(d.min()), float(d.max())
    scene = Scene(volume=SceneVolume(d, spacing=(1.0, 1.0, 1.0), origin=(10.0, -5.0, 3.0)), mode=mode)
    # from the feet (elevation -90): image columns = x, rows = y, one pixel per voxel
    scene.camera = Camera(elevation=-90, extent_mm=float(ny))
    scene.options.window = ((lo + hi) / 2, hi - lo)
    scene.options.empty_space_skipping = skip
    img = renderer.render(scene, size=(nx, ny))[..., 0].astype(float)
    proj = d.max(axis=0) if mode == "mip" else d.min(axis=0)
    want = (proj - lo) / (hi - lo) * 255
    assert np.abs(img - want).max() <= 1.5


def test_crop_box_cuts_the_volume(renderer):
    d = _volume()
    nz, ny, nx = d.shape
    lo, hi = float(d.min()), float(d.max())
    scene = Scene(volume=SceneVolume(d), mode="mip")
    scene.camera = Camera(elevation=-90, extent_mm=float(ny))
    scene.options.window = ((lo + hi) / 2, hi - lo)
    scene.options.background = BG
    scene.options.crop_box = ((0.0, 0.0, 0.0), (0.5, 1.0, 0.5))  # left half in x, lower half in z
    img = renderer.render(scene, size=(nx, ny))[..., 0].astype(float)
    want = (d[: nz // 2, :, : nx // 2].max(axis=0) - lo) / (hi - lo) * 255
    assert np.abs(img[:, : nx // 2] - want).max() <= 1.5
    assert img[:, nx // 2 + 1:].max() == 0


def test_slice_plane_shows_the_slice(renderer):
    d = _volume()
    nz, ny, nx = d.shape
    lo, hi = float(d.min()), float(d.max())
    scene = Scene(volume=SceneVolume(d), mode="surface")
    scene.camera = Camera(elevation=-90, extent_mm=float(ny))
    scene.options.window = ((lo + hi) / 2, hi - lo)
    scene.options.antialias = "none"
    scene.options.slice_plane = SlicePlane("z", 7)
    img = renderer.render(scene, size=(nx, ny))[..., 0].astype(float)
    want = (d[7] - lo) / (hi - lo) * 255
    assert np.abs(img - want).max() <= 1.5


def test_shadow_darkens_the_plane_under_the_sphere(renderer):
    plane = Mesh(np.array([[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]], float),
                 np.array([[0, 1, 2], [0, 2, 3]]), object_id=4)
    ball = icosphere(10.0, (0.0, 0.0, 25.0), subdiv=3, object_id=1)
    scene = Scene.from_meshes([ball, plane])
    scene.camera = Camera(elevation=40, azimuth=20)
    scene.light = Light(kind="directional", azimuth=0, elevation=89, relative_to="world", intensity=1.0)
    size = (300, 300)
    cs = setup_camera(scene, size)
    under = cs.project(np.array([[0.0, 0.0, 0.0]]), size)[0].astype(int)
    away = cs.project(np.array([[35.0, -35.0, 0.0]]), size)[0].astype(int)

    def patch(img, p):
        return img[p[1] - 2:p[1] + 3, p[0] - 2:p[0] + 3].astype(float).mean()

    off = renderer.render(scene, size=size)
    scene.options.shadows = True
    on = renderer.render(scene, size=size)
    assert patch(on, under) < 0.6 * patch(off, under)
    assert abs(patch(on, away) - patch(off, away)) < 0.03 * patch(off, away)


def _bone_blob():
    z, y, x = np.mgrid[:48, :64, :64]
    r2 = ((x - 32) / 14.0) ** 2 + ((y - 30) / 10.0) ** 2 + ((z - 24) / 16.0) ** 2
    return np.where(r2 < 1.0, 900, -1000).astype(np.int16)


def test_dvr_bone_blob_is_visible_and_skipping_is_exact(renderer):
    d = _bone_blob()
    scene = Scene(volume=SceneVolume(d, spacing=(1.0, 0.8, 0.8)), mode="dvr")
    scene.options.background = BG
    scene.options.preset = "ct-bone"
    scene.camera = Camera(azimuth=30, elevation=20)
    size = (160, 160)
    img = renderer.render(scene, size=size)
    m = fg_mask(img)
    lo, hi = scene.bounds()
    cs = setup_camera(scene, size)
    c = cs.project(np.array([[32 * 0.8, 30 * 0.8, 24.0]]), size)[0].astype(int)
    assert m[c[1], c[0]] and 0.05 < m.mean() < 0.6
    assert img[m].mean() > 80                  # lit, bone-coloured
    assert not m[:5].any() and not m[:, :5].any()   # air is transparent
    scene.options.empty_space_skipping = False
    img2 = renderer.render(scene, size=size)
    assert np.abs(img2.astype(int) - img.astype(int)).max() <= 2
    scene.options.volume_scale = 0.5
    img3 = renderer.render(scene, size=size)
    assert abs(fg_mask(img3).mean() - m.mean()) < 0.02


def test_surfaces_inside_the_volume_stop_rays(renderer):
    d = np.zeros((40, 32, 32), np.float32)
    d[24:34] = 1000.0                                  # bright slab high up
    ball = icosphere(5.0, (15.5, 15.5, 8.0), object_id=2)  # below it, inside the volume
    scene = Scene(meshes=[SceneMesh(ball)], volume=SceneVolume(d), mode="mip")
    scene.camera = Camera(elevation=-90, extent_mm=32.0)   # from the feet: rays meet the ball first
    scene.options.window = (500.0, 1000.0)
    size = (32, 32)
    with_s = renderer.render(scene, size=size).astype(float)[..., 0]
    scene.options.show_surfaces = False
    without = renderer.render(scene, size=size).astype(float)[..., 0]
    assert without.min() > 250                         # the slab everywhere
    assert with_s[14:18, 14:18].max() < 5              # rays stop at the ball: nothing bright before it
    assert with_s[0:3, 0:3].min() > 250                # away from the ball the slab shows


def test_turntable_gif_has_n_frames(renderer, tmp_path):
    from PIL import Image

    scene = Scene.from_meshes([icosphere(10.0, (-15, 0, 0), subdiv=3, object_id=1),
                               icosphere(6.0, (15, 0, 0), subdiv=3, object_id=3)])
    out = save_turntable(tmp_path / "turn.gif", scene, 7, (96, 64), renderer=renderer)
    with Image.open(out) as im:
        assert im.n_frames == 7 and im.size == (96, 64)
        frames = []
        for i in range(im.n_frames):
            im.seek(i)
            frames.append(np.asarray(im.convert("RGB")).astype(int))
    assert np.abs(frames[0] - frames[2]).max() > 50  # the view turns
    apng = save_turntable(tmp_path / "turn.png", scene, 3, (64, 64), renderer=renderer)
    with Image.open(apng) as im:
        assert getattr(im, "n_frames", 1) == 3


def test_flythrough_inside_a_tube(renderer, tmp_path):
    # open cylinder along x (radius 5 mm), camera inside looking along the axis
    n_a, n_l = 48, 40
    a = np.linspace(0, 2 * np.pi, n_a, endpoint=False)
    xs = np.linspace(0, 100, n_l)
    v = np.array([[x, 5 * np.cos(t), 5 * np.sin(t)] for x in xs for t in a])
    f = []
    for i in range(n_l - 1):
        for j in range(n_a):
            p, q = i * n_a + j, i * n_a + (j + 1) % n_a
            f += [[p, q, p + n_a], [q, q + n_a, p + n_a]]
    tube = Mesh(v, np.array(f), object_id=1)
    scene = Scene.from_meshes(tube)
    scene.options.background = BG
    path = np.array([[5.0, 0.0, 0.0], [40.0, 0.5, 0.0], [80.0, 0.0, 0.5]])
    out = save_flythrough(tmp_path / "fly", scene, path, 3, (96, 96), renderer=renderer)
    frames = sorted(out.glob("frame_*.png"))
    assert len(frames) == 3
    import cv2

    img = cv2.imread(str(frames[0]))
    m = fg_mask(img[..., ::-1])
    assert m.mean() > 0.8            # walls all around
    assert m[40:56, 40:56].mean() < 1.0 or img[48, 48].sum() < img[5, 48].sum()  # far end darker/empty


def test_supersede_cancels_pending_request(renderer):
    scene = Scene.from_meshes(icosphere(5.0, subdiv=2))
    gate = threading.Event()
    blocker = renderer.call(lambda engine: gate.wait(5))
    a = renderer.submit(scene, (32, 32), supersede_key="view")
    b = renderer.submit(scene, (48, 32), supersede_key="view")
    other = renderer.submit(scene, (16, 16), supersede_key="other")
    gate.set()
    assert b.result(10).shape == (32, 48, 3)
    assert other.result(10).shape == (16, 16, 3)
    assert a.cancelled()
    blocker.result(10)


def test_render_from_many_threads(renderer):
    scene = Scene.from_meshes(icosphere(5.0, subdiv=2))
    out = []

    def work(w):
        out.append(renderer.render(scene, size=(w, 20)).shape)

    ts = [threading.Thread(target=work, args=(20 + i,)) for i in range(4)]
    for t in ts:
        t.start()
    for t in ts:
        t.join(20)
    assert sorted(out) == sorted((20, 20 + i, 3) for i in range(4))


def test_scene_json_round_trip():
    m = icosphere(5.0, subdiv=1, object_id=3)
    scene = Scene.from_meshes([m], mode="transparent")
    scene.camera.azimuth = 33
    scene.camera.target = (1.0, 2.0, 3.0)
    scene.options.slice_plane = SlicePlane("y", 4)
    scene.options.crop_box = ((0, 0, 0), (1, 0.5, 1))
    scene.meshes[0].opacity = 0.5
    d = json.loads(json.dumps(scene.to_dict()))
    back = Scene.from_dict(d, meshes=[m])
    assert back.to_dict() == scene.to_dict()
    assert back.camera.target == (1.0, 2.0, 3.0) and back.options.slice_plane.axis == "y"


def test_save_png_round_trip(tmp_path):
    import cv2

    img = (np.arange(30 * 40 * 3) % 251).astype(np.uint8).reshape(30, 40, 3)
    save_png(tmp_path / "a.png", img)
    back = cv2.imread(str(tmp_path / "a.png"))[..., ::-1]
    assert np.array_equal(back, img)


def test_egl_failure_is_one_line_naming_packages():
    code = textwrap.dedent(
        """
        import os
        os.environ["CTUI_GL_BACKEND"] = "no-such-backend"
        from ctui.engine.render import get_renderer, EGLUnavailable
        try:
            get_renderer()
        except EGLUnavailable as exc:
            print(str(exc))
        """
    )
    res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    msg = res.stdout.strip()
    assert len(msg.splitlines()) == 1
    assert "libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri" in msg


# ---------------------------------------------------------------------------- CLI
def test_cli_stl_writes_png(renderer, tmp_path, capsys):
    import cv2

    from ctui.cli import main

    m = icosphere(12.0, subdiv=3)
    tri = m.vertices[m.faces].astype("<f4")
    n = np.zeros((len(m.faces), 3), "<f4")
    rec = np.zeros(len(m.faces), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"], rec["v"] = n, tri
    stl = tmp_path / "ball.stl"
    stl.write_bytes(b"\0" * 80 + np.uint32(len(rec)).tobytes() + rec.tobytes())
    out = tmp_path / "ball.png"
    rc = main(["render", str(stl), "--out", str(out), "--size", "120x90", "--shadows", "--light", "20,40"])
    assert rc == 0
    img = cv2.imread(str(out))
    assert img.shape == (90, 120, 3)
    bg = img[0, 0].astype(int)
    assert (np.abs(img.astype(int) - bg).sum(axis=2) > 12).mean() > 0.1


def test_cli_bad_input_exits_2_with_one_line(tmp_path):
    txt = tmp_path / "notes.txt"
    txt.write_text("not an image\n")
    for args in ([str(txt), "--out", str(tmp_path / "x.png")],
                 [str(tmp_path / "missing.stl"), "--out", str(tmp_path / "x.png")]):
        res = subprocess.run([sys.executable, "-m", "ctui", "render", *args], cwd=ROOT, capture_output=True,
                             text=True, timeout=120)
        assert res.returncode == 2, res.stderr
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("ctui render:"), res.stderr
    assert not (tmp_path / "x.png").exists()


def test_brick_minmax_matches_filtered_reference():
    """The empty-space skipping bounds: per 8^3 brick, min/max over the brick grown by
    one voxel (what trilinear sampling and gradients can reach) == scipy filters."""
    from scipy import ndimage

    from ctui.engine.render.volume_gpu import brick_minmax as _brick_minmax

    rng = np.random.default_rng(1)
    for shape in [(37, 50, 64), (9, 8, 17)]:
        u = rng.integers(0, 65535, size=shape).astype(np.uint16)
        mn, mx = _brick_minmax(u, 8)
        fx = ndimage.maximum_filter(u, 3, mode="nearest")
        fn = ndimage.minimum_filter(u, 3, mode="nearest")
        for i, j, k in np.ndindex(*mn.shape):
            sl = (slice(i * 8, i * 8 + 8), slice(j * 8, j * 8 + 8), slice(k * 8, k * 8 + 8))
            assert mx[i, j, k] * 65535 == pytest.approx(fx[sl].max()) and mn[i, j, k] * 65535 == pytest.approx(fn[sl].min())


def test_cli_project_renders_its_objects_in_their_colours(renderer, tmp_path):
    """A .ctui project: labels -> surfaces (MESH) in the project's geometry -> PNG
    showing each object's colour."""
    import cv2

    from ctui.cli import main
    from ctui.engine.core.colors import object_color
    from ctui.engine.io.series import load
    from ctui.engine.io.phantom import sample_path
    from ctui.engine.io.project import Project, save_project

    src = sample_path()
    vol = load(src)
    labels = np.zeros(vol.shape, np.uint8)
    labels[(vol.data > 150) & (vol.data < 400)] = 2     # kidneys (contrast)
    labels[(vol.data > 1000)] = 5                        # the metal tube
    proj = tmp_path / "p.ctui"
    save_project(proj, Project(source_path=str(src), labels=labels,
                               objects=[{"id": 2, "name": "kidneys"}, {"id": 5, "name": "tube"}]))
    out = tmp_path / "p.png"
    rc = main(["render", str(proj), "--out", str(out), "--size", "200x160", "--elevation", "10"])
    assert rc == 0
    img = cv2.imread(str(out))[..., ::-1].astype(float)
    for oid in (2, 5):
        want = np.array(object_color(oid), float)
        cos = (img @ want) / (np.linalg.norm(img, axis=2) * np.linalg.norm(want) + 1e-9)
        assert (cos > 0.995).sum() > 50, oid         # pixels of that hue are present
    rc = main(["render", str(proj), "--out", str(out), "--object", "9"])
    assert rc == 2


def test_cli_volume_modes_on_the_sample_series(renderer, tmp_path):
    import cv2

    from ctui.cli import main
    from ctui.engine.io.phantom import sample_path

    src = sample_path()
    for mode in ("dvr", "mip"):
        out = tmp_path / f"{mode}.png"
        assert main(["render", str(src), "--out", str(out), "--mode", mode, "--size", "96x96"]) == 0
        img = cv2.imread(str(out))
        assert (np.abs(img.astype(int) - img[0, 0]).sum(axis=2) > 12).mean() > 0.1
    assert main(["render", str(src), "--out", str(tmp_path / "s.png"), "--mode", "surface"]) == 2  # needs --iso
    out = tmp_path / "iso.gif"
    assert main(["render", str(src), "--out", str(out), "--iso", "500", "--turntable", "3", "--size", "64x64"]) == 0
    from PIL import Image

    with Image.open(out) as im:
        assert im.n_frames == 3


@pytest.mark.parametrize("aa", ["fxaa", "msaa"])
def test_antialiasing_blends_the_silhouette(renderer, aa):
    """Flat white disc on black: without AA every pixel is 0 or 255; with FXAA/MSAA
    the silhouette gets intermediate values along most of its length."""
    scene = Scene.from_meshes(icosphere(20.0, subdiv=4))
    scene.meshes[0].color = (1.0, 1.0, 1.0)
    scene.material = Material(ambient=1.0, diffuse=0.0, specular=0.0)
    scene.options.headlight = 0.0
    scene.options.background = BG
    scene.camera.extent_mm = 100.0
    scene.options.antialias = "none"
    hard = renderer.render(scene, size=(200, 200))[..., 1]
    assert np.isin(hard, [0, 255]).mean() > 0.999
    scene.options.antialias = aa
    soft = renderer.render(scene, size=(200, 200))[..., 1]
    mid = ((soft > 25) & (soft < 230)).sum()
    perimeter = 2 * math.pi * 40
    assert mid > 0.5 * perimeter
    assert abs((soft / 255.0).sum() - (hard / 255.0).sum()) < 0.01 * (hard / 255.0).sum()  # same coverage


def test_cli_flythrough_inside_a_tube(renderer, tmp_path):
    from PIL import Image

    from ctui.cli import main

    n_a, n_l = 32, 20
    a = np.linspace(0, 2 * np.pi, n_a, endpoint=False)
    zs = np.linspace(-50, 50, n_l)
    v = np.array([[6 * np.cos(t), 6 * np.sin(t), z] for z in zs for t in a], "<f4")
    f = []
    for i in range(n_l - 1):
        for j in range(n_a):
            p, q = i * n_a + j, i * n_a + (j + 1) % n_a
            f += [[p, q, p + n_a], [q, q + n_a, p + n_a]]
    f = np.array(f)
    rec = np.zeros(len(f), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = v[f]
    stl = tmp_path / "tube.stl"
    stl.write_bytes(b"\0" * 80 + np.uint32(len(rec)).tobytes() + rec.tobytes())
    out = tmp_path / "fly.gif"
    assert main(["render", str(stl), "--out", str(out), "--flythrough", "0,0,-45;0,0.5,0;0,0,45",
                 "--frames", "4", "--size", "64x64"]) == 0
    with Image.open(out) as im:
        assert im.n_frames == 4
        im.seek(1)
        fr = np.asarray(im.convert("RGB")).astype(int)
    bg = np.array([18, 18, 23])
    assert (np.abs(fr - bg).sum(axis=2) > 12).mean() > 0.7   # walls all around the view
    assert main(["render", str(stl), "--out", str(out), "--flythrough", "auto"]) == 2  # auto needs a project


def test_cli_flythrough_auto_on_a_one_object_project(renderer, tmp_path):
    """--flythrough auto on a project with one object follows its centreline (no
    --object needed): frames seen from inside show walls all around."""
    from PIL import Image

    from ctui.cli import main
    from ctui.engine.io.project import Project, save_project

    lab = np.zeros((60, 30, 30), np.uint8)
    z, y, x = np.mgrid[:60, :30, :30]
    lab[((x - 15) ** 2 + (y - 15) ** 2 <= 36) & (z > 4) & (z < 55)] = 1
    proj = tmp_path / "tube.ctui"
    save_project(proj, Project(source_path=None, labels=lab,
                               meta={"spacing_zyx_mm": [1.0, 1.0, 1.0], "origin_xyz_mm": [0.0, 0.0, 0.0]}))
    out = tmp_path / "fly.gif"
    rc = main(["render", str(proj), "--out", str(out), "--flythrough", "auto", "--frames", "3", "--size", "64x64"])
    assert rc == 0
    with Image.open(out) as im:
        assert im.n_frames == 3
        im.seek(1)
        fr = np.asarray(im.convert("RGB")).astype(int)
    bg = np.array([18, 18, 23])
    assert (np.abs(fr - bg).sum(axis=2) > 12).mean() > 0.7


def test_surface_render_frames_the_object_not_the_series(renderer):
    """A 10 mm ball in a 200 mm series: in surface mode it fills the image (issue 17's
    tiny object); ``frame="series"`` shows the whole box as before."""
    ball = icosphere(10.0, centre=(60.0, 60.0, 40.0), subdiv=3)
    vol = SceneVolume(np.zeros((40, 100, 100), np.int16), spacing=(2.0, 2.0, 2.0))
    scene = Scene(meshes=[SceneMesh(ball)], volume=vol, mode="surface")
    scene.options.background = BG
    size = (200, 200)
    objects = fg_mask(renderer.render(scene, size=size))
    scene.options.frame = "series"
    series = fg_mask(renderer.render(scene, size=size))
    # framed: the view spans the ball's bounding-box diagonal (20 * sqrt(3) * 1.05 mm),
    # so the ball is 55 % of the image; framing the series' 300 mm box shrinks it ~8x
    rows = np.flatnonzero(objects.any(axis=1))
    assert rows[-1] - rows[0] > 0.5 * size[1]
    assert 0 < series.sum() < objects.sum() / 30


def test_slice_plane_outside_the_framed_object_is_not_clipped(renderer):
    ball = icosphere(10.0, centre=(60.0, 60.0, 40.0), subdiv=3)
    d = np.full((40, 100, 100), 500, np.int16)
    scene = Scene(meshes=[SceneMesh(ball)], volume=SceneVolume(d, spacing=(2.0, 2.0, 2.0)), mode="surface")
    scene.options.background = BG
    scene.options.slice_plane = SlicePlane(axis="z", index=20)
    scene.options.window = (0.0, 100.0)  # the slice shows white
    scene.camera.elevation = 60.0
    img = renderer.render(scene, size=(160, 160))
    assert fg_mask(img).mean() > 0.95  # the plane fills the view around the ball, unclipped


def test_oversized_images_and_animations_refused_before_rendering(renderer, monkeypatch, tmp_path):
    from ctui.engine.core.errors import CtuiError
    from ctui.engine.render.outputs import turntable_frames

    monkeypatch.setenv("CTUI_MEMORY_LIMIT", str(2 * 1024 ** 3))
    scene = Scene.from_meshes(icosphere(5.0, subdiv=2))
    with pytest.raises(CtuiError, match="8192x8192"):
        renderer.submit(scene, (8192, 8192))
    with pytest.raises(CtuiError, match="2000 frames"):
        turntable_frames(scene, 2000, (800, 600), renderer=renderer)
    assert renderer.render(scene, size=(64, 48)).shape == (48, 64, 3)  # still fine afterwards


def test_cli_render_huge_size_one_line(renderer, tmp_path):
    import os

    from ctui.engine.io.meshes import save_mesh

    save_mesh(tmp_path / "b.stl", icosphere(5.0, subdiv=2))
    env = dict(os.environ, CTUI_MEMORY_LIMIT=str(2 * 1024 ** 3))
    res = subprocess.run([sys.executable, "-m", "ctui.cli", "render", str(tmp_path / "b.stl"), "--out",
                          str(tmp_path / "b.png"), "--size", "8192x8192"], env=env, capture_output=True, text=True,
                         cwd=ROOT, timeout=300)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "8192x8192" in lines[0] and "Traceback" not in res.stderr
    assert not (tmp_path / "b.png").exists()
