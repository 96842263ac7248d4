"""DICOM series loading.

Pipeline
--------
1. **Headers** of every file are read with ``pydicom.dcmread(stop_before_pixels=True)``
   (``force=True`` fallback for files without the 128-byte preamble / 'DICM' prefix or
   file meta). The pixel data element's header is parsed right after, giving the value
   offset and length, so the pixel pass reads exactly those bytes. Multi-frame files
   (Enhanced CT/MR) give one entry per frame, with per-frame positions, orientation,
   pixel spacing and rescale from the functional groups.
2. **Grouping** by SeriesInstanceUID; the largest series is loaded unless ``series=``
   picks one (index into :func:`scan_dicom`'s list, or a UID / UID prefix). Within the
   series, slices whose size or orientation differs from the majority are skipped with
   a reason.
3. **Sorting** along the slice normal n = row x col (ImageOrientationPatient) by
   n . ImagePositionPatient. Without positions: InstanceNumber order (a warning), then
   file name order. Spacing comes from the positions, never from SliceThickness.
4. **Pixels** are decoded in parallel threads straight into one preallocated array:
   uncompressed data is read with ``readinto`` from the known offset; compressed
   transfer syntaxes go through pydicom's pixel decoders (the ``codecs`` extra:
   ``pip install ctui[codecs]``). RescaleSlope/Intercept are applied per slice. The
   output dtype is int16 when the rescaled values fit (CT), the stored integer type
   when no rescale is needed, else float32.
5. **Geometry**: the volume is always returned on a regular orthogonal grid so meshes
   built from it are not distorted:

   * gantry tilt (positions drifting in-plane along the stack) is corrected by
     shifting each slice in-plane (linear interpolation) onto the orthogonal grid
     along the normal, as dcm2niix does; a warning gives the angle;
   * uneven gaps between slices (missing slices, variable spacing) are resampled
     (linear along the normal) onto a regular grid at the median gap; a warning gives
     the gaps. The original positions stay in ``Volume.slice_positions``.

No patient identifiers (name, ID, birth date, accession number, institution) are put
in the Volume; strings taken from headers are scrubbed of them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np

from ctui.engine.core.errors import LoadError
from ctui.engine.core.volume import Volume
from ctui.engine.io.series._common import check_memory, make_plan, rel, run_parallel, scrub_obj, to_grey
from ctui.engine.io.series.dicom_geometry import _dominant, _geometry, _resample_z, _tilt_correct, _uneven
from ctui.engine.io.series.dicom_headers import (
    MAX_COMPRESSION,
    Frame,
    Series,
    _ordered_series,
    _Skip,
    read_header,
    read_headers,
)
from ctui.engine.io.series.dicom_pixels import (
    _codec_missing,
    _decode_native,
    _decode_native_into,
    _decode_pydicom,
    _fast_ok,
    _out_dtype,
    codec_message,
)

__all__ = ["Frame", "Series", "read_header", "read_headers", "series_summary", "pick_series", "load_series",
           "codec_message", "MAX_COMPRESSION", "_ordered_series"]


def series_summary(s: Series, frames: list[Frame] | None = None) -> dict[str, Any]:
    """The contract's series dict (cheap: from headers)."""
    frames = frames if frames is not None else s.frames
    f0 = frames[0]
    try:
        geo = _geometry(list(frames), quiet=True)
        nz, dz = len(geo["order"]), geo["dz"]
    except Exception:
        nz, dz = len(frames), None
    dy, dx = f0.pixel_spacing or (1.0, 1.0)
    return {
        "uid": s.uid,
        "description": f0.description,
        "modality": f0.modality,
        "files": len(s.files),
        "shape_zyx": [nz, f0.rows, f0.cols],
        "spacing_zyx_mm": [round(dz, 6) if dz else None, dy, dx],
        "kind": "dicom-multiframe" if f0.nframes > 1 else "dicom",
    }


def pick_series(ordered: list[Series], series: Any, path: Any) -> Series:
    if series is None:
        return max(ordered, key=lambda s: len(s.frames))  # first of the largest
    if isinstance(series, (int, np.integer)) or (isinstance(series, str) and series.strip().isdigit() and len(series.strip()) < 6):
        i = int(series)
        if not 0 <= i < len(ordered):
            raise LoadError(f"series index {i} out of range: {len(ordered)} series found (0..{len(ordered) - 1})", path=path)
        return ordered[i]
    key = str(series).strip()
    exact = [s for s in ordered if s.uid == key]
    if exact:
        return exact[0]
    pref = [s for s in ordered if s.uid.startswith(key)]
    if len(pref) == 1:
        return pref[0]
    raise LoadError(f"no series with UID {key!r} ({len(ordered)} series found; `ctui info` lists them)", path=path)


def load_series(
    s: Series,
    *,
    path: Any,
    base: Path | None,
    skipped: list[dict[str, str]],
    ids: set[str],
    crop: Any = None,
    downsample: Any = None,
    progress: Callable[[int, int], Any] | None = None,
    resample: bool = True,
    memory_limit: int | None = None,
    all_series: list[dict[str, Any]] | None = None,
    _dtype: np.dtype | None = None,
) -> Volume:
    """Decode one series into a Volume (see the module docstring)."""
    n_skipped_at_entry = len(skipped)
    frames = _dominant(s.frames, skipped, base)
    # compressed files without a decoder: skip each with the reason
    usable = []
    for f in frames:
        if f.compressed and _codec_missing(f.syntax):
            skipped.append({"file": rel(f.file, base), "reason": codec_message(f.syntax)})
        else:
            usable.append(f)
    if not usable:
        reasons = {d["reason"] for d in skipped}
        only_codec = [r for r in reasons if "pip install" in r]
        raise LoadError(only_codec[0] if only_codec else "no loadable DICOM image in the series", path=path)
    frames = usable
    geo = _geometry(frames)
    for i in geo.get("dropped_no_position", []):
        f = frames[i]
        skipped.append({"file": rel(f.file, base), "reason": "no ImagePositionPatient while the rest of the series has it"})
    warnings = list(geo["warnings"])
    order = geo["order"]
    dup_set = set(range(len(frames))) - set(order) - set(geo.get("dropped_no_position", []))
    for i in sorted(dup_set):
        f = frames[i]
        skipped.append({"file": rel(f.file, base) + (f" frame {f.frame}" if f.nframes > 1 else ""),
                        "reason": "same position as another slice of the series"})
    sorted_frames = [frames[i] for i in order]
    f0 = sorted_frames[0]
    full_shape = (len(sorted_frames), f0.rows, f0.cols)
    plan = make_plan(full_shape, crop=crop, downsample=downsample, path=path)
    out_shape = plan.out_shape(full_shape)
    zsel = list(range(*plan.z.indices(full_shape[0])))
    dtype, optimistic = (_dtype, False) if _dtype is not None else _out_dtype([sorted_frames[k] for k in zsel])
    extra = 0
    if resample and geo["uneven"] and geo["positions"] is not None:
        span = geo["positions"][zsel[-1]] - geo["positions"][zsel[0]]
        extra = int(round(span / (geo["dz"] * plan.steps()[0]))) + 1
    nbytes = int(np.prod(out_shape)) * dtype.itemsize
    check_memory(nbytes + extra * out_shape[1] * out_shape[2] * 4, shape=out_shape, path=path, limit=memory_limit)

    out = np.empty(out_shape, dtype=dtype)
    ysl, xsl = plan.y, plan.x
    overflow = []

    full_plane = plan.y == slice(0, f0.rows, 1) and plan.x == slice(0, f0.cols, 1)

    def work(k: int, zi: int) -> str | None:
        f = sorted_frames[zi]
        if full_plane and _fast_ok(f, out.dtype):
            return _decode_native_into(f, out[k], optimistic, overflow, k)
        try:
            raw = _decode_native(f) if not f.compressed else _decode_pydicom(f)
        except _Skip as sk:
            return str(sk)
        if raw.shape[:2] != (f.rows, f.cols):
            return f"decoded size {raw.shape[:2]} differs from the header's {f.rows}x{f.cols}"
        if raw.ndim == 3:
            raw = to_grey(raw)
        if f.photometric == "MONOCHROME1" and not raw.dtype.kind == "f":
            # inverted grey: white is the minimum; flip so that higher = brighter
            bs = f.bits_stored
            if f.signed:
                raw = (-raw.astype(np.int32) - 1)
            else:
                raw = (2**bs - 1) - raw.astype(np.int32)
        sub = raw[ysl, xsl]
        if out.dtype.kind == "f":
            v = sub.astype(np.float32)
            if f.slope != 1.0:
                v *= np.float32(f.slope)
            if f.intercept != 0.0:
                v += np.float32(f.intercept)
            out[k] = v
        elif f.slope == 1 and f.intercept == 0 and not optimistic and sub.dtype.newbyteorder("=") == out.dtype:
            out[k] = sub
        else:
            v = sub.astype(np.int64 if sub.dtype.itemsize >= 4 else np.int32)
            if f.slope != 1:
                v *= int(f.slope)
            if f.intercept:
                v += int(f.intercept)
            if optimistic:
                info = np.iinfo(out.dtype)
                if v.size and (v.min() < info.min or v.max() > info.max):
                    overflow.append(k)
                    return None
            out[k] = v
        return None

    failures = run_parallel(zsel, work, progress=progress)
    if overflow:
        # values do not fit the optimistic dtype (rare): decode again into int32
        del out
        del skipped[n_skipped_at_entry:]
        return load_series(s, path=path, base=base, skipped=skipped, ids=ids, crop=crop, downsample=downsample,
                           progress=progress, resample=resample, memory_limit=memory_limit,
                           all_series=all_series, _dtype=np.dtype(np.int32))
    bad = {k for k, _ in failures}
    for k, reason in failures:
        f = sorted_frames[zsel[k]]
        skipped.append({"file": rel(f.file, base) + (f" frame {f.frame}" if f.nframes > 1 else ""), "reason": reason})
    keep_k = [k for k in range(len(zsel)) if k not in bad]
    if not keep_k:
        raise LoadError("no slice of the series could be decoded" + (f" ({failures[0][1]})" if failures else ""), path=path)
    positions = geo["positions"][zsel] if geo["positions"] is not None else None
    if bad:
        # drop failed slices in place (no second full-size array)
        for j, k in enumerate(keep_k):
            if j != k:
                out[j] = out[k]
        out = out[: len(keep_k)]
        if positions is not None:
            positions = positions[keep_k]
            warnings.append(f"{len(bad)} slices could not be decoded and are missing: the gaps are interpolated")
        else:
            warnings.append(f"{len(bad)} slices could not be decoded and are missing from the volume")
    zsel = [zsel[k] for k in keep_k]
    zs, ys, xs = plan.steps()
    dy, dx = f0.pixel_spacing or (None, None)
    if dy is None:
        dy = dx = 1.0
        warnings.append("no PixelSpacing: default spacing 1 mm in-plane")
    row, col, normal = geo["row"], geo["col"], geo["normal"]
    y0, x0 = plan.starts(full_shape)[1:]
    dz = geo["dz"] * zs
    # --- gantry tilt: shift slices in-plane onto the orthogonal grid
    meta: dict[str, Any] = {"format": "dicom", "transfer_syntax": f0.syntax, "rescale": [f0.slope, f0.intercept],
                            "photometric": f0.photometric}
    if geo["tilt_shifts"] is not None:
        offs = geo["tilt_shifts"][zsel]
        _tilt_correct(out, offs, row, col, dy * ys, dx * xs)
        warnings.append(f"gantry tilt {geo['tilt_deg']:.2f} deg: slices shifted in-plane onto an orthogonal grid "
                        f"along the slice normal (linear interpolation)")
        meta["gantry_tilt_deg"] = round(geo["tilt_deg"], 4)
    # --- uneven spacing: resample along the normal
    if positions is not None and len(positions) > 1:
        gaps = np.diff(positions)
        dz = float(np.median(gaps))
        if _uneven(gaps):
            msg = f"uneven slice spacing (gaps {gaps.min():.3g} to {gaps.max():.3g} mm)"
            if resample:
                out = _resample_z(out, positions, dz)
                warnings.append(msg + f": resampled to a regular {dz:.4g} mm grid along the slice normal (linear)")
                meta["resampled"] = True
            else:
                warnings.append(msg + ": kept as is (resample=False); slice_positions gives each slice's position")
    origin = geo["origin"] if geo["origin"] is not None else np.zeros(3)
    origin = np.asarray(origin, float) + x0 * dx * row + y0 * dy * col
    if positions is not None:
        origin = origin + (positions[0] - geo["positions"][0]) * normal
    elif zsel[0]:
        origin = origin + zsel[0] * geo["dz"] * normal
    direction = np.column_stack([row, col, normal])
    modality = f0.modality
    window = f0.window
    if window is None:
        from ctui.engine.core.windows import auto_window

        window = auto_window(out, modality=modality)
    if f0.photometric == "MONOCHROME1":
        warnings.append("MONOCHROME1 (inverted grey) image: values inverted so that higher is brighter")
    if not plan.is_full(full_shape):
        meta["crop_downsample"] = {"start_zyx": list(plan.starts(full_shape)), "step_zyx": list(plan.steps()),
                                   "full_shape_zyx": list(full_shape)}
    desc = scrub_obj(f0.description, ids)  # header text: scrubbed of patient identifiers
    n_files = len(s.files)
    source = f"DICOM {modality} series" + (f" '{desc}'" if desc else "") + f", {n_files} file{'s' * (n_files != 1)}, from {path}"
    vol = Volume(
        data=out,
        spacing=(dz, dy * ys, dx * xs),
        origin=tuple(origin),
        direction=direction,
        modality=modality,
        window=tuple(window),
        source=source,
        series=all_series or [],
        skipped=skipped,
        warnings=warnings,
        slice_positions=positions,
        meta=meta,
    )
    # the series list holds header text (descriptions); paths given by the user are kept as given
    vol.series = scrub_obj(vol.series, ids)
    return vol

