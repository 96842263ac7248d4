"""Bounded reading of NRRD data that is not plain raw bytes at a known offset.

pynrrd reads a ``gzip``/``bzip2``/``ascii``/``hex`` payload (or one after ``line skip``
lines) whole: a detached ``data file: /dev/zero`` reads until the OOM killer, a FIFO
blocks forever, a gzip stream declaring 960 voxels may inflate to gigabytes and
``line skip: 99999999`` loops. :func:`read_payload` reads only regular files, skips at
most the lines the file holds, and never decodes more than the header declares (one
byte more reveals an oversized stream, which is refused).
"""

from __future__ import annotations

import bz2
import os
import zlib
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from ctui.engine.core.errors import LoadError

HEADER_LIMIT = 1 << 20  # bytes of NRRD header read at most
_LINE_LIMIT = 1 << 20  # bytes of one skipped line
_TEXT_CHARS = 40  # characters one ascii value may take (with its separator)


def regular_file(path: Path, *, what: str, owner: Path) -> Path:
    """``path`` resolved, when it is a regular file; else a one-line LoadError naming ``owner``
    (devices, FIFOs, sockets and folders would block or never end)."""
    try:
        target = Path(path).resolve()
        ok = target.is_file()
    except (OSError, ValueError, RuntimeError):  # embedded NUL, name too long, link loop
        ok = False
        target = Path(path)
    if not ok:
        exists = os.path.lexists(path) if "\0" not in str(path) else False
        why = "is not a regular file" if exists else "is missing"
        raise LoadError(f"{what} {str(path)!r} named by the NRRD header {why}", path=owner)
    return target


def header_end(path: Path) -> int:
    """Byte offset just after the blank line that ends an attached NRRD header."""
    with open(path, "rb") as fh:
        head = fh.read(HEADER_LIMIT + 2)
    end = head.find(b"\n\n")
    if end < 0:
        raise LoadError("NRRD header without the blank line that ends it (or longer than 1 MB)", path=path)
    return end + 2


def _skip_lines(fh: BinaryIO, n: int, *, path: Path) -> None:
    for i in range(n):
        line = fh.readline(_LINE_LIMIT + 1)
        if not line:
            raise LoadError(f"NRRD line skip {n}: the data file ends after {i} lines", path=path)
        if len(line) > _LINE_LIMIT and not line.endswith(b"\n"):
            raise LoadError(f"NRRD line skip: line {i + 1} of the data is longer than 1 MB", path=path)


def _inflate(fh: BinaryIO, encoding: str, want: int, *, path: Path) -> bytes:
    """At most ``want`` bytes of a gzip/zlib or bzip2 stream (reads the input in chunks)."""
    dec = bz2.BZ2Decompressor() if encoding.startswith("bz") else zlib.decompressobj(zlib.MAX_WBITS | 32)
    try:
        return inflate_bounded(fh, dec, want)
    except (OSError, EOFError, ValueError, zlib.error) as exc:
        raise LoadError(f"corrupted {encoding} NRRD data ({' '.join(str(exc).split())[:100]})", path=path) from None


def inflate_bounded(fh: BinaryIO, dec: Any, want: int, *, chunk: int = 1 << 20) -> bytes:
    """At most ``want`` bytes out of the decompressor ``dec`` (zlib or bz2) fed from ``fh`` in chunks: a
    stream that inflates past what a header declares stops there (``dec.eof`` tells whether it ended)."""
    out = bytearray()
    while len(out) < want and not dec.eof:
        if isinstance(dec, bz2.BZ2Decompressor):
            src = fh.read(chunk) if dec.needs_input else b""
            if not src and dec.needs_input:
                break
            out += dec.decompress(src, max_length=want - len(out))
        else:
            src = dec.unconsumed_tail or fh.read(chunk)
            if not src:
                break
            out += dec.decompress(src, want - len(out))
    return bytes(out)


def _text_values(fh: BinaryIO, count: int, dtype: np.dtype, *, path: Path, partial: bool = False) -> np.ndarray:
    raw = fh.read(count * _TEXT_CHARS + 4096)
    words = raw.decode("ascii", errors="replace").split()
    if partial:
        words = words[:count]
    try:
        vals = np.array(words, dtype=np.float64 if dtype.kind == "f" else np.int64)
    except (UnicodeDecodeError, ValueError, OverflowError):
        raise LoadError("NRRD ascii data holds something that is not a number", path=path) from None
    if vals.size < count:
        raise LoadError(f"truncated: NRRD ascii data holds {vals.size} of the {count} values the header declares",
                        path=path)
    if vals.size > count:
        raise LoadError(f"NRRD ascii data holds more than the {count} values the header declares", path=path)
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        if vals.min() < info.min or vals.max() > info.max:
            raise LoadError(f"NRRD ascii data holds values outside {dtype.name}", path=path)
    return vals.astype(dtype.newbyteorder("="))


def read_payload(path: Path, hdr: dict, *, dtype: np.dtype, full: tuple[int, int, int],
                 datafile: str | None, zstop: int | None = None) -> np.ndarray:
    """The NRRD's voxels as a (z, y, x) array of ``dtype`` (native byte order), read with
    bounds: a regular data file, ``line skip`` within the file, decoding stopped at the
    declared size. Encodings: raw, gzip, bzip2, ascii/text, hex. ``zstop``: only the first
    ``zstop`` slices are decoded (the array has that many; the stream's end is not checked)."""
    partial = zstop is not None and zstop < full[0]
    if partial:
        full = (int(zstop), full[1], full[2])
    encoding = str(hdr.get("encoding", "raw")).strip().lower()
    try:
        line_skip = int(hdr.get("line skip", hdr.get("lineskip", 0)) or 0)
        byte_skip = int(hdr.get("byte skip", hdr.get("byteskip", 0)) or 0)
    except (TypeError, ValueError):
        raise LoadError("NRRD line skip / byte skip is not a whole number", path=path) from None
    count = int(np.prod(full, dtype=np.int64))
    need = count * dtype.itemsize
    if datafile is None:
        src, start = regular_file(path, what="the NRRD file", owner=path), header_end(path)
    else:
        src, start = regular_file(path.parent / str(datafile), what="data file", owner=path), 0
    size = src.stat().st_size
    if line_skip < 0 or line_skip > size or byte_skip < -1 or byte_skip > max(size, need):
        raise LoadError(f"unreasonable NRRD line skip {line_skip} / byte skip {byte_skip} for a data file of "
                        f"{size} bytes", path=path)
    with open(src, "rb") as fh:
        fh.seek(start)
        _skip_lines(fh, line_skip, path=path)
        if encoding == "raw":
            if byte_skip == -1:
                fh.seek(max(size - need, 0))
            else:
                fh.seek(byte_skip, os.SEEK_CUR)
            buf = fh.read(need)
        elif encoding in ("gzip", "gz", "bzip2", "bz2"):
            if byte_skip == -1:
                raise LoadError("NRRD byte skip -1 with compressed data is not supported", path=path)
            out = _inflate(fh, encoding, need + byte_skip + (0 if partial else 1), path=path)
            if len(out) > need + byte_skip:
                raise LoadError(f"compressed NRRD data holds more than the {need} bytes the header declares", path=path)
            buf = out[byte_skip:]
        elif encoding in ("ascii", "text", "txt"):
            return _text_values(fh, count, dtype, path=path, partial=partial).reshape(full)
        elif encoding == "hex":
            txt = b"".join(fh.read(2 * need + need // 2 + 4096).split())
            try:
                buf = bytes.fromhex(txt.decode("ascii"))
            except (UnicodeDecodeError, ValueError):
                raise LoadError("NRRD hex data holds something that is not hexadecimal", path=path) from None
            buf = buf[: need + 1]
        else:
            raise LoadError(f"unsupported NRRD encoding {encoding!r}", path=path)
    if len(buf) < need:
        raise LoadError(f"truncated: NRRD data holds {len(buf)} of the {need} bytes the header declares", path=path)
    return np.frombuffer(buf, dtype, count=count).reshape(full).astype(dtype.newbyteorder("="))
