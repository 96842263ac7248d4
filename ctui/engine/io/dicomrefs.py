"""Can a DICOM-SEG or an RTSTRUCT point at this series? Both reference the source images by
UIDs (SOP Class/Instance per image, Series and Study Instance UID, Frame of Reference UID);
a series without them cannot be referenced, and ctui never invents them (a made-up UID
names no image a PACS or a planning system holds: the file would be orphaned)."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import Any

from ctui.engine.core.errors import CtuiError

PER_IMAGE = (("SOPClassUID", "(0008,0016)"), ("SOPInstanceUID", "(0008,0018)"))
SHARED = (("SeriesInstanceUID", "(0020,000E)"), ("StudyInstanceUID", "(0020,000D)"),
          ("FrameOfReferenceUID", "(0020,0052)"))


def missing_references(sources: Sequence[Any]) -> list[str]:
    """The faults that stop ``sources`` (pydicom headers, one per image) being referenced, in words."""
    faults = []
    n = len(sources)
    for kw, tag in PER_IMAGE + SHARED:
        values = [str(ds.get(kw, "") or "").strip() for ds in sources]
        empty = sum(1 for v in values if not v)
        if empty:
            faults.append(f"{kw} {tag} missing or empty" + (f" on {empty} of {n} images" if empty < n else ""))
        elif (kw, tag) in SHARED and len(set(values)) > 1:
            faults.append(f"{kw} {tag} differs between its images ({len(set(values))} values)")
    instances = [str(ds.get("SOPInstanceUID", "") or "") for ds in sources]
    dup = len(instances) - len(set(instances))
    if dup and all(instances):
        faults.append(f"SOPInstanceUID (0008,0018) repeated ({dup} images share another's)")
    return faults


def require_references(sources: Sequence[Any], *, what: str, path: str | os.PathLike | None = None) -> None:
    """CtuiError naming every missing attribute when ``sources`` cannot be referenced by a ``what``."""
    faults = missing_references(sources)
    if faults:
        a = "an" if what.upper().startswith(("RT", "A", "E", "I", "O")) else "a"
        raise CtuiError(f"cannot write {a} {what} over this series: {'; '.join(faults)}. {a.title()} {what} "
                        "points at the series' images by these UIDs and ctui does not invent them: export NIfTI or "
                        "NRRD instead, or give the series as the scanner wrote it", path=path)


__all__ = ["missing_references", "require_references"]


def _vector(value: Any, n: int) -> list[float] | None:
    try:
        vals = [float(v) for v in value]
    except (TypeError, ValueError):
        return None
    return vals if len(vals) == n and all(math.isfinite(v) and abs(v) < 1e7 for v in vals) else None


def orientation_fault(iop: Any) -> str | None:
    """Why an ImageOrientationPatient value cannot be written into a SEG/RTSTRUCT (None: fine):
    six finite numbers, two unit vectors (within 1e-3) at right angles (within 1e-3)."""
    v = _vector(iop, 6)
    if v is None:
        return "not six finite numbers"
    row, col = v[:3], v[3:]
    nr, nc = math.sqrt(sum(a * a for a in row)), math.sqrt(sum(a * a for a in col))
    if abs(nr - 1) > 1e-3 or abs(nc - 1) > 1e-3:
        return f"its vectors are not unit length ({nr:.4g}, {nc:.4g})"
    if abs(sum(a * b for a, b in zip(row, col))) > 1e-3:
        return "its row and column vectors are not at right angles"
    return None


def plane_faults(sources: Sequence[Any]) -> list[str]:
    """Plane geometry a SEG/RTSTRUCT copies from ``sources`` that a reader would refuse:
    an invalid ImageOrientationPatient (zero, non-unit, non-orthogonal) or a position that is
    not three finite numbers, per image or per frame of an enhanced multi-frame image."""
    out: list[str] = []
    for ds in sources:
        name = os.path.basename(str(getattr(ds, "filename", "") or "")) or "an image"
        planes = [(ds.get("ImageOrientationPatient"), ds.get("ImagePositionPatient"), name)]
        if int(ds.get("NumberOfFrames", 1) or 1) > 1 and "PerFrameFunctionalGroupsSequence" in ds:
            shared = (ds.get("SharedFunctionalGroupsSequence") or [None])[0]
            planes = []
            for k, fg in enumerate(ds.PerFrameFunctionalGroupsSequence):
                po = _item(fg, "PlaneOrientationSequence") or _item(shared, "PlaneOrientationSequence")
                pp = _item(fg, "PlanePositionSequence") or _item(shared, "PlanePositionSequence")
                planes.append((po.get("ImageOrientationPatient") if po is not None else None,
                               pp.get("ImagePositionPatient") if pp is not None else None, f"{name} frame {k + 1}"))
        for iop, ipp, where in planes:
            fault = orientation_fault(iop) if iop is not None else None
            if fault:
                out.append(f"{where}: ImageOrientationPatient: {fault}")
            elif ipp is not None and _vector(ipp, 3) is None:
                out.append(f"{where}: ImagePositionPatient is not three finite numbers")
            if out:
                return out
    return out


def _item(fg: Any, key: str) -> Any:
    try:
        seq = fg.get(key) if fg is not None else None
        return seq[0] if seq else None
    except (AttributeError, IndexError, TypeError):
        return None


def require_planes(sources: Sequence[Any], path: Any) -> None:
    """CtuiError (one line) when :func:`plane_faults` finds one: the file would be written with
    geometry no reader accepts (it was, exit 0, and could not be read back)."""
    faults = plane_faults(sources)
    if faults:
        raise CtuiError(f"the series' plane geometry cannot be written into a DICOM-SEG/RTSTRUCT ({faults[0]}); "
                        "export a label map (nifti, nrrd) instead", path=path)


def write_fault(exc: BaseException) -> str:
    """pydicom's write error in one line: it appends the inner traceback's text to its message
    ("With tag (0010,0010) got exception: ...\nTraceback (most recent call last): ..."),
    which reached the CLI's one-line message."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    first = lines[0] if lines else type(exc).__name__
    return " ".join(first.split())[:200]
