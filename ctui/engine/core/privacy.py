"""Patient-identifier hygiene.

ctui never writes patient identifiers (name, ID, birth date, accession number,
institution...) into any output. This module holds the list of identifying DICOM
keywords, :func:`scrub` to drop them from metadata dicts before they are stored, and
:func:`find_strings` to search output files (including gzip streams and zip members)
for given strings, which the privacy tests use.
"""

from __future__ import annotations

import gzip
import io
import os
import zipfile
from pathlib import Path
from typing import Any, Iterable

#: DICOM keywords (PS3.15 basic profile subset) that identify a patient, an
#: operator or an institution. Compared case-insensitively, ignoring '_' and ' '.
IDENTIFYING_KEYWORDS: frozenset[str] = frozenset(
    k.lower()
    for k in (
        "PatientName", "PatientID", "PatientBirthDate", "PatientBirthTime", "PatientSex",
        "PatientAge", "PatientAddress", "PatientTelephoneNumbers", "PatientMotherBirthName",
        "OtherPatientIDs", "OtherPatientNames", "OtherPatientIDsSequence", "PatientBirthName",
        "IssuerOfPatientID", "MedicalRecordLocator", "EthnicGroup", "PatientComments",
        "AccessionNumber", "InstitutionName", "InstitutionAddress", "InstitutionalDepartmentName",
        "ReferringPhysicianName", "ReferringPhysicianAddress", "PerformingPhysicianName",
        "NameOfPhysiciansReadingStudy", "OperatorsName", "PhysiciansOfRecord", "RequestingPhysician",
        "StationName", "DeviceSerialNumber", "StudyID", "RequestAttributesSequence",
        "MilitaryRank", "BranchOfService", "Occupation", "PatientInsurancePlanCodeSequence",
        "PatientWeight", "PatientSize", "ResponsiblePerson", "ResponsibleOrganization",
    )
)


def _norm(key: str) -> str:
    return str(key).replace("_", "").replace(" ", "").lower()


def is_identifying(key: str) -> bool:
    """True if ``key`` names a patient/institution identifier (e.g. "PatientName")."""
    return _norm(key) in IDENTIFYING_KEYWORDS


def scrub(obj: Any) -> Any:
    """Return a copy of ``obj`` (dicts/lists, recursively) without identifying keys."""
    if isinstance(obj, dict):
        return {k: scrub(v) for k, v in obj.items() if not is_identifying(str(k))}
    if isinstance(obj, list):
        return [scrub(v) for v in obj]
    if isinstance(obj, tuple):
        return tuple(scrub(v) for v in obj)
    return obj


def _variants(s: str) -> list[bytes]:
    out = {s.encode("utf-8"), s.encode("utf-16-le")}
    if "^" in s:  # DICOM PN: also the rendered "Family Given" form and each component
        # components only when distinctive enough (a "NAME" component would match "Name" keys)
        out |= {s.replace("^", " ").encode(), *(p.encode() for p in s.split("^") if len(p) >= 6)}
    return sorted(out)


def _expand(data: bytes, depth: int = 0) -> Iterable[bytes]:
    """``data`` plus decompressed gzip streams / zip members inside it (bounded)."""
    yield data
    if depth > 2:
        return
    limit = 512 * 1024 * 1024
    if data[:2] == b"\x1f\x8b":
        try:
            with gzip.GzipFile(fileobj=io.BytesIO(data)) as gz:
                inner = gz.read(limit)
            yield from _expand(inner, depth + 1)
        except (OSError, EOFError, ValueError):
            pass
    if data[:4] == b"PK\x03\x04":
        try:
            with zipfile.ZipFile(io.BytesIO(data)) as zf:
                for info in zf.infolist():
                    if info.file_size <= limit:
                        yield from _expand(zf.read(info), depth + 1)
        except (zipfile.BadZipFile, OSError, ValueError, EOFError):
            pass
    # NRRD with attached gzip data: search the stream after the header too
    if data[:7] == b"NRRD000":
        i = data.find(b"\n\n")
        if i > 0 and data[i + 2 : i + 4] == b"\x1f\x8b":
            yield from _expand(data[i + 2 :], depth + 1)


def find_strings(paths: Iterable[str | os.PathLike], needles: Iterable[str], *, texts: Iterable[str] = ()) -> list[str]:
    """Search files (recursively for folders) and texts for ``needles``.

    Looks inside gzip streams (.nii.gz, NRRD gzip data) and zip members (projects).
    Returns a list of "where: needle" findings (empty when clean).
    """
    needles = list(needles)
    pats = [(n, v) for n in needles for v in _variants(n)]
    found: list[str] = []

    def check(where: str, data: bytes) -> None:
        for blob in _expand(data):
            for n, v in pats:
                if v in blob or v.lower() in blob.lower():
                    found.append(f"{where}: {n}")
                    return

    for t in texts:
        check("<text>", t.encode("utf-8", errors="replace"))
    for p in paths:
        p = Path(p)
        files = [f for f in p.rglob("*") if f.is_file()] if p.is_dir() else [p]
        for f in files:
            check(str(f), f.read_bytes())
    return found
