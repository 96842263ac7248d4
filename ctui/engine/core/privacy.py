"""Patient-identifier hygiene.

ctui never writes patient identifiers (name, ID, birth date, accession number,
institution...) into any output. This module holds the list of identifying DICOM
keywords, :func:`scrub` to drop them from metadata dicts before they are stored,
:func:`scrub_text` to remove a series' own identifiers from free text taken from its
headers (SeriesDescription, StudyDescription, private tags' text) or from its folder
name, :func:`hide_path` to keep a source path out of reports, and
:func:`find_strings` to search output files (including gzip streams and zip members)
for given strings, which the privacy tests use.

``scrub_text`` replaces whole words only: the tokens of the identifiers (a PN
"DOE^JOHN" gives "DOE" and "JOHN"), at least 3 letters (4 digits for numbers), never a
common word of series descriptions ("HEAD", "CHEST", "CONTRAST"...). The old scrubber
replaced any substring ("ANN" inside "SCANNER"), which garbled harmless text.
"""

from __future__ import annotations

import gzip
import io
import os
import re
import zipfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from ctui.engine.core.assumptions import Assumption

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


#: Words that may appear in a name or an ID but are common in descriptions and
#: never scrubbed on their own (upper-case compared).
COMMON_WORDS: frozenset[str] = frozenset(
    ["ABDOMEN", "ABD", "AND", "ANON", "ANONYMOUS", "AXIAL", "BODY", "BONE", "BRAIN", "CARDIAC", "CENTER", "CENTRE", "CHEST", "CLINIC", "CONTRAST", "CORONAL", "DEFAULT", "DEMO", "DEPT", "DOCTOR", "DYNAMIC", "FEMALE", "FOR", "HEAD", "HOSPITAL", "KNEE", "LEFT", "LIVER", "LUNG", "MALE", "MEDICAL", "NAME", "NECK", "NONE", "NULL", "OTHER", "PATIENT", "PELVIS", "PHANTOM", "POST", "PRE", "RADIOLOGY", "RIGHT", "SAGITTAL", "SCAN", "SCOUT", "SERIES", "SOFT", "SPINE", "STUDY", "TEST", "THE", "THORAX", "TISSUE", "UNKNOWN", "VENOUS", "WITH", "WITHOUT"]
)
_SPLIT = re.compile(r"[^0-9A-Za-z\u00C0-\uFFFF]+")
_REPLACEMENT = "[removed]"


def identifier_tokens(identifiers: Iterable[Any]) -> list[str]:
    """The words of ``identifiers`` that :func:`scrub_text` removes, longest first.

    Each identifier's tokens (split at anything but letters and digits): at least 3
    characters (4 when all digits), not in :data:`COMMON_WORDS`.
    """
    out: set[str] = set()
    for ident in identifiers:
        for tok in _SPLIT.split(str(ident or "")):
            if len(tok) < (4 if tok.isdigit() else 3) or tok.upper() in COMMON_WORDS:
                continue
            out.add(tok)
    return sorted(out, key=lambda t: (-len(t), t))


def _pattern(identifiers: Iterable[Any]) -> re.Pattern | None:
    toks = identifier_tokens(identifiers)
    if not toks:
        return None
    # whole words: not preceded/followed by a letter or digit ('_' separates, as in folder names)
    alt = "|".join(re.escape(t) for t in toks)
    return re.compile(rf"(?<![0-9A-Za-z\u00C0-\uFFFF])(?:{alt})(?![0-9A-Za-z\u00C0-\uFFFF])", re.IGNORECASE)


def scrub_text(text: str, identifiers: Iterable[Any]) -> str:
    """``text`` with every whole-word token of ``identifiers`` replaced by "[removed]".

    >>> scrub_text("CT DOE JOHN head, scanner ANN", ["DOE^JOHN", "ANN"])
    'CT [removed] [removed] head, scanner [removed]'
    >>> scrub_text("SCANNER HEAD", ["ANN^HEAD"])
    'SCANNER HEAD'
    """
    pat = _pattern(identifiers)
    return str(text) if pat is None else pat.sub(_REPLACEMENT, str(text))


def scrub_text_obj(obj: Any, identifiers: Iterable[Any]) -> Any:
    """:func:`scrub_text` applied to every string in ``obj`` (dicts' values, lists, tuples)."""
    pat = _pattern(identifiers)
    if pat is None:
        return obj

    def walk(o: Any) -> Any:
        if isinstance(o, str):
            new = pat.sub(_REPLACEMENT, o)
            if new != o and isinstance(o, Assumption):  # the typed warning stays typed
                return Assumption(new, o.kind, o.count, o.total)
            return new
        if isinstance(o, list):
            return [walk(v) for v in o]
        if isinstance(o, tuple):
            return tuple(walk(v) for v in o)
        if isinstance(o, dict):
            return {k: walk(v) for k, v in o.items()}
        return o

    return walk(obj)


#: DICOM free-text attributes that exports may copy from the source (study module and
#: friends) and that often hold a name: scrubbed of the source's identifiers.
FREE_TEXT_KEYWORDS: tuple[str, ...] = (
    "StudyDescription", "SeriesDescription", "ProtocolName", "ImageComments", "RequestedProcedureDescription",
    "PerformedProcedureStepDescription", "AdmittingDiagnosesDescription", "ReasonForStudy", "StudyComments",
)


def scrub_dataset_text(ds: Any, identifiers: Iterable[Any]) -> Any:
    """Scrub :data:`FREE_TEXT_KEYWORDS` of a pydicom Dataset (in place) with
    :func:`scrub_text`; returns ``ds``. ``identifiers``: the source's PatientName, IDs..."""
    pat = _pattern(identifiers)
    if pat is None:
        return ds
    for kw in FREE_TEXT_KEYWORDS:
        try:
            v = ds.get(kw)
        except Exception:  # noqa: BLE001 - a malformed value: drop it rather than copy it
            v = None
        if isinstance(v, str) and v:
            new = pat.sub(_REPLACEMENT, v)
            if new != v:
                setattr(ds, kw, new)
    return ds


def _path_forms(paths: Iterable[Any]) -> list[str]:
    forms: set[str] = set()
    for p in paths:
        if p is None or isinstance(p, bool) or str(p) == "":
            continue
        if isinstance(p, (list, tuple)):
            forms |= set(_path_forms(p))
            continue
        s = os.fspath(p)
        for f in (s, s.rstrip("/"), os.path.abspath(s), os.path.realpath(s)):
            if len(f) > 1 and f not in (os.sep, "."):
                forms.add(f)
    return sorted(forms, key=len, reverse=True)


def path_hider(paths: Iterable[Any], *, label: str = "<input>"):
    """A function ``text -> text`` replacing each of ``paths`` (as given, absolute and
    resolved) by ``label`` where it stands as a whole path (followed by nothing, a
    separator, a quote, a space or punctuation, not by more name characters).

    Reports print through this unless the user asks for paths (``--keep-identifiers``):
    folder names are often the patient's name.
    """
    forms = _path_forms(paths)
    if not forms:
        return lambda text: text
    pat = re.compile("(?:" + "|".join(re.escape(f) for f in forms) + r")(?![\w-]|\.\w)")
    return lambda text: pat.sub(label, text)


def hide_path(text: str, paths: Iterable[Any], *, label: str = "<input>") -> str:
    """``text`` with each of ``paths`` replaced by ``label`` (see :func:`path_hider`)."""
    return path_hider(paths, label=label)(str(text))


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
        if not p.exists():
            continue
        files = [f for f in p.rglob("*") if f.is_file()] if p.is_dir() else [p]
        for f in files:
            check(str(f), f.read_bytes())
    return found
