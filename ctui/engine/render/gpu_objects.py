"""GPU objects of the renderer: meshes (:class:`MeshGPU`) and the framebuffers of one image
size (:class:`Targets`). Used by :class:`ctui.engine.render.gl.GLEngine` on the render
thread only."""

from __future__ import annotations

import weakref

import numpy as np

from ctui.engine.core.meshdata import face_cross, signed_volume_mm3
from ctui.engine.render.scene import mesh_bounds


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (n, 3) float32 for a triangle mesh."""
    return _normals_of(np.asarray(vertices, np.float64), np.asarray(faces, np.int64), _face_terms(vertices, faces))


def _face_terms(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, ...]:
    """(ax, ay, az, nx, ny, nz): each face's first vertex and its edges' cross product (length
    twice its area), by components (``face_cross``: 3x faster than np.cross on rows, the same
    values), computed once for the normals, the mean area and the orientation."""
    vt = np.ascontiguousarray(np.asarray(vertices, np.float64).T)
    return face_cross(vt, np.asarray(faces, np.int64))


def _normals_of(v: np.ndarray, f: np.ndarray, terms: tuple[np.ndarray, ...]) -> np.ndarray:
    n = np.zeros((len(v), 3))
    idx = f.ravel()
    for k in range(3):
        n[:, k] = np.bincount(idx, weights=np.repeat(terms[3 + k], 3), minlength=len(v))
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    ln[ln == 0] = 1.0
    return (n / ln).astype(np.float32)


def _signed_volume(v: np.ndarray, terms: tuple[np.ndarray, ...]) -> float:
    """Enclosed volume (Gauss) from the face terms, about the vertices' mean (well conditioned)."""
    if not len(terms[0]):
        return 0.0
    m = v.mean(axis=0)
    return float(sum((terms[3 + k] * (terms[k] - m[k])).sum() for k in range(3)) / 6.0)


class MeshGPU:
    """A mesh's vertex/index buffers and vertex arrays for the surface, flat and depth programs."""

    def __init__(self, ctx, progs, mesh) -> None:
        v = np.ascontiguousarray(mesh.vertices, dtype=np.float32)
        f = np.ascontiguousarray(mesh.faces, dtype=np.uint32)
        if len(f) > 50_000:
            # faces ordered by their lowest vertex index: neighbouring triangles share
            # vertices in the vertex cache (llvmpipe: ~15% less CPU on a 1M mesh)
            f = f[np.argsort(f.min(axis=1), kind="stable")]
        terms = _face_terms(v, f)
        nrm = mesh.normals
        if nrm is None or np.shape(nrm) != v.shape:
            nrm = _normals_of(v, f, terms)
        inter = np.empty((len(v), 6), np.float32)
        inter[:, :3] = v
        inter[:, 3:] = nrm
        self.vbo = ctx.buffer(inter.tobytes())
        self.ibo = ctx.buffer(f.tobytes())
        self.vao = ctx.vertex_array(progs["surface"], [(self.vbo, "3f 3f", "in_pos", "in_normal")], self.ibo)
        self.vao_v = ctx.vertex_array(progs["surface_v"], [(self.vbo, "3f 3f", "in_pos", "in_normal")], self.ibo)
        self.vao_depth = ctx.vertex_array(progs["depth"], [(self.vbo, "3f 12x", "in_pos")], self.ibo)
        self.nbytes = inter.nbytes + f.nbytes
        self.mean_area = float(0.5 * np.sqrt(terms[3] ** 2 + terms[4] ** 2 + terms[5] ** 2).mean()) if len(f) else 0.0
        self.cull = cull_mode(v, f, volume=_signed_volume(v.astype(np.float64), terms))
        del terms
        self.lo, self.hi = mesh_bounds(mesh)
        self.ref = weakref.ref(mesh.vertices) if isinstance(mesh.vertices, np.ndarray) else None
        self.fref = weakref.ref(mesh.faces) if isinstance(mesh.faces, np.ndarray) else None

    def release(self) -> None:
        for o in (self.vao, self.vao_v, self.vao_depth, self.vbo, self.ibo):
            o.release()


def cull_mode(v: np.ndarray, f: np.ndarray, *, volume: float | None = None) -> str | None:
    """"back" for a closed, consistently oriented mesh with outward faces (its back
    faces can never be seen from outside), "front" when its faces point inwards,
    None for open or inconsistent meshes (both sides may show). ``volume``: the mesh's
    signed volume when known."""
    if len(f) == 0:
        return None
    n = np.int64(len(v))
    f = f.astype(np.int64)
    a, b = f.ravel(), f[:, [1, 2, 0]].ravel()
    # each directed edge (a, b) as 2 x (its undirected key) + (a < b), sorted once: closed and
    # consistently oriented <=> the keys come in pairs 2u, 2u + 1 (each edge once each way)
    key = np.minimum(a, b) * n + np.maximum(a, b)
    key <<= 1
    key += a < b
    key.sort()
    if len(key) % 2 or np.any(key[0::2] & 1) or not np.array_equal(key[0::2] + 1, key[1::2]):
        return None  # an edge used twice the same way (inconsistent, non-manifold) or without its twin (open)
    if len(key) > 2 and not np.all(key[2::2] > key[1:-1:2]):
        return None  # an undirected edge of more than two faces
    vol = signed_volume_mm3(v, f) if volume is None else volume
    return "back" if vol > 0 else "front"


class Targets:
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
