"""Measurement reports as DICOM SR (TID 1500, Comprehensive 3D SR) with highdicom, and reading them back.

Writing (:func:`write_sr`): one TID 1411 volumetric ROI measurement group per object, each
referencing the object's segment of a DICOM-SEG (``ReferencedSegment``: the SEG instance, its
segment number and the source images of the segment's frames) and holding the quantities of
:data:`QUANTITIES` that were measured (volume by voxel counting and by the surface mesh,
surface area, mean and SD of HU, the three principal axes and, where sections were measured
along a path, its length and the extreme sections with their arc lengths and centres as 3D
points). Codes: SNOMED CT, DCM and UCUM as highdicom's examples use them; what the standard
has no code for (the mesh methods, arc lengths) uses the private scheme ``99CTUI``. A common
structure's name ("left kidney", "liver", "aorta"...) gives the finding and its site
(:func:`anatomy`). The evidence is the source series and the SEG; patient identifiers copied
from them are blanked unless ``keep_identifiers``.

Reading (:func:`read_sr`) returns, per group, the tracking identifier, the referenced segment
and every measurement, with :data:`QUANTITIES`' key where it is one of ctui's.

highdicom and pydicom are imported inside the functions: seconds of import for ``ctui --help``.
"""

from __future__ import annotations

import copy
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ctui import __version__
from ctui.engine.core.atomic import atomic_path
from ctui.engine.core.errors import FormatError

SR_SOP_CLASS = "1.2.840.10008.5.1.4.1.1.88.34"  # Comprehensive 3D SR
PRIVATE = "99CTUI"

#: (code value, scheme, meaning) triples
VOLUME = ("118565006", "SCT", "Volume")
AREA = ("42798000", "SCT", "Area")
DIAMETER = ("81827009", "SCT", "Diameter")
ATTENUATION = ("112031", "DCM", "Attenuation Coefficient")
GREY = ("GREY", PRIVATE, "Grey level")
MEAN = ("373098007", "SCT", "Mean")
SD = ("386136009", "SCT", "Standard Deviation")
MAXIMUM = ("56851009", "SCT", "Maximum")
MINIMUM = ("255605001", "SCT", "Minimum")
ML = ("ml", "UCUM", "milliliter")
MM = ("mm", "UCUM", "millimeter")
MM2 = ("mm2", "UCUM", "square millimeter")
HU = ("[hnsf'U]", "UCUM", "Hounsfield unit")
NO_UNIT = ("1", "UCUM", "no units")
VOXELS = ("126030", "DCM", "Sum of segmented voxel method for volume")
MESH_VOLUME = ("MESHVOL", PRIVATE, "Volume enclosed by the surface mesh (Gauss theorem)")
MESH_AREA = ("MESHAREA", PRIVATE, "Area of the surface mesh")
MOMENTS = ("MOMENTS", PRIVATE, "Full axis of the ellipsoid with the object's second moments")
CENTERLINE = ("130490", "DCM", "Centerline")
SECTION = ("SECTION", PRIVATE, "Cross-section normal to the path")

#: ctui's quantity key -> (concept, unit, method, derivation); the reader maps them back.
QUANTITIES: dict[str, tuple] = {
    "volume_voxels_ml": (VOLUME, ML, VOXELS, None),
    "volume_mesh_ml": (VOLUME, ML, MESH_VOLUME, None),
    "area_mm2": (AREA, MM2, MESH_AREA, None),
    "mean": (ATTENUATION, HU, None, MEAN),
    "sd": (ATTENUATION, HU, None, SD),
    "mean_value": (GREY, NO_UNIT, None, MEAN),
    "sd_value": (GREY, NO_UNIT, None, SD),
    "axis_1_mm": (("131187009", "SCT", "Major Axis"), MM, MOMENTS, None),
    "axis_2_mm": (("131188004", "SCT", "Minor Axis"), MM, MOMENTS, None),
    "axis_3_mm": (("131189007", "SCT", "Perpendicular Axis"), MM, MOMENTS, None),
    "path_length_mm": (("121211", "DCM", "Path length"), MM, CENTERLINE, None),
    "max_diameter_mm": (DIAMETER, MM, SECTION, MAXIMUM),
    "min_diameter_mm": (DIAMETER, MM, SECTION, MINIMUM),
    "max_area_mm2": (AREA, MM2, SECTION, MAXIMUM),
    "min_area_mm2": (AREA, MM2, SECTION, MINIMUM),
    "max_diameter_s_mm": (("SMAXD", PRIVATE, "Arc length of the section of maximum diameter"), MM, SECTION, None),
    "min_diameter_s_mm": (("SMIND", PRIVATE, "Arc length of the section of minimum diameter"), MM, SECTION, None),
    "max_area_s_mm": (("SMAXA", PRIVATE, "Arc length of the section of maximum area"), MM, SECTION, None),
    "min_area_s_mm": (("SMINA", PRIVATE, "Arc length of the section of minimum area"), MM, SECTION, None),
    # a section's own planar group (TID 1410: its contour in patient mm)
    "section_area_mm2": (AREA, MM2, SECTION, None),
    "section_eq_diameter_mm": (("EQDIAM", PRIVATE, "Diameter of the circle of equal area"), MM, SECTION, None),
    "s_mm": (("ARCLEN", PRIVATE, "Arc length along the path"), MM, SECTION, None),
}
#: a section's keys in its planar group <- the keys of ``ctui measure --json``'s section rows
SECTION_KEYS = {"s_mm": "s_mm", "section_area_mm2": "area_mm2", "section_eq_diameter_mm": "eq_diameter_mm",
                "min_diameter_mm": "min_diameter_mm", "max_diameter_mm": "max_diameter_mm"}

#: words of an object's name -> SNOMED CT structure (a small table of common structures)
STRUCTURES: dict[str, tuple[str, str, str]] = {
    "kidney": ("64033007", "SCT", "Kidney"), "liver": ("10200004", "SCT", "Liver"),
    "spleen": ("78961009", "SCT", "Spleen"), "aorta": ("15825003", "SCT", "Aorta"),
    "pancreas": ("15776009", "SCT", "Pancreas"), "gallbladder": ("28231008", "SCT", "Gallbladder"),
    "stomach": ("69695003", "SCT", "Stomach"), "heart": ("80891009", "SCT", "Heart"),
    "lung": ("39607008", "SCT", "Lung"), "bladder": ("89837001", "SCT", "Urinary bladder"),
    "inferior vena cava": ("64131007", "SCT", "Inferior vena cava"), "ivc": ("64131007", "SCT", "Inferior vena cava"),
    "vertebra": ("51282000", "SCT", "Vertebra"), "bone": ("272673000", "SCT", "Bone"),
    "tumor": ("108369006", "SCT", "Tumor"), "tumour": ("108369006", "SCT", "Tumor"),
    "lesion": ("52988006", "SCT", "Lesion"),
}
LATERALITY = {"left": ("7771000", "SCT", "Left"), "right": ("24028007", "SCT", "Right")}
TISSUE = ("85756007", "SCT", "Tissue")


def anatomy(name: str) -> tuple[tuple | None, tuple | None]:
    """(structure, laterality) codes for an object's name ("kidney_left" -> Kidney, Left), or Nones."""
    text = " ".join(w for w in re.split(r"[^a-z]+", str(name).lower()) if w)
    words = text.split()
    for key in sorted(STRUCTURES, key=len, reverse=True):
        if (f" {key} " in f" {text} ") or (" " not in key and (key + "s") in words):
            side = next((LATERALITY[w] for w in words if w in LATERALITY), None)
            return STRUCTURES[key], side
    return None, None


def _code(triple: Sequence[str]) -> Any:
    import highdicom as hd

    return hd.sr.CodedConcept(value=triple[0], scheme_designator=triple[1], meaning=triple[2])


@dataclass
class SrObject:
    """One object to write: its ``name``, its ``segment_number`` in the SEG, ``values``
    {QUANTITIES key: number (None: not measured)} for its volumetric group and ``sections``
    (the extreme sections: ``ctui measure --json`` section rows with ``contour_mm`` (k, 3)
    patient mm), each written as a planar group."""

    name: str
    segment_number: int
    values: dict[str, float | None]
    sections: list[dict] = field(default_factory=list)


def _measurement(key: str, value: float) -> Any:
    import highdicom as hd

    concept, unit, method, derivation = QUANTITIES[key]
    return hd.sr.Measurement(name=_code(concept), value=float(value), unit=_code(unit),
                             method=_code(method) if method else None,
                             derivation=_code(derivation) if derivation else None)


def referenced_segment(seg: Any, number: int) -> Any:
    """A ``ReferencedSegment`` to segment ``number`` of the SEG dataset ``seg`` with the source images
    of its frames (per-frame DerivationImageSequence; the segment number per frame or shared, as
    ctui's one-segment SEGs have it)."""
    import highdicom as hd

    shared = (seg.get("SharedFunctionalGroupsSequence") or [None])[0]
    default = None
    if shared is not None and "SegmentIdentificationSequence" in shared:
        default = int(shared.SegmentIdentificationSequence[0].ReferencedSegmentNumber)
    images: dict[str, str] = {}
    for frame in seg.get("PerFrameFunctionalGroupsSequence", []):
        ident = frame.get("SegmentIdentificationSequence")
        n = int(ident[0].ReferencedSegmentNumber) if ident else default
        if n != number:
            continue
        for der in frame.get("DerivationImageSequence", []):
            for src in der.get("SourceImageSequence", []):
                images.setdefault(str(src.ReferencedSOPInstanceUID), str(src.ReferencedSOPClassUID))
    if not images:  # no per-frame sources: the series the SEG is over
        series = str(seg.ReferencedSeriesSequence[0].SeriesInstanceUID)
        return hd.sr.ReferencedSegment(sop_class_uid=str(seg.SOPClassUID), sop_instance_uid=str(seg.SOPInstanceUID),
                                       segment_number=number, source_series=hd.sr.SourceSeriesForSegmentation(series))
    return hd.sr.ReferencedSegment(
        sop_class_uid=str(seg.SOPClassUID), sop_instance_uid=str(seg.SOPInstanceUID), segment_number=number,
        source_images=[hd.sr.SourceImageForSegmentation(cls, uid) for uid, cls in images.items()])


def _groups(obj: SrObject, seg: Any, frame_of_reference: str) -> list[Any]:
    """The object's volumetric group (TID 1411, its segment) and one planar group (TID 1410, the
    section's closed contour as a 3D polygon) per extreme section."""
    import highdicom as hd

    structure, side = anatomy(obj.name)
    sites = [hd.sr.FindingSite(_code(structure), laterality=_code(side) if side else None)] if structure else None
    common = {"finding_type": _code(structure or TISSUE), "finding_sites": sites,
              "algorithm_id": hd.sr.AlgorithmIdentification(name="ctui", version=__version__)}
    name = obj.name[:64] or "object"
    out = [hd.sr.VolumetricROIMeasurementsAndQualitativeEvaluations(
        tracking_identifier=hd.sr.TrackingIdentifier(uid=hd.UID(), identifier=name),
        referenced_segment=referenced_segment(seg, obj.segment_number),
        measurements=[_measurement(k, v) for k, v in obj.values.items() if v is not None and k in QUANTITIES],
        **common)]
    for sec in obj.sections:
        contour = np.asarray(sec.get("contour_mm"), dtype=float).reshape(-1, 3)
        if len(contour) < 3 or not frame_of_reference:
            continue
        region = hd.sr.ImageRegion3D(graphic_type=hd.sr.GraphicTypeValues3D.POLYGON,
                                     graphic_data=np.vstack([contour, contour[:1]]),
                                     frame_of_reference_uid=frame_of_reference)
        items = [_measurement(k, sec[src]) for k, src in SECTION_KEYS.items() if sec.get(src) is not None]
        out.append(hd.sr.PlanarROIMeasurementsAndQualitativeEvaluations(
            tracking_identifier=hd.sr.TrackingIdentifier(
                uid=hd.UID(), identifier=f"{name[:40]} section at {float(sec['s_mm']):g} mm"),
            referenced_region=region, measurements=items, **common))
    return out


def write_sr(path: str | os.PathLike, objects: Sequence[SrObject], sources: Sequence[Any], seg: Any, *,
             keep_identifiers: bool = False, title: str = "ctui measurements") -> Path:
    """Write the TID 1500 measurement report (atomic) and return its path.

    ``sources``: the series' headers (``dicomseg.source_datasets``); ``seg``: the DICOM-SEG's
    dataset (pydicom, pixels not needed) whose segments ``objects`` name by number.
    """
    import highdicom as hd
    from pydicom.dataset import Dataset
    from pydicom.sr.codedict import codes

    from ctui.engine.io.dicomseg import TYPE2_IDENTIFIERS, blank_identifiers  # pydicom

    first = sources[0]
    frame_of_reference = str(first.get("FrameOfReferenceUID", "") or "")
    device = hd.sr.ObserverContext(
        observer_type=codes.DCM.Device,
        observer_identifying_attributes=hd.sr.DeviceObserverIdentifyingAttributes(
            uid=hd.UID(), name="ctui", manufacturer_name="ctui", model_name="ctui"))
    modality = str(first.get("Modality", "") or "").upper()
    procedure = ("25045-6", "LN", "CT unspecified body region") if modality == "CT" else (
        ("25056-3", "LN", "MR unspecified body region") if modality == "MR" else ("P5-09051", "SRT", "Imaging procedure"))
    report = hd.sr.MeasurementReport(
        observation_context=hd.sr.ObservationContext(observer_device_context=device),
        procedure_reported=_code(procedure), title=codes.DCM.ImagingMeasurementReport,
        imaging_measurements=[g for o in objects for g in _groups(o, seg, frame_of_reference)])
    lead = copy.deepcopy(first)  # highdicom copies the patient and study from the first evidence item
    for kw in (*TYPE2_IDENTIFIERS, "StudyDate", "StudyTime"):  # highdicom reads them
        if kw not in lead:
            setattr(lead, kw, "")
    if "SpecificCharacterSet" in lead and not lead.SpecificCharacterSet:
        del lead.SpecificCharacterSet  # empty (default repertoire): highdicom refuses '' as a value
    blank_identifiers(lead, keep=keep_identifiers)
    evidence = [lead, *sources[1:], seg]
    sr = hd.sr.Comprehensive3DSR(
        evidence=evidence, content=report, series_instance_uid=hd.UID(),
        series_number=int(first.get("SeriesNumber", 0) or 0) + 2000, sop_instance_uid=hd.UID(), instance_number=1,
        manufacturer="ctui", is_complete=True, series_description=title[:64])
    blank_identifiers(sr, keep=keep_identifiers)
    scheme = Dataset()  # the private coding scheme's declaration (PS3.3 C.12.1.1.2)
    scheme.CodingSchemeDesignator, scheme.CodingSchemeName = PRIVATE, "ctui measurement codes"
    scheme.CodingSchemeResponsibleOrganization = "ctui"
    sr.CodingSchemeIdentificationSequence = [*sr.get("CodingSchemeIdentificationSequence", []), scheme]
    p = Path(path)
    with atomic_path(p) as tmp:
        sr.save_as(str(tmp), enforce_file_format=True)
    return p


# =========================================================================== read
def is_sr(path: str | os.PathLike) -> bool:
    """True when ``path`` is a DICOM SR file (its header says so)."""
    p = Path(path)
    if not p.is_file():
        return False
    try:
        with open(p, "rb") as f:
            head = f.read(132)
    except OSError:
        return False
    if head[128:132] != b"DICM":
        return False
    from ctui.engine.io.dicomseg import import_pydicom  # pydicom, only for DICOM files

    pydicom = import_pydicom()
    try:
        ds = pydicom.dcmread(p, stop_before_pixels=True, specific_tags=["SOPClassUID"])
    except Exception:  # noqa: BLE001 - not readable: not an SR
        return False
    return str(ds.get("SOPClassUID", "")).startswith("1.2.840.10008.5.1.4.1.1.88.")


def _triple(code: Any) -> tuple[str, str] | None:
    return None if code is None else (str(code.value), str(code.scheme_designator))


_KEYS = {(c[:2], m[:2] if m else None, d[:2] if d else None): k for k, (c, _u, m, d) in QUANTITIES.items()}


def _measurements(g: Any) -> list[dict]:
    out = []
    for m in g.get_measurements():
        key = _KEYS.get((_triple(m.name), _triple(m.method), _triple(m.derivation)))
        out.append({"key": key, "name": m.name.meaning, "value": float(m.value), "unit": m.unit.value,
                    "method": m.method.meaning if m.method else None,
                    "derivation": m.derivation.meaning if m.derivation else None})
    return out


def _described(g: Any, kind: str) -> dict[str, Any]:
    sites = g.finding_sites
    return {"kind": kind, "name": str(g.tracking_identifier), "tracking_uid": str(g.tracking_uid),
            "finding": g.finding_type.meaning if g.finding_type else None,
            "site": sites[0].value.meaning if sites else None,
            "laterality": sites[0].laterality.meaning if sites and sites[0].laterality else None,
            "measurements": _measurements(g)}


def read_sr(path: str | os.PathLike) -> dict[str, Any]:
    """The report's groups: {"sop_instance_uid", "evidence": [SOP instance UIDs], "groups": [{"kind"
    ("object": a volumetric group; "section": a planar one), "name", "tracking_uid", "finding",
    "site", "laterality", "segment": {"sop_instance_uid", "segment_number", "source_images"}
    (objects), "contour_mm" (sections: [[x, y, z], ...] patient mm), "measurements": [{"key"
    (:data:`QUANTITIES` key or None), "name", "value", "unit", "method", "derivation"}]}]}."""
    import highdicom as hd

    try:
        sr = hd.sr.srread(path)
        report = sr.content
        volumetric = report.get_volumetric_roi_measurement_groups()
        planar = report.get_planar_roi_measurement_groups()
    except Exception as exc:  # noqa: BLE001 - any fault of a foreign file: one message
        raise FormatError(f"not a readable TID 1500 measurement report ({' '.join(str(exc).split())[:160]})",
                          path=path) from None
    evidence = [str(i.ReferencedSOPInstanceUID) for s in sr.get("CurrentRequestedProcedureEvidenceSequence", [])
                for r in s.ReferencedSeriesSequence for i in r.ReferencedSOPSequence]
    out = []
    for g in volumetric:
        d = _described(g, "object")
        seg = g.referenced_segment
        d["segment"] = None if seg is None else {
            "sop_instance_uid": str(seg.referenced_sop_instance_uid),
            "segment_number": int(seg.referenced_segment_numbers[0]),
            "source_images": [str(s.referenced_sop_instance_uid) for s in seg.source_images_for_segmentation]}
        out.append(d)
    for g in planar:
        d = _described(g, "section")
        roi = g.roi
        d["contour_mm"] = None if roi is None else [[float(c) for c in q] for q in getattr(roi, "value", [])]
        out.append(d)
    return {"sop_instance_uid": str(sr.SOPInstanceUID), "evidence": evidence, "groups": out}
