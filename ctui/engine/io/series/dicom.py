"""DICOM series loading (headers: :mod:`.dicom_headers` and its fast path
:mod:`.dicom_quick`; geometry: :mod:`.dicom_geometry`; pixels: :mod:`.dicom_pixels`).

Pipeline
--------
1. **Headers** of every file: the common Part-10 little-endian single-frame header is
   walked directly for the ~30 elements ctui reads (no pydicom import: ``ctui info`` on
   300 slices takes ~0.5 s of CPU); anything else goes through
   ``pydicom.dcmread(stop_before_pixels=True)`` (``force=True`` fallback for files
   without the preamble or file meta). The pixel data element's header gives the value
   offset and length, so the pixel pass reads exactly those bytes; sizes a header
   claims are checked against the file size. Multi-frame files (Enhanced CT/MR) give
   one entry per frame from the functional groups.
2. **Grouping** by SeriesInstanceUID of the image objects only: DICOM-SEG, RTSTRUCT,
   RT doses/plans, presentation states, SR, KO... are skipped as non-image objects
   (``skipped`` entries with an ``object`` kind; :mod:`.dicom_sop`). The series with most
   slices is loaded unless ``series=``
   picks one (index into :func:`scan`'s list, or a UID / UID prefix). Within the
   series, slices whose size or orientation differs from the majority are skipped with
   a reason.
3. **Sorting** along the slice normal n = row x col (ImageOrientationPatient) by
   n . ImagePositionPatient; slices far from the rest (a gap > 10x the median and
   > 10 mm) are skipped as outliers. Without positions: InstanceNumber order (a
   warning), then file name order. Spacing comes from the positions, never from
   SliceThickness.
4. **Pixels** are decoded in parallel threads straight into one preallocated array
   (its size checked first against :func:`ctui.engine.core.limits.available_memory`:
   free RAM, RLIMIT_AS and the cgroup limit): uncompressed data is read with
   ``readinto`` from the known offset; compressed transfer syntaxes go through
   pydicom's decoders (the ``codecs`` extra). RescaleSlope/Intercept are applied per
   slice; the output dtype is int16 when the rescaled values fit (CT), the stored
   integer type when no rescale is needed, else float32.
5. **Geometry**: the volume is always returned on a regular orthogonal grid so meshes
   built from it are not distorted:

   * gantry tilt (positions drifting in-plane along the stack): each slice is shifted
     in-plane (linear interpolation) onto the orthogonal grid along the normal, as
     dcm2niix does, and the grid grows to keep every pixel (up to 2x; beyond that the
     share cut is said); a warning gives the angle and the growth;
   * uneven gaps (missing slices, variable spacing) are resampled (linear along the
     normal) at the smallest gap as dcm2niix does (at most 2x the slice count), or
     the user's ``spacing`` dz (at most 4x); a warning says what was done. The original positions stay in
     ``Volume.slice_positions``.

No patient identifiers (name, ID, birth date, accession number, institution) are put
in the Volume; the series description, the source text and the series list are
scrubbed of the headers' own identifiers (:func:`ctui.engine.core.privacy.scrub_text`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ctui.engine.core.assumptions import Assumption, dropped_share_error
from ctui.engine.core.errors import LoadError
from ctui.engine.core.volume import Volume
from ctui.engine.core.windows import auto_window
from ctui.engine.io.series._common import (Plan, allocate, check_memory, make_plan, rel, run_parallel, scrub_obj,
                                           to_grey)
from ctui.engine.io.series._common import _safe
from ctui.engine.io.series.dicom_geometry import GridPlan, _dominant, _geometry, apply_grid, plan_grid
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
from ctui.engine.io.series.stacks import parse_spacing

__all__ = ["Frame", "Series", "read_header", "read_headers", "series_summary", "pick_series", "load_series",
           "codec_message", "MAX_COMPRESSION", "_ordered_series"]


def series_summary(s: Series, frames: list[Frame] | None = None, *, ids: set[str] | None = None) -> dict[str, Any]:
    """The contract's series dict (cheap: from headers); the description is scrubbed of
    ``ids`` (the headers' own patient identifiers)."""
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
        "description": scrub_obj(f0.description, ids) if ids else f0.description,
        "modality": f0.modality,
        "files": len(s.files),
        "shape_zyx": [nz, f0.rows, f0.cols],
        "spacing_zyx_mm": [round(dz, 6) if dz else None, dy, dx],
        "kind": "dicom-multiframe" if f0.nframes > 1 else "dicom",
    }


def pick_series(ordered: list[Series], series: Any, path: Any, *, slices: list[int] | None = None) -> Series:
    """The series ``series`` names (index into ``ordered`` or a UID / unique UID prefix);
    by default the one with most slices (``slices``: each series' slice count after
    duplicates and outliers, as :func:`series_summary` gives it; else its frame count),
    the first in ``ordered`` on a tie. Only image series reach here: DICOM-SEG, RTSTRUCT,
    SR... are skipped by the header reader (:mod:`.dicom_sop`)."""
    if series is None:
        counts = slices if slices is not None and len(slices) == len(ordered) else [len(s.frames) for s in ordered]
        return ordered[max(range(len(ordered)), key=lambda i: (counts[i], -i))]
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


@dataclass
class Prepared:
    """A series ready to decode: sorted frames, the crop/downsample plan, the output dtype
    and the regular grid (all from headers)."""

    frames: list[Frame]
    geo: dict[str, Any]
    plan: Plan
    full_shape: tuple[int, int, int]
    zsel: list[int]
    dtype: np.dtype
    optimistic: bool
    grid: GridPlan
    warnings: list[str]
    pixel_spacing: tuple[float, float]
    dz_user: float | None = None


def _skip_frame(skipped: list[dict[str, str]], f: Frame, base: Path | None, reason: str) -> None:
    skipped.append({"file": rel(f.file, base) + (f" frame {f.frame}" if f.nframes > 1 else ""), "reason": reason})


def prepare_series(s: Series, *, path: Any, base: Path | None, skipped: list[dict[str, str]], crop: Any = None,
                   downsample: Any = None, resample: bool = True, spacing: Any = None,
                   memory_limit: int | None = None, dtype: np.dtype | None = None, check: bool = True) -> Prepared:
    """Everything about a series that headers tell: order, geometry, output grid and
    dtype; files left out go to ``skipped``. Checks the memory the load will need
    (unless ``check`` is False: describing a series allocates nothing)."""
    frames = _dominant(s.frames, skipped, base)
    usable = []
    for f in frames:  # compressed files without a decoder: skip each with the reason
        if f.compressed and _codec_missing(f.syntax):
            _skip_frame(skipped, f, base, codec_message(f.syntax))
        else:
            usable.append(f)
    if not usable:
        reasons = {d["reason"] for d in skipped}
        only_codec = [r for r in reasons if "pip install" in r]
        raise LoadError(only_codec[0] if only_codec else "no loadable DICOM image in the series", path=path)
    frames = usable
    geo = _geometry(frames)
    for i in geo.get("dropped_no_position", []):
        _skip_frame(skipped, frames[i], base, "no ImagePositionPatient while the rest of the series has it")
    for i in geo.get("outliers", []):
        _skip_frame(skipped, frames[i], base, f"position {float(frames[i].ipp @ geo['normal']):.6g} mm along the "
                    f"slice normal is far from the rest of the series (outlier)")
    for i in geo.get("duplicates", []):
        _skip_frame(skipped, frames[i], base, "same position as another slice of the series")
    sorted_frames = [frames[i] for i in geo["order"]]
    f0 = sorted_frames[0]
    full_shape = (len(sorted_frames), f0.rows, f0.cols)
    plan = make_plan(full_shape, crop=crop, downsample=downsample, path=path)
    zsel = list(range(*plan.z.indices(full_shape[0])))
    if dtype is None:
        dtype, optimistic = _out_dtype([sorted_frames[k] for k in zsel])
    else:
        optimistic = False
    warnings = list(geo["warnings"])
    odd = sorted({f.ignored_scaling for f in sorted_frames if f.ignored_scaling})
    if odd:
        text = f"implausible header values: {odd[0]}" + (f" (and {len(odd) - 1} other kinds)" if len(odd) > 1 else "")
        warnings.append(Assumption(text, "spacing" if "PixelSpacing" in text else "values"))
    dy, dx = f0.pixel_spacing or (None, None)
    if dy is None:
        dy = dx = 1.0
        if not any("PixelSpacing" in w for w in warnings):
            warnings.append(Assumption("no PixelSpacing: default spacing 1 mm in-plane", "spacing"))
    zs, ys, xs = plan.steps()
    dz_user = None
    if spacing is not None:
        dz_user = parse_spacing(spacing, path)[0] * zs
    out_shape = plan.out_shape(full_shape)
    grid = plan_grid(geo, zsel, dy=dy * ys, dx=dx * xs, ny=out_shape[1], nx=out_shape[2], dz_user=dz_user,
                     resample=resample)
    final = grid.out_shape(len(zsel))
    # the decoded stack plus the largest regridded copy are alive at once
    nbytes = (int(np.prod(out_shape)) + (int(np.prod(final)) if final != out_shape else 0)) * dtype.itemsize
    if check:
        check_memory(nbytes, shape=final, path=path, limit=memory_limit)
    return Prepared(frames=sorted_frames, geo=geo, plan=plan, full_shape=full_shape, zsel=zsel, dtype=dtype,
                    optimistic=optimistic, grid=grid, warnings=warnings, pixel_spacing=(dy, dx), dz_user=dz_user)


def _decode_frame(f: Frame, dst: np.ndarray, ysl: slice, xsl: slice, full_plane: bool, optimistic: bool,
                  overflow: list, k: int) -> str | None:
    """Decode one frame into ``dst`` (its output slice); None or the reason it failed."""
    if full_plane and _fast_ok(f, dst.dtype):
        return _decode_native_into(f, dst, optimistic, overflow, k)
    try:
        raw = _decode_native(f) if not f.compressed else _decode_pydicom(f)
    except _Skip as sk:
        return str(sk)
    if raw.shape[:2] != (f.rows, f.cols):
        return f"decoded size {raw.shape[:2]} differs from the header's {f.rows}x{f.cols}"
    if raw.ndim == 3:
        raw = to_grey(raw)
    # MONOCHROME1 is display polarity only (white = the minimum): the stored values, rescaled,
    # are the HU / modality values, so they are kept as they are (a warning says so)
    sub = raw[ysl, xsl]
    if dst.dtype.kind == "f":
        v = sub.astype(np.float32)
        if f.slope != 1.0:
            v *= np.float32(f.slope)
        if f.intercept != 0.0:
            v += np.float32(f.intercept)
        dst[...] = v
    elif f.slope == 1 and f.intercept == 0 and not optimistic and sub.dtype.newbyteorder("=") == dst.dtype:
        dst[...] = sub
    else:
        v = sub.astype(np.int64 if sub.dtype.itemsize >= 4 else np.int32)
        if f.slope != 1:
            v *= int(f.slope)
        if f.intercept:
            v += int(f.intercept)
        if optimistic:
            info = np.iinfo(dst.dtype)
            if v.size and (v.min() < info.min or v.max() > info.max):
                overflow.append(k)
                return None
        dst[...] = v
    return None


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
    spacing: Any = None,
    memory_limit: int | None = None,
    all_series: list[dict[str, Any]] | None = None,
    _dtype: np.dtype | None = None,
) -> Volume:
    """Decode one series into a Volume (see the module docstring).

    ``spacing``: (dz, dy, dx) or a number; its dz is the step of the regular grid an
    unevenly spaced or tilted series is resampled onto (default: the smallest gap, at
    most 2x the slices, as dcm2niix). In-plane spacing always comes from the header.
    """
    n_skipped_at_entry = len(skipped)
    prep = prepare_series(s, path=path, base=base, skipped=skipped, crop=crop, downsample=downsample,
                          resample=resample, spacing=spacing, memory_limit=memory_limit, dtype=_dtype)
    sorted_frames, plan, zsel = prep.frames, prep.plan, prep.zsel
    f0 = sorted_frames[0]
    out = allocate(plan.out_shape(prep.full_shape), prep.dtype)
    overflow: list[int] = []
    full_plane = plan.y == slice(0, f0.rows, 1) and plan.x == slice(0, f0.cols, 1)

    def work(k: int, zi: int) -> str | None:
        return _decode_frame(sorted_frames[zi], out[k], plan.y, plan.x, full_plane, prep.optimistic, overflow, k)

    failures = run_parallel(zsel, work, progress=progress)
    if overflow:
        # values do not fit the optimistic dtype (rare): decode again into int32
        del out
        del skipped[n_skipped_at_entry:]
        return load_series(s, path=path, base=base, skipped=skipped, ids=ids, crop=crop, downsample=downsample,
                           progress=progress, resample=resample, spacing=spacing, memory_limit=memory_limit,
                           all_series=all_series, _dtype=np.dtype(np.int32))
    bad = {k for k, _ in failures}
    for k, reason in failures:
        _skip_frame(skipped, sorted_frames[zsel[k]], base, reason)
    keep_k = [k for k in range(len(zsel)) if k not in bad]
    if not keep_k:
        raise LoadError("no slice of the series could be decoded" + (f" ({failures[0][1]})" if failures else ""), path=path)
    warnings = prep.warnings
    grid = prep.grid
    if bad:
        # drop failed slices in place (no second full-size array), then plan the grid again
        for j, k in enumerate(keep_k):
            if j != k:
                out[j] = out[k]
        out = out[: len(keep_k)]
        zsel = [zsel[k] for k in keep_k]
        dy, dx = prep.pixel_spacing
        zs, ys, xs = plan.steps()
        grid = plan_grid(prep.geo, zsel, dy=dy * ys, dx=dx * xs, ny=out.shape[1], nx=out.shape[2],
                         dz_user=prep.dz_user, resample=resample)
        refusal = dropped_share_error(len(bad), len(zsel) + len(bad))
        if refusal:
            raise LoadError(refusal + f" ({failures[0][1]})", path=path)
        warnings.append(Assumption(f"{len(bad)} of {len(zsel) + len(bad)} slices could not be decoded and are missing"
                                   + (": the gaps are interpolated" if grid.positions is not None else " from the volume"),
                                   "slices", len(bad), len(zsel) + len(bad)))

    def check(nbytes: int, what: str) -> None:
        check_memory(nbytes, shape=(1, 1, 1), path=path, limit=memory_limit, what=what)

    out = apply_grid(out, grid, check=check)
    return _volume(out, prep, grid, zsel, s=s, path=path, skipped=skipped, ids=ids, all_series=all_series)


def inspect_series(s: Series, *, path: Any, base: Path | None, skipped: list[dict[str, str]], ids: set[str],
                   crop: Any = None, downsample: Any = None, resample: bool = True, spacing: Any = None,
                   all_series: list[dict[str, Any]] | None = None, **_: Any) -> Volume:
    """The Volume :func:`load_series` would give, from headers and three sample slices
    (first, middle, last): ``data`` is a zero-byte read-only placeholder of the final
    shape and dtype; ``meta["headers_only"]`` is True and ``meta["value_range"]`` the
    sampled slices' range (``ctui info`` on 300 slices of 512x512 reads no other pixel)."""
    prep = prepare_series(s, path=path, base=base, skipped=skipped, crop=crop, downsample=downsample,
                          resample=resample, spacing=spacing, check=False)
    plan, zsel, f0 = prep.plan, prep.zsel, prep.frames[0]
    ny, nx = plan.out_shape(prep.full_shape)[1:]
    picks = sorted({zsel[0], zsel[len(zsel) // 2], zsel[-1]})
    check_memory(len(picks) * ny * nx * prep.dtype.itemsize, shape=(len(picks), ny, nx), path=path,
                 what=f"{len(picks)} sample slices of {ny}x{nx}")
    # int16 is the optimistic guess (load_series decodes again into int32 when a value does not
    # fit): the sample is decoded into int32 so that unsigned CT above 33791 HU is not wrapped
    sdtype = np.dtype(np.int32) if prep.optimistic and prep.dtype.itemsize < 4 else prep.dtype
    sample = np.empty((len(picks), ny, nx), sdtype)
    full_plane = plan.y == slice(0, f0.rows, 1) and plan.x == slice(0, f0.cols, 1)
    # the same error mapping as load_series (run_parallel's _safe): undecodable pixels skip the sample
    why = [_safe(lambda k_, zi_: _decode_frame(prep.frames[zi_], sample[k_], plan.y, plan.x, full_plane, False, [], k_),
                 k, zi) for k, zi in enumerate(picks)]
    ok = [k for k, r in enumerate(why) if r is None]
    sampled = [picks[k] for k in ok]
    sample = sample[ok] if ok else np.zeros((1, ny, nx), sdtype)  # for the window only; no value range
    grid = prep.grid
    shape = grid.out_shape(len(zsel))
    fits = sdtype == prep.dtype or (sample.min() >= np.iinfo(prep.dtype).min and sample.max() <= np.iinfo(prep.dtype).max)
    placeholder = np.broadcast_to(np.zeros((), prep.dtype if fits else sdtype), shape)
    vol = _volume(placeholder, prep, grid, zsel, s=s, path=path, skipped=skipped, ids=ids, all_series=all_series,
                  sample=sample)
    vol.meta["headers_only"] = True
    if len(ok) < len(picks):
        first = next(r for r in why if r is not None)
        vol.warnings.append(f"{len(picks) - len(ok)} of {len(picks)} sampled slices could not be decoded ({first})")
    # the range of the sampled slices only (None when none decoded): ctui info says so
    vol.meta["value_range"] = [float(sample.min()), float(sample.max())] if ok else None
    vol.meta["sampled_slices"] = [zsel.index(zi) for zi in sampled]
    return vol


def _grid_origin(prep: Prepared, grid: GridPlan, zsel: list[int]) -> np.ndarray:
    """Patient position (x, y, z) of voxel (0, 0, 0) of the output grid."""
    geo, plan = prep.geo, prep.plan
    dy, dx = prep.pixel_spacing
    zs, ys, xs = plan.steps()
    y0, x0 = plan.starts(prep.full_shape)[1:]
    row, col, normal = geo["row"], geo["col"], geo["normal"]
    origin = geo["origin"] if geo["origin"] is not None else np.zeros(3)
    origin = np.asarray(origin, float) + x0 * dx * row + y0 * dy * col
    origin = origin - grid.pad_yx[0] * dy * ys * col - grid.pad_yx[1] * dx * xs * row
    if grid.positions is not None:
        origin = origin + (grid.positions[0] - geo["positions"][0]) * normal
    elif zsel[0]:
        origin = origin + zsel[0] * geo["dz"] * normal
    return origin


def _volume(out: np.ndarray, prep: Prepared, grid: GridPlan, zsel: list[int], *, s: Series, path: Any,
            skipped: list[dict[str, str]], ids: set[str], all_series: list[dict[str, Any]] | None,
            sample: np.ndarray | None = None) -> Volume:
    f0 = prep.frames[0]
    plan = prep.plan
    dy, dx = prep.pixel_spacing
    zs, ys, xs = plan.steps()
    warnings = prep.warnings + grid.warnings
    meta: dict[str, Any] = {"format": "dicom", "transfer_syntax": f0.syntax, "rescale": [f0.slope, f0.intercept],
                            "photometric": f0.photometric, **grid.meta}
    dz = grid.dz if grid.positions is not None or prep.dz_user else prep.geo["dz"] * zs
    window = f0.window
    if window is None:
        window = auto_window(out if sample is None else sample, modality=f0.modality)
    if f0.photometric == "MONOCHROME1":
        warnings.append("MONOCHROME1 image (displayed inverted by its modality: white = low values): the values "
                        "are kept as stored and rescaled, shown with ctui's usual polarity")
    if not plan.is_full(prep.full_shape):
        meta["crop_downsample"] = {"start_zyx": list(plan.starts(prep.full_shape)), "step_zyx": list(plan.steps()),
                                   "full_shape_zyx": list(prep.full_shape)}
    vol = Volume(
        data=out,
        spacing=(dz, dy * ys, dx * xs),
        origin=tuple(_grid_origin(prep, grid, zsel)),
        direction=np.column_stack([prep.geo["row"], prep.geo["col"], prep.geo["normal"]]),
        modality=f0.modality,
        window=tuple(window),
        source=describe_source(s, f0, path, ids),
        series=all_series or [],
        skipped=skipped,
        warnings=warnings,
        slice_positions=grid.positions,
        meta=meta,
    )
    # the series list holds header text (descriptions): scrubbed of the headers' own identifiers
    vol.series = scrub_obj(vol.series, ids)
    return vol


def describe_source(s: Series, f0: Frame, path: Any, ids: set[str]) -> str:
    """"DICOM CT series 'desc', N files, from PATH" with the headers' patient identifiers
    (name, ID, birth date...) scrubbed from the description and the path."""
    n_files = len(s.files)
    desc = f0.description
    text = (f"DICOM {f0.modality} series" + (f" '{desc}'" if desc else "")
            + f", {n_files} file{'s' * (n_files != 1)}, from {path}")
    return scrub_obj(text, ids)
