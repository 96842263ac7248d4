"""DICOM pixels: the output dtype and each frame's decode (native read into the output
slice, or pydicom's decoders for compressed transfer syntaxes)."""

from __future__ import annotations

import warnings
from typing import Sequence

import numpy as np

from ctui.engine.io.series.dicom_deflate import DEFLATED, inflate_for_pixels
from ctui.engine.io.series.dicom_headers import Frame, _quiet_pydicom, _Skip


def _out_dtype(frames: Sequence[Frame]) -> tuple[np.dtype, bool]:
    """(dtype, optimistic): optimistic means values are checked and the load redone
    in int32 if any slice does not fit."""
    if any(f.float_kind for f in frames) or any(f.samples > 1 for f in frames):
        return np.dtype(np.float32), False
    if any(f.slope != int(f.slope) or f.intercept != int(f.intercept) for f in frames):
        return np.dtype(np.float32), False
    lo, hi = np.inf, -np.inf
    for f in {(f.bits_stored, f.signed, f.slope, f.intercept, f.bits): f for f in frames}.values():
        bs = 1 if f.bits == 1 else f.bits_stored
        rlo, rhi = (-(2 ** (bs - 1)), 2 ** (bs - 1) - 1) if f.signed else (0, 2**bs - 1)
        a, b = sorted((rlo * f.slope + f.intercept, rhi * f.slope + f.intercept))
        lo, hi = min(lo, a), max(hi, b)
    for dt in (np.uint8, np.int16, np.uint16):
        info = np.iinfo(dt)
        if info.min <= lo and hi <= info.max:
            return np.dtype(dt), False
    if max(f.bits for f in frames) <= 16:
        # possible range wider than 16 bits only because of the stored range (e.g. 16
        # stored bits with a -1024 intercept): real CT values fit int16, so decode
        # optimistically and verify (a slice that does not fit triggers an int32 pass)
        return np.dtype(np.int16 if lo < 0 else np.uint16), True
    if np.iinfo(np.int32).min <= lo and hi <= np.iinfo(np.int32).max:
        return np.dtype(np.int32), False
    return np.dtype(np.float32), False


def _decode_native(f: Frame) -> np.ndarray:
    """Stored values of one frame, shape (rows, cols) or (rows, cols, samples)."""
    dt = f.raw_dtype
    n = f.rows * f.cols * f.samples
    buf = np.empty(n, dtype=dt)
    with open(f.file, "rb") as fh:
        fh.seek(int(f.offset) + f.frame * n * dt.itemsize)
        got = fh.readinto(memoryview(buf).cast("B"))
    if got != n * dt.itemsize:
        raise _Skip(f"truncated: {got} of {n * dt.itemsize} pixel bytes")
    if f.samples > 1:
        if f.planar == 1:
            arr = buf.reshape(f.samples, f.rows, f.cols).transpose(1, 2, 0)
        else:
            arr = buf.reshape(f.rows, f.cols, f.samples)
    else:
        arr = buf.reshape(f.rows, f.cols)
    if not f.float_kind and f.bits_stored < f.bits:
        arr = _mask_bits(arr, f)
    return arr


def _fast_ok(f: Frame, out_dtype: np.dtype) -> bool:
    """Whether a frame can be read straight into the output slice (no temporary)."""
    return (
        not f.compressed
        and f.samples == 1
        and not f.float_kind
        and f.bits_stored == f.bits
        and f.photometric == "MONOCHROME2"
        and out_dtype.kind in "iu"
        and out_dtype.itemsize == f.bits // 8
        and f.slope == 1.0
        and f.intercept == int(f.intercept)
    )


def _decode_native_into(f: Frame, dst: np.ndarray, optimistic: bool, overflow: list, k: int) -> str | None:
    """Read a frame's stored values into ``dst`` (the output slice) and rescale in place.

    Peak memory: nothing beyond ``dst`` (the intercept is added in place through a
    same-size view, in numpy's small buffered chunks).
    """
    raw_dt = f.raw_dtype
    view = dst.view(raw_dt.newbyteorder("="))
    n = f.rows * f.cols * raw_dt.itemsize
    with open(f.file, "rb") as fh:
        fh.seek(int(f.offset) + f.frame * n)
        got = fh.readinto(memoryview(view.reshape(-1)).cast("B"))
    if got != n:
        return f"truncated: {got} of {n} pixel bytes"
    if raw_dt.byteorder == ">" or (raw_dt.byteorder == "=" and f.big_endian):
        view.byteswap(inplace=True)
    icpt = int(f.intercept)
    if view.dtype == dst.dtype and icpt == 0:
        return None
    if optimistic or icpt:
        lo, hi = int(view.min()) + icpt, int(view.max()) + icpt
        info = np.iinfo(dst.dtype)
        if lo < info.min or hi > info.max:
            overflow.append(k)
            return None
    # modular arithmetic in the stored type: once the bounds check above has passed,
    # (stored + intercept) mod 2^bits read through ``dst``'s type is the exact value,
    # and the in-place add needs no temporary (a mixed-dtype ufunc would copy the
    # overlapping input)
    view += np.array(icpt).astype(view.dtype)
    return None


def _mask_bits(arr: np.ndarray, f: Frame) -> np.ndarray:
    """Drop bits above BitsStored (overlays in old files); sign-extend when signed."""
    bs, nb = f.bits_stored, f.bits
    a = arr.astype(arr.dtype.newbyteorder("="), copy=False)
    if f.signed:
        shift = np.array(nb - bs, dtype=a.dtype)
        return (a << shift) >> shift  # arithmetic shift sign-extends
    return a & np.array((1 << bs) - 1, dtype=a.dtype)


def _decode_pydicom(f: Frame) -> np.ndarray:
    import pydicom
    from pydicom.pixels import pixel_array

    _quiet_pydicom()
    try:
        src = inflate_for_pixels(f.file, f.frame_bytes * f.nframes) if f.syntax == DEFLATED else f.file
        ds = pydicom.dcmread(src, force=True)
        if f.syntax in JPEG_LS:
            check_jpeg_ls(ds, f)
        if not hasattr(ds, "file_meta") or "TransferSyntaxUID" not in ds.file_meta:
            from pydicom.dataset import FileMetaDataset

            ds.file_meta = getattr(ds, "file_meta", None) or FileMetaDataset()
            ds.file_meta.TransferSyntaxUID = f.syntax
        with warnings.catch_warnings():  # pydicom's excess-frames notice: judged by the caller's size check
            warnings.simplefilter("ignore")
            arr = pixel_array(ds, index=f.frame if f.nframes > 1 else None)
    except Exception as exc:
        msg = str(exc)
        if _codec_missing(f.syntax) or "plugin" in msg.lower() and "missing" in msg.lower():
            raise _Skip(codec_message(f.syntax)) from None
        raise
    if f.samples > 1 and arr.ndim == 3:
        if f.photometric.startswith("YBR"):
            from pydicom.pixels import convert_color_space

            arr = convert_color_space(arr, f.photometric, "RGB")
    return arr


JPEG_LS = ("1.2.840.10008.1.2.4.80", "1.2.840.10008.1.2.4.81")


def check_jpeg_ls(ds, f: Frame) -> None:
    """Refuse a JPEG-LS frame that is truncated or is not the header's image before CharLS
    sees it: CharLS takes 5-13 s of CPU to fail on a truncated frame (an 8-slice series 30-60 s).
    The frame must start with SOI, end with EOI (zero padding aside) and hold a SOF-55
    segment giving the header's rows and columns."""
    from pydicom.encaps import get_frame  # pydicom: with the decoder

    try:
        frame = bytes(get_frame(ds.PixelData, f.frame if f.nframes > 1 else 0, number_of_frames=f.nframes))
    except Exception as exc:  # noqa: BLE001 - broken encapsulation: pydicom says how
        raise _Skip(f"corrupt JPEG-LS fragments ({' '.join(str(exc).split())[:100]})") from None
    body = frame.rstrip(b"\0")
    if not (body.startswith(b"\xff\xd8") and body.endswith(b"\xff\xd9")):
        raise _Skip(f"truncated JPEG-LS frame ({len(frame)} bytes, no end-of-image marker): not decoded")
    sof = body.find(b"\xff\xf7")
    if sof < 0 or len(body) < sof + 9:
        raise _Skip("corrupt JPEG-LS frame (no frame header): not decoded")
    rows, cols = int.from_bytes(body[sof + 5:sof + 7], "big"), int.from_bytes(body[sof + 7:sof + 9], "big")
    if (rows, cols) != (f.rows, f.cols):
        raise _Skip(f"JPEG-LS frame of {rows}x{cols} under a {f.rows}x{f.cols} header: not decoded")


def _codec_missing(syntax: str) -> bool:
    try:
        from pydicom.pixels.decoders.base import get_decoder

        return not get_decoder(syntax).is_available
    except Exception:
        return True


def codec_message(syntax: str) -> str:
    try:
        from pydicom.uid import UID

        name = UID(syntax).name
    except Exception:  # pragma: no cover
        name = syntax
    return f"compressed pixel data ({name}) needs a decoder: pip install 'ctui[codecs]'"

