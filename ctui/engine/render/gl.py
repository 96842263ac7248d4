"""The OpenGL side of the renderer. A :class:`GLEngine` lives on the render thread
(:mod:`ctui.engine.render.context`) and must only be used there."""

from __future__ import annotations

import math
from collections import OrderedDict
from typing import Any

import numpy as np

from ctui.engine.core.windows import auto_window
from ctui.engine.render import shaders
from ctui.engine.render.camera import CameraSetup, look_at, ortho, setup_camera, light_position
from ctui.engine.render.gpu_objects import MeshGPU, Targets, vertex_normals  # noqa: F401 - vertex_normals: public here too
from ctui.engine.render.scene import Scene, SceneMesh, SceneVolume, VOLUME_MODES
from ctui.engine.render.transfer import resolve_preset, transfer_table
from ctui.engine.render.volume_gpu import VolumeGPU, overview_step

TF_SIZE = 1024


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
        self.meshes: OrderedDict[tuple, MeshGPU] = OrderedDict()
        self.volumes: OrderedDict[int, VolumeGPU] = OrderedDict()
        self.targets: Targets | None = None
        self.shadow_tex = None
        self.shadow_fbo = None
        self.tf_tex = None
        self._tf_key: Any = None
        self._tf_table: np.ndarray | None = None
        self.timings: dict[str, float] = {}
        self.max_samples = int(getattr(c, "max_samples", 4) or 1)

    # ------------------------------------------------------------------ caches
    def _mesh(self, mesh) -> MeshGPU:
        key = (id(mesh.vertices), id(mesh.faces), id(mesh.normals))
        g = self.meshes.get(key)
        if g is not None and (g.ref is None or g.ref() is mesh.vertices) and (g.fref is None or g.fref() is mesh.faces):
            self.meshes.move_to_end(key)
            return g
        if g is not None:
            g.release()
            del self.meshes[key]
        g = MeshGPU(self.ctx, self.progs, mesh)
        self.meshes[key] = g
        total = sum(m.nbytes for m in self.meshes.values())
        while total > self.MESH_CACHE_BYTES and len(self.meshes) > 1:
            _, old = self.meshes.popitem(last=False)
            total -= old.nbytes
            old.release()
        return g

    def _volume(self, vol: SceneVolume, *, step: int = 1, reduce: str = "stride") -> VolumeGPU:
        key = id(vol.data)
        g = self.volumes.get(key)
        if g is not None and (g.ref is None or g.ref() is vol.data) and (g.step, g.reduce) == (
                VolumeGPU.effective(vol, step, reduce)):
            self.volumes.move_to_end(key)
            return g
        if g is not None:
            g.release()
            del self.volumes[key]
        while len(self.volumes) >= 2:
            _, old = self.volumes.popitem(last=False)
            old.release()
        g = VolumeGPU(self.ctx, vol, step=step, reduce=reduce)
        self.volumes[key] = g
        return g

    def clear_cache(self) -> None:
        for g in self.meshes.values():
            g.release()
        for v in self.volumes.values():
            v.release()
        self.meshes.clear()
        self.volumes.clear()

    def _targets(self, size: tuple[int, int], samples: int) -> Targets:
        t = self.targets
        if t is None or t.size != size or t.samples != samples:
            if t is not None:
                t.release()
            self.targets = t = Targets(self.ctx, size, samples)
        return t

    # ------------------------------------------------------------------ render
    def render(self, scene: Scene, size: tuple[int, int]) -> np.ndarray:
        """Render ``scene`` to an (h, w, 3) uint8 RGB array (row 0 = top)."""
        w, h = int(size[0]), int(size[1])
        if w < 1 or h < 1 or w > 16384 or h > 16384:
            raise ValueError(f"bad image size {w}x{h}")
        opts = scene.options
        mode = scene.mode
        volume_mode = mode in VOLUME_MODES and scene.volume is not None
        aa = opts.antialias
        samples = min(4, self.max_samples) if (aa == "msaa" and not volume_mode) else 0
        t = self._targets((w, h), samples)
        cs = setup_camera(scene, (w, h))
        lpos, ldir = light_position(scene, cs)
        opaque, transparent = self._split_items(scene, volume_mode)

        # ---- shadow pass
        light_vp = np.eye(4)
        shadows = bool(opts.shadows) and mode in ("surface", "transparent") and bool(opaque or transparent)
        if shadows:
            light_vp = self._shadow_pass(scene, cs, lpos, ldir, [m for m, _ in opaque + transparent])
        self._opaque_pass(scene, t, samples, cs, (lpos, ldir, light_vp, shadows), opaque, transparent)
        if transparent and mode != "wire":
            final_tex = self._transparent_pass(t, samples, transparent)
        else:
            if samples:
                self.ctx.copy_framebuffer(t.scene, t.ms)
            final_tex = t.color
        if volume_mode:
            final_tex = self._volume_pass(scene, cs, t, final_tex, lpos, ldir)
        return self._readback(t, final_tex, fxaa=aa == "fxaa" and not volume_mode)

    def _split_items(self, scene: Scene, volume_mode: bool) -> tuple[list, list]:
        """(opaque, transparent) lists of (SceneMesh, opacity) to draw."""
        opts = scene.options
        items = [m for m in scene.meshes if m.visible and m.mesh.n_faces]
        if volume_mode and not opts.show_surfaces:
            items = []
        opaque, transparent = [], []
        for m in items:
            a = float(m.opacity)
            if scene.mode == "transparent" and a >= 1.0:
                a = float(opts.transparent_opacity)
            if volume_mode:
                a = 1.0  # surfaces inside a volume: opaque, the rays stop at them
            (opaque if a >= 0.999 else transparent).append((m, a))
        return opaque, transparent

    def _opaque_pass(self, scene: Scene, t: Targets, samples: int, cs: CameraSetup, light, opaque: list,
                     transparent: list) -> None:
        """Opaque surfaces (or every surface as wires), the slice plane and the wireframe overlay."""
        ctx, opts = self.ctx, scene.options
        lpos, ldir, light_vp, shadows = light
        w, h = t.size
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
        wire = scene.mode == "wire"
        if wire:
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
        if opts.wireframe_overlay and opaque and not wire:
            ctx.wireframe = True
            ctx.depth_func = "<="
            for m, _ in opaque:
                self._draw(m, 2, tuple(opts.wire_color))
            ctx.wireframe = False
            ctx.depth_func = "<"

    def _transparent_pass(self, t: Targets, samples: int, transparent: list):
        """Weighted blended order-independent transparency over the opaque image; its texture."""
        ctx = self.ctx
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
        return t.comp_tex

    def _readback(self, t: Targets, final_tex, *, fxaa: bool) -> np.ndarray:
        """FXAA (optional) and the (h, w, 3) uint8 image, row 0 = top."""
        ctx = self.ctx
        w, h = t.size
        ctx.disable(ctx.DEPTH_TEST)
        if fxaa:
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

    def _window_norm(self, scene: Scene, g: VolumeGPU) -> tuple[float, float]:
        win = scene.options.window or scene.volume.window
        if win is None:
            win = auto_window(scene.volume.data, modality=scene.volume.modality)
        c, wd = float(win[0]), max(float(win[1]), 1e-6)
        return g.norm(c - wd / 2.0), g.norm(c + wd / 2.0)

    def _tf(self, scene: Scene, g: VolumeGPU) -> np.ndarray:
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

    def _proxy_depths(self, g: VolumeGPU, tf: tuple, cs: CameraSetup, t: Targets, vsize: tuple[int, int]) -> int:
        """Empty-space skipping: depths of the nearest and farthest occupied-brick faces per
        pixel into t.near_tex / t.far_tex; the shader's ``u_skip`` (1: the eye is inside)."""
        ctx = self.ctx
        kind, param, key = tf
        # proxy geometry: nearest and farthest occupied-brick faces per pixel
        occ = g.occupancy(kind, param) if key != g._proxy_key else g.occ
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
        return 1 if (not cs.ortho and g.eye_near_occupied(cs.eye)) else 2

    def _ray_uniforms(self, p, scene: Scene, cs: CameraSetup, g: VolumeGPU, mode: int, window: tuple[float, float],
                      ldir, skip: int) -> None:
        """The ray caster's geometry, crop box, sampling, window and lighting uniforms."""
        opts = scene.options
        wlo, whi = window
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

    def _volume_pass(self, scene: Scene, cs: CameraSetup, t: Targets, scene_tex, lpos, ldir):
        ctx = self.ctx
        opts = scene.options
        mode = {"mip": 0, "minip": 1, "dvr": 2}[scene.mode]
        w, h = t.size
        s = float(np.clip(opts.volume_scale, 0.1, 1.0))
        # an overview where the image cannot show more detail (orthographic views only)
        step = overview_step(scene.volume.spacing, 2.0 * cs.half_height / max(1.0, h * s)) if cs.ortho else 1
        g = self._volume(scene.volume, step=step, reduce=("max", "min", "stride")[mode])
        tab = self._tf(scene, g)
        wlo, whi = self._window_norm(scene, g)
        if mode == 2:
            kind, param, key = "dvr", tab, ("dvr", self._tf_key)
        elif mode == 0:
            kind, param, key = "mip", wlo, ("mip", round(wlo, 6))
        else:
            kind, param, key = "minip", whi, ("minip", round(whi, 6))
        vsize = (max(1, int(round(w * s))), max(1, int(round(h * s))))
        fbo = t.volume_target(ctx, vsize)
        skip = self._proxy_depths(g, (kind, param, key), cs, t, vsize) if opts.empty_space_skipping else 0
        fbo.use()
        ctx.viewport = (0, 0, *vsize)
        ctx.disable(ctx.DEPTH_TEST)
        ctx.disable(ctx.BLEND)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        shaded = mode == 2 and bool(opts.shading)
        ray_key = "ray_shaded" if shaded else "ray"
        p = self.progs[ray_key]
        self._ray_uniforms(p, scene, cs, g, mode, (wlo, whi), ldir, skip)
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
