"""The OpenGL side of the renderer. A :class:`GLEngine` lives on the render thread
(:mod:`ctui.engine.render.context`) and must only be used there."""

from __future__ import annotations

import math
import weakref
from collections import OrderedDict
from typing import Any

import numpy as np

from ctui.engine.render import shaders
from ctui.engine.render.camera import CameraSetup, look_at, ortho, setup_camera, light_position
from ctui.engine.render.scene import Scene, SceneMesh, SceneVolume, VOLUME_MODES
from ctui.engine.render.transfer import resolve_preset, transfer_table

BRICK = 8
TF_SIZE = 1024
MAX_TEXTURE_VOXELS = 300_000_000  # ~600 MB as 16-bit; larger volumes are subsampled
GRADIENT_TEXTURE_MAX_VOXELS = 80_000_000  # 320 MB of RGBA8 gradients at most


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
        if len(f) > 50_000:
            # faces ordered by their lowest vertex index: neighbouring triangles share
            # vertices in the vertex cache (llvmpipe: ~15% less CPU on a 1M mesh)
            f = f[np.argsort(f.min(axis=1), kind="stable")]
        nrm = mesh.normals
        if nrm is None or np.shape(nrm) != v.shape:
            nrm = vertex_normals(v, f)
        inter = np.empty((len(v), 6), np.float32)
        inter[:, :3] = v
        inter[:, 3:] = nrm
        self.vbo = ctx.buffer(inter.tobytes())
        self.ibo = ctx.buffer(f.tobytes())
        self.vao = ctx.vertex_array(progs["surface"], [(self.vbo, "3f 3f", "in_pos", "in_normal")], self.ibo)
        self.vao_v = ctx.vertex_array(progs["surface_v"], [(self.vbo, "3f 3f", "in_pos", "in_normal")], self.ibo)
        self.vao_depth = ctx.vertex_array(progs["depth"], [(self.vbo, "3f 12x", "in_pos")], self.ibo)
        self.nbytes = inter.nbytes + f.nbytes
        from ctui.engine.core.meshdata import face_areas

        self.mean_area = float(face_areas(v, f).mean()) if len(f) else 0.0
        self.cull = _cull_mode(v, f)
        from ctui.engine.render.scene import mesh_bounds

        self.lo, self.hi = mesh_bounds(mesh)
        self.ref = weakref.ref(mesh.vertices) if isinstance(mesh.vertices, np.ndarray) else None
        self.fref = weakref.ref(mesh.faces) if isinstance(mesh.faces, np.ndarray) else None

    def release(self) -> None:
        for o in (self.vao, self.vao_v, self.vao_depth, self.vbo, self.ibo):
            o.release()


def _cull_mode(v: np.ndarray, f: np.ndarray) -> str | None:
    """"back" for a closed, consistently oriented mesh with outward faces (its back
    faces can never be seen from outside), "front" when its faces point inwards,
    None for open or inconsistent meshes (both sides may show)."""
    if len(f) == 0:
        return None
    n = np.int64(len(v))
    f = f.astype(np.int64)
    a, b = f.ravel(), f[:, [1, 2, 0]].ravel()
    fwd = np.sort(a * n + b)
    if np.any(fwd[1:] == fwd[:-1]):
        return None  # a directed edge used twice: inconsistent or non-manifold
    if not np.array_equal(fwd, np.sort(b * n + a)):
        return None  # an edge without its twin: open surface
    from ctui.engine.core.meshdata import signed_volume_mm3

    vol = signed_volume_mm3(v, f)
    return "back" if vol > 0 else "front"


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
        self._proxy_key: Any = None
        self._proxy = None  # (vbo, vao) or None when nothing is occupied
        self.occ: np.ndarray | None = None
        self.nbytes = u16.nbytes
        self.grad_tex = None
        self.ref = weakref.ref(data) if isinstance(data, np.ndarray) else None
        # geometry: voxel index (of the subsampled grid) -> world
        a = vol.affine()
        s = np.diag([step, step, step, 1.0])
        self.vox_to_world = a @ s
        self.world_to_vox = np.linalg.inv(self.vox_to_world)

    def gradients(self, ctx, data: np.ndarray):
        """RGBA8 signed 3D texture: unit gradient (index space) and an edge weight
        (precomputed once: one fetch per sample instead of six in the ray caster).
        Built from ``data`` (the volume's voxels) slab by slab; volumes above
        GRADIENT_TEXTURE_MAX_VOXELS get it at a coarser stride (trilinear
        interpolation of the normals keeps shading smooth)."""
        if self.grad_tex is None:
            step = self.step
            while data[::step, ::step, ::step].size > GRADIENT_TEXTURE_MAX_VOXELS:
                step += 1
            src = data[::step, ::step, ::step]
            nz, ny, nx = src.shape
            scale = 1.0 / max(self.vmax - self.vmin, 1e-12)
            out = np.empty((nz, ny, nx, 4), np.int8)
            for z0 in range(0, nz, 16):
                z1 = min(z0 + 16, nz)
                lo, hi = max(z0 - 1, 0), min(z1 + 1, nz)
                blk = np.asarray(src[lo:hi], np.float32) * scale
                core = blk[z0 - lo:z0 - lo + (z1 - z0)]
                gz = (np.gradient(blk, axis=0)[z0 - lo:z0 - lo + (z1 - z0)] * 2.0 if hi - lo > 1
                      else np.zeros_like(core))
                gy = np.gradient(core, axis=1) * 2.0 if ny > 1 else np.zeros_like(core)
                gx = np.gradient(core, axis=2) * 2.0 if nx > 1 else np.zeros_like(core)
                mag = np.sqrt(gx * gx + gy * gy + gz * gz)
                inv = 127.0 / np.maximum(mag, 1e-12)
                out[z0:z1, ..., 0] = np.rint(gx * inv).astype(np.int8)
                out[z0:z1, ..., 1] = np.rint(gy * inv).astype(np.int8)
                out[z0:z1, ..., 2] = np.rint(gz * inv).astype(np.int8)
                # edge weight: 0 at noise-level gradients, 1 at >= ~2.5% of the range per voxel
                out[z0:z1, ..., 3] = np.rint(np.clip((mag * 40.0 - 0.25) / 0.75, 0.0, 1.0) * 127.0).astype(np.int8)
            self.grad_tex = ctx.texture3d((nx, ny, nz), 4, out.tobytes(), dtype="ni1")
            self.grad_tex.filter = (ctx.LINEAR, ctx.LINEAR)
            self.grad_tex.repeat_x = self.grad_tex.repeat_y = self.grad_tex.repeat_z = False
            self.nbytes += out.nbytes
        return self.grad_tex

    def norm(self, value: float) -> float:
        return (value - self.vmin) / max(self.vmax - self.vmin, 1e-12)

    def occupancy(self, kind: str, param: Any) -> np.ndarray:
        """Bool (bz, by, bx): bricks where a sample can change the result.

        kind "dvr": ``param`` = TF table (n, 4) with step-corrected alpha; "mip": param =
        normalised window low; "minip": normalised window high."""
        if kind == "dvr":
            vis = param[:, 3] > 0.002
            c = np.concatenate([[0], np.cumsum(vis)])
            n = len(param) - 1
            lo = np.clip(np.floor(self.bmin * n).astype(np.int64), 0, n)
            hi = np.clip(np.ceil(self.bmax * n).astype(np.int64), 0, n)
            return (c[hi + 1] - c[lo]) > 0
        if kind == "mip":
            return self.bmax > param
        return self.bmin < param

    def proxy(self, ctx, prog, occ: np.ndarray, key: Any):
        """VAO of the occupied bricks' boundary faces (voxel coordinates), cached by key."""
        if key == self._proxy_key:
            return self._proxy[1] if self._proxy else None
        if self._proxy:
            self._proxy[1].release()
            self._proxy[0].release()
        self._proxy = None
        self._proxy_key = key
        self.occ = occ
        tris = _proxy_triangles(occ, BRICK, self.dims)
        if len(tris):
            vbo = ctx.buffer(tris.astype("f4").tobytes())
            self._proxy = (vbo, ctx.vertex_array(prog, [(vbo, "3f", "in_pos")]))
            return self._proxy[1]
        return None

    def eye_near_occupied(self, eye_world: np.ndarray) -> bool:
        """True when the eye is in or next to an occupied brick (the near proxy
        faces may then be clipped away: sample from the eye)."""
        if self.occ is None:
            return True
        p = self.world_to_vox @ np.r_[eye_world, 1.0]
        b = np.floor((p[:3] + 0.5) / BRICK).astype(int)[::-1]  # (bz, by, bx)
        sh = np.array(self.occ.shape)
        lo = np.clip(b - 1, 0, sh)
        hi = np.clip(b + 2, 0, sh)
        if np.any(hi <= lo):
            return False
        return bool(self.occ[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]].any())

    def release(self) -> None:
        self.tex.release()
        if self._proxy:
            self._proxy[1].release()
            self._proxy[0].release()
        if self.grad_tex is not None:
            self.grad_tex.release()


def _proxy_triangles(occ: np.ndarray, b: int, dims: tuple[int, int, int]) -> np.ndarray:
    """Triangles (k*3, 3) in voxel (x, y, z) coordinates of the faces between occupied
    and empty bricks (and the grid's border), clipped to the voxel grid."""
    nx, ny, nz = dims
    ext = np.array([nx, ny, nz], float) - 0.5
    out = []
    occ_xyz = np.transpose(occ, (2, 1, 0))  # index [bx, by, bz]
    for ax in range(3):
        pad = [(0, 0)] * 3
        pad[ax] = (1, 1)
        p = np.pad(occ_xyz, pad)
        lo_sl = [slice(None)] * 3
        hi_sl = [slice(None)] * 3
        lo_sl[ax] = slice(0, -1)
        hi_sl[ax] = slice(1, None)
        face = p[tuple(lo_sl)] != p[tuple(hi_sl)]
        idx = np.argwhere(face)  # (k, 3): along ax: boundary index, others: brick index
        if not len(idx):
            continue
        a1, a2 = [k for k in range(3) if k != ax]
        k = len(idx)
        c = np.zeros((k, 4, 3))
        pos = np.minimum(idx[:, ax] * b - 0.5, ext[ax])
        u0 = idx[:, a1] * b - 0.5
        u1 = np.minimum(u0 + b, ext[a1])
        v0 = idx[:, a2] * b - 0.5
        v1 = np.minimum(v0 + b, ext[a2])
        c[:, :, ax] = pos[:, None]
        c[:, 0, a1], c[:, 0, a2] = u0, v0
        c[:, 1, a1], c[:, 1, a2] = u1, v0
        c[:, 2, a1], c[:, 2, a2] = u1, v1
        c[:, 3, a1], c[:, 3, a2] = u0, v1
        out.append(c[:, [0, 1, 2, 0, 2, 3]].reshape(-1, 3))
    return np.concatenate(out) if out else np.zeros((0, 3))


def _brick_reduce(a: np.ndarray, b: int, axis: int, fn) -> np.ndarray:
    """Reduce ``a`` along ``axis`` over bricks of ``b`` voxels grown by one voxel on
    each side (``fn`` = np.maximum or np.minimum); the result has ceil(n / b) entries
    along ``axis``."""
    a = np.moveaxis(a, axis, -1)
    n = a.shape[-1]
    nb = -(-n // b)
    pad = nb * b - n
    if pad:
        a = np.concatenate([a, np.repeat(a[..., -1:], pad, axis=-1)], axis=-1)
    blocks = a.reshape(*a.shape[:-1], nb, b)
    red = fn.reduce(blocks, axis=-1)
    first, last = blocks[..., 0], blocks[..., -1]
    out = red.copy()
    if nb > 1:
        out[..., 1:] = fn(out[..., 1:], last[..., :-1])   # one voxel of the previous brick
        out[..., :-1] = fn(out[..., :-1], first[..., 1:])  # one voxel of the next brick
    return np.moveaxis(out, -1, axis)


def _brick_minmax(u16: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-brick min and max (normalised 0..1) over each b^3 brick grown by one voxel
    (trilinear filtering and the gradients reach one voxel outside). Separable block
    reductions: ~50x faster than scipy's 3x3x3 min/max filters on 256^3."""
    mx, mn = u16, u16
    for ax in (2, 1, 0):
        mx = _brick_reduce(mx, b, ax, np.maximum)
        mn = _brick_reduce(mn, b, ax, np.minimum)
    return mn.astype(np.float32) / 65535.0, mx.astype(np.float32) / 65535.0


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
                for o in (self.vol_fbo, self.vol_tex, self.near_fbo, self.near_tex, self.far_fbo, self.far_tex):
                    o.release()
            self.vol_tex = ctx.texture(vsize, 4, dtype="f2")
            self.vol_tex.filter = (ctx.LINEAR, ctx.LINEAR)
            self.vol_tex.repeat_x = self.vol_tex.repeat_y = False
            self.vol_fbo = ctx.framebuffer([self.vol_tex])
            self.near_tex = ctx.depth_texture(vsize)
            self.far_tex = ctx.depth_texture(vsize)
            for t in (self.near_tex, self.far_tex):
                t.compare_func = ""
                t.filter = (ctx.NEAREST, ctx.NEAREST)
            self.near_fbo = ctx.framebuffer(depth_attachment=self.near_tex)
            self.far_fbo = ctx.framebuffer(depth_attachment=self.far_tex)
        return self.vol_fbo

    def release(self) -> None:
        objs = [self.scene, self.oit, self.comp, self.out, self.color, self.depth, self.accum, self.reveal,
                self.comp_tex, self.out_tex]
        if self.ms is not None:
            objs += [self.ms, self.ms_oit, *self._ms_objs]
        if self.vol_fbo is not None:
            objs += [self.vol_fbo, self.vol_tex, self.near_fbo, self.near_tex, self.far_fbo, self.far_tex]
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
            "surface_v": c.program(vertex_shader=shaders.SURFACE_VERTEX_VS, fragment_shader=shaders.SURFACE_VERTEX_FS),
            "depth": c.program(vertex_shader=shaders.DEPTH_VS, fragment_shader=shaders.DEPTH_FS),
            "oit": c.program(vertex_shader=shaders.FULLSCREEN_VS, fragment_shader=shaders.OIT_COMPOSITE_FS),
            "fxaa": c.program(vertex_shader=shaders.FULLSCREEN_VS, fragment_shader=shaders.FXAA_FS),
            "slice": c.program(vertex_shader=shaders.SLICE_VS, fragment_shader=shaders.SLICE_FS),
            "ray": c.program(vertex_shader=shaders.FULLSCREEN_VS, fragment_shader=shaders.RAYCAST_FS),
            "ray_shaded": c.program(vertex_shader=shaders.FULLSCREEN_VS,
                                    fragment_shader=shaders.RAYCAST_FS.replace("//DEFINES", "#define SHADING 1")),
            "proxy": c.program(vertex_shader=shaders.PROXY_VS, fragment_shader=shaders.DEPTH_FS),
            "vcomp": c.program(vertex_shader=shaders.FULLSCREEN_VS, fragment_shader=shaders.VOLUME_COMPOSITE_FS),
        }
        self.fs_vaos = {k: c.vertex_array(self.progs[k], []) for k in ("oit", "fxaa", "ray", "ray_shaded", "vcomp")}
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
        for p in (self.progs["surface"], self.progs["surface_v"]):
            self._set_surface_uniforms(p, scene, cs, lpos, ldir, light_vp, shadows)
        self._draw_ctx = (cs, (w, h), opts.lighting)
        wire_only = mode == "wire"
        if wire_only:
            ctx.wireframe = True
            for m, _ in opaque + transparent:
                self._draw(m, 2, m.rgb(), cull=False)
            ctx.wireframe = False
        else:
            if opts.wireframe_overlay:
                ctx.polygon_offset = (1.0, 1.0)
            for m, _ in opaque:
                self._draw(m, 0, m.rgb())
            ctx.polygon_offset = (0.0, 0.0)
            if opts.slice_plane is not None and scene.volume is not None:
                self._draw_slice(scene, cs)
            if opts.wireframe_overlay and opaque:
                ctx.wireframe = True
                ctx.depth_func = "<="
                for m, _ in opaque:
                    self._draw(m, 2, tuple(opts.wire_color))
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
            for m, a in transparent:
                self._draw(m, 1, m.rgb(), opacity=a, cull=False)  # both sides of see-through objects
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
    def _draw(self, item: SceneMesh, pass_: int, color, *, opacity: float = 1.0, cull: bool = True) -> None:
        """Draw one mesh with the surface program chosen for its on-screen triangle size."""
        ctx = self.ctx
        g = self._mesh(item.mesh)
        cs, size, lighting = self._draw_ctx
        per_vertex = lighting == "vertex"
        if lighting == "auto" and pass_ != 2:
            # per-vertex lighting when triangles are ~pixel-sized (looks the same, far cheaper)
            if cs.ortho:
                ppm = size[1] / (2.0 * cs.half_height)
            else:
                c = (g.lo + g.hi) / 2.0
                dist = max(float(np.dot(c - cs.eye, cs.forward)) - float(np.linalg.norm(g.hi - g.lo)) / 2.0, 1e-3)
                ppm = size[1] / (2.0 * cs.half_height * dist)
            per_vertex = g.mean_area * ppm * ppm < 3.0
        prog = self.progs["surface_v" if per_vertex else "surface"]
        prog["u_pass"].value = pass_
        prog["u_color"].value = tuple(color)
        _set(prog, "u_opacity", float(opacity))
        mode = g.cull if cull else None
        if mode is not None and cs.eye is not None and not cs.ortho:
            if np.all(cs.eye > g.lo) and np.all(cs.eye < g.hi):
                mode = None  # camera may be inside: show both sides
        if mode is not None:
            ctx.enable(ctx.CULL_FACE)
            ctx.front_face = "ccw"
            ctx.cull_face = mode
        (g.vao_v if per_vertex else g.vao).render()
        if mode is not None:
            ctx.disable(ctx.CULL_FACE)

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
            from ctui.engine.core.windows import auto_window

            win = auto_window(scene.volume.data, modality=scene.volume.modality)
        c, wd = float(win[0]), max(float(win[1]), 1e-6)
        return g.norm(c - wd / 2.0), g.norm(c + wd / 2.0)

    def _tf(self, scene: Scene, g: _VolumeGPU) -> np.ndarray:
        name = resolve_preset(scene.options.preset)
        win = scene.options.window or scene.volume.window
        step = 1.0 / max(float(scene.options.samples_per_voxel), 0.05)
        key = (name, g.vmin, g.vmax, tuple(win) if win else None, step)
        if key != self._tf_key:
            tab = transfer_table(name, g.vmin, g.vmax, window=win, n=TF_SIZE)
            # opacity correction for the sampling step (alpha is per voxel length)
            tab[:, 3] = 1.0 - np.power(1.0 - np.clip(tab[:, 3], 0.0, 0.999), step)
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
        tab = self._tf(scene, g)
        wlo, whi = self._window_norm(scene, g)
        if mode == 2:
            kind, param, key = "dvr", tab, ("dvr", self._tf_key)
        elif mode == 0:
            kind, param, key = "mip", wlo, ("mip", round(wlo, 6))
        else:
            kind, param, key = "minip", whi, ("minip", round(whi, 6))
        s = float(np.clip(opts.volume_scale, 0.1, 1.0))
        vsize = (max(1, int(round(w * s))), max(1, int(round(h * s))))
        fbo = t.volume_target(ctx, vsize)
        skip = 0
        if opts.empty_space_skipping:
            # proxy geometry: nearest and farthest occupied-brick faces per pixel
            if key != g._proxy_key:
                occ = g.occupancy(kind, param)
            else:
                occ = g.occ
            vao = g.proxy(ctx, self.progs["proxy"], occ, key)
            pp = self.progs["proxy"]
            pp["u_vp"].write((cs.vp @ g.vox_to_world).T.astype("f4").tobytes())
            ctx.viewport = (0, 0, *vsize)
            ctx.enable(ctx.DEPTH_TEST)
            ctx.disable(ctx.BLEND)
            t.near_fbo.use()
            t.near_fbo.clear(depth=1.0)
            ctx.depth_func = "<"
            if vao is not None:
                vao.render()
            t.far_fbo.use()
            t.far_fbo.clear(depth=0.0)
            ctx.depth_func = ">"
            if vao is not None:
                vao.render()
            ctx.depth_func = "<"
            skip = 1 if (not cs.ortho and g.eye_near_occupied(cs.eye)) else 2
        fbo.use()
        ctx.viewport = (0, 0, *vsize)
        ctx.disable(ctx.DEPTH_TEST)
        ctx.disable(ctx.BLEND)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        shaded = mode == 2 and bool(opts.shading)
        ray_key = "ray_shaded" if shaded else "ray"
        p = self.progs[ray_key]
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
        _set(p, "u_mode", mode)
        _set(p, "u_step", 1.0 / max(float(opts.samples_per_voxel), 0.05))
        _set(p, "u_window", (wlo, whi))
        _set(p, "u_light_dir", tuple(-np.asarray(ldir)))
        _set(p, "u_light_intensity", float(scene.light.intensity))
        _set(p, "u_headlight", float(opts.headlight))
        mat = scene.material
        _set(p, "u_material", (mat.ambient, mat.diffuse, mat.specular, max(mat.shininess, 1.0)))
        has_surf = any(m.visible and m.mesh.n_faces for m in scene.meshes) and opts.show_surfaces
        _set(p, "u_use_depth", 1 if has_surf else 0)
        _set(p, "u_jitter", 1 if mode == 2 else 0)
        _set(p, "u_skip", skip)
        _set(p, "u_tf_scale", ((TF_SIZE - 1) / TF_SIZE, 0.5 / TF_SIZE))
        if shaded:
            g.gradients(ctx, scene.volume.data).use(4)
            _set(p, "u_grad", 4)
        g.tex.use(0)
        t.near_tex.use(1)
        t.far_tex.use(5)
        self.tf_tex.use(2)
        t.depth.use(3)
        _set(p, "u_vol", 0)
        _set(p, "u_near", 1)
        _set(p, "u_far", 5)
        _set(p, "u_tf", 2)
        _set(p, "u_depth", 3)
        self.fs_vaos[ray_key].render(vertices=3)
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
