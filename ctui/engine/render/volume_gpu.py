"""A volume on the GPU for the ray caster: a 16-bit normalised 3D texture, its brick
min/max grid (empty-space skipping), gradients and the proxy geometry of occupied bricks.
Used by :class:`ctui.engine.render.gl.GLEngine` on the render thread only."""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from ctui.engine.render.scene import SceneVolume

BRICK = 8
MAX_TEXTURE_VOXELS = 300_000_000  # ~600 MB as 16-bit; larger volumes are subsampled
GRADIENT_TEXTURE_MAX_VOXELS = 80_000_000  # 320 MB of RGBA8 gradients at most


class VolumeGPU:
    """A volume as a 16-bit normalised 3D texture plus its brick min/max grid."""

    def __init__(self, ctx, vol: SceneVolume, *, step: int = 1, reduce: str = "stride") -> None:
        """``step``: the overview's stride at least (an image that cannot show more detail:
        :func:`overview_step`); ``reduce``: how a block of step^3 voxels becomes one,
        "stride" (its first voxel), "max" (MIP: nothing bright is lost) or "min" (MinIP)."""
        data = vol.data
        self.step, self.reduce = step, reduce = self.effective(vol, step, reduce)
        src = block_reduce(data, step, self.reduce) if step > 1 and self.reduce != "stride" else (
            data[::step, ::step, ::step] if step > 1 else data)
        nz, ny, nx = src.shape
        self.dims = (nx, ny, nz)
        self.vmin = float(np.min(src))
        self.vmax = float(np.max(src))
        scale = 65535.0 / max(self.vmax - self.vmin, 1e-12)
        self.tex = ctx.texture3d(self.dims, 1, None, dtype="nu2")
        mins, maxs = [], []
        for z0 in range(0, nz, 32):  # slab by slab: no full-size float or 16-bit copy
            sl = (np.asarray(src[z0:z0 + 32], np.float32) - self.vmin) * scale
            u16 = np.clip(sl + 0.5, 0, 65535).astype(np.uint16)
            self.tex.write(u16, viewport=(0, 0, z0, nx, ny, u16.shape[0]))
            mins.append(_plane_reduce(u16, BRICK, np.minimum))
            maxs.append(_plane_reduce(u16, BRICK, np.maximum))
        self.tex.filter = (ctx.LINEAR, ctx.LINEAR)
        self.tex.repeat_x = self.tex.repeat_y = self.tex.repeat_z = False
        # brick min/max: x and y per slab, then z over the (64x smaller) stack: as brick_minmax
        self.bmin = brick_reduce(np.concatenate(mins), BRICK, 0, np.minimum).astype(np.float32) / 65535.0
        self.bmax = brick_reduce(np.concatenate(maxs), BRICK, 0, np.maximum).astype(np.float32) / 65535.0
        self._proxy_key: Any = None
        self._proxy = None  # (vbo, vao) or None when nothing is occupied
        self.occ: np.ndarray | None = None
        self.nbytes = nz * ny * nx * 2
        self.grad_tex = None
        self.ref = weakref.ref(data) if isinstance(data, np.ndarray) else None
        # geometry: voxel index (of the subsampled grid) -> world
        a = vol.affine()
        s = np.diag([step, step, step, 1.0])
        self.vox_to_world = a @ s
        self.world_to_vox = np.linalg.inv(self.vox_to_world)

    @staticmethod
    def effective(vol: SceneVolume, step: int, reduce: str) -> tuple[int, str]:
        """(stride, reduction) a volume gets for the ``step`` asked: larger for volumes over
        MAX_TEXTURE_VOXELS or 2048 voxels along an axis; "stride" at full resolution."""
        shape = vol.data.shape
        step = max(1, int(step))
        while (int(np.prod([-(-n // step) for n in shape])) > MAX_TEXTURE_VOXELS
               or max(n // step for n in shape) > 2048):
            step += 1
        return step, (reduce if step > 1 else "stride")

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
            self.grad_tex = ctx.texture3d((nx, ny, nz), 4, out, dtype="ni1")  # the array: no bytes copy
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
        tris = proxy_triangles(occ, BRICK, self.dims)
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


def proxy_triangles(occ: np.ndarray, b: int, dims: tuple[int, int, int]) -> np.ndarray:
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


def brick_reduce(a: np.ndarray, b: int, axis: int, fn) -> np.ndarray:
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


def _plane_reduce(u16: np.ndarray, b: int, fn) -> np.ndarray:
    """:func:`brick_reduce` along x then y (the first two steps of :func:`brick_minmax`)."""
    return brick_reduce(brick_reduce(u16, b, 2, fn), b, 1, fn)


def brick_minmax(u16: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-brick min and max (normalised 0..1) over each b^3 brick grown by one voxel
    (trilinear filtering and the gradients reach one voxel outside). Separable block
    reductions: ~50x faster than scipy's 3x3x3 min/max filters on 256^3."""
    mx, mn = u16, u16
    for ax in (2, 1, 0):
        mx = brick_reduce(mx, b, ax, np.maximum)
        mn = brick_reduce(mn, b, ax, np.minimum)
    return mn.astype(np.float32) / 65535.0, mx.astype(np.float32) / 65535.0


def overview_step(spacing, mm_per_pixel: float) -> int:
    """The coarsest stride that still gives 1.5 voxels per image pixel along every axis
    (1: the image can show every voxel; a MIP's block max keeps every bright voxel)."""
    return max(1, int(mm_per_pixel / (1.5 * max(float(v) for v in spacing))))


def block_reduce(data: np.ndarray, step: int, how: str) -> np.ndarray:
    """``data`` (z, y, x) reduced by blocks of ``step`` voxels along every axis (the last
    block may be partial) with max or min, one slab of ``step`` slices at a time."""
    fn = np.maximum if how == "max" else np.minimum
    nz, ny, nx = data.shape
    iy, ix = np.arange(0, ny, step), np.arange(0, nx, step)
    out = np.empty((len(range(0, nz, step)), len(iy), len(ix)), data.dtype)
    for k, z0 in enumerate(range(0, nz, step)):
        slab = fn.reduce(np.asarray(data[z0:z0 + step]), axis=0)
        out[k] = fn.reduceat(fn.reduceat(slab, iy, axis=0), ix, axis=1)
    return out
