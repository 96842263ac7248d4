"""File-name suffixes of the volume and label-map formats, written once (lower case; match with
``name.lower().endswith(...)``). Plain constants: importing this loads nothing else."""

from __future__ import annotations

NIFTI_SUFFIXES = (".nii", ".nii.gz")
NRRD_SUFFIXES = (".nrrd", ".nhdr")
GIPL_SUFFIXES = (".gipl", ".gipl.gz")
#: files read as label maps by name (Slicer's .seg.nrrd ends in .nrrd too)
LABELMAP_SUFFIXES = (".nii", ".nii.gz", ".nrrd", ".seg.nrrd", ".nhdr")
