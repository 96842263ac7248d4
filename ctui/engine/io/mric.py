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

The reader trusts nothing: every count is checked against the bytes left in the file
before anything is allocated, so a corrupted or hostile file can never make it
allocate more than the file's own size; any fault raises a one-line
:class:`~ctui.engine.core.errors.FormatError` naming the file, the fault and its offset.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ctui.engine.core.atomic import atomic_write
from ctui.engine.core.errors import FormatError

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
    """

    width: int
    height: int
    axis: tuple[int, int] = (0, 0)
    image: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.uint8))
    slices: list[list[list[np.ndarray]]] = field(default_factory=list)

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

    Returns
    -------
    Path of the written file.
    """
    data = encode_mric(slices, width=width, height=height, axis=axis, image=image, path=path)
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    return Path(path)


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
    MricData with ``.width .height .axis .image (h, w) uint8 .slices``.

    Raises
    ------
    FormatError
        Missing/unreadable file, wrong signature, truncated, oversized (trailing
        data), or inconsistent contents (negative counts, counts larger than the
        bytes left, points outside the slice, marker byte other than 255).
    """
    p = Path(path)
    buf = read_regular_file(p, MAX_FILE_BYTES, what="an MRIC file")
    return decode_mric(buf, p)


def read_regular_file(path: Path, limit: int, *, what: str) -> bytes:
    """Read a whole regular file of at most ``limit`` bytes, or raise FormatError.

    Checks the file type before opening it (opening a FIFO would block) and never
    reads more than ``limit + 1`` bytes.
    """
    import stat

    try:
        st = os.stat(path)
    except OSError as exc:
        raise FormatError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        raise FormatError(f"{path}: is a folder, not {what}")
    if not stat.S_ISREG(st.st_mode):
        raise FormatError(f"{path}: not a regular file")
    if st.st_size > limit:
        raise FormatError(f"{path}: {st.st_size} bytes is too large for {what}")
    try:
        with open(path, "rb") as fh:
            buf = fh.read(min(limit, st.st_size) + 1)
    except OSError as exc:
        raise FormatError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if len(buf) > limit:
        raise FormatError(f"{path}: too large for {what}")
    return buf
