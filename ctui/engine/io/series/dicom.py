"""DICOM series loading.

Pipeline
--------
1. **Headers** of every file are read with ``pydicom.dcmread(stop_before_pixels=True)``
   (``force=True`` fallback for files without the 128-byte preamble / 'DICM' prefix or
   file meta). The pixel data element's header is parsed right after, giving the value
   offset and length, so the pixel pass reads exactly those bytes. Multi-frame files
   (Enhanced CT/MR) give one entry per frame, with per-frame positions, orientation,
   pixel spacing and rescale from the functional groups.
2. **Grouping** by SeriesInstanceUID; the largest series is loaded unless ``series=``
   picks one (index into :func:`scan_dicom`'s list, or a UID / UID prefix). Within the
   series, slices whose size or orientation differs from the majority are skipped with
   a reason.
3. **Sorting** along the slice normal n = row x col (ImageOrientationPatient) by
   n . ImagePositionPatient. Without positions: InstanceNumber order (a warning), then
   file name order. Spacing comes from the positions, never from SliceThickness.
4. **Pixels** are decoded in parallel threads straight into one preallocated array:
   uncompressed data is read with ``readinto`` from the known offset; compressed
   transfer syntaxes go through pydicom's pixel decoders (the ``codecs`` extra:
   ``pip install ctui[codecs]``). RescaleSlope/Intercept are applied per slice. The
   output dtype is int16 when the rescaled values fit (CT), the stored integer type
   when no rescale is needed, else float32.
5. **Geometry**: the volume is always returned on a regular orthogonal grid so meshes
   built from it are not distorted:

   * gantry tilt (positions drifting in-plane along the stack) is corrected by
     shifting each slice in-plane (linear interpolation) onto the orthogonal grid
     along the normal, as dcm2niix does; a warning gives the angle;
   * uneven gaps between slices (missing slices, variable spacing) are resampled
     (linear along the normal) onto a regular grid at the median gap; a warning gives
     the gaps. The original positions stay in ``Volume.slice_positions``.

No patient identifiers (name, ID, birth date, accession number, institution) are put
in the Volume; strings taken from headers are scrubbed of them.
"""

from __future__ import annotations

import os
import struct
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ctui.engine.core.errors import LoadError
from ctui.engine.core.volume import Volume
from ctui.engine.io.series._common import check_memory, make_plan, natural_key, rel, run_parallel, scrub_obj, to_grey

PIXEL_TAGS = {0x7FE00010: "int", 0x7FE00008: "f4", 0x7FE00009: "f8"}
_LONG_VRS = {b"OB", b"OW", b"OF", b"OD", b"OL", b"OV", b"UN", b"SQ", b"UT", b"UC", b"UR"}
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
MAX_COMPRESSION = 1000  # decoded bytes per stored byte we accept before decoding


class _Skip(Exception):
    """A file that is skipped; str(self) is the reason."""


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
def _num(v: Any, default: float | None = None) -> float | None:
    try:
        if v is None or v == "":
            return default
        if isinstance(v, (list, tuple)) or hasattr(v, "__len__") and not isinstance(v, (str, bytes)):
            v = v[0]
        f = float(v)
    except (TypeError, ValueError, IndexError, OverflowError):
        return default
    return f if np.isfinite(f) else default


def _slope(v: Any, default: float = 1.0) -> float:
    """RescaleSlope, or ``default`` when missing or implausible (0, non-finite, > 1e6)."""
    f = _num(v)
    return f if f is not None and f != 0 and abs(f) <= 1e6 else default


def _intercept(v: Any, default: float = 0.0) -> float:
    """RescaleIntercept, or ``default`` when missing or implausible (non-finite, > 1e7)."""
    f = _num(v)
    return f if f is not None and abs(f) <= 1e7 else default


def _int_or_none(v: Any) -> int | None:
    f = _num(v)
    return int(f) if f is not None and np.isfinite(f) and abs(f) < 2**31 else None


def _vec(v: Any, n: int) -> np.ndarray | None:
    try:
        if v is None:
            return None
        a = np.array([float(x) for x in v], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        return None
    # positions / orientations beyond a kilometre are corrupt values, not geometry
    if a.shape != (n,) or not np.all(np.isfinite(a)) or np.abs(a).max() > 1e6:
        return None
    return a


_BIN = {"US": "H", "SS": "h", "UL": "I", "SL": "i", "FL": "f", "FD": "d"}


class _Fast:
    """Read-only ``get(keyword)`` over a dataset that decodes simple elements from their
    raw bytes (pydicom's general value conversion costs ~30 us an element, which made
    header reading 2.5x slower). Sequences, person names and text that needs the
    character set go through pydicom."""

    _PYDICOM = {"SQ", "PN", "LO", "SH", "ST", "LT", "UT", "UC"}

    def __init__(self, ds: Any) -> None:
        self.ds = ds

    def get(self, keyword: str, default: Any = None) -> Any:
        from pydicom.datadict import dictionary_VR, tag_for_keyword
        from pydicom.dataelem import RawDataElement

        tag = tag_for_keyword(keyword)
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
        if vr in self._PYDICOM or elem.value is None:
            try:
                return self.ds[tag].value
            except Exception:
                return default
        raw = bytes(elem.value)
        if vr in _BIN:
            code = _BIN[vr]
            size = struct.calcsize(code)
            n = len(raw) // size
            if n == 0:
                return default
            vals = struct.unpack(("<" if elem.is_little_endian else ">") + code * n, raw[: n * size])
            return vals[0] if n == 1 else list(vals)
        text = raw.decode("latin-1").strip("\x00 ")
        if not text:
            return default
        parts = [t.strip() for t in text.split("\\")]
        return parts[0] if len(parts) == 1 else parts

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
    tests/test_fuzz_dicom.py).
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
    by FMT's tests/test_privacy.py). ctui judges values itself, so validation on
    reading is turned off and the logger's non-error records are dropped.
    """
    global _QUIET
    if _QUIET:
        return
    import logging

    from pydicom import config

    config.settings.reading_validation_mode = config.IGNORE
    logging.getLogger("pydicom").addFilter(lambda rec: rec.levelno >= logging.ERROR)
    _QUIET = True


def read_header(path: str | os.PathLike) -> tuple[list[Frame], list[str]]:
    """Read one file's header: its frames and the patient identifiers found (for scrubbing).

    Raises _Skip(reason) when the file is not a loadable DICOM image. pydicom's
    validation warnings about malformed values are silenced: bad values are judged
    here (a skip with a reason, or a default with a Volume warning).
    """
    import warnings

    _quiet_pydicom()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with np.errstate(all="ignore"):
            return _read_header(path)


def _read_header(path: str | os.PathLike) -> tuple[list[Frame], list[str]]:
    import pydicom
    from pydicom.errors import InvalidDicomError

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
        forced = False
        capped = _Capped(fh, size)
        try:
            ds = pydicom.dcmread(capped, stop_before_pixels=True, defer_size=_DEFER)
        except InvalidDicomError:
            fh.seek(0)
            forced = True
            try:
                ds = pydicom.dcmread(capped, stop_before_pixels=True, force=True, defer_size=_DEFER)
            except Exception:
                raise _Skip("not a DICOM file or image") from None
        except Exception as exc:
            raise _Skip(f"broken DICOM header ({type(exc).__name__})") from None
        try:
            pos = fh.tell()
            if forced and not (ds.get("Rows") and ds.get("Columns")):
                raise _Skip("not a DICOM file or image")
            implicit, little = ds.original_encoding
            if implicit is None:
                implicit, little = True, True
            meta = getattr(ds, "file_meta", None)
            syntax = str(meta.get("TransferSyntaxUID", "")) if meta is not None else ""
            if not syntax:
                syntax = "1.2.840.10008.1.2" if implicit else ("1.2.840.10008.1.2.1" if little else "1.2.840.10008.1.2.2")
            frames = _frames_from_dataset(_Fast(ds), path, syntax, full=ds)
            ids = []
            for kw in _ID_KEYWORDS:
                v = _Fast(ds).get(kw)
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


def _frames_from_dataset(ds: Any, path: str, syntax: str, *, full: Any = None) -> list[Frame]:
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
    if ps is not None and np.all(ps > 0):
        base.pixel_spacing = (float(ps[0]), float(ps[1]))
    if nframes == 1:
        return [base]
    # ---- multi-frame: functional groups
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
            if ps is not None and np.all(ps > 0):
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
    files: Sequence[Path], *, base: Path | None = None, progress: Callable[[int, int], Any] | None = None
) -> tuple[dict[str, Series], list[dict[str, str]], set[str]]:
    """Headers of all ``files``: series by UID, skipped files, identifiers seen."""
    series: dict[str, Series] = {}
    skipped: list[dict[str, str]] = []
    ids: set[str] = set()
    total = len(files)
    for k, p in enumerate(files):
        try:
            frames, fid = read_header(p)
        except _Skip as s:
            skipped.append({"file": rel(p, base), "reason": str(s)})
        else:
            ids.update(fid)
            uid = frames[0].series_uid or f"(no SeriesInstanceUID) {Path(p).parent.name}"
            s = series.setdefault(uid, Series(uid))
            s.frames.extend(frames)
            s.files.add(str(p))
        if progress and (k % 16 == 15 or k + 1 == total):
            progress(k + 1, total)
    return series, skipped, ids


def _ordered_series(series: dict[str, Series]) -> list[Series]:
    return sorted(
        series.values(),
        key=lambda s: (s.frames[0].series_number if s.frames[0].series_number is not None else 1 << 30, s.uid),
    )


def _dominant(frames: list[Frame], skipped: list[dict[str, str]], base: Path | None) -> list[Frame]:
    """Keep the frames sharing the most common size and orientation; skip the rest with a reason."""
    sizes = Counter((f.rows, f.cols) for f in frames)
    (r, c), _ = sizes.most_common(1)[0]
    keep = []
    for f in frames:
        if (f.rows, f.cols) != (r, c):
            skipped.append({"file": rel(f.file, base) + (f" frame {f.frame}" if f.nframes > 1 else ""),
                            "reason": f"slice size {f.rows}x{f.cols} differs from the series' {r}x{c}"})
        else:
            keep.append(f)
    with_iop = [f for f in keep if f.iop is not None]
    if with_iop:
        keys = Counter(tuple(np.round(f.iop, 3)) for f in with_iop)
        ref = np.array(keys.most_common(1)[0][0])
        out = []
        for f in keep:
            if f.iop is not None and np.max(np.abs(f.iop - ref)) > 1e-2:
                skipped.append({"file": rel(f.file, base) + (f" frame {f.frame}" if f.nframes > 1 else ""),
                                "reason": "image orientation differs from the rest of the series"})
            else:
                out.append(f)
        keep = out
    return keep


def series_summary(s: Series, frames: list[Frame] | None = None) -> dict[str, Any]:
    """The contract's series dict (cheap: from headers)."""
    frames = frames if frames is not None else s.frames
    f0 = frames[0]
    try:
        geo = _geometry(list(frames), quiet=True)
        nz, dz = len(geo["order"]), geo["dz"]
    except Exception:
        nz, dz = len(frames), None
    dy, dx = f0.pixel_spacing or (1.0, 1.0)
    return {
        "uid": s.uid,
        "description": f0.description,
        "modality": f0.modality,
        "files": len(s.files),
        "shape_zyx": [nz, f0.rows, f0.cols],
        "spacing_zyx_mm": [round(dz, 6) if dz else None, dy, dx],
        "kind": "dicom-multiframe" if f0.nframes > 1 else "dicom",
    }


def pick_series(ordered: list[Series], series: Any, path: Any) -> Series:
    if series is None:
        return max(ordered, key=lambda s: len(s.frames))  # first of the largest
    if isinstance(series, (int, np.integer)) or (isinstance(series, str) and series.strip().isdigit() and len(series.strip()) < 6):
        i = int(series)
        if not 0 <= i < len(ordered):
            raise LoadError(f"series index {i} out of range: {len(ordered)} series found (0..{len(ordered) - 1})", path=path)
        return ordered[i]
    key = str(series).strip()
    exact = [s for s in ordered if s.uid == key]
    if exact:
        return exact[0]
    pref = [s for s in ordered if s.uid.startswith(key)]
    if len(pref) == 1:
        return pref[0]
    raise LoadError(f"no series with UID {key!r} ({len(ordered)} series found; `ctui info` lists them)", path=path)


# ===================================================================== geometry
def _geometry(frames: list[Frame], *, quiet: bool = False) -> dict[str, Any]:
    """Order, spacing and orientation of a series' frames.

    Returns dict: order (indices into frames), positions (mm along normal, sorted, or
    None), dz, row, col, normal, origin, tilt_shifts (mm, per sorted frame, (n,3)) or
    None, tilt_deg, uneven (bool), gaps, warnings, duplicates (indices dropped).
    """
    warnings: list[str] = []
    f0 = frames[0]
    iop = next((f.iop for f in frames if f.iop is not None), None)
    if iop is not None:
        row, col = iop[:3], iop[3:]
        nr, nc = np.linalg.norm(row), np.linalg.norm(col)
        if nr < 1e-6 or nc < 1e-6:
            iop = None
        else:
            row, col = row / nr, col / nc
            if abs(float(row @ col)) > 1e-3:
                col = col - (col @ row) * row
                nc = float(np.linalg.norm(col))
                if nc < 1e-3:
                    warnings.append("ImageOrientationPatient row and column vectors are parallel (invalid): "
                                    "axial orientation assumed")
                    iop = None
                else:
                    col = col / nc
                    warnings.append("ImageOrientationPatient row and column vectors are not orthogonal; made orthogonal")
    elif any(f.ipp is not None for f in frames) and f0.sop_class != "1.2.840.10008.5.1.4.1.1.7":
        warnings.append("no ImageOrientationPatient: axial orientation assumed")
    if iop is None:
        row, col = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    normal = np.cross(row, col)
    have_pos = [f.ipp is not None for f in frames]
    result: dict[str, Any] = {"row": row, "col": col, "normal": normal, "tilt_shifts": None, "tilt_deg": 0.0,
                              "uneven": False, "gaps": None, "duplicates": [], "warnings": warnings,
                              "missing_positions": False}
    n = len(frames)
    if n and all(have_pos):
        d = np.array([float(f.ipp @ normal) for f in frames])
        inst = [f.instance if f.instance is not None else 0 for f in frames]
        order = sorted(range(n), key=lambda i: (d[i], inst[i], f0.file))
        ds = d[order]
        # duplicate positions (multiple echoes/phases in one series): keep the first
        keep = [order[0]]
        dup = []
        for i in order[1:]:
            if abs(d[i] - d[keep[-1]]) < 1e-3:
                dup.append(i)
            else:
                keep.append(i)
        if dup:
            warnings.append(f"{len(dup)} slices share a position with another slice (several echoes, phases or "
                            f"acquisitions in one series?); kept the first at each position")
        order = keep
        ds = d[order]
        gaps = np.diff(ds)
        if len(gaps):
            dz = float(np.median(gaps))
            if dz <= 0:
                dz = 1.0
            if _uneven(gaps):
                result["uneven"] = True
                result["gaps"] = (float(gaps.min()), float(gaps.max()))
        else:
            dz = f0.spacing_between or f0.thickness or 1.0
        # gantry tilt: in-plane offset of each slice's position from the first one's
        p0 = frames[order[0]].ipp
        offs = np.array([frames[i].ipp - p0 - (d[i] - d[order[0]]) * normal for i in order])
        inplane = np.linalg.norm(offs, axis=1)
        psz = min(f0.pixel_spacing or (1.0, 1.0))
        span = ds[-1] - ds[0]
        tilt = float(np.degrees(np.arctan2(np.linalg.norm(offs[-1]), span))) if span > 0 else 0.0
        # rounding of positions in the header gives tiny offsets: only a stack whose
        # positions move by more than a quarter pixel in-plane (and > 0.1 deg) is tilted
        if len(order) > 1 and inplane.max() > max(0.25 * psz, 0.05) and tilt > 0.1:
            result["tilt_shifts"] = offs
            result["tilt_deg"] = tilt
        result.update(order=order, positions=ds, dz=dz, origin=p0)
        return result
    # ---- no (or partial) positions
    if any(have_pos) and sum(have_pos) >= n / 2:
        # positions on most slices: the others are dropped by the caller
        keepi = [i for i in range(n) if have_pos[i]]
        sub = _geometry([frames[i] for i in keepi], quiet=quiet)
        sub["order"] = [keepi[i] for i in sub["order"]]
        sub["dropped_no_position"] = [i for i in range(n) if not have_pos[i]]
        return sub
    result["missing_positions"] = True
    dz = f0.spacing_between or f0.thickness
    if all(f.instance is not None for f in frames) and len({f.instance for f in frames}) == n:
        order = sorted(range(n), key=lambda i: frames[i].instance)
        how = "InstanceNumber"
    elif f0.nframes > 1 and all(f.file == f0.file for f in frames):
        order = list(range(n))
        how = "frame order"
    else:
        order = sorted(range(n), key=lambda i: (frames[i].instance or 0, natural_key(frames[i].file), frames[i].frame))
        how = "InstanceNumber and file name" if any(f.instance is not None for f in frames) else "file name"
    src = "SpacingBetweenSlices" if f0.spacing_between else ("SliceThickness" if f0.thickness else None)
    if not dz or dz <= 0:
        dz = 1.0
        src = None
    warnings.append(
        f"no ImagePositionPatient: slices ordered by {how}; slice spacing "
        + (f"{dz:g} mm from {src}" if src else "unknown, default spacing 1 mm")
    )
    result.update(order=order, positions=None, dz=float(dz), origin=f0.ipp if f0.ipp is not None else np.zeros(3))
    return result


def _uneven(gaps: np.ndarray) -> bool:
    """Gaps between slices differ by more than 5% of the median gap (and 0.01 mm):
    header rounding of positions stays below that, a missing slice is far above."""
    if len(gaps) == 0:
        return False
    dz = float(np.median(gaps))
    return float(gaps.max() - gaps.min()) > max(0.05 * abs(dz), 0.01)


# ===================================================================== pixels
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
        ds = pydicom.dcmread(f.file, force=True)
        if not hasattr(ds, "file_meta") or "TransferSyntaxUID" not in ds.file_meta:
            from pydicom.dataset import FileMetaDataset

            ds.file_meta = getattr(ds, "file_meta", None) or FileMetaDataset()
            ds.file_meta.TransferSyntaxUID = f.syntax
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


def load_series(
    s: Series,
    *,
    path: Any,
    base: Path | None,
    skipped: list[dict[str, str]],
    ids: set[str],
    crop: Any = None,
    downsample: Any = None,
    progress: Callable[[int, int], Any] | None = None,
    resample: bool = True,
    memory_limit: int | None = None,
    all_series: list[dict[str, Any]] | None = None,
    _dtype: np.dtype | None = None,
) -> Volume:
    """Decode one series into a Volume (see the module docstring)."""
    n_skipped_at_entry = len(skipped)
    frames = _dominant(s.frames, skipped, base)
    # compressed files without a decoder: skip each with the reason
    usable = []
    for f in frames:
        if f.compressed and _codec_missing(f.syntax):
            skipped.append({"file": rel(f.file, base), "reason": codec_message(f.syntax)})
        else:
            usable.append(f)
    if not usable:
        reasons = {d["reason"] for d in skipped}
        only_codec = [r for r in reasons if "pip install" in r]
        raise LoadError(only_codec[0] if only_codec else "no loadable DICOM image in the series", path=path)
    frames = usable
    geo = _geometry(frames)
    for i in geo.get("dropped_no_position", []):
        f = frames[i]
        skipped.append({"file": rel(f.file, base), "reason": "no ImagePositionPatient while the rest of the series has it"})
    warnings = list(geo["warnings"])
    order = geo["order"]
    dup_set = set(range(len(frames))) - set(order) - set(geo.get("dropped_no_position", []))
    for i in sorted(dup_set):
        f = frames[i]
        skipped.append({"file": rel(f.file, base) + (f" frame {f.frame}" if f.nframes > 1 else ""),
                        "reason": "same position as another slice of the series"})
    sorted_frames = [frames[i] for i in order]
    f0 = sorted_frames[0]
    full_shape = (len(sorted_frames), f0.rows, f0.cols)
    plan = make_plan(full_shape, crop=crop, downsample=downsample, path=path)
    out_shape = plan.out_shape(full_shape)
    zsel = list(range(*plan.z.indices(full_shape[0])))
    dtype, optimistic = (_dtype, False) if _dtype is not None else _out_dtype([sorted_frames[k] for k in zsel])
    extra = 0
    if resample and geo["uneven"] and geo["positions"] is not None:
        span = geo["positions"][zsel[-1]] - geo["positions"][zsel[0]]
        extra = int(round(span / (geo["dz"] * plan.steps()[0]))) + 1
    nbytes = int(np.prod(out_shape)) * dtype.itemsize
    check_memory(nbytes + extra * out_shape[1] * out_shape[2] * 4, shape=out_shape, path=path, limit=memory_limit)

    out = np.empty(out_shape, dtype=dtype)
    ysl, xsl = plan.y, plan.x
    overflow = []

    full_plane = plan.y == slice(0, f0.rows, 1) and plan.x == slice(0, f0.cols, 1)

    def work(k: int, zi: int) -> str | None:
        f = sorted_frames[zi]
        if full_plane and _fast_ok(f, out.dtype):
            return _decode_native_into(f, out[k], optimistic, overflow, k)
        try:
            raw = _decode_native(f) if not f.compressed else _decode_pydicom(f)
        except _Skip as sk:
            return str(sk)
        if raw.shape[:2] != (f.rows, f.cols):
            return f"decoded size {raw.shape[:2]} differs from the header's {f.rows}x{f.cols}"
        if raw.ndim == 3:
            raw = to_grey(raw)
        if f.photometric == "MONOCHROME1" and not raw.dtype.kind == "f":
            # inverted grey: white is the minimum; flip so that higher = brighter
            bs = f.bits_stored
            if f.signed:
                raw = (-raw.astype(np.int32) - 1)
            else:
                raw = (2**bs - 1) - raw.astype(np.int32)
        sub = raw[ysl, xsl]
        if out.dtype.kind == "f":
            v = sub.astype(np.float32)
            if f.slope != 1.0:
                v *= np.float32(f.slope)
            if f.intercept != 0.0:
                v += np.float32(f.intercept)
            out[k] = v
        elif f.slope == 1 and f.intercept == 0 and not optimistic and sub.dtype.newbyteorder("=") == out.dtype:
            out[k] = sub
        else:
            v = sub.astype(np.int64 if sub.dtype.itemsize >= 4 else np.int32)
            if f.slope != 1:
                v *= int(f.slope)
            if f.intercept:
                v += int(f.intercept)
            if optimistic:
                info = np.iinfo(out.dtype)
                if v.size and (v.min() < info.min or v.max() > info.max):
                    overflow.append(k)
                    return None
            out[k] = v
        return None

    failures = run_parallel(zsel, work, progress=progress)
    if overflow:
        # values do not fit the optimistic dtype (rare): decode again into int32
        del out
        del skipped[n_skipped_at_entry:]
        return load_series(s, path=path, base=base, skipped=skipped, ids=ids, crop=crop, downsample=downsample,
                           progress=progress, resample=resample, memory_limit=memory_limit,
                           all_series=all_series, _dtype=np.dtype(np.int32))
    bad = {k for k, _ in failures}
    for k, reason in failures:
        f = sorted_frames[zsel[k]]
        skipped.append({"file": rel(f.file, base) + (f" frame {f.frame}" if f.nframes > 1 else ""), "reason": reason})
    keep_k = [k for k in range(len(zsel)) if k not in bad]
    if not keep_k:
        raise LoadError("no slice of the series could be decoded" + (f" ({failures[0][1]})" if failures else ""), path=path)
    positions = geo["positions"][zsel] if geo["positions"] is not None else None
    if bad:
        # drop failed slices in place (no second full-size array)
        for j, k in enumerate(keep_k):
            if j != k:
                out[j] = out[k]
        out = out[: len(keep_k)]
        if positions is not None:
            positions = positions[keep_k]
            warnings.append(f"{len(bad)} slices could not be decoded and are missing: the gaps are interpolated")
        else:
            warnings.append(f"{len(bad)} slices could not be decoded and are missing from the volume")
    zsel = [zsel[k] for k in keep_k]
    zs, ys, xs = plan.steps()
    dy, dx = f0.pixel_spacing or (None, None)
    if dy is None:
        dy = dx = 1.0
        warnings.append("no PixelSpacing: default spacing 1 mm in-plane")
    row, col, normal = geo["row"], geo["col"], geo["normal"]
    y0, x0 = plan.starts(full_shape)[1:]
    dz = geo["dz"] * zs
    # --- gantry tilt: shift slices in-plane onto the orthogonal grid
    meta: dict[str, Any] = {"format": "dicom", "transfer_syntax": f0.syntax, "rescale": [f0.slope, f0.intercept],
                            "photometric": f0.photometric}
    if geo["tilt_shifts"] is not None:
        offs = geo["tilt_shifts"][zsel]
        _tilt_correct(out, offs, row, col, dy * ys, dx * xs)
        warnings.append(f"gantry tilt {geo['tilt_deg']:.2f} deg: slices shifted in-plane onto an orthogonal grid "
                        f"along the slice normal (linear interpolation)")
        meta["gantry_tilt_deg"] = round(geo["tilt_deg"], 4)
    # --- uneven spacing: resample along the normal
    if positions is not None and len(positions) > 1:
        gaps = np.diff(positions)
        dz = float(np.median(gaps))
        if _uneven(gaps):
            msg = f"uneven slice spacing (gaps {gaps.min():.3g} to {gaps.max():.3g} mm)"
            if resample:
                out = _resample_z(out, positions, dz)
                warnings.append(msg + f": resampled to a regular {dz:.4g} mm grid along the slice normal (linear)")
                meta["resampled"] = True
            else:
                warnings.append(msg + ": kept as is (resample=False); slice_positions gives each slice's position")
    origin = geo["origin"] if geo["origin"] is not None else np.zeros(3)
    origin = np.asarray(origin, float) + x0 * dx * row + y0 * dy * col
    if positions is not None:
        origin = origin + (positions[0] - geo["positions"][0]) * normal
    elif zsel[0]:
        origin = origin + zsel[0] * geo["dz"] * normal
    direction = np.column_stack([row, col, normal])
    modality = f0.modality
    window = f0.window
    if window is None:
        from ctui.engine.core.windows import auto_window

        window = auto_window(out, modality=modality)
    if f0.photometric == "MONOCHROME1":
        warnings.append("MONOCHROME1 (inverted grey) image: values inverted so that higher is brighter")
    if not plan.is_full(full_shape):
        meta["crop_downsample"] = {"start_zyx": list(plan.starts(full_shape)), "step_zyx": list(plan.steps()),
                                   "full_shape_zyx": list(full_shape)}
    desc = scrub_obj(f0.description, ids)  # header text: scrubbed of patient identifiers
    n_files = len(s.files)
    source = f"DICOM {modality} series" + (f" '{desc}'" if desc else "") + f", {n_files} file{'s' * (n_files != 1)}, from {path}"
    vol = Volume(
        data=out,
        spacing=(dz, dy * ys, dx * xs),
        origin=tuple(origin),
        direction=direction,
        modality=modality,
        window=tuple(window),
        source=source,
        series=all_series or [],
        skipped=skipped,
        warnings=warnings,
        slice_positions=positions,
        meta=meta,
    )
    # the series list holds header text (descriptions); paths given by the user are kept as given
    vol.series = scrub_obj(vol.series, ids)
    return vol


def _tilt_correct(out: np.ndarray, offs: np.ndarray, row: np.ndarray, col: np.ndarray, dy: float, dx: float) -> None:
    """Shift each slice in place by its in-plane offset (mm, (nz, 3)), in pixel units."""
    from scipy import ndimage

    fill = float(out.min()) if out.size else 0.0
    for k in range(out.shape[0]):
        sy, sx = float(offs[k] @ col) / dy, float(offs[k] @ row) / dx
        if abs(sy) < 1e-3 and abs(sx) < 1e-3:
            continue
        src = out[k].astype(np.float32)
        shifted = ndimage.shift(src, (sy, sx), order=1, mode="constant", cval=fill)
        if out.dtype.kind in "iu":
            shifted = np.rint(shifted)
        out[k] = shifted


def _resample_z(out: np.ndarray, positions: np.ndarray, dz: float) -> np.ndarray:
    """Linear resampling of slices at ``positions`` (mm, increasing) onto a regular grid."""
    p0 = positions[0]
    n = int(round((positions[-1] - p0) / dz)) + 1
    grid = p0 + dz * np.arange(n)
    res = np.empty((n, *out.shape[1:]), dtype=out.dtype)
    idx = np.clip(np.searchsorted(positions, grid, side="right") - 1, 0, len(positions) - 2)
    for k in range(n):
        i = idx[k]
        a, b = positions[i], positions[i + 1]
        t = 0.0 if b == a else float(np.clip((grid[k] - a) / (b - a), 0.0, 1.0))
        if t < 1e-6:
            res[k] = out[i]
        elif t > 1 - 1e-6:
            res[k] = out[i + 1]
        else:
            v = out[i].astype(np.float32) * (1 - t) + out[i + 1].astype(np.float32) * t
            res[k] = np.rint(v) if res.dtype.kind in "iu" else v
    return res
