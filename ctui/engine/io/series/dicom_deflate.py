"""Deflated Explicit VR Little Endian (1.2.840.10008.1.2.1.99) files, inflated within a bound.

pydicom inflates such a file's whole dataset in one ``zlib.decompress`` call before any size
check (3 MB of deflated zeros -> about 5 GB; 1.5 GB -> 2.9 GB RSS and 16 s), and a header
read then looked for the pixel element at its inflated position in the deflated file, so
valid deflated series were refused ("no pixel data"). Here the file meta is read as stored,
the dataset inflated with ``zlib.decompressobj().decompress(data, max_length)`` in chunks up to
a bound, and handed on as an in-memory Explicit VR Little Endian file: :func:`inflate`.
The header pass inflates the first MiB, learns the pixel bytes the header claims, then
inflates at most that much more (:func:`inflate_for_header`); decoding inflates at most the
frame bytes plus the header (:func:`inflate_for_pixels`).
"""

from __future__ import annotations

import io
import os
import stat
import zlib
from typing import Any

DEFLATED = "1.2.840.10008.1.2.1.99"
EXPLICIT_LE = "1.2.840.10008.1.2.1"
_FIRST = 1 << 20  # inflated bytes read for the header
_SLACK = 4 << 20  # header and trailing elements beyond the claimed pixel bytes
_CHUNK = 1 << 20


class InflateError(Exception):
    """A deflated file that cannot be inflated (corrupt stream, bad file meta); str: why."""


def is_deflated(head: bytes) -> bool:
    """Whether the first bytes of a file (its file meta) name the deflated transfer syntax."""
    return DEFLATED.encode() in head[:8192]


def inflate(path: str, limit: int) -> tuple[bytes, bool]:
    """(an Explicit VR Little Endian file in memory: preamble, file meta with that transfer
    syntax, at most ``limit`` bytes of the inflated dataset; whether the stream holds more)."""
    from pydicom.filereader import _read_file_meta_info, read_preamble  # pydicom: with the DICOM loader
    from pydicom.filewriter import write_file_meta_info

    try:
        with open(path, "rb") as fh:
            read_preamble(fh, False)
            meta = _read_file_meta_info(fh)
            dec = zlib.decompressobj(-zlib.MAX_WBITS)
            out = bytearray()
            more = False
            while True:
                chunk = dec.unconsumed_tail or fh.read(_CHUNK)
                if not chunk:
                    break
                try:
                    out += dec.decompress(chunk, max(1, min(_CHUNK, limit + 1 - len(out))))
                except zlib.error:
                    if not out:
                        raise
                    break  # corrupt past the start: what inflated is judged (a truncated slice)
                if len(out) > limit:
                    more = True
                    del out[limit:]
                    break
                if dec.eof:
                    break
    except (zlib.error, OSError, ValueError, EOFError) as exc:
        raise InflateError(f"deflated data cannot be inflated ({type(exc).__name__}: {exc})"[:160]) from None
    except Exception as exc:  # noqa: BLE001 - pydicom's meta reader: any fault is a broken header
        raise InflateError(f"broken DICOM file meta ({type(exc).__name__})") from None
    buf = io.BytesIO()
    buf.write(b"\0" * 128 + b"DICM")
    try:
        meta.TransferSyntaxUID = EXPLICIT_LE
        write_file_meta_info(buf, meta, enforce_standard=False)
    except Exception as exc:  # noqa: BLE001 - a mutated file meta pydicom cannot write back
        raise InflateError(f"broken DICOM file meta ({type(exc).__name__})") from None
    buf.write(out)
    return buf.getvalue(), more


def _claimed_bytes(data: bytes) -> int:
    """Pixel bytes the (partly inflated) header claims; 0 when it cannot tell."""
    import pydicom  # with the DICOM readers

    try:
        ds = pydicom.dcmread(io.BytesIO(data), stop_before_pixels=True, force=True)
        rows, cols = int(ds.get("Rows") or 0), int(ds.get("Columns") or 0)
        bits, samples = int(ds.get("BitsAllocated") or 16), int(ds.get("SamplesPerPixel") or 1)
        frames = int(str(ds.get("NumberOfFrames") or 1) or 1)
        return max(0, rows * cols * samples * max(bits, 8) // 8 * max(frames, 1))
    except Exception:  # noqa: BLE001 - judged by the header pass itself
        return 0


def inflate_for_header(path: str, memory: int | None) -> bytes:
    """The file inflated enough for the header pass: the first MiB, then at most the pixel
    bytes its header claims (and never more than ``memory``)."""
    data, more = inflate(path, _FIRST)
    if not more:
        return data
    need = _claimed_bytes(data)
    if memory is not None and need > memory:
        raise InflateError(f"header claims {need} bytes of pixels, more than the memory ctui may use")
    return inflate(path, need + _SLACK)[0]


def inflate_for_pixels(path: str, frame_bytes: int) -> Any:
    """The file inflated for decoding (at most ``frame_bytes`` plus the header), as a file object."""
    return io.BytesIO(inflate(path, int(frame_bytes) + _SLACK)[0])


def header_frames(path: str, memory: int | None, parse: Any, skip: type) -> tuple[list, list]:
    """A deflated file's frames and identifiers: ``parse(fileobj, path, size)`` (the header
    pass's pydicom parser) on the bounded inflation; the frames then decode through
    :func:`inflate_for_pixels`. ``skip``: the exception class for a file left out."""
    try:
        data = inflate_for_header(path, memory)
    except InflateError as exc:
        raise skip(str(exc)) from None
    frames, ids = parse(io.BytesIO(data), path, len(data))
    for f in frames:
        f.syntax, f.compressed, f.offset, f.big_endian = DEFLATED, True, None, False
    return frames, ids


#: inflated bytes a whole deflated label file (DICOM-SEG, RTSTRUCT) may take
MAX_WHOLE = 1 << 30


def dcmread(path: Any, **kw: Any) -> Any:
    """``pydicom.dcmread(path, **kw)``, but a deflated file is inflated within a bound first
    (headers only with ``stop_before_pixels``: the first MiB and the claimed pixel bytes;
    else at most :data:`MAX_WHOLE`, more raising ValueError)."""
    import pydicom  # with the DICOM readers

    if not stat.S_ISREG(os.stat(path).st_mode):  # a FIFO would block the read
        raise ValueError("not a regular file (FIFO, device or socket)")
    with open(path, "rb") as fh:
        head = fh.read(8192)
    if not is_deflated(head):
        return pydicom.dcmread(path, **kw)
    try:
        if kw.get("stop_before_pixels"):
            data = inflate_for_header(str(path), None)
        else:
            data, more = inflate(str(path), MAX_WHOLE)
            if more:
                raise ValueError(f"deflated dataset inflates to more than {MAX_WHOLE >> 20} MiB")
    except InflateError as exc:
        raise ValueError(str(exc)) from None
    return pydicom.dcmread(io.BytesIO(data), **kw)
