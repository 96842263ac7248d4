"""Can a DICOM-SEG or an RTSTRUCT point at this series? Both reference the source images by
UIDs (SOP Class/Instance per image, Series and Study Instance UID, Frame of Reference UID);
a series without them cannot be referenced, and ctui never invents them (a made-up UID
names no image a PACS or a planning system holds: the file would be orphaned)."""

from __future__ import annotations

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
