"""Read any label file over a series: DICOM-SEG, RTSTRUCT, NIfTI / NRRD label maps.

:func:`read_label_file` returns :class:`ImportedLabels`: a uint8 label map (z, y, x) on
the series' grid (or on the file's own grid when no series is given and the file has
one), one object per segment / ROI / label value with its name and colour, and the
warnings met on the way.

Geometry check
--------------
The file's voxel grid is mapped onto the series' grid through both affines. It is
accepted when every file voxel lands on a series voxel: same spacing and orientation up
to axis order and flips, an offset of whole voxels (a DICOM-SEG with frames only where
the objects are, a label map cropped to a box, a flipped NIfTI), and nothing outside
the series. Anything else is refused with a message that says how the grids differ and
what to do (resample the label map onto the series, or pick the series it was drawn on).

Overlapping segments
--------------------
A BINARY DICOM-SEG (or an RTSTRUCT) may hold overlapping segments. Each becomes one
object (id = its segment / ROI number when all fit 1..255, else 1..S in order). The
label map, one value per voxel, gives an overlapped voxel to the **later** segment, with
a warning naming the pairs and voxel counts; ``masks`` keeps every overlapping segment's
own full mask, so measuring an object (:meth:`ImportedLabels.mask`) uses all its voxels.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.core.colors import object_color
from ctui.engine.core.errors import CtuiError, FormatError
from ctui.engine.core.geometry import Geometry
from ctui.engine.io.labels import load_labels
from ctui.engine.io.series.dicom_deflate import dcmread as bounded_dcmread
from ctui.engine.io.suffixes import GIPL_SUFFIXES, NIFTI_SUFFIXES, NRRD_SUFFIXES

KINDS = ("dicom-seg", "rtstruct", "nifti", "nrrd", "gipl")


@dataclass
class ImportedLabels:
    """Labels read from a file, placed on a grid.

    Attributes
    ----------
    labels : ndarray (z, y, x) uint8 on ``geometry`` (0 background).
    objects : list of dict ``{"id", "name", "color" (r, g, b 0..255), "source_number"}``.
    geometry : Geometry of ``labels`` (the series' when one was given).
    kind : "dicom-seg", "rtstruct", "nifti", "nrrd" or "gipl".
    masks : {object id: bool (z, y, x)} full masks of objects that overlap others.
    warnings : list of str.
    path : the file read.
    """

    labels: np.ndarray
    objects: list[dict]
    geometry: Geometry
    kind: str
    masks: dict[int, np.ndarray] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    path: str = ""

    def mask(self, object_id: int) -> np.ndarray:
        """The object's full bool mask (z, y, x), overlaps included."""
        m = self.masks.get(int(object_id))
        return m if m is not None else self.labels == int(object_id)

    def voxel_counts(self) -> dict[int, int]:
        """{object id: voxels of its full mask}."""
        return {int(o["id"]): int(np.count_nonzero(self.mask(o["id"]))) for o in self.objects}


# =========================================================================== sniffing
def label_kind(path: str | os.PathLike) -> str:
    """'dicom-seg', 'rtstruct', 'nifti' or 'nrrd' for a label file; FormatError otherwise."""
    p = Path(path)
    name = p.name.lower()
    if name.endswith(NIFTI_SUFFIXES):
        return "nifti"
    if name.endswith(NRRD_SUFFIXES):
        return "nrrd"
    if p.is_dir():
        raise FormatError("is a folder: give the label file (DICOM-SEG, RTSTRUCT, .nii, .nii.gz, .nrrd)", path=p)

    try:
        ds = bounded_dcmread(str(p), stop_before_pixels=True, specific_tags=["SOPClassUID", "Modality"])
    except Exception as exc:  # noqa: BLE001 - pydicom raises many types (struct.error...) on foreign/broken files
        raise FormatError(f"not a label file: expected DICOM-SEG, RTSTRUCT, .nii, .nii.gz or .nrrd "
                          f"({' '.join(str(exc).split())[:120]})", path=p) from None
    from ctui.engine.io.dicomseg import RTSTRUCT_SOP_CLASS, SEG_SOP_CLASS  # DICOM label readers

    uid, modality = str(ds.get("SOPClassUID", "")), str(ds.get("Modality", ""))
    if uid == SEG_SOP_CLASS or modality == "SEG":
        return "dicom-seg"
    if uid == RTSTRUCT_SOP_CLASS or modality == "RTSTRUCT":
        return "rtstruct"
    raise FormatError(f"a DICOM {modality or 'file'} is not a segmentation (expected a SEG or an RTSTRUCT)", path=p)


def is_label_file(path: str | os.PathLike) -> bool:
    """True for a DICOM-SEG/RTSTRUCT file or a NIfTI/NRRD name (cheap; no full read)."""
    try:
        label_kind(path)
    except (FormatError, OSError):
        return False
    return True


# =========================================================================== geometry
def _fmt(v: Any) -> str:
    return "(" + ", ".join(f"{float(x):.4g}" for x in np.ravel(v)) + ")"


def describe_mismatch(src: Geometry, dst: Geometry) -> str:
    """How the grid ``src`` (a label file) differs from ``dst`` (the series), in words."""
    diffs = []
    if tuple(src.shape) != tuple(dst.shape):
        diffs.append(f"shape (z, y, x) {list(src.shape)} vs the series' {list(dst.shape)}")
    if not np.allclose(sorted(src.spacing), sorted(dst.spacing), rtol=1e-3, atol=1e-4):
        diffs.append(f"spacing (z, y, x) {_fmt(src.spacing)} mm vs {_fmt(dst.spacing)} mm")
    if not np.allclose(np.abs(np.round(src.direction.T @ dst.direction, 3)).max(axis=1), 1.0, atol=1e-3):
        diffs.append("orientation differs (the axes are not parallel to the series')")
    off = np.asarray(src.origin) - np.asarray(dst.origin)
    if np.abs(off).max() > 1e-3:
        diffs.append(f"origin {_fmt(src.origin)} vs {_fmt(dst.origin)} mm (offset {_fmt(off)} mm)")
    return "; ".join(diffs) or "the voxels do not line up"


def _refuse(path: Any, src: Geometry, dst: Geometry, why: str) -> CtuiError:
    return CtuiError(f"does not fit the series: {why}: {describe_mismatch(src, dst)}. Resample the label map onto "
                     "the series (e.g. 3D Slicer 'Resample Image (BRAINS)' with the series as reference) or give the "
                     "series it was drawn on", path=path, option="series")


def place_on_grid(arr: np.ndarray, src: Geometry, dst: Geometry, *, path: Any = None, tol: float = 0.02,
                  same_shape: bool = False) -> np.ndarray:
    """Put ``arr`` ((..., z, y, x) on ``src``) onto the grid ``dst``: returns (..., *dst.shape).

    Accepted: same voxel size and axes up to order and flips, whole-voxel offsets, and
    nothing non-zero outside ``dst``; ``same_shape`` (a whole label map, not a SEG's
    frames): the grid's size must be the series' too (axes reordered). Raises CtuiError
    (with :func:`describe_mismatch`) otherwise.
    """
    m = np.linalg.inv(dst.affine) @ src.affine  # src (x, y, z, 1) -> dst (x, y, z, 1)
    r = np.round(m[:3, :3])
    if np.abs(m[:3, :3] - r).max() > tol or not np.array_equal(np.abs(r).sum(axis=0), np.ones(3)) \
            or not np.array_equal(np.abs(r).sum(axis=1), np.ones(3)):
        raise _refuse(path, src, dst, "voxel size or orientation differ")
    t = m[:3, 3]
    if np.abs(t - np.round(t)).max() > tol:
        raise _refuse(path, src, dst, "the grids are shifted by a fraction of a voxel")
    rz = r[::-1, ::-1]  # in (z, y, x) order
    tz = np.round(t[::-1]).astype(int)
    lead = arr.ndim - 3
    axes = [int(np.flatnonzero(rz[i])[0]) for i in range(3)]
    out_arr = np.transpose(arr, list(range(lead)) + [lead + a for a in axes])
    starts = []
    for i in range(3):
        n = out_arr.shape[lead + i]
        if rz[i, axes[i]] < 0:
            out_arr = np.flip(out_arr, axis=lead + i)
            starts.append(int(tz[i]) - (n - 1))
        else:
            starts.append(int(tz[i]))
    if same_shape and tuple(out_arr.shape[lead:]) != tuple(dst.shape):
        raise _refuse(path, src, dst, f"its shape {tuple(out_arr.shape[lead:])} (z, y, x) is not the series' "
                      f"{tuple(dst.shape)}")
    out = np.zeros(arr.shape[:lead] + tuple(dst.shape), dtype=arr.dtype)
    src_sl, dst_sl = [], []
    for i in range(3):
        n, N, s = out_arr.shape[lead + i], dst.shape[i], starts[i]
        lo, hi = max(s, 0), min(s + n, N)
        if hi <= lo:
            raise _refuse(path, src, dst, "the label map lies entirely outside the series")
        src_sl.append(slice(lo - s, hi - s))
        dst_sl.append(slice(lo, hi))
    lead_sl = (slice(None),) * lead
    inside = out_arr[lead_sl + tuple(src_sl)]
    if np.count_nonzero(inside) != np.count_nonzero(out_arr):
        raise _refuse(path, src, dst, "labelled voxels lie outside the series")
    out[lead_sl + tuple(dst_sl)] = inside
    return out


# =========================================================================== assembling
def _ids(numbers: Sequence[int]) -> list[int]:
    nums = [int(n) for n in numbers]
    if nums and all(1 <= n <= 255 for n in nums) and len(set(nums)) == len(nums):
        return nums
    if len(nums) > 255:
        raise CtuiError(f"{len(nums)} segments: ctui holds at most 255 objects")
    return list(range(1, len(nums) + 1))


def assemble(mask_of: Callable[[int], np.ndarray], numbers: Sequence[int], names: Sequence[str],
             colors: Sequence[Any]) -> tuple[np.ndarray, list[dict], dict[int, np.ndarray], list[str]]:
    """One label map from per-segment masks: later segments win overlaps (see module docstring).

    ``mask_of(k)`` gives segment k's full bool mask on the target grid; it is called once
    per segment, and once more for the segments that overlap another (their masks are
    kept), so memory stays at the label map plus one mask, plus the overlapping ones.
    Returns (labels uint8, objects, masks of overlapping objects, warnings).
    """
    ids = _ids(numbers)
    labels: np.ndarray | None = None
    objects, involved = [], set()
    for k, oid in enumerate(ids):
        m = mask_of(k)
        if labels is None:
            labels = np.zeros(m.shape, np.uint8)
        under = labels[m]
        hit = np.flatnonzero(np.bincount(under, minlength=256)[1:]) + 1
        if hit.size:
            involved |= {oid, *(int(h) for h in hit)}
        labels[m] = oid
        color = tuple(int(c) for c in colors[k]) if colors[k] is not None else object_color(oid)
        objects.append({"id": oid, "name": names[k] or f"object {oid}", "color": list(color),
                        "source_number": int(numbers[k])})
    assert labels is not None
    overlapping = {oid: np.ascontiguousarray(mask_of(k)) for k, oid in enumerate(ids) if oid in involved}
    warnings = []
    if overlapping:
        name = {o["id"]: o["name"] for o in objects}
        keys = sorted(overlapping, key=ids.index)
        pairs = [f"{name[a]}/{name[b]} {n}" for i, a in enumerate(keys) for b in keys[i + 1:]
                 if (n := int(np.count_nonzero(overlapping[a] & overlapping[b])))]
        warnings.append("overlapping segments (voxels): " + ", ".join(pairs) + "; the label map shows the later "
                        "segment there, measurements use each segment's own mask")
    return labels, objects, overlapping, warnings


# =========================================================================== readers
def _from_seg(p: Path, grid: Geometry | None, frame_of_reference: str = "",
              instances: Collection[str] = ()) -> ImportedLabels:
    from ctui.engine.io.dicomseg import read_seg  # DICOM label readers: loaded for a DICOM-SEG/RTSTRUCT only

    c = read_seg(p)
    c.warnings[:0] = _seg_reference_warnings(c, frame_of_reference, instances)
    geom = grid if grid is not None else c.geometry

    def mask_of(k: int) -> np.ndarray:
        m = c.mask(k)
        return m if grid is None else place_on_grid(m, c.geometry, grid, path=p)

    labels, objects, overlap, warnings = assemble(mask_of, [s.number for s in c.segments],
                                                  [s.label for s in c.segments], [s.color for s in c.segments])
    return ImportedLabels(labels, objects, geom, "dicom-seg", overlap, c.warnings + warnings, str(p))


def _from_rtstruct(p: Path, grid: Geometry | None, frame_of_reference: str = "") -> ImportedLabels:
    from ctui.engine.io.rtstruct import read_rtstruct, roi_mask  # DICOM label readers

    if grid is None:
        raise CtuiError("an RTSTRUCT holds contours only: open it as labels over the series it was drawn on",
                        path=p, option="labels")
    c = read_rtstruct(p)
    if not c.rois:
        raise FormatError("the RTSTRUCT holds no ROI (empty or cut short)", path=p)
    warnings = _frame_warnings(c, frame_of_reference)
    placed = {"any": False}
    voxel_ml = float(np.prod(grid.spacing)) / 1000.0

    def mask_of(k: int) -> np.ndarray:
        roi = c.rois[k]
        m, info = roi_mask(roi, grid)
        placed["any"] |= bool(m.any())
        if any(w.startswith(f"ROI {roi.name}:") for w in warnings):
            return m  # called again for overlapping ROIs: said once
        notes = []
        if info.off_slice:
            notes.append(f"{info.off_slice} contours are not on a slice of the series and were left out")
        if info.outside_slices:
            lost = f"{info.outside_voxels} voxels ({info.outside_voxels * voxel_ml:.1f} mL)" if info.outside_voxels \
                else "parts"
            notes.append(f"contours reach beyond the image on {info.outside_slices} slices: {lost} outside the "
                         f"series were cut off (the object measures {int(m.sum()) * voxel_ml:.1f} mL inside)")
        for why, n in sorted(roi.left_out.items()):
            notes.append(f"{n} {why} contours (points or lines, not areas) were left out" if why.isupper() else
                         f"{n} contours with {why} were left out")
        if notes:
            warnings.append(f"ROI {roi.name}: " + "; ".join(notes))
        return m

    labels, objects, overlap, w = assemble(mask_of, [r.number for r in c.rois], [r.name for r in c.rois],
                                           [r.color for r in c.rois])
    if not placed["any"]:
        raise CtuiError("no contour of the RTSTRUCT lies on a slice of the series: it was drawn on another series",
                        path=p)
    return ImportedLabels(labels, objects, grid, "rtstruct", overlap, warnings + w, str(p))


def _frame_warnings(c: Any, frame_of_reference: str) -> list[str]:
    """A warning when the RTSTRUCT's (or an ROI's) Frame of Reference UID is not the series'."""
    if not frame_of_reference:
        return []
    theirs = {u for u in [c.frame_of_reference, *(r.frame_of_reference for r in c.rois)] if u}
    other = sorted(theirs - {frame_of_reference})
    if not other:
        return []
    return [f"Frame of Reference mismatch: the RTSTRUCT's contours are in {', '.join(other)[:120]}, the series is "
            f"in {frame_of_reference}: positions may not correspond (check it was drawn on this series)"]


def _seg_reference_warnings(c: Any, frame_of_reference: str, instances: Collection[str]) -> list[str]:
    """Warnings when a DICOM-SEG references another Frame of Reference or other images than the
    series it is placed on (its geometry is still checked by place_on_grid: a mismatch is refused)."""
    out = []
    if frame_of_reference and c.frame_of_reference and c.frame_of_reference != frame_of_reference:
        out.append(f"Frame of Reference mismatch: the DICOM-SEG is in {c.frame_of_reference[:64]}, the series is in "
                   f"{frame_of_reference[:64]}: positions may not correspond (check it was made on this series)")
    refs = set(c.referenced_instances)
    if instances and refs and not refs <= set(instances):
        n = len(refs - set(instances))
        out.append(f"the DICOM-SEG references {n} of its {len(refs)} source images outside this series "
                   f"(series {', '.join(c.referenced_series)[:80] or 'unknown'}): it was made on another series")
    return out


def _from_labelmap(p: Path, grid: Geometry | None, kind: str) -> ImportedLabels:
    lab, vol = load_labels(p)
    geom = Geometry.of(vol)
    if grid is not None:
        lab = place_on_grid(lab, geom, grid, path=p, same_shape=True)
        geom = grid
    ids = [int(i) for i in np.flatnonzero(np.bincount(lab.ravel(), minlength=256)) if i != 0]
    names = _nrrd_names(p) if kind == "nrrd" else {}
    described = itksnap_labels(p) if kind == "gipl" else {}
    names.update({i: name for i, (name, _) in described.items()})
    objects = [{"id": i, "name": names.get(i, f"object {i}"),
                "color": list(described[i][1] if i in described else object_color(i)), "source_number": i}
               for i in ids]
    return ImportedLabels(lab, objects, geom, kind, {}, [], str(p))


_ITKSNAP_LINE = re.compile(r'^\s*(\d+)\s+(\d+)\s+(\d+)\s+(\d+)\s+\S+\s+\S+\s+\S+\s+"(.*)"\s*$')


def itksnap_labels(p: Path) -> dict[int, tuple[str, tuple[int, int, int]]]:
    """Names and colours of an ITK-SNAP label description beside the label map (``seg.gipl.gz`` ->
    ``seg.label``: lines ``IDX R G B A VIS MSH "NAME"``), else {}. Read up to 1 MB; other lines skipped."""
    stem = p.name[: -len(".gz")] if p.name.lower().endswith(".gz") else p.name
    desc = p.with_name(stem.rsplit(".", 1)[0] + ".label")
    try:
        if not desc.is_file():
            return {}
        with open(desc, "rb") as fh:
            text = fh.read(1 << 20).decode("utf-8", "replace")
    except OSError:
        return {}
    out: dict[int, tuple[str, tuple[int, int, int]]] = {}
    for line in text.splitlines():
        m = _ITKSNAP_LINE.match(line)
        if m and 0 < int(m[1]) < 256:
            r, g, b = (min(255, int(v)) for v in m.group(2, 3, 4))
            out[int(m[1])] = (m[5][:64], (r, g, b))
    return out


def _nrrd_names(p: Path) -> dict[int, str]:
    """Segment names of a 3D Slicer .seg.nrrd (Segment{i}_Name / _LabelValue), else {}."""
    try:
        import nrrd

        with open(p, "rb") as fh:
            header = nrrd.read_header(fh)
    except Exception:  # noqa: BLE001 - names are a nicety; load_labels already validated the file
        return {}
    out = {}
    for k, v in header.items():
        if k.startswith("Segment") and k.endswith("_Name"):
            pre = k[: -len("Name")]
            try:
                out[int(header.get(pre + "LabelValue", 0))] = str(v)
            except (TypeError, ValueError):
                continue
    return out


def read_label_file(path: str | os.PathLike, *, grid: Any = None, frame_of_reference: str = "",
                    instances: Collection[str] = ()) -> ImportedLabels:
    """Read a label file, placed on ``grid`` (a Volume or Geometry of the series) when given.

    Without ``grid`` the file's own geometry is used (DICOM-SEG, NIfTI, NRRD); an RTSTRUCT
    needs one. ``frame_of_reference``: the series' FrameOfReferenceUID, when known (an
    RTSTRUCT or DICOM-SEG in another frame gets a warning); ``instances``: the series'
    SOPInstanceUIDs, when known (a DICOM-SEG made on other images gets a warning). Raises FormatError (unreadable file) or
    CtuiError (geometry mismatch, said how).
    """
    p = Path(path)
    if not p.exists():
        raise CtuiError("no such label file", path=p)
    g = None if grid is None else Geometry.of(grid)
    if p.name.lower().endswith(GIPL_SUFFIXES):  # ITK-SNAP's label maps (a GIPL alone opens as a volume)
        return _from_labelmap(p, g, "gipl")
    kind = label_kind(p)
    if kind == "dicom-seg":
        return _from_seg(p, g, frame_of_reference, instances)
    if kind == "rtstruct":
        return _from_rtstruct(p, g, frame_of_reference)
    return _from_labelmap(p, g, kind)
