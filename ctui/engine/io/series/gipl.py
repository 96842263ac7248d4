"""GIPL (.gipl, .gipl.gz): the Guy's Image Processing Lab format ITK-SNAP and ITK read and write.

A fixed 256-byte big-endian header, then the voxels (x fastest, big-endian), the whole file
gzip-compressed for ``.gipl.gz``. The header fields read (byte offsets)::

    0   dims        uint16[4]   nx, ny, nz, nt (0 counts as 1 for z and t)
    8   image type  uint16      7 int8, 1/8 uint8, 15 int16, 16 uint16, 31 uint32, 32 int32, 64 float32, 65 float64
    10  pixdim      float32[4]  dx, dy, dz mm (and dt)
    204 origin      float64[4]  x, y, z mm of the first voxel
    252 magic       uint32      0xefffe9b0 (or the older 0x2ae389b8)

GIPL stores no direction cosines: the index axes are taken as the patient's L, P, S axes
(identity direction, as ITK reads it), an ``orientation`` :class:`Assumption` on every
volume. Values are kept as stored (no rescaling). The header's sizes are checked against
the file's before anything is allocated (a ``.gipl.gz``: its gzip size field and deflate's
largest expansion); a compressed file is inflated whole, bounded by the declared size
(peak: the array plus the inflated bytes), then copied slice by slice through crop/downsample.
"""

from __future__ import annotations

import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.core.assumptions import Assumption
from ctui.engine.core.errors import LoadError
from ctui.engine.core.volume import Volume
from ctui.engine.io.series.nrrd_data import inflate_bounded
from ctui.engine.io.series.raw import _read_planned, _slice_at
from ctui.engine.io.series.stacks import _finish, parse_spacing
from ctui.engine.io.suffixes import GIPL_SUFFIXES

#: File names read as GIPL (lower case).
HEADER_BYTES = 256
MAGIC = (0xEFFFE9B0, 0x2AE389B8)
#: image type code -> numpy type (big-endian); 1 (binary) is one byte a voxel, as ITK reads it
TYPES = {1: ">u1", 7: ">i1", 8: ">u1", 15: ">i2", 16: ">u2", 31: ">u4", 32: ">i4", 64: ">f4", 65: ">f8"}
_COMPLEX = {144, 160, 192, 193}
#: deflate's largest expansion (bytes out per byte in), bounding what a .gipl.gz can hold
DEFLATE_MAX_RATIO = 1032
ORIENTATION_NOTE = ("GIPL stores no orientation: its x, y, z axes taken as the patient's left, posterior, "
                    "superior (identity direction, as ITK reads it)")


def is_gipl(path: str | os.PathLike) -> bool:
    """True for a .gipl / .gipl.gz file name."""
    return os.fspath(path).lower().endswith(GIPL_SUFFIXES)


@dataclass(frozen=True)
class GiplHeader:
    """What :func:`read_header` found: ``shape`` (nz, ny, nx), ``dtype`` (big-endian),
    ``spacing_xyz`` mm as stored (may be 0 or NaN), ``origin`` (x, y, z) mm, ``volumes`` (nt),
    ``compressed`` (gzip)."""

    shape: tuple[int, int, int]
    dtype: np.dtype
    spacing_xyz: tuple[float, float, float]
    origin: tuple[float, float, float]
    volumes: int
    compressed: bool

    @property
    def data_bytes(self) -> int:
        """Bytes of the first volume's voxels."""
        nz, ny, nx = self.shape
        return nz * ny * nx * self.dtype.itemsize


def _gzip_isize(fh: Any) -> int:
    """A gzip file's last 4 bytes: its uncompressed size mod 2**32 (single member)."""
    fh.seek(-4, os.SEEK_END)
    isize = int.from_bytes(fh.read(4), "little")
    fh.seek(0)
    return isize


def _read_bytes(path: Path, want: int, *, compressed: bool) -> bytes:
    """The first ``want`` bytes of the file (inflated for a .gipl.gz; never more)."""
    try:
        with open(path, "rb") as fh:
            if not compressed:
                return fh.read(want)
            if fh.read(2) != b"\x1f\x8b":
                raise LoadError("not a gzip file (a .gipl.gz is gzip-compressed)", path=path)
            fh.seek(0)
            return inflate_bounded(fh, zlib.decompressobj(16 + zlib.MAX_WBITS), want)
    except zlib.error as exc:
        raise LoadError(f"corrupted GIPL gzip stream ({exc})", path=path) from None
    except OSError as exc:
        raise LoadError(f"cannot read ({exc.strerror or exc})", path=path) from None


def read_header(path: str | os.PathLike) -> GiplHeader:
    """The GIPL header of ``path``, checked against the file's size. Raises
    :class:`LoadError` (one line naming the file) for a short, foreign or truncated file."""
    p = Path(path)
    compressed = p.name.lower().endswith(".gz")
    head = _read_bytes(p, HEADER_BYTES, compressed=compressed)
    if len(head) < HEADER_BYTES:
        raise LoadError(f"truncated GIPL header: {len(head)} of its {HEADER_BYTES} bytes", path=p)
    magic = struct.unpack(">I", head[252:256])[0]
    if magic not in MAGIC:
        raise LoadError(f"not a GIPL file (magic number 0x{magic:08x} at byte 252, expected 0x{MAGIC[0]:08x})",
                        path=p)
    nx, ny, nz, nt = struct.unpack(">4H", head[0:8])
    code = struct.unpack(">H", head[8:10])[0]
    if code in _COMPLEX:
        raise LoadError(f"complex-valued GIPL (image type {code}) is not supported", path=p)
    if code not in TYPES:
        raise LoadError(f"unknown GIPL image type {code}", path=p)
    if nx == 0 or ny == 0:
        raise LoadError(f"GIPL header declares an empty image ({nx} x {ny} x {nz})", path=p)
    dx, dy, dz = struct.unpack(">3f", head[10:22])
    ox, oy, oz = (float(v) if np.isfinite(v) and abs(v) < 1e9 else 0.0 for v in struct.unpack(">3d", head[204:228]))
    hdr = GiplHeader((max(nz, 1), ny, nx), np.dtype(TYPES[code]), (float(dx), float(dy), float(dz)), (ox, oy, oz),
                     max(nt, 1), compressed)
    _check_size(p, hdr)
    return hdr


def _check_size(p: Path, hdr: GiplHeader) -> None:
    """The header's data size against the file's, before anything is allocated."""
    nz, ny, nx = hdr.shape
    need = hdr.data_bytes
    what = f"{nx} x {ny} x {nz} {hdr.dtype.name} voxels ({need} bytes)"
    size = p.stat().st_size
    if not hdr.compressed:
        if size - HEADER_BYTES < need:
            raise LoadError(f"truncated GIPL file: its header declares {what}, the file holds "
                            f"{max(0, size - HEADER_BYTES)} bytes after the header", path=p)
        return
    if need > size * DEFLATE_MAX_RATIO + 1024:
        raise LoadError(f"GIPL header declares {what}, more than the {size}-byte compressed file can hold", path=p)
    with open(p, "rb") as fh:
        isize = _gzip_isize(fh)
    if HEADER_BYTES + need < 2**32 and isize < HEADER_BYTES + need:
        raise LoadError(f"truncated or corrupted GIPL file: its header declares {what}, the gzip stream holds "
                        f"{max(0, isize - HEADER_BYTES)} bytes after the header", path=p)


def _spacing(hdr: GiplHeader) -> tuple[tuple[float, float, float], list[str]]:
    """(dz, dy, dx) mm from the header; a zero, negative, NaN or huge value -> 1 mm with an assumption."""
    out, bad = [], []
    for a, v in enumerate(hdr.spacing_xyz):
        if not (np.isfinite(v) and 1e-3 <= v <= 1e5):  # core.limits MIN/MAX_SPACING_MM
            bad.append(f"{'xyz'[a]} ({v:g})")
            v = 1.0
        out.append(v)
    warnings: list[str] = []
    if bad:
        warnings.append(Assumption(f"the GIPL header gives an invalid voxel size along {', '.join(bad)}: 1 mm used "
                                   "instead; give spacing=(dz, dy, dx) (--spacing dz,dy,dx) for true measurements",
                                   "spacing"))
    return (out[2], out[1], out[0]), warnings


def read_voxels(path: str | os.PathLike, hdr: GiplHeader | None = None) -> np.ndarray:
    """The whole first volume, (nz, ny, nx), native byte order (label maps: :mod:`ctui.engine.io.labels`)."""
    p = Path(path)
    hdr = hdr or read_header(p)
    vol = load_gipl(p, skipped=[], header=hdr)
    return np.asarray(vol.data)


def load_gipl(path: Path, *, skipped: list[dict[str, str]], crop: Any = None, downsample: Any = None,
              progress: Any = None, memory_limit: int | None = None, spacing: Any = None,
              header: GiplHeader | None = None) -> Volume:
    """A GIPL volume: data (z, y, x) in its stored type (native byte order), spacing (dz, dy, dx) mm
    from the header (or ``spacing``), origin from the header, identity direction (an assumption)."""
    p = Path(path)
    hdr = header or read_header(p)
    nz, ny, nx = hdr.shape
    dt = hdr.dtype
    slice_bytes = ny * nx * dt.itemsize
    warnings: list[str] = [Assumption(ORIENTATION_NOTE, "orientation")]
    if hdr.volumes > 1:
        warnings.append(f"GIPL holds {hdr.volumes} volumes: loaded the first")
    sp, sp_warnings = _spacing(hdr)
    if spacing is not None:
        sp, sp_warnings = parse_spacing(spacing, p), []
    warnings += sp_warnings
    if hdr.compressed:
        raw = _read_bytes(p, HEADER_BYTES + hdr.data_bytes, compressed=True)
        if len(raw) < HEADER_BYTES + hdr.data_bytes:
            raise LoadError(f"truncated GIPL file: {len(raw) - HEADER_BYTES} of the {hdr.data_bytes} bytes of "
                            f"voxels its header declares", path=p)

        def reader(zi: int) -> np.ndarray:
            return np.frombuffer(raw, dtype=dt, count=ny * nx, offset=HEADER_BYTES + zi * slice_bytes).reshape(ny, nx)
    else:
        def reader(zi: int) -> np.ndarray:
            img, got = _slice_at(p, HEADER_BYTES + zi * slice_bytes, (ny, nx), dt)
            if got != slice_bytes:
                raise LoadError(f"truncated at slice {zi}", path=p)
            return img

    full = (nz, ny, nx)
    out, plan, zsel, failures = _read_planned(full, dt.newbyteorder("="), reader, crop=crop, downsample=downsample,
                                              path=p, memory_limit=memory_limit, progress=progress)
    if failures:
        raise LoadError(f"cannot read slice {zsel[failures[0][0]]}: {failures[0][1]}", path=p)
    meta = {"format": "gipl", "dtype": dt.str, "files": 1}
    return _finish(out, spacing=sp, given=True, warnings=warnings, source=f"GIPL {dt.str}, {nz}x{ny}x{nx}, from {p}",
                   path=p, meta=meta, skipped=skipped, plan=plan, full=full, origin=hdr.origin, direction=np.eye(3),
                   what="the GIPL header")


def header_info(path: Path) -> dict[str, Any]:
    """scan() entry of a GIPL file, from its header only."""
    hdr = read_header(path)
    sp, _ = _spacing(hdr)
    return {"uid": "", "description": "GIPL", "modality": "OT", "files": 1, "shape_zyx": list(hdr.shape),
            "spacing_zyx_mm": [round(v, 6) for v in sp], "kind": "gipl"}
