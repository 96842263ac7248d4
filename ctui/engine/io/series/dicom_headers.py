"""DICOM headers: one record (:class:`Frame`) per 2D image, from the header only.

Every file is read with ``pydicom.dcmread(stop_before_pixels=True)`` (``force=True``
fallback); the pixel data element's header is parsed right after, giving the value
offset and length, so the pixel pass reads exactly those bytes. Multi-frame files give
one Frame per frame from the functional groups. Sizes claimed by a header are checked
against the file's size before anything is built or allocated.
"""

from __future__ import annotations

import io
import logging
import os
import struct
import threading
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ctui.engine.core.limits import available_memory, fmt_bytes
from ctui.engine.io.series._common import rel
from ctui.engine.io.series.dicom_quick import _LONG_VRS, CODECS, PIXEL_TAGS, TEXT_VRS, decode_raw, quick_parse
from ctui.engine.io.series.dicom_deflate import header_frames, is_deflated
from ctui.engine.io.series.dicom_sop import _check_image, _NotImage, _Skip, series_uid_of
from ctui.engine.io.series.dicom_values import (  # noqa: F401 - re-exported for the loaders
    _implausible,
    _int_or_none,
    _intercept,
    _num,
    _plausible_spacing,
    _slope,
    _vec,
)

_NATIVE_SYNTAXES = {
    "1.2.840.10008.1.2",  # implicit VR little endian
    "1.2.840.10008.1.2.1",  # explicit VR little endian
    "1.2.840.10008.1.2.2",  # explicit VR big endian (retired)
}
_ID_KEYWORDS = (
    "PatientName",
    "PatientID",
    "PatientBirthDate",
    "AccessionNumber",
    "InstitutionName",
    "OtherPatientIDs",
    "ReferringPhysicianName",
)
# header values bigger than this are not read (pydicom seeks past them): a corrupt
# length field cannot make us allocate gigabytes for a small file
_DEFER = 1 << 20
#: bytes read to parse a header in memory (most headers are a few kB; longer ones are
#: parsed from the file)
_HEAD_BYTES = 32 << 10
MAX_COMPRESSION = 1000  # decoded bytes per stored byte we accept before decoding


@dataclass
class Frame:
    """One 2D image: a single-frame file or one frame of a multi-frame file."""

    file: str
    frame: int = 0
    nframes: int = 1
    offset: int | None = None  # value offset of native pixel data
    syntax: str = "1.2.840.10008.1.2.1"
    compressed: bool = False
    big_endian: bool = False
    rows: int = 0
    cols: int = 0
    samples: int = 1
    planar: int = 0
    bits: int = 16
    bits_stored: int = 16
    signed: bool = False
    float_kind: str = ""  # "", "f4", "f8"
    photometric: str = "MONOCHROME2"
    slope: float = 1.0
    intercept: float = 0.0
    ipp: np.ndarray | None = None
    iop: np.ndarray | None = None
    pixel_spacing: tuple[float, float] | None = None
    thickness: float | None = None
    spacing_between: float | None = None
    instance: int | None = None
    series_uid: str = ""
    series_number: int | None = None
    description: str = ""
    modality: str = "OT"
    window: tuple[float, float] | None = None
    sop_class: str = ""
    ignored_scaling: str = ""  # an implausible RescaleSlope/Intercept or PixelSpacing replaced (said in a warning)

    @property
    def frame_bytes(self) -> int:
        return self.rows * self.cols * self.samples * max(self.bits, 8) // 8

    @property
    def raw_dtype(self) -> np.dtype:
        if self.float_kind:
            dt = np.dtype(self.float_kind)
        else:
            dt = np.dtype(f"{'i' if self.signed else 'u'}{max(self.bits, 8) // 8}")
        return dt.newbyteorder(">" if self.big_endian else "<")


@dataclass
class Series:
    uid: str
    frames: list[Frame] = field(default_factory=list)
    skipped: list[dict[str, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    files: set[str] = field(default_factory=set)


# ===================================================================== headers
class _Fast:
    """Read-only ``get(keyword)`` over a dataset that decodes simple elements from their
    raw bytes (pydicom's general value conversion costs ~30 us an element, which made
    header reading 2.5x slower). Sequences, person names and text that needs the
    character set go through pydicom."""

    _PYDICOM = {"SQ", "PN", "LO", "SH", "ST", "LT", "UT", "UC"}

    def __init__(self, ds: Any) -> None:
        self.ds = ds
        cs = ""
        try:
            elem = ds.get_item(0x00080005)
            if elem is not None:
                raw = elem.value
                cs = (raw.decode("latin-1") if isinstance(raw, bytes) else str(raw or "")).strip("\x00 ")
        except Exception:
            cs = "?"
        # text VRs decoded here when the character set is a plain one (pydicom's decoding
        # of person names and long strings was a third of the header time)
        self.codec = CODECS.get(cs)

    _TAGS: dict[str, Any] = {}

    def get(self, keyword: str, default: Any = None) -> Any:
        from pydicom.datadict import dictionary_VR, tag_for_keyword
        from pydicom.dataelem import RawDataElement

        tag = self._TAGS.get(keyword, -1)
        if tag == -1:
            tag = self._TAGS[keyword] = tag_for_keyword(keyword)
        if tag is None:
            return default
        try:
            elem = self.ds.get_item(tag)
        except Exception:
            return default
        if elem is None:
            return default
        if not isinstance(elem, RawDataElement):
            return elem.value
        try:
            vr = str(elem.VR) if elem.VR else dictionary_VR(tag)
        except KeyError:
            return default
        if elem.value is None or vr == "SQ" or (vr in self._PYDICOM and (self.codec is None or vr not in TEXT_VRS)):
            try:
                return self.ds[tag].value
            except Exception:
                return default
        v = decode_raw(vr, bytes(elem.value), elem.is_little_endian, self.codec or "latin-1")
        return default if v is None else v

    def __contains__(self, keyword: str) -> bool:
        return self.get(keyword) is not None


def _first(ds: Any, keyword: str) -> Any:
    try:
        return ds.get(keyword)
    except Exception:
        return None


def _seq_item(ds: Any, *path: str) -> Any:
    """ds.A[0].B[0]... or None."""
    cur = ds
    for kw in path:
        try:
            seq = cur.get(kw)
        except Exception:
            return None
        if not seq:
            return None
        cur = seq[0]
    return cur


def _pixel_element(fh, pos: int, implicit: bool, little: bool, size: int) -> tuple[int, int, str]:
    """Parse the pixel data element header at ``pos``: (value offset, length, kind)."""
    fh.seek(pos)
    head = fh.read(12)
    if len(head) < 8:
        raise _Skip("no pixel data (not an image, or truncated before the pixels)")
    e = "<" if little else ">"
    group, elem = struct.unpack(e + "HH", head[:4])
    tag = (group << 16) | elem
    if tag not in PIXEL_TAGS:
        raise _Skip("no pixel data (not an image, or truncated before the pixels)")
    if implicit:
        (length,) = struct.unpack(e + "I", head[4:8])
        off = pos + 8
    else:
        vr = head[4:6]
        if vr in _LONG_VRS:
            if len(head) < 12:
                raise _Skip("truncated in the pixel data header")
            (length,) = struct.unpack(e + "I", head[8:12])
            off = pos + 12
        else:
            (length,) = struct.unpack(e + "H", head[6:8])
            off = pos + 8
    return off, length, PIXEL_TAGS[tag]


class _Capped:
    """File wrapper whose ``read(n)`` never asks for more than the bytes left.

    CPython's buffered ``read(n)`` allocates ``n`` bytes up front, and pydicom reads
    file-meta elements whole (``defer_size`` does not apply there), so a corrupted
    0x7FFFFFFF element length in a 1 kB file allocated 2 GiB (found by FMT's
    tests/fuzz/test_fuzz_dicom.py).
    """

    def __init__(self, fh: Any, size: int) -> None:
        self._fh = fh
        self._size = size

    def read(self, n: int | None = -1) -> bytes:
        if n is not None and n >= 0:
            n = min(n, max(self._size - self._fh.tell(), 0))
        return self._fh.read(n)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._fh, name)


_QUIET = False


def _quiet_pydicom() -> None:
    """Stop pydicom echoing element values in warnings and log records.

    pydicom's value validation warns *and logs* (logger "pydicom") with the offending
    value, which for a corrupted header can include the patient's name and ID (found
    by FMT's tests/engine/core/test_privacy.py). ctui judges values itself, so validation on
    reading is turned off and the logger's non-error records are dropped.
    """
    global _QUIET
    if _QUIET:
        return
    from pydicom import config

    config.settings.reading_validation_mode = config.IGNORE
    logging.getLogger("pydicom").addFilter(lambda rec: rec.levelno >= logging.ERROR)
    _QUIET = True


def read_header(path: str | os.PathLike, *, memory: int | None = None) -> tuple[list[Frame], list[str]]:
    """Read one file's header: its frames and the patient identifiers found (for scrubbing).

    Raises _Skip(reason) when the file is not a loadable DICOM image. pydicom's
    validation warnings about malformed values are silenced: bad values are judged
    here (a skip with a reason, or a default with a Volume warning).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with np.errstate(all="ignore"):
            frames, ids = _read_header(path, memory)
    if memory is not None:
        f0 = frames[0]
        need = f0.frame_bytes * len(frames)
        if need > memory:
            raise _Skip(f"header claims {fmt_bytes(need)} of pixels ({len(frames)}x{f0.rows}x{f0.cols}), more than "
                        f"the {fmt_bytes(memory)} of memory ctui may use")
    return frames, ids


def _read_header(path: str | os.PathLike, memory: int | None = None) -> tuple[list[Frame], list[str]]:
    path = str(path)
    try:
        size = os.path.getsize(path)
    except OSError as exc:
        raise _Skip(f"cannot read ({exc.strerror or exc})") from None
    if size == 0:
        raise _Skip("empty file")
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise _Skip(f"cannot read ({exc.strerror or exc})") from None
    with fh:
        # the header is parsed from the file's first bytes in memory (pydicom's many small
        # reads and tells on a file cost more than the parsing: 300 CT headers 2x faster);
        # a header longer than that is parsed from the file itself
        head = fh.read(_HEAD_BYTES)
        if is_deflated(head):  # inflated within a bound, never by pydicom in one call
            return header_frames(path, memory, _parse, _Skip)
        quick = quick_parse(head)
        if quick is not None:
            try:
                return _checked_frames(quick, path, size, quick.syntax, quick.implicit, True, quick.pixel_pos,
                                       io.BytesIO(head))
            except _NotImage:
                raise
            except _Skip:
                pass  # judged again through pydicom: same reasons for the files that are really bad
        try:
            return _parse(io.BytesIO(head), path, size)
        except _Skip as sk:
            # a file without the DICM preamble that the first bytes do not parse as DICOM is
            # not parsed on to its end (a 20 GB sparse file of zeros reads as empty elements)
            if isinstance(sk, _NotImage) or len(head) >= size or head[128:132] != b"DICM":
                raise
        fh.seek(0)
        return _parse(_Capped(fh, size), path, size)


def _parse(fh: Any, path: str, size: int) -> tuple[list[Frame], list[str]]:
    """Frames and identifiers of one file from ``fh`` (positioned at its start), through pydicom."""
    import pydicom
    from pydicom.errors import InvalidDicomError

    _quiet_pydicom()

    forced = False
    try:
        ds = pydicom.dcmread(fh, stop_before_pixels=True, defer_size=_DEFER)
    except InvalidDicomError:
        fh.seek(0)
        forced = True
        try:
            ds = pydicom.dcmread(fh, stop_before_pixels=True, force=True, defer_size=_DEFER)
        except Exception:
            raise _Skip("not a DICOM file or image") from None
    except Exception as exc:
        raise _Skip(f"broken DICOM header ({type(exc).__name__})") from None
    try:
        pos = fh.tell()
        _check_image(ds)
        if forced and not (ds.get("Rows") and ds.get("Columns")):
            raise _Skip("not a DICOM file or image")
        implicit, little = ds.original_encoding
        if implicit is None:
            implicit, little = True, True
        meta = getattr(ds, "file_meta", None)
        syntax = str(meta.get("TransferSyntaxUID", "")) if meta is not None else ""
        if not syntax:
            syntax = "1.2.840.10008.1.2" if implicit else ("1.2.840.10008.1.2.1" if little else "1.2.840.10008.1.2.2")
        return _checked_frames(_Fast(ds), path, size, syntax, implicit, little, pos, fh)
    except _Skip as sk:
        sk.series_uid = series_uid_of(ds)  # a slice of that series is lost
        raise
    except Exception as exc:
        raise _Skip(f"broken DICOM header ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})") from None


def _checked_frames(ds: Any, path: str, size: int, syntax: str, implicit: bool, little: bool, pos: int,
                    fh: Any) -> tuple[list[Frame], list[str]]:
    """Frames of a parsed header (``ds.get(keyword)``), the pixel data element at ``pos``
    in ``fh`` checked against the file's ``size``; and the identifiers found."""
    try:
        frames = _frames_from_dataset(ds, path, syntax)
        ids = []
        for kw in _ID_KEYWORDS:
            v = ds.get(kw)
            if v:
                ids.append(str(v))
        compressed = syntax not in _NATIVE_SYNTAXES
        off, length, kind = _pixel_element(fh, pos, implicit, little, size)
        f0 = frames[0]
        need = f0.frame_bytes * f0.nframes
        if kind != "int":
            for f in frames:
                f.float_kind = kind
                f.bits = 32 if kind == "f4" else 64
            need = f0.rows * f0.cols * f0.samples * frames[0].bits // 8 * f0.nframes
        if compressed and length != 0xFFFFFFFF and syntax != "1.2.840.10008.1.2.1.99":
            compressed = False  # some writers label native data with a compressed syntax
        if not compressed:
            if f0.bits == 1:
                compressed = True  # bit-packed: leave to pydicom
            elif length == 0xFFFFFFFF:
                raise _Skip("encapsulated pixel data under an uncompressed transfer syntax")
            elif min(length, size - off) < need:
                have = max(0, min(length, size - off))
                raise _Skip(f"truncated: pixel data has {have} bytes, {need} expected for "
                            f"{f0.nframes}x{f0.rows}x{f0.cols}x{f0.bits}-bit")
        else:
            if need > MAX_COMPRESSION * max(size - off, 1) + (1 << 20):
                raise _Skip(f"header claims {need} bytes of pixels, too many for a {size}-byte file")
        for f in frames:
            f.offset = None if compressed else off
            f.compressed = compressed
            f.big_endian = not little and not compressed
        return frames, ids
    except _Skip:
        raise
    except Exception as exc:
        raise _Skip(f"broken DICOM header ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})") from None


def _frames_from_dataset(ds: Any, path: str, syntax: str) -> list[Frame]:
    _check_image(ds)
    rows, cols = int(ds.get("Rows") or 0), int(ds.get("Columns") or 0)
    if rows <= 0 or cols <= 0:
        raise _Skip("no image (Rows/Columns missing)")
    bits = int(ds.get("BitsAllocated") or 16)
    if bits not in (1, 8, 16, 32, 64):
        raise _Skip(f"unsupported BitsAllocated {bits}")
    samples = int(ds.get("SamplesPerPixel") or 1)
    if samples not in (1, 3, 4):
        raise _Skip(f"unsupported SamplesPerPixel {samples}")
    nframes = int(_num(ds.get("NumberOfFrames"), 1) or 1)
    if nframes < 1 or nframes > 100_000:
        raise _Skip(f"implausible NumberOfFrames {ds.get('NumberOfFrames')}")
    if nframes > 1:  # before building one record per frame (FMT fuzz: 65535 frames in 1 kB took 10 s)
        try:
            fsize = os.path.getsize(path)
        except OSError:
            fsize = 0
        if rows * cols * samples * bits // 8 * nframes > MAX_COMPRESSION * fsize + (1 << 20):
            raise _Skip(f"truncated or corrupt: header claims {nframes} frames of {rows}x{cols}, too many for a {fsize}-byte file")
    bs = int(ds.get("BitsStored") or bits)
    signed = int(ds.get("PixelRepresentation") or 0) == 1
    window = None
    wc, ww = _num(ds.get("WindowCenter")), _num(ds.get("WindowWidth"))
    if wc is not None and ww is not None and ww > 0:
        window = (wc, ww)
    sn = _num(ds.get("SeriesNumber"))
    base = Frame(
        file=path,
        nframes=nframes,
        syntax=syntax,
        rows=rows,
        cols=cols,
        samples=samples,
        planar=int(ds.get("PlanarConfiguration") or 0),
        bits=bits,
        bits_stored=max(1, min(bs, bits)),
        signed=signed,
        photometric=str(ds.get("PhotometricInterpretation") or "MONOCHROME2").strip(),
        slope=_slope(ds.get("RescaleSlope")),
        ignored_scaling=_implausible(ds),
        intercept=_intercept(ds.get("RescaleIntercept")),
        ipp=_vec(ds.get("ImagePositionPatient"), 3),
        iop=_vec(ds.get("ImageOrientationPatient"), 6),
        pixel_spacing=None,
        thickness=_num(ds.get("SliceThickness")),
        spacing_between=_num(ds.get("SpacingBetweenSlices")),
        instance=_int_or_none(ds.get("InstanceNumber")),
        series_uid=str(ds.get("SeriesInstanceUID") or ""),
        series_number=int(sn) if sn is not None else None,
        description=str(ds.get("SeriesDescription") or ""),
        modality=str(ds.get("Modality") or "OT").strip() or "OT",
        window=window,
        sop_class=str(ds.get("SOPClassUID") or ""),
    )
    ps = _vec(ds.get("PixelSpacing"), 2)
    if ps is None:
        ps = _vec(ds.get("ImagerPixelSpacing"), 2)
    if ps is not None and _plausible_spacing(ps):
        base.pixel_spacing = (float(ps[0]), float(ps[1]))
    if nframes == 1:
        return [base]
    return _multiframe(ds, base, nframes)


def _multiframe(ds: Any, base: Frame, nframes: int) -> list[Frame]:
    """One Frame per frame of a multi-frame file, from its functional groups."""
    shared = _seq_item(ds, "SharedFunctionalGroupsSequence")
    try:
        per = ds.get("PerFrameFunctionalGroupsSequence")
    except Exception:
        per = None
    per = list(per) if per else []
    out = []

    def lookup(own: Any, seq: str) -> Any:
        """Item of functional group ``seq``: the frame's own group first, then the shared one."""
        for g in (own, shared):
            if g is not None:
                it = _seq_item(g, seq)
                if it is not None:
                    return it
        return None

    for i in range(nframes):
        f = Frame(**{k: getattr(base, k) for k in base.__dataclass_fields__})
        f.frame = i
        f.instance = i + 1
        own = per[i] if i < len(per) else None
        # a top-level position cannot be every frame's: only per-frame (or shared) positions count
        f.ipp = _vec(getattr(lookup(own, "PlanePositionSequence"), "ImagePositionPatient", None), 3)
        o = _vec(getattr(lookup(own, "PlaneOrientationSequence"), "ImageOrientationPatient", None), 6)
        if o is not None:
            f.iop = o
        pm = lookup(own, "PixelMeasuresSequence")
        if pm is not None:
            ps = _vec(pm.get("PixelSpacing"), 2)
            if ps is not None and _plausible_spacing(ps):
                f.pixel_spacing = (float(ps[0]), float(ps[1]))
            st = _num(pm.get("SliceThickness"))
            if st is not None:
                f.thickness = st
            sb = _num(pm.get("SpacingBetweenSlices"))
            if sb is not None:
                f.spacing_between = sb
        pv = lookup(own, "PixelValueTransformationSequence")
        if pv is not None:
            f.slope = _slope(pv.get("RescaleSlope"), f.slope)
            f.intercept = _intercept(pv.get("RescaleIntercept"), f.intercept)
        voi = lookup(own, "FrameVOILUTSequence")
        if voi is not None:
            wc, ww = _num(voi.get("WindowCenter")), _num(voi.get("WindowWidth"))
            if wc is not None and ww is not None and ww > 0:
                f.window = (wc, ww)
        out.append(f)
    return out

# ===================================================================== grouping
def read_headers(
    files: Sequence[Path], *, base: Path | None = None, progress: Callable[[int, int], Any] | None = None,
    remember: bool = False,
) -> tuple[dict[str, Series], list[dict[str, str]], set[str]]:
    """Headers of all ``files``: series by UID, skipped files, identifiers seen. ``remember``:
    keep them for the next call in this thread (used once, if the files are unchanged).

    A file whose header claims more pixel bytes than the process may allocate (free
    RAM, RLIMIT_AS, cgroup limit) is skipped with that reason, naming the file."""
    kept = getattr(_KEPT, "last", None)  # one use only, in the thread that kept it
    _KEPT.last = None
    key = _files_key(files, base) if kept is not None or remember else None
    if kept is not None and key is not None and kept[0] == key:  # the preview read these files just now
        _, series0, skipped0, ids0 = kept
        if progress and files:
            progress(len(files), len(files))
        return ({u: Series(s.uid, list(s.frames), list(s.skipped), list(s.warnings), set(s.files))
                 for u, s in series0.items()}, [dict(d) for d in skipped0], set(ids0))
    memory = int(0.9 * available_memory())
    series: dict[str, Series] = {}
    skipped: list[dict[str, str]] = []
    ids: set[str] = set()
    total = len(files)
    for k, p in enumerate(files):
        try:
            frames, fid = read_header(p, memory=memory)
        except _Skip as s:
            skipped.append({"file": rel(p, base), "reason": str(s)})
            if getattr(s, "series_uid", "") and not isinstance(s, _NotImage):
                skipped[-1]["series"] = s.series_uid  # an image of that series could not be read
            if isinstance(s, _NotImage):  # listed as a non-image object (ctui info shows them apart)
                skipped[-1]["object"] = s.kind
        else:
            ids.update(fid)
            uid = frames[0].series_uid or f"(no SeriesInstanceUID) {Path(p).parent.name}"
            s = series.setdefault(uid, Series(uid))
            s.frames.extend(frames)
            s.files.add(str(p))
        if progress and (k % 16 == 15 or k + 1 == total):
            progress(k + 1, total)
    if remember and key is not None:
        _KEPT.last = (key, {u: Series(s.uid, list(s.frames), list(s.skipped), list(s.warnings), set(s.files))
                            for u, s in series.items()}, [dict(d) for d in skipped], set(ids))
    return series, skipped, ids


#: headers kept by ``read_headers(remember=True)`` (the TUI's preview) for the next read of the
#: same unchanged files in the same thread (the full load right after it), then dropped
_KEPT = threading.local()


def _files_key(files: Sequence[Path], base: Path | None) -> tuple | None:
    """The files' names, sizes, modification times and inodes (None: one could not be
    stat'ed): equal keys mean headers read before still hold."""
    try:
        return (str(base), tuple(str(p) for p in files),
                tuple((st.st_size, st.st_mtime_ns, st.st_ino) for st in (os.stat(p) for p in files)))
    except OSError:
        return None


def _ordered_series(series: dict[str, Series]) -> list[Series]:
    return sorted(
        series.values(),
        key=lambda s: (s.frames[0].series_number if s.frames[0].series_number is not None else 1 << 30, s.uid),
    )


