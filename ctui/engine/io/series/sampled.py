"""``ctui info`` of a large NIfTI, NRRD or MetaImage file: the header and sample slices, as for DICOM.

Decoding a whole volume to print its value range cost a 2 MB ``.nii.gz`` declaring
2000x2000x1000 voxels 7.7 GB and 39 s. :func:`inspect_volume_file` gives a headers-only
Volume (``data`` a zero-byte placeholder, ``meta["headers_only"]``, ``value_range`` of
the sampled slices) when the declared voxels exceed :data:`SAMPLE_ABOVE` bytes: the
first, middle and last slices, each loaded through the format's own reader with a
one-slice crop (NIfTI slices its gzip stream as it reads; raw NRRD and MetaImage read the
slab, a compressed NRRD is inflated up to the slice; a compressed MetaImage is inflated
whole, bounded by its declared size). In
a compressed file only slices within the first :data:`COMPRESSED_REACH` bytes are
sampled. Smaller files are loaded whole (None: the caller's usual path).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.core.volume import Volume
from ctui.engine.core.windows import auto_window
from ctui.engine.io.suffixes import NIFTI_SUFFIXES, NRRD_SUFFIXES

SAMPLE_ABOVE = 64 << 20  # declared bytes above which info samples slices
COMPRESSED_REACH = 256 << 20  # decompressed bytes a sampled slice of a compressed file may lie beyond


def _declared(p: Path) -> tuple[tuple[int, int, int], int, bool] | None:
    """((nz, ny, nx), bytes a voxel, compressed) from the header, or None (not sampled)."""
    name = p.name.lower()
    try:
        if name.endswith(NIFTI_SUFFIXES):
            import nibabel as nib

            img = nib.load(str(p))
            shp = [int(s) for s in img.shape] + [1, 1]
            return (shp[2], shp[1], shp[0]), int(img.header.get_data_dtype().itemsize), name.endswith(".gz")
        if name.endswith(NRRD_SUFFIXES):
            from ctui.engine.io.series.research import _TYPE, _read_nrrd_header  # loaded with its format

            hdr = _read_nrrd_header(p)
            # a compressed or text payload is decoded up to the sampled slice only (read_payload's zstop)
            packed = str(hdr.get("encoding", "raw")).lower() != "raw" or bool(int(hdr.get("line skip", 0) or 0))
            sizes = [int(s) for s in np.atleast_1d(hdr.get("sizes", []))] + [1, 1]
            code = _TYPE.get(str(hdr.get("type", "")).strip().lower())
            return ((sizes[2], sizes[1], sizes[0]), np.dtype(code).itemsize, packed) if code else None
        if name.endswith((".mhd", ".mha")):
            from ctui.engine.io.series.metaimage import _MET_TYPES, read_mhd_header  # each format on first use

            hdr, _ = read_mhd_header(p)
            if hdr.get("CompressedData", "False").lower() == "true":
                return None  # a zlib stream is inflated whole (bounded by the declared size)
            dims = [int(v) for v in hdr.get("DimSize", "").split()] + [1, 1]
            code = _MET_TYPES.get(hdr.get("ElementType", "").strip())
            return ((dims[2], dims[1], dims[0]), np.dtype(code).itemsize, False) if code else None
    except Exception:  # noqa: BLE001 - an unreadable header: the full load reports it
        return None
    return None


def inspect_volume_file(p: Path, load_file: Callable[..., Volume], *, spacing: Any = None, crop: Any = None,
                        downsample: Any = None, memory_limit: Any = None, **_: Any) -> Volume | None:
    """A headers-only Volume of the NIfTI/NRRD file ``p`` from sampled slices, or None
    (small, cropped or downsampled, compressed NRRD, or no slice could be read: load it
    whole). ``load_file(p, skipped=, spacing=, crop=, memory_limit=)`` is the format's loader."""
    if crop is not None or downsample is not None:
        return None
    d = _declared(p)
    if d is None:
        return None
    (nz, ny, nx), itemsize, compressed = d
    slice_bytes = ny * nx * max(itemsize, 1)
    if min(nz, ny, nx) < 1 or nz * slice_bytes <= SAMPLE_ABOVE:
        return None
    picks = sorted({0, nz // 2, nz - 1})
    if compressed:
        picks = [z for z in picks if (z + 1) * slice_bytes <= COMPRESSED_REACH] or [0]
    first, samples, ok, why, lo_hi = None, [], [], [], []
    for z in picks:
        try:
            v = load_file(p, skipped=[], spacing=spacing, crop=(z, z + 1, None, None, None, None),
                          memory_limit=memory_limit)
        except CtuiError as exc:
            why.append(str(exc))
            continue
        if z == 0:
            first = v
        flat = np.asarray(v.data).ravel()
        samples.append(flat[:: max(1, flat.size // 250_000)].astype(np.float32))  # window: 250 k values a slice
        fin_z = flat[np.isfinite(flat)] if flat.dtype.kind == "f" else flat
        if fin_z.size:
            lo_hi.append((float(fin_z.min()), float(fin_z.max())))
        ok.append(z)
    if first is None:
        return None
    sample = np.concatenate(samples)
    fin = sample[np.isfinite(sample)]
    placeholder = np.broadcast_to(np.zeros((), first.data.dtype), (nz, ny, nx))
    warnings = list(first.warnings) + ([f"{len(picks) - len(ok)} sampled slices could not be read ({why[0]})"]
                                       if why else [])
    vol = Volume(data=placeholder, spacing=first.spacing, origin=first.origin, direction=first.direction,
                 modality=first.modality, window=auto_window(fin.reshape(1, 1, -1) if fin.size else
                                                             np.zeros((1, 1, 1)), modality=first.modality),
                 source=f"{first.meta.get('format', 'volume')} {nz}x{ny}x{nx}, from {p}", warnings=warnings,
                 meta={**first.meta, "headers_only": True, "sampled_slices": ok,
                       "value_range": [min(v[0] for v in lo_hi), max(v[1] for v in lo_hi)] if lo_hi else None})
    return vol
