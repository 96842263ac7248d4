"""DICOM objects that are not image slices (DICOM-SEG, RTSTRUCT, RT plans and doses,
presentation states, structured reports, key object selections...): recognised from the
SOP Class UID (or, without one, the Modality) so the loader lists them as non-image
objects instead of choosing one as the volume.

``non_image(sop_class, modality)`` -> (kind, reason) or None for an image;
``_check_image(ds)`` raises ``_NotImage`` (a ``_Skip``: the header reader's "skip this
file, here is why") for one.
"""

from __future__ import annotations

from typing import Any

_STORAGE = "1.2.840.10008.5.1.4.1.1."
_LABELS_HINT = "open it as labels over its image series"

#: exact SOP Class UIDs -> (kind, reason)
_EXACT: dict[str, tuple[str, str]] = {
    _STORAGE + "66.4": ("DICOM-SEG", f"DICOM-SEG: {_LABELS_HINT}"),
    _STORAGE + "66.7": ("DICOM-SEG", f"DICOM-SEG: {_LABELS_HINT}"),  # Label Map Segmentation
    _STORAGE + "481.3": ("RTSTRUCT", f"RTSTRUCT: {_LABELS_HINT}"),
    _STORAGE + "481.2": ("RT Dose", "RT Dose: a dose grid, not an image series (non-image object)"),
    _STORAGE + "66.5": ("surface segmentation", "DICOM surface segmentation: not an image series (non-image object)"),
    _STORAGE + "66": ("raw data", "DICOM raw data: not an image series (non-image object)"),
    _STORAGE + "66.1": ("registration", "spatial registration: not an image series (non-image object)"),
    _STORAGE + "66.2": ("fiducials", "spatial fiducials: not an image series (non-image object)"),
    _STORAGE + "66.3": ("registration", "deformable registration: not an image series (non-image object)"),
    _STORAGE + "66.6": ("tractography", "tractography results: not an image series (non-image object)"),
    _STORAGE + "88.59": ("KO", "key object selection (KO): references, not an image series (non-image object)"),
    _STORAGE + "4.2": ("spectroscopy", "MR spectroscopy: not an image series (non-image object)"),
}

#: SOP Class UID prefixes -> (kind, reason); RT Image (481.1) is an image and not listed
_PREFIX: tuple[tuple[str, tuple[str, str]], ...] = (
    (_STORAGE + "481.", ("RT object", "RT plan or record: not an image series (non-image object)")),
    ("1.2.840.10008.5.1.4.34.", ("RT object", "RT plan or record: not an image series (non-image object)")),
    (_STORAGE + "11.", ("presentation state",
                        "presentation state: display settings, not an image series (non-image object)")),
    (_STORAGE + "88.", ("SR", "structured report (SR): not an image series (non-image object)")),
    (_STORAGE + "104.", ("document", "encapsulated document: not an image series (non-image object)")),
    (_STORAGE + "9.", ("waveform", "waveform: not an image series (non-image object)")),
    (_STORAGE + "68.", ("surface scan", "surface scan: not an image series (non-image object)")),
)

#: Modality -> SOP Class UID used when a file has no SOP Class UID
_MODALITY = {"SEG": _STORAGE + "66.4", "RTSTRUCT": _STORAGE + "481.3", "RTDOSE": _STORAGE + "481.2",
             "RTPLAN": _STORAGE + "481.5", "RTRECORD": _STORAGE + "481.4", "PR": _STORAGE + "11.1",
             "SR": _STORAGE + "88.11", "KO": _STORAGE + "88.59", "REG": _STORAGE + "66.1",
             "FID": _STORAGE + "66.2", "DOC": _STORAGE + "104.1"}

RT_IMAGE = _STORAGE + "481.1"


def non_image(sop_class: str, modality: str = "") -> tuple[str, str] | None:
    """(kind, reason) when the object is not an image slice a volume can be built of,
    else None. ``kind`` is short ("DICOM-SEG", "RTSTRUCT", "RT Dose", "SR"...); ``reason``
    is what ``Volume.skipped`` says (for SEG and RTSTRUCT: how to open it as labels)."""
    uid = (sop_class or "").strip().rstrip("\x00")
    if not uid:
        uid = _MODALITY.get((modality or "").strip().upper(), "")
    if not uid or uid == RT_IMAGE:
        return None
    hit = _EXACT.get(uid)
    if hit:
        return hit
    for prefix, value in _PREFIX:
        if uid.startswith(prefix):
            return value
    return None


class _Skip(Exception):
    """A file that is skipped; str(self) is the reason."""


def series_uid_of(ds: Any) -> str:
    """The header's SeriesInstanceUID, "" when it cannot be read."""
    try:
        return str(ds.get("SeriesInstanceUID", "") or "")[:64]
    except Exception:  # noqa: BLE001 - a broken element: the file is skipped anyway
        return ""


class _NotImage(_Skip):
    """A DICOM object that is not an image slice (SEG, RTSTRUCT, SR...); ``kind`` names it."""

    def __init__(self, kind: str, reason: str) -> None:
        super().__init__(reason)
        self.kind = kind


def _check_image(ds: Any) -> None:
    """Raise _NotImage for a non-image object (:func:`.dicom_sop.non_image`)."""
    hit = non_image(str(ds.get("SOPClassUID") or ""), str(ds.get("Modality") or ""))
    if hit:
        raise _NotImage(*hit)
