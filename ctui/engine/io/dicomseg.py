"""DICOM Segmentation (SEG) objects: write with highdicom over the source series, read back.

Writing (:func:`write_seg`)
---------------------------
A ctui label map (z, y, x) uint8 over a DICOM series becomes one SEG instance that

* references every source SOP instance (SOPClassUID + SOPInstanceUID), found by reading
  the series' headers again (:func:`source_datasets`, no pixels) and sorting them along
  the slice normal exactly as the loader does; the slices must sit where the volume's
  geometry puts them (a resampled, cropped or tilt-corrected volume is refused);
* holds one segment per object (ids 1..255 renumbered 1..S in ascending order) with
  the object's name, its colour as CIELab, algorithm type SEMIAUTOMATIC and algorithm
  "ctui" (family: neighborhood analysis: threshold fill + propagation);
* is BINARY, with frames only where a segment has voxels (highdicom's
  ``omit_empty_frames``), its plane positions taken from the source images;
* carries no PatientName, PatientID or PatientBirthDate (blanked: empty type-2 values)
  nor the other identifying attributes highdicom copies from the source, unless
  ``keep_identifiers``.

Reading (:func:`read_seg`) returns the segments' descriptions and each segment's mask
on the SEG's own voxel grid (highdicom ``get_volume``), converted to ctui's geometry
convention; :mod:`ctui.engine.io.imports` places them on a series' grid.
"""

from __future__ import annotations

import copy
import os
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ctui import __version__
from ctui.engine.core.atomic import atomic_path
from ctui.engine.core.colors import object_color
from ctui.engine.core.errors import CtuiError, FormatError
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.limits import check_allocation
from ctui.engine.core.privacy import is_identifying, scrub_dataset_text
from ctui.engine.core.progress import Progress, report
from ctui.engine.io.dicomrefs import require_planes, require_references, write_fault
from ctui.engine.io.labels import present_ids
from ctui.engine.io.series.dicom_deflate import dcmread as bounded_dcmread

SEG_SOP_CLASS = "1.2.840.10008.5.1.4.1.1.66.4"
RTSTRUCT_SOP_CLASS = "1.2.840.10008.5.1.4.1.1.481.3"
#: identifying attributes that are type 2 in the modules highdicom/ctui write: kept empty
TYPE2_IDENTIFIERS = ("PatientName", "PatientID", "PatientBirthDate", "PatientSex", "StudyID",
                     "AccessionNumber", "ReferringPhysicianName")
_NOT_IMAGES = {SEG_SOP_CLASS, RTSTRUCT_SOP_CLASS, "1.2.840.10008.5.1.4.1.1.88.22", "1.2.840.10008.5.1.4.1.1.88.33"}


# =========================================================================== source
def import_pydicom() -> Any:
    """pydicom, imported without ``requests`` when nothing has imported that yet (on the main
    thread): pydicom imports it only to download its own test files, which ctui never asks
    for, and it is a third of pydicom's import (0.05-0.07 s of ``ctui export``). The same
    pattern as ``mesh.jit.start_target``: the import is answered "absent" for that moment."""
    import sys
    import threading

    if "pydicom" in sys.modules or "requests" in sys.modules or threading.current_thread() is not threading.main_thread():
        import pydicom

        return pydicom
    sys.modules["requests"] = None  # type: ignore[assignment]  # "import requests" -> ImportError
    try:
        import pydicom
    finally:
        if sys.modules.get("requests", 0) is None:
            del sys.modules["requests"]
    return pydicom


def _read_headers(path: Path) -> list[Any]:
    import_pydicom()  # a CtuiError naming the missing package
    from pydicom.errors import InvalidDicomError

    files = sorted(f for f in path.rglob("*") if f.is_file()) if path.is_dir() else [path]
    out = []
    for f in files:
        if f.suffix.lower() in (".json", ".txt", ".md", ".png", ".jpg", ".nrrd", ".nii", ".gz", ".csv"):
            continue
        try:
            ds = bounded_dcmread(f, stop_before_pixels=True)  # a deflated file inflated within a bound
        except (InvalidDicomError, OSError, ValueError, EOFError, TypeError, AttributeError, KeyError):
            continue
        if "SOPInstanceUID" not in ds or str(ds.get("SOPClassUID", "")) in _NOT_IMAGES:
            continue
        ds.filename = str(f)
        out.append(ds)
    return out


def _wanted_series(volume: Any, series: str | None, groups: dict[str, list[Any]], path: Path) -> str:
    if series:
        key = str(series).strip()
        if key in groups:
            return key
        if key.startswith("(no SeriesInstanceUID)") and "" in groups:  # the loader's name for a UID-less series
            return ""
        listed = getattr(volume, "series", None) or []  # a Volume lists its series; a Geometry does not
        if key.isdigit() and int(key) < len(listed):
            return str(listed[int(key)].get("uid"))
        if key.isdigit() and len(groups) == 1 and int(key) == 0:
            return next(iter(groups))
        hits = [u for u in groups if u.startswith(key)]
        if len(hits) == 1:
            return hits[0]
        raise CtuiError(f"no series {key!r} among {len(groups)} found", path=path)
    listed = getattr(volume, "series", None) or []
    if listed:
        idx = int((getattr(volume, "meta", None) or {}).get("series_index", 0) or 0)
        uid = listed[min(idx, len(listed) - 1)].get("uid")
        if uid in groups:
            return str(uid)
    return max(groups, key=lambda u: len(groups[u]))


def _normal(ds: Any) -> np.ndarray:
    iop = np.asarray([float(v) for v in ds.ImageOrientationPatient], dtype=np.float64)
    return np.cross(iop[:3], iop[3:])


def source_datasets(path: str | os.PathLike, volume: Any = None, *, series: str | None = None) -> list[Any]:
    """The headers (pydicom Datasets, no pixel data) of a series' images, in volume slice order.

    Parameters
    ----------
    path : folder or file of the DICOM series the labels were drawn on.
    volume : Volume, optional
        What ctui loaded from ``path``; when given, the series it picked is used and every
        slice is checked to sit where the volume's geometry puts it (within 1% of a voxel).
    series : SeriesInstanceUID (or a unique prefix, or an index) when ``path`` holds several.

    Returns
    -------
    list of Dataset: one per slice (slice 0 lowest along the slice normal), or a single
    multi-frame dataset.

    Raises
    ------
    CtuiError
        No DICOM image at ``path``, images without position/orientation, or a volume
        whose grid is not the series' own (resampled, cropped, downsampled, tilt-corrected).
    """
    p = Path(path)
    if not p.exists():
        raise CtuiError("the source series is not there (give its folder)", path=p, option="series")
    headers = _read_headers(p)
    if not headers:
        raise CtuiError("no DICOM image found: DICOM-SEG and RTSTRUCT need the DICOM series the labels were drawn on",
                        path=p)
    groups: dict[str, list[Any]] = {}
    for ds in headers:
        groups.setdefault(str(ds.get("SeriesInstanceUID", "")), []).append(ds)
    dss = groups[_wanted_series(volume, series, groups, p)]
    if len(dss) == 1 and int(dss[0].get("NumberOfFrames", 1) or 1) > 1:
        return dss  # one multi-frame image: highdicom reads its per-frame positions
    for ds in dss:
        if "ImagePositionPatient" not in ds or "ImageOrientationPatient" not in ds:
            raise CtuiError(f"{ds.filename}: no ImagePositionPatient/ImageOrientationPatient: a DICOM-SEG or RTSTRUCT "
                            "cannot place its voxels on this series", path=p)
    normal = _normal(dss[0])
    dss.sort(key=lambda d: float(np.dot([float(v) for v in d.ImagePositionPatient], normal)))
    if volume is not None:
        _check_grid(dss, volume, p)
    return dss


def _check_grid(dss: list[Any], volume: Any, p: Path) -> None:
    nz, ny, nx = volume.shape
    d0 = dss[0]
    if len(dss) != nz or (int(d0.Rows), int(d0.Columns)) != (ny, nx):
        raise CtuiError(f"the series has {len(dss)} slices of {int(d0.Rows)}x{int(d0.Columns)}, the labels' grid is "
                        f"{nz}x{ny}x{nx}: DICOM-SEG/RTSTRUCT need labels on the series' own grid (not cropped, "
                        "downsampled or resampled)", path=p)
    tol = 0.01 * min(volume.spacing) + 1e-3
    for k, ds in enumerate(dss):
        ipp = np.asarray([float(v) for v in ds.ImagePositionPatient])
        want = volume.index_to_mm((k, 0, 0))
        if np.abs(ipp - want).max() > tol:
            raise CtuiError(f"slice {k} of the series is at {np.round(ipp, 3).tolist()} mm, the labels' grid puts it at "
                            f"{np.round(want, 3).tolist()} mm (the volume was resampled or tilt-corrected): "
                            "DICOM-SEG/RTSTRUCT need the series' own grid", path=p)


def blank_identifiers(ds: Any, *, keep: bool = False) -> Any:
    """Empty the type-2 patient identifiers and drop the other identifying attributes (in place)."""
    if keep:
        return ds
    ids = [str(ds.get(kw) or "") for kw in (*TYPE2_IDENTIFIERS, "OtherPatientIDs")]
    scrub_dataset_text(ds, ids)  # a StudyDescription copied from the source may hold the name
    for kw in TYPE2_IDENTIFIERS:
        if kw in ds:
            setattr(ds, kw, "")
    for elem in list(ds):
        kw = elem.keyword
        if kw and kw not in TYPE2_IDENTIFIERS and is_identifying(kw):
            del ds[elem.tag]
    return ds


# =========================================================================== write
def _objects_in(labels: np.ndarray, objects: Sequence[dict] | None,
                masks: dict[int, np.ndarray] | None = None) -> list[dict]:
    """{id, name, color} of the objects present in ``labels`` or in ``masks`` (objects whose own
    mask overlaps others, possibly hidden in the label map), ascending ids."""
    present = set(present_ids(labels))
    present |= {int(k) for k, m in (masks or {}).items() if m.any()}
    info = {int(o["id"]): o for o in (objects or []) if "id" in o}
    out = []
    for oid in sorted(present):
        o = info.get(oid, {})
        color = tuple(int(c) for c in o.get("color", object_color(oid)))[:3]
        out.append({"id": oid, "name": str(o.get("name") or f"object {oid}"), "color": color})
    return out


def _segment_description(n: int, obj: dict) -> Any:
    import highdicom as hd
    from pydicom.sr.codedict import codes

    return hd.seg.SegmentDescription(
        segment_number=n,
        segment_label=obj["name"][:64],
        segmented_property_category=codes.SCT.Tissue,
        segmented_property_type=codes.SCT.Tissue,
        algorithm_type=hd.seg.SegmentAlgorithmTypeValues.SEMIAUTOMATIC,
        algorithm_identification=hd.AlgorithmIdentificationSequence(
            name="ctui", family=codes.cid7162.NeighborhoodAnalysis, version=__version__),
        display_color=hd.color.CIELabColor.from_rgb(*obj["color"]),
    )


def write_seg(path: str | os.PathLike, labels: np.ndarray, sources: Sequence[Any], *,
              objects: Sequence[dict] | None = None, keep_identifiers: bool = False,
              series_description: str = "ctui segmentation", masks: dict[int, np.ndarray] | None = None,
              progress: Progress | None = None) -> Path:
    """Write ``labels`` as a BINARY DICOM-SEG over the source images.

    Parameters
    ----------
    path : target ``.dcm`` file (written atomically).
    labels : ndarray (z, y, x) uint8, 0 background, object ids 1..255; on the series' grid.
    sources : the series' headers from :func:`source_datasets` (slice order).
    objects : dicts with ``id``, ``name``, ``color`` (r, g, b 0..255), as in a project.
    keep_identifiers : keep the patient name/ID/birth date copied from the source.
    masks : {object id: bool (z, y, x)} full masks of objects that overlap others (imported
        segments): then every segment is written from its own mask, overlaps kept.

    Returns the written path. Raises CtuiError when ``labels`` holds no object. Single-frame
    source images: built with pydicom (:mod:`ctui.engine.io.segwriter`); one multi-frame
    source image: with highdicom.
    """
    require_references(sources, what="DICOM-SEG", path=path)  # never invents the UIDs it points at
    require_planes(sources, path)  # nor writes geometry no reader accepts
    lab = np.asarray(labels)
    masks = masks or {}
    objs = _objects_in(lab, objects, masks)
    if not objs:
        raise CtuiError("no object in the labels: nothing to write", path=path)
    report(progress, 0.05, 1.0, "DICOM-SEG: segments")
    if masks:  # overlapping segments: one bool plane per segment (S x the volume, only for such imports)
        seg_array = np.stack([masks[o["id"]] if o["id"] in masks else lab == o["id"] for o in objs], axis=-1)
    else:
        lut = np.zeros(256, np.uint8)
        for n, o in enumerate(objs, start=1):
            lut[o["id"]] = n
        # ids 1..N already are the segment numbers (objs: every id present): no relabelled copy
        same = all(o["id"] == n for n, o in enumerate(objs, start=1)) and lab.dtype == np.uint8
        seg_array = lab if same else lut[lab]
    if len(sources) == 1 and seg_array.shape[0] > 1:
        seg_array = _multiframe_order(seg_array, sources[0])
    report(progress, 0.2, 1.0, "DICOM-SEG: frames")
    if int(sources[0].get("NumberOfFrames", 1) or 1) == 1:  # single-frame images: pydicom alone (segwriter)
        from ctui.engine.io.segwriter import build_seg  # loaded with its format

        try:
            seg = build_seg(seg_array, sources, objs, series_description=series_description, version=__version__)
        except (ValueError, TypeError, AttributeError, KeyError, IndexError) as exc:  # a source lacks an attribute
            raise CtuiError(f"cannot write a DICOM-SEG over this series ({' '.join(str(exc).split())[:200]})",
                            path=getattr(sources[0], "filename", None)) from None
        return _save(seg, path, keep_identifiers, progress)
    import highdicom as hd

    descs = [_segment_description(n, o) for n, o in enumerate(objs, start=1)]
    try:
        seg = hd.seg.Segmentation(
            source_images=_prepared(sources, keep_identifiers), pixel_array=seg_array,
            segmentation_type=hd.seg.SegmentationTypeValues.BINARY, segment_descriptions=descs,
            series_instance_uid=hd.UID(), series_number=int(getattr(sources[0], "SeriesNumber", 0) or 0) + 1000,
            sop_instance_uid=hd.UID(), instance_number=1, manufacturer="ctui", manufacturer_model_name="ctui",
            software_versions=__version__, device_serial_number="0", series_description=series_description[:64],
            content_label="CTUI", content_description="ctui segmentation", omit_empty_frames=True,
        )
    except (ValueError, TypeError, AttributeError, KeyError) as exc:  # highdicom's checks of the source images
        raise CtuiError(f"cannot write a DICOM-SEG over this series ({' '.join(str(exc).split())[:200]})",
                        path=getattr(sources[0], "filename", None)) from None
    return _save(seg, path, keep_identifiers, progress)


def _save(seg: Any, path: str | os.PathLike, keep_identifiers: bool, progress: Progress | None) -> Path:
    blank_identifiers(seg, keep=keep_identifiers)
    report(progress, 0.9, 1.0, "DICOM-SEG: writing")
    p = Path(path)
    try:
        with atomic_path(p) as tmp:
            seg.save_as(str(tmp), enforce_file_format=True)
    except (ValueError, TypeError, OverflowError, KeyError, struct.error) as exc:  # a source value pydicom cannot encode
        raise CtuiError(f"cannot write the DICOM-SEG: {write_fault(exc)}", path=p) from None
    report(progress, 1.0, 1.0, "DICOM-SEG written")
    return p


def _prepared(sources: Sequence[Any], keep: bool) -> list[Any]:
    """The sources with the patient/study attributes highdicom copies present (blank unless ``keep``).

    Only the first image's patient and study modules are copied, so only it is changed (a copy).
    """
    first = copy.deepcopy(sources[0])
    for kw in (*TYPE2_IDENTIFIERS, "StudyDate", "StudyTime"):
        if kw not in first:
            setattr(first, kw, "")
    if "SpecificCharacterSet" in first and not first.SpecificCharacterSet:
        del first.SpecificCharacterSet  # empty (default repertoire): highdicom refuses '' as a value
    blank_identifiers(first, keep=keep)
    return [first, *sources[1:]]


def _multiframe_order(seg_array: np.ndarray, ds: Any) -> np.ndarray:
    """Reorder slice-ordered labels into the frame order of one multi-frame source image."""
    try:
        pffg = ds.PerFrameFunctionalGroupsSequence
        iop = ds.SharedFunctionalGroupsSequence[0].PlaneOrientationSequence[0].ImageOrientationPatient
        normal = np.cross(np.asarray(iop[:3], float), np.asarray(iop[3:], float))
        pos = [float(np.dot(np.asarray(f.PlanePositionSequence[0].ImagePositionPatient, float), normal)) for f in pffg]
    except (AttributeError, IndexError, KeyError):
        return seg_array
    rank = np.argsort(np.argsort(pos, kind="stable"), kind="stable")  # frame i holds slice rank[i]
    if len(rank) != seg_array.shape[0]:
        raise CtuiError(f"the multi-frame source has {len(rank)} frames, the labels {seg_array.shape[0]} slices")
    return seg_array[rank]


# =========================================================================== read
@dataclass
class SegSegment:
    """One segment: ``number`` (SEG segment number), ``label``, ``color`` RGB 0..255, ``algorithm_type``."""

    number: int
    label: str
    color: tuple[int, int, int] | None = None
    algorithm_type: str = ""


@dataclass
class SegContents:
    """A DICOM-SEG read back.

    Each segment's voxels are kept as a bounding box on ``geometry`` (ctui convention: slice
    axis along row x column) and the bool crop inside it (memory grows with the objects,
    not with the number of segments times the volume); :meth:`mask` gives one segment's
    full mask. ``referenced_instances`` lists the SOPInstanceUIDs of the source images the
    SEG references; ``referenced_series`` their SeriesInstanceUID(s).
    """

    segments: list[SegSegment]
    geometry: Geometry
    segmentation_type: str
    boxes: list[tuple[slice, slice, slice] | None] = field(default_factory=list)
    crops: list[np.ndarray | None] = field(default_factory=list)
    frame_of_reference: str = ""
    referenced_series: list[str] = field(default_factory=list)
    referenced_instances: list[str] = field(default_factory=list)
    number_of_frames: int = 0
    warnings: list[str] = field(default_factory=list)

    def mask(self, k: int) -> np.ndarray:
        """Segment ``k`` (index into ``segments``) as bool (z, y, x) on ``geometry``."""
        out = np.zeros(self.geometry.shape, dtype=bool)
        if self.boxes[k] is not None:
            out[self.boxes[k]] = self.crops[k]
        return out

    def voxel_counts(self) -> list[int]:
        return [0 if c is None else int(np.count_nonzero(c)) for c in self.crops]


def _rgb(desc: Any) -> tuple[int, int, int] | None:
    lab = desc.get("RecommendedDisplayCIELabValue")
    if lab is None:
        return None
    import highdicom as hd

    try:
        return tuple(int(c) for c in hd.color.CIELabColor.from_dicom_value(list(lab)).to_rgb(clip=True))
    except (ValueError, TypeError):
        return None


def geometry_from_hd(affine: np.ndarray, shape: Sequence[int]) -> tuple[Geometry, bool]:
    """ctui Geometry of a highdicom volume (affine on (slice, row, column) indices).

    Returns (geometry, flipped): ``flipped`` True when the slice axis was reversed so that
    slice 0 is the lowest along row x column (ctui's convention); flip the array's axis 0.
    """
    a = np.asarray(affine, dtype=np.float64)
    cols = a[:3, :3]
    sp = np.linalg.norm(cols, axis=0)  # (dz, dy, dx)
    dirs = cols / sp[None, :]
    row_dir, col_dir, slice_dir = dirs[:, 2], dirs[:, 1], dirs[:, 0]
    origin = a[:3, 3].copy()
    flipped = bool(np.dot(np.cross(row_dir, col_dir), slice_dir) < 0)
    if flipped:
        origin = origin + (int(shape[0]) - 1) * sp[0] * slice_dir
        slice_dir = -slice_dir
    direction = np.column_stack([row_dir, col_dir, slice_dir])
    return Geometry(tuple(int(s) for s in shape[:3]), tuple(sp), tuple(origin), direction), flipped


def _crop(mask: np.ndarray) -> tuple[tuple[slice, slice, slice] | None, np.ndarray | None]:
    if not mask.any():
        return None, None
    box = tuple(slice(int(ix[0]), int(ix[-1]) + 1) for ix in
                (np.flatnonzero(mask.any(axis=(1, 2))), np.flatnonzero(mask.any(axis=(0, 2))),
                 np.flatnonzero(mask.any(axis=(0, 1)))))
    return box, mask[box].copy()  # type: ignore[return-value]  # box: tuple() of a generator: mypy sees any length, the length is fixed by construction


def _orphan_frames(seg: Any, numbers: set[int]) -> list[str]:
    """A warning when frames point at a segment the SEG does not describe: they are left out
    (they were, without a word)."""
    bad = 0
    for fg in seg.get("PerFrameFunctionalGroupsSequence", None) or []:
        sis = fg.get("SegmentIdentificationSequence")
        if sis and int(sis[0].get("ReferencedSegmentNumber", 0) or 0) not in numbers:
            bad += 1
    return [f"{bad} frames point at a segment the file does not describe: left out"] if bad else []


def _check_frames(p: Path) -> None:
    """Refuse a SEG whose NumberOfFrames its pixel data or per-frame groups contradict,
    before highdicom builds per-frame tables for it (NumberOfFrames 2**31-1 in a 130 KB
    file: > 6 GB), and check one frame stack against the memory available."""
    try:
        ds = bounded_dcmread(str(p), defer_size=1024, force=True)
        nf = int(ds.get("NumberOfFrames", 1) or 1)
        rows, cols = int(ds.get("Rows", 0) or 0), int(ds.get("Columns", 0) or 0)
        bits = int(ds.get("BitsAllocated", 1) or 1)
        pffg = ds.get("PerFrameFunctionalGroupsSequence")
        elem = ds.get_item("PixelData") if "PixelData" in ds else None
        length = int(getattr(elem, "length", 0) or 0) if elem is not None else 0
        size = p.stat().st_size
    except Exception:  # noqa: BLE001 - not a readable DICOM file: highdicom reports it below
        return
    if nf < 1 or rows < 1 or cols < 1:
        raise FormatError(f"NumberOfFrames {nf}, Rows {rows}, Columns {cols}: not a segmentation's frames", path=p)
    if pffg is not None and len(pffg) != nf:
        raise FormatError(f"NumberOfFrames {nf} but {len(pffg)} per-frame functional groups: the DICOM-SEG is "
                          "inconsistent", path=p)
    if length in (0, 0xFFFFFFFF):  # encapsulated: each frame takes at least an 8-byte item
        if nf * 8 > size:
            raise FormatError(f"NumberOfFrames {nf} cannot fit in a file of {size} bytes", path=p)
    else:
        need = (nf * rows * cols * max(bits, 1) + 7) // 8
        if length < need:
            raise FormatError(f"NumberOfFrames {nf} of {rows}x{cols} needs {need} bytes of pixel data, the file "
                              f"holds {length}", path=p)
    check_allocation(2 * nf * rows * cols * max(bits // 8, 1), what="a DICOM-SEG's frames", path=p)


def _read_one(seg: Any, n: int, fractional: bool, out: SegContents) -> None:
    """Decode segment ``n`` alone (a full volume) and keep its crop in ``out``."""
    vol = seg.get_volume(segment_numbers=[n], combine_segments=False, dtype=np.float32 if fractional else np.uint8)
    arr = np.asarray(vol.array)
    arr = arr[..., 0] if arr.ndim == 4 else arr
    out.geometry, flipped = geometry_from_hd(vol.affine, arr.shape[:3])
    mask = arr >= 0.5 if fractional else arr != 0
    box, crop = _crop(mask[::-1] if flipped else mask)
    out.boxes.append(box)
    out.crops.append(crop)


def _read_combined(seg: Any, numbers: list[int], out: SegContents) -> bool:
    """Non-overlapping segments (numbers <= 255) decoded in one highdicom call as one label map
    and cropped in one pass (``ndimage.find_objects``): a 255-segment SEG took one full volume
    decode and three passes per segment (a minute on a real series). False when the segments
    overlap (highdicom's RuntimeError): the caller reads them one by one."""
    from scipy import ndimage

    try:
        vol = seg.get_volume(segment_numbers=numbers, combine_segments=True, relabel=False, dtype=np.uint8)
    except RuntimeError:  # overlapping segments cannot share one label map
        return False
    arr = np.asarray(vol.array)
    arr = arr[..., 0] if arr.ndim == 4 else arr
    out.geometry, flipped = geometry_from_hd(vol.affine, arr.shape[:3])
    lab = arr[::-1] if flipped else arr
    boxes = ndimage.find_objects(lab, max_label=255)
    for n in numbers:
        box = boxes[n - 1]
        out.boxes.append(box)
        out.crops.append(None if box is None else lab[box] == n)
    return True


def read_seg(path: str | os.PathLike) -> SegContents:
    """Read a DICOM-SEG (BINARY, FRACTIONAL thresholded at half, or LABELMAP), one segment at a time.

    Overlapping BINARY segments are kept apart: one mask per segment. A LABELMAP's
    segment 0 (background) is left out. Raises FormatError for a file that is not a SEG
    or whose frames do not form a regular volume. Peak memory: one volume of the SEG's
    grid (1 byte a voxel, 4 for FRACTIONAL) plus the segments' crops.
    """
    import highdicom as hd

    p = Path(path)
    _check_frames(p)
    try:
        seg = hd.seg.segread(str(p))
        numbers = [int(n) for n in seg.segment_numbers if n != 0]  # a LABELMAP's 0 is its background
        if not numbers:
            raise FormatError("the DICOM-SEG holds no segment", path=p)
        fractional = str(seg.SegmentationType) == "FRACTIONAL"
        # one segment's volume (at most a slice per frame) and its crop, before highdicom allocates it
        check_allocation(2 * int(seg.Rows) * int(seg.Columns) * max(int(seg.get("NumberOfFrames", 1) or 1), 1)
                         * (4 if fractional else 1), what="a DICOM-SEG segment volume", path=p)
        out = SegContents([], Geometry((1, 1, 1)), str(seg.SegmentationType),
                          frame_of_reference=str(seg.get("FrameOfReferenceUID", "")),
                          number_of_frames=int(seg.get("NumberOfFrames", 0) or 0))
        if fractional or max(numbers) > 255 or not _read_combined(seg, numbers, out):
            for n in numbers:  # overlapping (or fractional) segments: one full volume each, kept apart
                _read_one(seg, n, fractional, out)
        for n in numbers:
            d = seg.get_segment_description(n)
            out.segments.append(SegSegment(number=n, label=str(d.get("SegmentLabel", "")), color=_rgb(d),
                                           algorithm_type=str(d.get("SegmentAlgorithmType", ""))))
        refs = seg.get_source_image_uids()
        out.warnings += _orphan_frames(seg, set(numbers))
    except CtuiError:
        raise
    except MemoryError:
        raise FormatError("not enough memory to read this DICOM-SEG", path=p) from None
    except Exception as exc:  # noqa: BLE001 - pydicom/highdicom raise many types on foreign or broken files
        raise FormatError(f"not a readable DICOM-SEG or its frames do not form a regular volume "
                          f"({type(exc).__name__}: {' '.join(str(exc).split())[:160]})", path=p) from None
    out.referenced_series = sorted({str(r[1]) for r in refs})
    out.referenced_instances = [str(r[2]) for r in refs]
    return out
