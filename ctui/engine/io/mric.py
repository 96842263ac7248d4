"""MRIC contour files, byte-compatible with the prototype ("MeshCreator") writer.

Layout (all little-endian)::

    17 bytes   ASCII signature  b"VAJIRA-MRICUBE-V8"
    int32      width
    int32      height
    int32      slice count
    int32      axis x
    int32      axis y
    width*height bytes   cross-section image, rows of ``width`` bytes (uint8)
    per slice:
        int32  object count
        per object:
            int32  border count
            per border:
                int32  point count
                point count * (int16 x, int16 y, uint8 255)

Points are integer pixel coordinates (x = column, y = row) on the slice grid, so
``0 <= x <= width`` and ``0 <= y <= height`` (the upper bound is inclusive because a
border traced along pixel edges may touch the far edge).

Geometry: the format stores no voxel size, so an MRIC read back alone meshed at 1 mm
(a 130 mL kidney came back as 38 mL). :func:`write_mric` given ``spacing`` (and
``origin``, ``direction``) writes it to a sidecar ``<name>.mric.json`` next to the file
(the MRIC bytes stay those the prototype reads); :func:`read_mric` reads it back into
``MricData.spacing/origin/direction`` (None without a sidecar: callers then need the
user's ``--spacing`` and refuse otherwise, see :func:`require_spacing`).

The reader trusts nothing: every count is checked against the bytes left in the file
before anything is allocated, so a corrupted or hostile file can never make it
allocate more than the file's own size; any fault raises a one-line
:class:`~ctui.engine.core.errors.FormatError` naming the file, the fault and its offset.
"""

from __future__ import annotations

import json
import math
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ctui.engine.core.atomic import atomic_write, regular_source
from ctui.engine.core.errors import CtuiError, FormatError
from ctui.engine.core.limits import check_allocation

SIGNATURE = b"VAJIRA-MRICUBE-V8"
HEADER = struct.Struct("<5i")
POINT_DTYPE = np.dtype([("x", "<i2"), ("y", "<i2"), ("m", "u1")])  # 5 bytes, packed
MARKER = 255
#: Largest file the reader accepts (the format has no use for more; guards RAM).
MAX_FILE_BYTES = 2 * 1024**3

Border = np.ndarray  # (n, 2) int32 (x, y)


@dataclass
class MricData:
    """Contents of an MRIC file.

    Attributes
    ----------
    width, height : int
        Slice size in pixels.
    axis : tuple (int, int)
        The prototype's "axis" point (x, y), stored verbatim.
    image : ndarray (height, width) uint8
        Cross-section image.
    slices : list (per slice) of list (per object) of list (per border) of ndarray (n, 2) int32
        Border points as (x, y) pixel coordinates.
    spacing : (dz, dy, dx) mm, or None when unknown (no sidecar)
    origin : (x, y, z) mm of pixel (0, 0) of slice 0; direction : (3, 3) or None (identity)
        From the sidecar ``<file>.json`` (see the module docstring).
    """

    width: int
    height: int
    axis: tuple[int, int] = (0, 0)
    image: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.uint8))
    slices: list[list[list[np.ndarray]]] = field(default_factory=list)
    spacing: tuple[float, float, float] | None = None
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: np.ndarray | None = None

    @property
    def n_slices(self) -> int:
        return len(self.slices)

    def n_points(self) -> int:
        """Total number of border points in the file."""
        return sum(len(b) for s in self.slices for o in s for b in o)


# --------------------------------------------------------------------------- writing
def _as_points(border, path, width: int, height: int) -> np.ndarray:
    pts = np.asarray(border)
    if pts.size == 0:
        return np.zeros((0, 2), np.int32)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise FormatError(f"{path}: cannot write MRIC: a border must be an (n, 2) array of x, y, got shape {pts.shape}")
    if not np.issubdtype(pts.dtype, np.integer):
        if not np.all(np.isfinite(pts)):
            raise FormatError(f"{path}: cannot write MRIC: a border has non-finite coordinates")
        pts = np.rint(pts)
    pts = pts.astype(np.int64)
    if pts.min() < 0 or pts[:, 0].max() > width or pts[:, 1].max() > height:
        raise FormatError(
            f"{path}: cannot write MRIC: border point outside the {width}x{height} slice "
            f"(x {pts[:, 0].min()}..{pts[:, 0].max()}, y {pts[:, 1].min()}..{pts[:, 1].max()})"
        )
    return pts.astype(np.int32)


def encode_mric(
    slices: Sequence[Sequence[Sequence[np.ndarray]]],
    *,
    width: int,
    height: int,
    axis: tuple[int, int] = (0, 0),
    image: np.ndarray | None = None,
    path: str | os.PathLike = "<mric>",
) -> bytes:
    """Encode MRIC contents to bytes (see :func:`write_mric` for the arguments)."""
    width, height = int(width), int(height)
    if not (0 < width <= 32767 and 0 < height <= 32767):
        raise FormatError(f"{path}: cannot write MRIC: slice size {width}x{height} outside 1..32767")
    if image is None:
        img = np.zeros((height, width), np.uint8)
    else:
        img = np.asarray(image)
        if img.shape != (height, width):
            raise FormatError(f"{path}: cannot write MRIC: image shape {img.shape} is not (height, width) = ({height}, {width})")
        if img.dtype != np.uint8:
            img = np.clip(img, 0, 255).astype(np.uint8)
    parts: list[bytes] = [SIGNATURE, HEADER.pack(width, height, len(slices), int(axis[0]), int(axis[1])), np.ascontiguousarray(img).tobytes()]
    i32 = struct.Struct("<i")
    for objects in slices:
        parts.append(i32.pack(len(objects)))
        for borders in objects:
            parts.append(i32.pack(len(borders)))
            for border in borders:
                pts = _as_points(border, path, width, height)
                rec = np.empty(len(pts), POINT_DTYPE)
                rec["x"] = pts[:, 0]
                rec["y"] = pts[:, 1]
                rec["m"] = MARKER
                parts.append(i32.pack(len(pts)))
                parts.append(rec.tobytes())
    return b"".join(parts)


def write_mric(
    path: str | os.PathLike,
    slices: Sequence[Sequence[Sequence[np.ndarray]]],
    *,
    width: int,
    height: int,
    axis: tuple[int, int] = (0, 0),
    image: np.ndarray | None = None,
    spacing=None,
    origin=None,
    direction=None,
) -> Path:
    """Write an MRIC contour file atomically.

    Parameters
    ----------
    path : path
        Target file (written via a temporary file, fsync and rename).
    slices : list (per slice) of list (per object) of list (per border) of array (n, 2)
        Border points (x, y) in pixels; float coordinates are rounded to the nearest
        integer. Each must satisfy 0 <= x <= width, 0 <= y <= height.
    width, height : int
        Slice size in pixels (1..32767: points are stored as int16).
    axis : (int, int)
        The prototype's axis point, stored as is.
    image : ndarray (height, width) uint8, optional
        Cross-section image; zeros when omitted.
    spacing, origin, direction : optional
        The labels' geometry ((dz, dy, dx) mm, (x, y, z) mm, 3x3): written to the
        sidecar ``<path>.json`` so the file meshes at its true size when read back.
        Without ``spacing`` an existing sidecar (of the file replaced) is removed.

    Returns
    -------
    Path of the written file.
    """
    data = encode_mric(slices, width=width, height=height, axis=axis, image=image, path=path)
    side = None
    if spacing is not None:
        side = _sidecar_json(path, len(slices), height, width, spacing, origin, direction)
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    sc = sidecar_path(path)
    if side is not None:
        with atomic_write(sc, "w") as fh:
            fh.write(side)
    elif sc.is_file():
        sc.unlink()  # it described the file just replaced
    return Path(path)


def sidecar_path(path: str | os.PathLike) -> Path:
    """``kidney.mric`` -> ``kidney.mric.json``: where an MRIC file's geometry is kept."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def _finite3(v, what: str, path, *, positive: bool = False) -> tuple[float, float, float]:
    try:
        out = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        raise FormatError(f"{path}: {what} must be three numbers, got {v!r}") from None
    if len(out) != 3 or not all(math.isfinite(x) for x in out) or (positive and min(out) <= 0):
        raise FormatError(f"{path}: {what} must be three {'positive ' if positive else ''}finite numbers, got {v!r}")
    return out


def _sidecar_json(path, nz: int, ny: int, nx: int, spacing, origin, direction) -> str:
    sp = _finite3(spacing, "spacing (dz, dy, dx)", path, positive=True)
    org = _finite3(origin if origin is not None else (0.0, 0.0, 0.0), "origin (x, y, z)", path)
    d = np.eye(3) if direction is None else np.asarray(direction, float).reshape(3, 3)
    if not np.all(np.isfinite(d)):
        raise FormatError(f"{path}: direction must be finite")
    return json.dumps({"format": "ctui MRIC geometry", "version": 1, "shape_zyx": [nz, ny, nx],
                       "spacing_zyx_mm": list(sp), "origin_xyz_mm": list(org),
                       "direction": [[float(x) for x in r] for r in d]}, indent=1) + "\n"


def read_sidecar(path: str | os.PathLike, data: MricData) -> None:
    """Fill ``data.spacing/origin/direction`` from ``<path>.json`` when it exists."""
    sc = sidecar_path(path)
    if not sc.is_file():
        return
    buf = read_regular_file(sc, 1 << 20, what="an MRIC geometry sidecar")
    try:
        d = json.loads(buf.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise FormatError(f"{sc}: not a valid MRIC geometry sidecar ({type(exc).__name__})") from None
    if not isinstance(d, dict) or "spacing_zyx_mm" not in d:
        raise FormatError(f"{sc}: not a valid MRIC geometry sidecar (no spacing_zyx_mm)")
    shape = d.get("shape_zyx")
    if shape is not None and list(shape)[1:] != [data.height, data.width]:
        raise FormatError(f"{sc}: describes {shape[1]}x{shape[2]} slices, the MRIC file has "
                          f"{data.height}x{data.width}")
    data.spacing = _finite3(d["spacing_zyx_mm"], "spacing_zyx_mm", sc, positive=True)
    data.origin = _finite3(d.get("origin_xyz_mm", (0, 0, 0)), "origin_xyz_mm", sc)
    try:
        m = np.asarray(d.get("direction", np.eye(3).tolist()), float).reshape(3, 3)
    except (TypeError, ValueError):
        raise FormatError(f"{sc}: direction must be a 3x3 matrix") from None
    if not np.all(np.isfinite(m)) or abs(np.linalg.det(m)) < 1e-6:
        raise FormatError(f"{sc}: direction must be a finite, non-degenerate 3x3 matrix")
    data.direction = m


def require_spacing(data: MricData, path: str | os.PathLike, spacing=None) -> tuple[float, float, float]:
    """The voxel size to mesh ``data`` at: the user's ``spacing`` (dz, dy, dx) mm, else the
    sidecar's; raises CtuiError when neither is known (never a silent 1 mm)."""
    if spacing is not None:
        return _finite3(spacing, "spacing (dz, dy, dx)", path, positive=True)
    if data.spacing is None:
        raise CtuiError(f"the MRIC file stores no voxel size and {sidecar_path(path).name} is missing; "
                        f"give the voxel spacing dz,dy,dx (mm)", path=path, option="spacing")
    return data.spacing


# --------------------------------------------------------------------------- reading
def decode_mric(buf: bytes, path: str | os.PathLike = "<mric>") -> MricData:
    """Parse MRIC bytes; raise :class:`FormatError` on any inconsistency."""
    mv = memoryview(buf)
    size = len(mv)
    name = str(path)

    def fail(msg: str, off: int) -> FormatError:
        return FormatError(f"{name}: not a valid MRIC file: {msg} (at byte {off} of {size})")

    if size < len(SIGNATURE) or bytes(mv[: len(SIGNATURE)]) != SIGNATURE:
        if size < len(SIGNATURE) and SIGNATURE.startswith(bytes(mv)):
            raise fail("truncated signature", size)
        raise FormatError(f"{name}: not an MRIC file (signature is not {SIGNATURE.decode()})")
    pos = len(SIGNATURE)
    if size - pos < HEADER.size:
        raise fail("truncated header", size)
    width, height, n_slices, ax, ay = HEADER.unpack_from(mv, pos)
    pos += HEADER.size
    if width <= 0 or height <= 0 or width > 32767 or height > 32767:
        raise fail(f"bad slice size {width}x{height}", len(SIGNATURE))
    if n_slices < 0:
        raise fail(f"negative slice count {n_slices}", len(SIGNATURE) + 8)
    n_img = width * height
    if n_img > size - pos:
        raise fail(f"truncated: the {width}x{height} image needs {n_img} bytes, {size - pos} left", pos)
    image = np.frombuffer(mv, np.uint8, count=n_img, offset=pos).reshape(height, width).copy()
    pos += n_img
    if n_slices * 4 > size - pos:
        raise fail(f"slice count {n_slices} does not fit in the {size - pos} bytes left", len(SIGNATURE) + 8)

    def count(what: str, unit: int) -> int:
        nonlocal pos
        if size - pos < 4:
            raise fail(f"truncated: {what} count missing", pos)
        (n,) = struct.unpack_from("<i", mv, pos)
        if n < 0:
            raise fail(f"negative {what} count {n}", pos)
        if n * unit > size - pos - 4:
            raise fail(f"{what} count {n} does not fit in the {size - pos - 4} bytes left", pos)
        pos += 4
        return n

    slices: list[list[list[np.ndarray]]] = []
    for _ in range(n_slices):
        objects: list[list[np.ndarray]] = []
        for _ in range(count("object", 4)):
            borders: list[np.ndarray] = []
            for _ in range(count("border", 4)):
                n = count("point", POINT_DTYPE.itemsize)
                rec = np.frombuffer(mv, POINT_DTYPE, count=n, offset=pos)
                if n:
                    if np.any(rec["m"] != MARKER):
                        bad = int(np.argmax(rec["m"] != MARKER))
                        raise fail(f"point marker byte is {int(rec['m'][bad])}, not 255", pos + bad * 5 + 4)
                    xs = rec["x"].astype(np.int32)
                    ys = rec["y"].astype(np.int32)
                    outside = (xs < 0) | (xs > width) | (ys < 0) | (ys > height)
                    if np.any(outside):
                        bad = int(np.argmax(outside))
                        raise fail(f"point ({xs[bad]}, {ys[bad]}) outside the {width}x{height} slice", pos + bad * 5)
                    pts = np.stack([xs, ys], axis=1)
                else:
                    pts = np.zeros((0, 2), np.int32)
                pos += n * POINT_DTYPE.itemsize
                borders.append(pts)
            objects.append(borders)
        slices.append(objects)
    if pos != size:
        raise fail(f"{size - pos} bytes of trailing data after the last slice", pos)
    return MricData(width=width, height=height, axis=(ax, ay), image=image, slices=slices)


def read_mric(path: str | os.PathLike) -> MricData:
    """Read an MRIC contour file.

    Returns
    -------
    MricData with ``.width .height .axis .image (h, w) uint8 .slices`` and, from the
    sidecar ``<path>.json`` when present, ``.spacing .origin .direction``.

    Raises
    ------
    FormatError
        Missing/unreadable file, wrong signature, truncated, oversized (trailing
        data), or inconsistent contents (negative counts, counts larger than the
        bytes left, points outside the slice, marker byte other than 255).
    """
    p = Path(path)
    buf = read_regular_file(p, MAX_FILE_BYTES, what="an MRIC file")
    data = decode_mric(buf, p)
    read_sidecar(p, data)
    return data


def read_regular_file(path: Path, limit: int, *, what: str) -> bytes:
    """Read a whole regular file of at most ``limit`` bytes, or raise FormatError.

    Checks the file type before opening it (opening a FIFO would block) and never
    reads more than ``limit + 1`` bytes.
    """
    st = regular_source(path, what=what)
    if st.st_size > limit:
        raise FormatError(f"{path}: {st.st_size} bytes is too large for {what}")
    # the bytes and the arrays decoded from them, against the process's memory limits
    check_allocation(2 * st.st_size, what=what, path=path)
    try:
        with open(path, "rb") as fh:
            buf = fh.read(min(limit, st.st_size) + 1)
    except OSError as exc:
        raise FormatError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if len(buf) > limit:
        raise FormatError(f"{path}: too large for {what}")
    return buf
