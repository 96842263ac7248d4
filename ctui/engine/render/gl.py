"""The OpenGL side of the renderer. A :class:`GLEngine` lives on the render thread
(:mod:`ctui.engine.render.context`) and must only be used there."""

from __future__ import annotations

import math
import time
import weakref
from collections import OrderedDict
from typing import Any

import numpy as np

from . import shaders
from .camera import CameraSetup, look_at, ortho, setup_camera, light_position
from .scene import Scene, SceneMesh, SceneVolume, VOLUME_MODES
from .transfer import resolve_preset, transfer_table

BRICK = 8
TF_SIZE = 1024
MAX_TEXTURE_VOXELS = 300_000_000  # ~600 MB as 16-bit; larger volumes are subsampled


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (n, 3) float32 for a triangle mesh."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # length = 2 * area
    n = np.zeros((len(v), 3))
    for k in range(3):
        idx = f.ravel()
        n[:, k] = np.bincount(idx, weights=np.repeat(fn[:, k], 3), minlength=len(v))
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    ln[ln == 0] = 1.0
    return (n / ln).astype(np.float32)


class _MeshGPU:
    def __init__(self, ctx, progs, mesh) -> None:
        v = np.ascontiguousarray(mesh.vertices, dtype=np.float32)
        f = np.ascontiguousarray(mesh.faces, dtype=np.uint32)
        nrm = mesh.normals
        if nrm is None or np.shape(nrm) != v.shape:
            nrm = vertex_normals(v, f)
        inter = np.empty((len(v), 6), np.float32)
        inter[:, :3] = v
        inter[:, 3:] = nrm
        self.vbo = ctx.buffer(inter.tobytes())
        self.ibo = ctx.buffer(f.tobytes())
        self.vao = ctx.vertex_array(progs["surface"], [(self.vbo, "3f 3f", "in_pos", "in_normal")], self.ibo)
        self.vao_depth = ctx.vertex_array(progs["depth"], [(self.vbo, "3f 12x", "in_pos")], self.ibo)
        self.nbytes = inter.nbytes + f.nbytes
        self.ref = weakref.ref(mesh.vertices) if isinstance(mesh.vertices, np.ndarray) else None
        self.fref = weakref.ref(mesh.faces) if isinstance(mesh.faces, np.ndarray) else None

    def release(self) -> None:
        for o in (self.vao, self.vao_depth, self.vbo, self.ibo):
            o.release()


class _VolumeGPU:
    """A volume as a 16-bit normalised 3D texture plus its brick min/max grid."""

    def __init__(self, ctx, vol: SceneVolume) -> None:
        data = vol.data
        step = 1
        while data[::step, ::step, ::step].size > MAX_TEXTURE_VOXELS or max(s // step for s in data.shape) > 2048:
            step += 1
        self.step = step
        src = data[::step, ::step, ::step] if step > 1 else data
        nz, ny, nx = src.shape
        self.dims = (nx, ny, nz)
        self.vmin = float(np.min(src))
        self.vmax = float(np.max(src))
        scale = 65535.0 / max(self.vmax - self.vmin, 1e-12)
        u16 = np.empty(src.shape, np.uint16)
        for z0 in range(0, nz, 32):  # slab by slab: no full-size float copy
            sl = (np.asarray(src[z0:z0 + 32], np.float32) - self.vmin) * scale
            u16[z0:z0 + 32] = np.clip(sl + 0.5, 0, 65535).astype(np.uint16)
        self.tex = ctx.texture3d(self.dims, 1, u16.tobytes(), dtype="nu2")
        self.tex.filter = (ctx.LINEAR, ctx.LINEAR)
        self.tex.repeat_x = self.tex.repeat_y = self.tex.repeat_z = False
        self.bmin, self.bmax = _brick_minmax(u16, BRICK)
        nb = self.bmin.shape  # (bz, by, bx)
        self.nbricks = (nb[2], nb[1], nb[0])
        self.brick_tex = ctx.texture3d(self.nbricks, 4, None, dtype="f4")
        self.brick_tex.filter = (ctx.NEAREST, ctx.NEAREST)
        self._occ_key: Any = None
        self.nbytes = u16.nbytes
        self.ref = weakref.ref(data) if isinstance(data, np.ndarray) else None
        # geometry: voxel index (of the subsampled grid) -> world
        a = vol.affine()
        s = np.diag([step, step, step, 1.0])
        self.vox_to_world = a @ s
        self.world_to_vox = np.linalg.inv(self.vox_to_world)

    def norm(self, value: float) -> float:
        return (value - self.vmin) / max(self.vmax - self.vmin, 1e-12)

    def update_bricks(self, tf: np.ndarray | None, key: Any) -> None:
        """Fill the brick texture: r = min, g = max (normalised), b = occupancy for ``tf``."""
        if key == self._occ_key:
            return
        occ = np.ones_like(self.bmin, dtype=np.float32)
        if tf is not None:
            vis = tf[:, 3] > 0.001
            c = np.concatenate([[0], np.cumsum(vis)])
            n = len(tf) - 1
            lo = np.floor(self.bmin * n).astype(np.int64)
            hi = np.ceil(self.bmax * n).astype(np.int64)
            occ = ((c[hi + 1] - c[lo]) > 0).astype(np.float32)
        arr = np.stack([self.bmin, self.bmax, occ, np.zeros_like(occ)], axis=-1).astype(np.float32)
        self.brick_tex.write(np.ascontiguousarray(arr).tobytes())
        self._occ_key = key

    def release(self) -> None:
        self.tex.release()
        self.brick_tex.release()


def _brick_minmax(u16: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-brick min and max (normalised 0..1) over each b^3 brick grown by one voxel
    (trilinear filtering and central differences reach one voxel outside)."""
    from scipy import ndimage

    mx = ndimage.maximum_filter(u16, size=3, mode="nearest")
    mn = ndimage.minimum_filter(u16, size=3, mode="nearest")
    nz, ny, nx = u16.shape
    pz, py, px = (-nz) % b, (-ny) % b, (-nx) % b
    if pz or py or px:
        mx = np.pad(mx, ((0, pz), (0, py), (0, px)), mode="edge")
        mn = np.pad(mn, ((0, pz), (0, py), (0, px)), mode="edge")
    sh = (mx.shape[0] // b, b, mx.shape[1] // b, b, mx.shape[2] // b, b)
    bmax = mx.reshape(sh).max(axis=(1, 3, 5)).astype(np.float32) / 65535.0
    bmin = mn.reshape(sh).min(axis=(1, 3, 5)).astype(np.float32) / 65535.0
    return bmin, bmax


class _Targets:
    """Framebuffers for one image size."""

    def __init__(self, ctx, size: tuple[int, int], samples: int) -> None:
        self.size = size
        self.samples = samples
        T = ctx.texture
        self.color = T(size, 4)
        self.depth = ctx.depth_texture(size)
        self.scene = ctx.framebuffer([self.color], self.depth)
        self.accum = T(size, 4, dtype="f4")
        self.reveal = T(size, 1, dtype="f4")
        self.oit = ctx.framebuffer([self.accum, self.reveal], self.depth)
        self.comp_tex = T(size, 4)
        self.comp = ctx.framebuffer([self.comp_tex])
        self.out_tex = T(size, 4)
        self.out = ctx.framebuffer([self.out_tex])
        for t in (self.color, self.comp_tex, self.out_tex):
            t.filter = (ctx.LINEAR, ctx.LINEAR)
            t.repeat_x = t.repeat_y = False
        for t in (self.accum, self.reveal):
            t.filter = (ctx.NEAREST, ctx.NEAREST)
        self.depth.compare_func = ""
        self.ms = self.ms_oit = None
        if samples > 1:
            ms_depth = ctx.depth_renderbuffer(size, samples=samples)
            self.ms = ctx.framebuffer([ctx.renderbuffer(size, 4, samples=samples)], ms_depth)
            self.ms_oit = ctx.framebuffer([ctx.renderbuffer(size, 4, samples=samples, dtype="f4"),
                                           ctx.renderbuffer(size, 1, samples=samples, dtype="f4")], ms_depth)
            self._ms_objs = [ms_depth, *self.ms.color_attachments, *self.ms_oit.color_attachments]
        self.vol_tex = None
        self.vol_fbo = None

    def volume_target(self, ctx, vsize: tuple[int, int]):
        if self.vol_tex is None or self.vol_tex.size != vsize:
            if self.vol_fbo is not None:
                self.vol_fbo.release()
                self.vol_tex.release()
            self.vol_tex = ctx.texture(vsize, 4, dtype="f2")
            self.vol_tex.filter = (ctx.LINEAR, ctx.LINEAR)
            self.vol_tex.repeat_x = self.vol_tex.repeat_y = False
            self.vol_fbo = ctx.framebuffer([self.vol_tex])
        return self.vol_fbo

    def release(self) -> None:
        objs = [self.scene, self.oit, self.comp, self.out, self.color, self.depth, self.accum, self.reveal,
                self.comp_tex, self.out_tex]
        if self.ms is not None:
            objs += [self.ms, self.ms_oit, *self._ms_objs]
        if self.vol_fbo is not None:
            objs += [self.vol_fbo, self.vol_tex]
        for o in objs:
            o.release()


class GLEngine:
    """Owns the moderngl context; renders :class:`Scene` objects to RGB arrays."""

    MESH_CACHE_BYTES = 1_500_000_000

    def __init__(self, ctx) -> None:
        self.ctx = ctx
        c = ctx
        self.progs = {
            "surface": c.program(vertex_shader=shaders.SURFACE_VS, fragment_shader=shaders.SURFACE_FS),
            "depth": c.program(vertex_shader=shaders.DEPTH_VS, fragment_shader=shaders.DEPTH_FS),
            "oit": c.program(vertex_shader=shaders.FULLSCREEN_VS, fragment_shader=shaders.OIT_COMPOSITE_FS),
            "fxaa": c.program(vertex_shader=shaders.FULLSCREEN_VS, fragment_shader=shaders.FXAA_FS),
            "slice": c.program(vertex_shader=shaders.SLICE_VS, fragment_shader=shaders.SLICE_FS),
            "ray": c.program(vertex_shader=shaders.FULLSCREEN_VS, fragment_shader=shaders.RAYCAST_FS),
            "vcomp": c.program(vertex_shader=shaders.FULLSCREEN_VS, fragment_shader=shaders.VOLUME_COMPOSITE_FS),
        }
        self.fs_vaos = {k: c.vertex_array(self.progs[k], []) for k in ("oit", "fxaa", "ray", "vcomp")}
        self.meshes: OrderedDict[tuple, _MeshGPU] = OrderedDict()
        self.volumes: OrderedDict[int, _VolumeGPU] = OrderedDict()
        self.targets: _Targets | None = None
        self.shadow_tex = None
        self.shadow_fbo = None
        self.tf_tex = None
        self._tf_key: Any = None
        self._tf_table: np.ndarray | None = None
        self.timings: dict[str, float] = {}
        self.max_samples = int(getattr(c, "max_samples", 4) or 1)

    # ------------------------------------------------------------------ caches
    def _mesh(self, mesh) -> _MeshGPU:
        key = (id(mesh.vertices), id(mesh.faces), id(mesh.normals))
        g = self.meshes.get(key)
        if g is not None and (g.ref is None or g.ref() is mesh.vertices) and (g.fref is None or g.fref() is mesh.faces):
            self.meshes.move_to_end(key)
            return g
        if g is not None:
            g.release()
            del self.meshes[key]
        g = _MeshGPU(self.ctx, self.progs, mesh)
        self.meshes[key] = g
        total = sum(m.nbytes for m in self.meshes.values())
        while total > self.MESH_CACHE_BYTES and len(self.meshes) > 1:
            _, old = self.meshes.popitem(last=False)
            total -= old.nbytes
            old.release()
        return g

    def _volume(self, vol: SceneVolume) -> _VolumeGPU:
        key = id(vol.data)
        g = self.volumes.get(key)
        if g is not None and (g.ref is None or g.ref() is vol.data):
            self.volumes.move_to_end(key)
            return g
        if g is not None:
            g.release()
            del self.volumes[key]
        while len(self.volumes) >= 2:
            _, old = self.volumes.popitem(last=False)
            old.release()
        g = _VolumeGPU(self.ctx, vol)
        self.volumes[key] = g
        return g

    def clear_cache(self) -> None:
        for g in self.meshes.values():
            g.release()
        for v in self.volumes.values():
            v.release()
        self.meshes.clear()
        self.volumes.clear()

    def _targets(self, size: tuple[int, int], samples: int) -> _Targets:
        t = self.targets
        if t is None or t.size != size or t.samples != samples:
            if t is not None:
                t.release()
            self.targets = t = _Targets(self.ctx, size, samples)
        return t

    # ------------------------------------------------------------------ render
    def render(self, scene: Scene, size: tuple[int, int]) -> np.ndarray:
        """Render ``scene`` to an (h, w, 3) uint8 RGB array (row 0 = top)."""
        w, h = int(size[0]), int(size[1])
        if w < 1 or h < 1 or w > 16384 or h > 16384:
            raise ValueError(f"bad image size {w}x{h}")
        ctx = self.ctx
        opts = scene.options
        mode = scene.mode
        volume_mode = mode in VOLUME_MODES and scene.volume is not None
        aa = opts.antialias
        samples = min(4, self.max_samples) if (aa == "msaa" and not volume_mode) else 0
        t = self._targets((w, h), samples)
        cs = setup_camera(scene, (w, h))
        lpos, ldir = light_position(scene, cs)

        items = [m for m in scene.meshes if m.visible and m.mesh.n_faces]
        if volume_mode and not opts.show_surfaces:
            items = []
        opaque, transparent = [], []
        for m in items:
            a = float(m.opacity)
            if mode == "transparent" and a >= 1.0:
                a = float(opts.transparent_opacity)
            if volume_mode:
                a = 1.0  # surfaces inside a volume: opaque, the rays stop at them
            (opaque if a >= 0.999 else transparent).append((m, a))

        # ---- shadow pass
        light_vp = np.eye(4)
        shadows = bool(opts.shadows) and mode in ("surface", "transparent") and bool(items)
        if shadows:
            light_vp = self._shadow_pass(scene, cs, lpos, ldir, [m for m, _ in opaque + transparent])

        # ---- opaque pass
        bg = tuple(float(c) for c in opts.background)
        scene_fbo = t.ms if samples else t.scene
        scene_fbo.use()
        ctx.viewport = (0, 0, w, h)
        ctx.disable(ctx.BLEND)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        scene_fbo.clear(*bg, 1.0, depth=1.0)
        prog = self.progs["surface"]
        self._set_surface_uniforms(prog, scene, cs, lpos, ldir, light_vp, shadows)
        wire_only = mode == "wire"
        if wire_only:
            ctx.wireframe = True
            prog["u_pass"].value = 2
            for m, _ in opaque + transparent:
                prog["u_color"].value = m.rgb()
                self._mesh(m.mesh).vao.render()
            ctx.wireframe = False
        else:
            prog["u_pass"].value = 0
            if opts.wireframe_overlay:
                ctx.polygon_offset = (1.0, 1.0)
            for m, _ in opaque:
                prog["u_color"].value = m.rgb()
                self._mesh(m.mesh).vao.render()
            ctx.polygon_offset = (0.0, 0.0)
            if opts.slice_plane is not None and scene.volume is not None:
                self._draw_slice(scene, cs)
            if opts.wireframe_overlay and opaque:
                ctx.wireframe = True
                ctx.depth_func = "<="
                prog["u_pass"].value = 2
                prog["u_color"].value = tuple(opts.wire_color)
                for m, _ in opaque:
                    self._mesh(m.mesh).vao.render()
                ctx.wireframe = False
                ctx.depth_func = "<"

        final_tex = None
        if transparent and not wire_only:
            # ---- weighted blended order-independent transparency
            oit_fbo = t.ms_oit if samples else t.oit
            oit_fbo.depth_mask = False  # keep the opaque depth: clear colours only
            oit_fbo.use()
            oit_fbo.clear(0.0, 0.0, 0.0, 0.0)
            ctx.enable(ctx.BLEND)
            ctx.blend_func = ctx.ONE, ctx.ONE
            ctx.blend_equation = ctx.FUNC_ADD
            prog["u_pass"].value = 1
            for m, a in transparent:
                prog["u_color"].value = m.rgb()
                prog["u_opacity"].value = a
                self._mesh(m.mesh).vao.render()
            ctx.disable(ctx.BLEND)
            oit_fbo.depth_mask = True
            if samples:
                ctx.copy_framebuffer(t.scene, t.ms)
                ctx.copy_framebuffer(t.oit, t.ms_oit)
            t.comp.use()
            ctx.disable(ctx.DEPTH_TEST)
            t.color.use(0)
            t.accum.use(1)
            t.reveal.use(2)
            p = self.progs["oit"]
            p["u_opaque"].value, p["u_accum"].value, p["u_reveal"].value = 0, 1, 2
            self.fs_vaos["oit"].render(vertices=3)
            final_tex = t.comp_tex
        else:
            if samples:
                ctx.copy_framebuffer(t.scene, t.ms)
            final_tex = t.color

        # ---- volume
        if volume_mode:
            final_tex = self._volume_pass(scene, cs, t, final_tex, lpos, ldir)

        # ---- anti-aliasing / readback
        ctx.disable(ctx.DEPTH_TEST)
        if aa == "fxaa" and not volume_mode:
            t.out.use()
            final_tex.use(0)
            p = self.progs["fxaa"]
            p["u_tex"].value = 0
            p["u_inv"].value = (1.0 / w, 1.0 / h)
            self.fs_vaos["fxaa"].render(vertices=3)
            fbo = t.out
        elif final_tex is t.color:
            fbo = t.scene
        elif final_tex is t.comp_tex:
            fbo = t.comp
        else:
            fbo = t.out
        raw = fbo.read(components=3, alignment=1)
        img = np.frombuffer(raw, np.uint8).reshape(h, w, 3)
        return np.ascontiguousarray(img[::-1])

    # ------------------------------------------------------------------ pieces
    def _set_surface_uniforms(self, prog, scene, cs: CameraSetup, lpos, ldir, light_vp, shadows) -> None:
        lt = scene.light
        mat = scene.material
        prog["u_vp"].write(cs.vp.T.astype("f4").tobytes())
        _set(prog, "u_light_vp", light_vp.T.astype("f4").tobytes(), raw=True)
        _set(prog, "u_ortho", 1 if cs.ortho else 0)
        _set(prog, "u_eye", tuple(cs.eye))
        _set(prog, "u_view_back", tuple(-cs.forward))
        kind = {"point": 0, "spot": 1, "directional": 2}.get(lt.kind, 0)
        _set(prog, "u_light_kind", kind)
        _set(prog, "u_light_pos", tuple(lpos))
        _set(prog, "u_light_dir", tuple(ldir))
        _set(prog, "u_spot_cos", math.cos(math.radians(lt.spot_angle_deg)))
        _set(prog, "u_light_intensity", float(lt.intensity))
        _set(prog, "u_light_color", tuple(float(c) for c in lt.color))
        _set(prog, "u_headlight", float(scene.options.headlight))
        _set(prog, "u_material", (mat.ambient, mat.diffuse, mat.specular, max(mat.shininess, 1.0)))
        _set(prog, "u_shadows", 1 if shadows else 0)
        _set(prog, "u_opacity", 1.0)
        if shadows:
            self.shadow_tex.use(5)
            _set(prog, "u_shadow_map", 5)
            _set(prog, "u_shadow_bias", 0.0015)

    def _shadow_pass(self, scene, cs: CameraSetup, lpos, ldir, items: list[SceneMesh]) -> np.ndarray:
        ctx = self.ctx
        sm = int(scene.options.shadow_map_size)
        if self.shadow_tex is None or self.shadow_tex.size != (sm, sm):
            if self.shadow_tex is not None:
                self.shadow_fbo.release()
                self.shadow_tex.release()
            self.shadow_tex = ctx.depth_texture((sm, sm))
            self.shadow_tex.compare_func = "<="
            self.shadow_tex.filter = (ctx.LINEAR, ctx.LINEAR)
            self.shadow_tex.repeat_x = self.shadow_tex.repeat_y = False
            self.shadow_fbo = ctx.framebuffer(depth_attachment=self.shadow_tex)
        centre = scene.centre()
        r = cs.radius
        # orthographic shadow frustum along the light's direction, fitted to the scene
        eye = centre - ldir * (2.0 * r)
        up = np.array([0.0, 0.0, 1.0]) if abs(ldir[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
        view = look_at(eye, centre, up)
        proj = ortho(-r, r, -r, r, 0.5 * r, 3.5 * r)
        vp = proj @ view
        self.shadow_fbo.use()
        ctx.viewport = (0, 0, sm, sm)
        self.shadow_fbo.clear(depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.disable(ctx.BLEND)
        ctx.polygon_offset = (2.0, 4.0)
        p = self.progs["depth"]
        p["u_vp"].write(vp.T.astype("f4").tobytes())
        for m in items:
            self._mesh(m.mesh).vao_depth.render()
        ctx.polygon_offset = (0.0, 0.0)
        return vp

    def _draw_slice(self, scene: Scene, cs: CameraSetup) -> None:
        ctx = self.ctx
        vol = scene.volume
        g = self._volume(vol)
        sp = scene.options.slice_plane
        axis = {"z": 2, "axial": 2, "y": 1, "coronal": 1, "x": 0, "sagittal": 0}[str(sp.axis).lower()]
        nx, ny, nz = g.dims
        n = (nx, ny, nz)[axis]
        idx = (n - 1) / 2.0 if sp.index is None else float(np.clip(sp.index / g.step, 0, n - 1))
        # 4 corners in voxel index space (x, y, z) of the subsampled grid
        lo, hi = [-0.5] * 3, [nx - 0.5, ny - 0.5, nz - 0.5]
        a1, a2 = [k for k in range(3) if k != axis]
        corners = []
        for u, v in ((0, 0), (1, 0), (1, 1), (0, 1)):
            c = [0.0, 0.0, 0.0]
            c[axis] = idx
            c[a1] = hi[a1] if u else lo[a1]
            c[a2] = hi[a2] if v else lo[a2]
            corners.append(c)
        vox = np.array(corners)
        world = (np.c_[vox, np.ones(4)] @ g.vox_to_world.T)[:, :3]
        tex = (vox + 0.5) / np.array(g.dims, float)
        tri = np.array([0, 1, 2, 0, 2, 3])
        data = np.c_[world[tri], tex[tri]].astype("f4")
        vbo = ctx.buffer(data.tobytes())
        p = self.progs["slice"]
        vao = ctx.vertex_array(p, [(vbo, "3f 3f", "in_pos", "in_tex")])
        p["u_vp"].write(cs.vp.T.astype("f4").tobytes())
        g.tex.use(3)
        p["u_vol"].value = 3
        p["u_window"].value = self._window_norm(scene, g)
        vao.render()
        vao.release()
        vbo.release()

    def _window_norm(self, scene: Scene, g: _VolumeGPU) -> tuple[float, float]:
        win = scene.options.window or scene.volume.window
        if win is None:
            from ..windows import auto_window

            win = auto_window(scene.volume.data, modality=scene.volume.modality)
        c, wd = float(win[0]), max(float(win[1]), 1e-6)
        return g.norm(c - wd / 2.0), g.norm(c + wd / 2.0)

    def _tf(self, scene: Scene, g: _VolumeGPU) -> np.ndarray:
        name = resolve_preset(scene.options.preset)
        win = scene.options.window or scene.volume.window
        key = (name, g.vmin, g.vmax, tuple(win) if win else None)
        if key != self._tf_key:
            tab = transfer_table(name, g.vmin, g.vmax, window=win, n=TF_SIZE)
            if self.tf_tex is None:
                self.tf_tex = self.ctx.texture((TF_SIZE, 1), 4, dtype="f4")
                self.tf_tex.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
                self.tf_tex.repeat_x = self.tf_tex.repeat_y = False
            self.tf_tex.write(tab.tobytes())
            self._tf_key, self._tf_table = key, tab
        return self._tf_table

    def _volume_pass(self, scene: Scene, cs: CameraSetup, t: _Targets, scene_tex, lpos, ldir):
        ctx = self.ctx
        opts = scene.options
        g = self._volume(scene.volume)
        mode = {"mip": 0, "minip": 1, "dvr": 2}[scene.mode]
        w, h = t.size
        if mode == 2:
            tab = self._tf(scene, g)
            g.update_bricks(tab, ("tf", self._tf_key))
        else:
            g.update_bricks(None, "none")
        s = float(np.clip(opts.volume_scale, 0.1, 1.0))
        vsize = (max(1, int(round(w * s))), max(1, int(round(h * s))))
        fbo = t.volume_target(ctx, vsize)
        fbo.use()
        ctx.viewport = (0, 0, *vsize)
        ctx.disable(ctx.DEPTH_TEST)
        ctx.disable(ctx.BLEND)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        p = self.progs["ray"]
        inv_vp = np.linalg.inv(cs.vp)
        _set(p, "u_inv_vp", inv_vp.T.astype("f4").tobytes(), raw=True)
        _set(p, "u_world_to_vox", g.world_to_vox.T.astype("f4").tobytes(), raw=True)
        lin = g.vox_to_world[:3, :3]
        _set(p, "u_vox_to_world", lin.T.astype("f4").tobytes(), raw=True)
        _set(p, "u_grad_to_world", np.linalg.inv(lin).T.T.astype("f4").tobytes(), raw=True)
        _set(p, "u_dims", tuple(float(d) for d in g.dims))
        lo = np.array([-0.5, -0.5, -0.5])
        hi = np.array(g.dims, float) - 0.5
        if opts.crop_box is not None:
            c0 = np.clip(np.asarray(opts.crop_box[0], float), 0, 1)
            c1 = np.clip(np.asarray(opts.crop_box[1], float), 0, 1)
            span = hi - lo
            lo, hi = lo + span * np.minimum(c0, c1), lo + span * np.maximum(c0, c1)
        _set(p, "u_crop_lo", tuple(lo))
        _set(p, "u_crop_hi", tuple(hi))
        _set(p, "u_brick", float(BRICK))
        _set(p, "u_nbricks", tuple(int(v) for v in g.nbricks))
        _set(p, "u_mode", mode)
        _set(p, "u_step", 1.0 / max(float(opts.samples_per_voxel), 0.05))
        _set(p, "u_window", self._window_norm(scene, g))
        _set(p, "u_shading", 1 if opts.shading else 0)
        _set(p, "u_light_dir", tuple(-np.asarray(ldir)))
        _set(p, "u_light_intensity", float(scene.light.intensity))
        _set(p, "u_headlight", float(opts.headlight))
        mat = scene.material
        _set(p, "u_material", (mat.ambient, mat.diffuse, mat.specular, max(mat.shininess, 1.0)))
        has_surf = any(m.visible and m.mesh.n_faces for m in scene.meshes) and opts.show_surfaces
        _set(p, "u_use_depth", 1 if has_surf else 0)
        _set(p, "u_jitter", 1 if mode == 2 else 0)
        _set(p, "u_skip", 1 if opts.empty_space_skipping else 0)
        _set(p, "u_tf_scale", ((TF_SIZE - 1) / TF_SIZE, 0.5 / TF_SIZE))
        g.tex.use(0)
        g.brick_tex.use(1)
        if self.tf_tex is None:
            self._tf(scene, g)
        self.tf_tex.use(2)
        t.depth.use(3)
        _set(p, "u_vol", 0)
        _set(p, "u_bricks", 1)
        _set(p, "u_tf", 2)
        _set(p, "u_depth", 3)
        self.fs_vaos["ray"].render(vertices=3)
        # composite over the surfaces / background at full size
        out = t.out if scene_tex is not t.out_tex else t.comp
        out.use()
        ctx.viewport = (0, 0, w, h)
        scene_tex.use(0)
        t.vol_tex.use(1)
        q = self.progs["vcomp"]
        q["u_scene"].value = 0
        q["u_vol"].value = 1
        self.fs_vaos["vcomp"].render(vertices=3)
        return t.out_tex if out is t.out else t.comp_tex


def _set(prog, name: str, value, *, raw: bool = False) -> None:
    """Set a uniform if the compiler kept it."""
    try:
        u = prog[name]
    except KeyError:
        return
    if raw:
        u.write(value)
    else:
        u.value = value
