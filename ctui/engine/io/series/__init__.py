"""Load CT/MR series and image stacks into :class:`~ctui.engine.core.volume.Volume`.

``load(path, **options)`` recognises what it is given:

* **DICOM**: a folder (searched recursively), one file, or a list of files; with or
  without the preamble / file meta; single- and multi-frame; grouped by
  SeriesInstanceUID (the image series with most slices unless ``series=``; DICOM-SEG,
  RTSTRUCT, SR and other non-image objects are skipped, each with an ``object`` kind
  and a reason: SEG and RTSTRUCT open as labels with --labels), sorted along the slice
  normal, rescaled to HU for CT; tilt and uneven spacing corrected onto a regular
  grid (see :mod:`ctui.engine.io.series.dicom`);
* **image stacks**: a folder of PNG/BMP/TIFF/JPEG slices (natural order: 2 before 10)
  or a multi-page TIFF; colour becomes grey; ``spacing`` default 1 mm (a warning);
* **raw**: one headerless file with ``shape=(z, y, x)`` (or ``(y, x)``: z from the
  size) and ``dtype`` (``'>u2'`` = big-endian uint16), or a folder / glob / list of
  headerless per-slice files with ``shape=(y, x)`` in numeric name order
  (CThead.1 .. CThead.113);
* **MetaImage** ``.mhd`` (+ ``.raw``) and ``.mha``; **GIPL** ``.gipl`` / ``.gipl.gz`` (ITK-SNAP).

Files that are not images, are broken, or whose slice size differs are skipped with a
reason each (``Volume.skipped``); when nothing loads a :class:`LoadError` names the
path. Before allocating, the memory needed is compared with the available memory; a
:class:`CtuiError` offers ``crop=`` / ``downsample=`` when it would not fit. Those two
options are applied while decoding, so the full array is never allocated.

Pixels are decoded by a thread pool into one preallocated array (peak memory: the
final array plus one slice buffer per thread).
"""

from __future__ import annotations

import glob
import os
import stat
from collections import Counter
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ctui.engine.core.assumptions import Assumption, dropped_share_error
from ctui.engine.core.errors import CtuiError, LoadError
from ctui.engine.core.progress import Progress, report
from ctui.engine.core.volume import Volume
from ctui.engine.core.windows import auto_window, ct_hint, looks_like_ct
from ctui.engine.io.series._common import IMAGE_SUFFIXES, available_memory, fmt_bytes, list_files, make_plan, natural_key, rel
from ctui.engine.io.suffixes import GIPL_SUFFIXES, NIFTI_SUFFIXES, NRRD_SUFFIXES

__all__ = ["load", "inspect", "scan", "estimate", "LoadError"]

_MHD = {".mhd", ".mha"}
_RESEARCH = (".nii", ".nii.gz", ".nrrd", ".nhdr", ".gipl", ".gipl.gz")


def _is_volume_file(p: Path) -> bool:
    """A single-file volume format with its own geometry (MetaImage, NIfTI, NRRD)."""
    name = p.name.lower()
    return p.suffix.lower() in _MHD or name.endswith(_RESEARCH)


def _load_volume_file(p: Path, **kw: Any) -> Volume:
    name = p.name.lower()
    if name.endswith(NIFTI_SUFFIXES):
        from ctui.engine.io.series.research import load_nifti  # loaded with its format

        return load_nifti(p, **kw)
    if name.endswith(NRRD_SUFFIXES):
        from ctui.engine.io.series.research import load_nrrd  # loaded with its format

        return load_nrrd(p, **kw)
    if name.endswith(GIPL_SUFFIXES):
        from ctui.engine.io.series.gipl import load_gipl  # loaded with its format

        return load_gipl(p, **kw)
    from ctui.engine.io.series.metaimage import load_mhd  # loaded with its format

    return load_mhd(p, **kw)


def _as_paths(path: Any) -> tuple[Path | None, list[Path] | None]:
    """(single path, None) or (common base, list of files)."""
    if isinstance(path, (list, tuple)):
        files = [Path(p) for p in path]
        if not files:
            raise LoadError("no files given", path="(empty list)")
        if len(files) == 1:
            return files[0], None
        try:
            base = Path(os.path.commonpath([str(p.parent) for p in files]))
        except ValueError:
            base = None
        return base, files
    s = str(path)
    if any(ch in s for ch in "*?[") and not Path(s).exists():
        files = sorted((Path(p) for p in glob.glob(s)), key=lambda p: natural_key(str(p)))
        files = [p for p in files if p.is_file()]
        if not files:
            raise LoadError("no file matches the pattern", path=s)
        return Path(os.path.commonpath([str(p.parent) for p in files])), files
    return Path(s), None


def _is_dicom_candidate(p: Path) -> bool:
    return p.suffix.lower() not in IMAGE_SUFFIXES | _MHD | {".raw", ".txt", ".md", ".json", ".nii", ".gz", ".nrrd", ".orig",
                                                             ".gipl"}


def _looks_dicom(p: Path) -> bool:
    """Cheap sniff: 'DICM' at 128, or a plausible first group-0008/0002 tag."""
    try:
        with open(p, "rb") as fh:
            head = fh.read(132)
    except OSError:
        return False
    if len(head) >= 132 and head[128:132] == b"DICM":
        return True
    if len(head) >= 8:
        group = int.from_bytes(head[0:2], "little")
        return group in (0x0002, 0x0008) or int.from_bytes(head[0:2], "big") in (0x0002, 0x0008)
    return False


def _classify(files: Sequence[Path], *, shape: Any) -> str:
    """'dicom', 'images', 'raw' or 'mhd' for a set of files."""
    if shape is not None:
        return "raw"
    if any(_looks_dicom(p) for p in files[:: max(1, len(files) // 64)][:64]) or any(
        _looks_dicom(p) for p in files if _is_dicom_candidate(p)
    ):
        return "dicom"
    if any(p.suffix.lower() in IMAGE_SUFFIXES for p in files):
        return "images"
    vols = [p for p in files if _is_volume_file(p)]
    if len(vols) == 1:
        return "mhd"
    return "dicom"  # last resort: try every file as DICOM (force=True), skipping with reasons


def load(
    path: str | os.PathLike | Sequence[str | os.PathLike],
    *,
    series: int | str | None = None,
    spacing: Any = None,
    shape: Any = None,
    dtype: Any = None,
    progress: Callable[[int, int], Any] | None = None,
    crop: Sequence[int | None] | None = None,
    downsample: int | Sequence[int] | None = None,
    offset: int | None = None,
    resample: bool = True,
    memory_limit: int | None = None,
    headers_only: bool = False,
    cache: bool = False,
    **options: Any,
) -> Volume:
    """Load a series, image stack or raw volume.

    Parameters
    ----------
    path : folder, file, glob pattern or list of files.
    series : int or str, optional
        DICOM series to load: index into :func:`scan`'s list (0-based) or a
        SeriesInstanceUID (or unique prefix). Default: the image series with most slices.
    spacing : float or (dz, dy, dx) mm, optional
        For image stacks and raw data (default 1 mm with a warning); overrides a
        MetaImage header's spacing. DICOM: only dz counts, the step of the regular grid
        an unevenly spaced or tilted series is resampled onto, or the slice step when
        the headers give no positions (a warning when an evenly spaced series ignores it).
    shape : (z, y, x) or (y, x), optional
        Raw data: the volume (one file) or slice (one file per slice) shape. Giving a
        shape makes ``path`` be read as raw.
    dtype : numpy dtype or str, optional
        Raw data: e.g. ``uint8``, ``int16``, ``'>u2'`` (big-endian uint16), ``float32``.
    progress : callable(done, total), optional
        Called as slices are decoded.
    crop : (z0, z1, y0, y1, x0, x1), optional
        Voxel index ranges of the full volume to load (end exclusive; None = edge).
    downsample : int or (sz, sy, sx), optional
        Integer strides: an int strides y and x (all slices kept); three ints stride
        z, y and x. Spacing grows accordingly.
    offset : int, optional
        Raw data: header bytes to skip.
    resample : bool
        DICOM: resample unevenly spaced slices onto a regular grid (default True).
    memory_limit : int, optional
        Bytes the volume may use (default: 90% of available memory).
    headers_only : bool
        DICOM: describe the volume from the headers and three sample slices (see
        :func:`inspect`); other inputs load whole.
    cache : bool
        Through the memory-mapped voxel cache (:mod:`ctui.engine.io.voxcache`): ``data`` maps a file.

    Returns
    -------
    Volume
        data (z, y, x) (int16 HU for CT when the values fit, else float32 or the stored
        integer type), spacing (dz, dy, dx) mm, origin/direction in LPS mm.

    Raises
    ------
    LoadError
        Nothing loadable at ``path`` (the message names it and why).
    CtuiError
        Bad options, or the volume would not fit in memory.
    """
    if options:
        raise CtuiError(f"unknown load option(s): {', '.join(sorted(options))}", path=path)
    opts = dict(series=series, spacing=spacing, shape=shape, dtype=dtype, crop=crop, offset=offset, resample=resample)
    if not headers_only and (got := _through_cache(path, cache, downsample=downsample, progress=progress, **opts)):
        return got
    single, files = _as_paths(path)
    common = dict(crop=crop, downsample=downsample, progress=progress, memory_limit=memory_limit)
    skipped: list[dict[str, str]] = []
    if files is None:
        p = single
        assert p is not None
        _check_exists(p)
        if p.is_dir():
            base = p
            files = _folder_files(p, skipped)
        else:
            base = p.parent
            vol = _single_file(p, headers_only=headers_only, shape=shape, dtype=dtype, spacing=spacing,
                               offset=offset, skipped=skipped, common=common)
            if vol is not None:
                return vol
            files = [p]
        path_label = p
    else:
        base = single
        path_label = f"{base}/ ({len(files)} files)" if base else f"{len(files)} files"
    kind = _classify(files, shape=shape)
    if kind != "dicom":
        return _with_series(_load_files(kind, files, single=single, base=base, path_label=path_label, shape=shape,
                                        dtype=dtype, spacing=spacing, offset=offset, skipped=skipped, common=common))
    return _finite(_load_dicom(files, base=base, path_label=path_label, skipped=skipped, series=series,
                               spacing=spacing, resample=resample, headers_only=headers_only, progress=progress,
                               common=common))


def _through_cache(path: Any, cache: bool, *, downsample: Any, **options: Any) -> Volume | None:
    """``cache``: the series through the voxel cache; else, asked for a uniform 2x/4x overview
    (``downsample=(f, f, f)``, a volume render's plan), the overview of its cache entry if it has
    one (no decode); else None (decode as usual)."""
    if cache:
        from ctui.engine.io.voxcache import load_cached  # only for series that do not fit in memory

        return load_cached(path, loader=load, downsample=downsample, **options)
    if not (isinstance(downsample, (tuple, list)) and len(downsample) == 3 and len(set(downsample)) == 1
            and int(downsample[0]) in (2, 4)):
        return None
    from ctui.engine.io.voxcache import cached_overview  # a lookup only when a uniform 2x/4x overview is asked

    options.pop("progress", None)
    return cached_overview(path, int(downsample[0]), **options)


def _check_exists(p: Path) -> None:
    if not p.exists():
        if p.is_symlink():
            raise LoadError("broken or looping symbolic link", path=p)
        raise LoadError("no such file or folder", path=p)


def _folder_files(p: Path, skipped: list[dict[str, str]]) -> list[Path]:
    """The files of a folder given to :func:`load`; a one-line LoadError when there are none."""
    files = list_files(p, skipped=skipped)
    if not files:
        raise LoadError("empty folder: no files to load" if not skipped else
                        f"no regular files to load ({skipped[0]['file']}: {skipped[0]['reason']})", path=p)
    return files


def _finite(vol: Volume) -> Volume:
    """NaN and infinite voxels (float pixel data, raw float16/32, NIfTI) set to the lowest
    finite value, with a warning: a NaN reaches meshes as NaN vertices, volumes as null.
    Slice by slice (one slice of temporaries)."""
    d = vol.data
    if d.dtype.kind != "f" or d.size == 0 or vol.meta.get("headers_only") or d.ndim != 3:
        return vol
    bad, lo = 0, np.inf
    for z in range(d.shape[0]):
        fin = np.isfinite(d[z])
        n = int(fin.size - np.count_nonzero(fin))
        bad += n
        if fin.any():
            lo = min(lo, float(d[z][fin].min()) if n else float(d[z].min()))
    if not bad:
        return vol
    lo = lo if np.isfinite(lo) else 0.0
    if not d.flags.writeable:
        vol.data = d = np.array(d)
    for z in range(d.shape[0]):
        sl = d[z]
        sl[~np.isfinite(sl)] = lo
    vol.warnings.append(Assumption(f"{bad} voxels are NaN or infinite: set to the lowest finite value {lo:g}", "values"))
    return vol


def _load_files(kind: str, files: list[Path], *, single: Path | None, base: Path | None, path_label: Any,
                shape: Any, dtype: Any, spacing: Any, offset: Any, skipped: list[dict[str, str]],
                common: dict[str, Any]) -> Volume:
    """Files classified as raw data, an image stack or one volume file ("mhd")."""
    if kind == "raw":
        from ctui.engine.io.series.raw import load_raw  # loaded with its format

        one = len(files) == 1 and not (single and single.is_dir())
        return load_raw(files[0] if one else (single or files[0]), None if one else files, shape=shape, dtype=dtype,
                        spacing=spacing, offset=offset, base=base, skipped=skipped, **common)
    if kind == "images":
        from ctui.engine.io.series.stacks import load_images  # loaded with its format

        imgs = [f for f in files if f.suffix.lower() in IMAGE_SUFFIXES]
        for f in files:
            if f.suffix.lower() not in IMAGE_SUFFIXES:
                skipped.append({"file": _rel(f, base), "reason": "not an image file (by extension)"})
        return load_images(imgs, path=path_label, base=base, skipped=skipped, spacing=spacing, **common)
    vf = next(f for f in files if _is_volume_file(f))
    return _load_volume_file(vf, skipped=skipped, spacing=spacing, **common)


def _single_file(p: Path, *, headers_only: bool, shape: Any, dtype: Any, spacing: Any, offset: Any,
                 skipped: list[dict[str, str]], common: dict[str, Any]) -> Volume | None:
    """A single file given by itself (:func:`_load_one_file`); a large NIfTI/NRRD described from
    sampled slices when ``headers_only`` (:mod:`.sampled`). None: try it as DICOM."""
    if headers_only and shape is None and _is_volume_file(p) and p.is_file():
        from ctui.engine.io.series.sampled import inspect_volume_file  # lazy: only ctui info imports it

        sampled = inspect_volume_file(p, _load_volume_file, spacing=spacing, **common)
        if sampled is not None:
            return _with_series(sampled)
    vol = _load_one_file(p, shape=shape, dtype=dtype, spacing=spacing, offset=offset, skipped=skipped,
                         common=common)
    return None if vol is None else _with_series(vol)


def _load_one_file(p: Path, *, shape: Any, dtype: Any, spacing: Any, offset: Any, skipped: list[dict[str, str]],
                   common: dict[str, Any]) -> Volume | None:
    """A single file given by itself: a volume file, raw data or one image; None for
    DICOM (or anything else, tried as DICOM)."""
    if not stat.S_ISREG(p.stat().st_mode):
        raise LoadError("not a regular file (FIFO, device or socket)", path=p)
    if not os.access(p, os.R_OK):
        raise LoadError("cannot read (permission denied)", path=p)
    if p.stat().st_size == 0:
        raise LoadError("empty file", path=p)
    if _is_volume_file(p) and shape is None:
        return _load_volume_file(p, skipped=skipped, spacing=spacing, **common)
    if shape is not None:
        from ctui.engine.io.series.raw import load_raw  # loaded with its format

        return load_raw(p, None, shape=shape, dtype=dtype, spacing=spacing, offset=offset, base=p.parent,
                        skipped=skipped, **common)
    if p.suffix.lower() in IMAGE_SUFFIXES:
        from ctui.engine.io.series.stacks import load_images  # loaded with its format

        return load_images([p], path=p, base=p.parent, skipped=skipped, spacing=spacing, **common)
    return None


def _load_dicom(files: list[Path], *, base: Path | None, path_label: Any, skipped: list[dict[str, str]],
                series: Any, spacing: Any, resample: bool, headers_only: bool, progress: Any,
                common: dict[str, Any]) -> Volume:
    """The DICOM part of :func:`load`: headers, series choice, then decode (or inspect)."""
    from ctui.engine.io.series import dicom  # the DICOM loader (a dozen modules) loads when DICOM files are met

    n_files = len(files)
    # progress: headers count as the first half of the work, decoding as the second
    head_progress = (lambda done, total: progress(done, 2 * total)) if progress else None
    found, skip2, ids = dicom.read_headers(files, base=base, progress=head_progress)
    skipped.extend(skip2)
    if progress:
        common["progress"] = lambda done, total: progress(n_files + done, n_files + total)
    if not found:
        reasons = {d["reason"] for d in skipped}
        why = next(iter(reasons)) if len(reasons) == 1 else "no DICOM image, image stack or MetaImage found"
        objects = sorted({d["object"] for d in skipped if d.get("object")})
        if objects and len(reasons) > 1:
            why = (f"no image series, only non-image DICOM objects ({', '.join(objects)})"
                   + ("; open a DICOM-SEG or RTSTRUCT as labels over its image series"
                      if {"DICOM-SEG", "RTSTRUCT"} & set(objects) else ""))
        hint = ("; for headerless raw data give its shape and data type"
                if any("not a DICOM" in r for r in reasons) else "")
        option = "labels" if {"DICOM-SEG", "RTSTRUCT"} & set(objects) else ("shape" if hint else None)
        raise LoadError(f"nothing loadable: {why}{hint}", path=path_label, option=option)
    ordered = dicom._ordered_series(found)
    summaries = [dicom.series_summary(s, ids=ids) for s in ordered]
    chosen = dicom.pick_series(ordered, series, path_label, slices=[d["shape_zyx"][0] for d in summaries])
    loader = dicom.inspect_series if headers_only else dicom.load_series
    vol = loader(chosen, path=path_label, base=base, skipped=skipped, ids=ids, resample=resample,
                 spacing=spacing, all_series=summaries, **common)
    unnamed = [d for d in skip2 if not d.get("series") and not d.get("object") and "not a DICOM" not in d["reason"]
               and "empty file" not in d["reason"]] if len(ordered) == 1 else []  # broken files of the one series
    _lost_slices(vol, [d for d in skip2 if d.get("series") == chosen.uid] + unnamed, len(chosen.frames),
                 path_label, refuse=not headers_only)
    if len(ordered) > 1:
        idx = ordered.index(chosen)
        vol.warnings.append(f"{len(ordered)} series found; loaded [{idx}] {chosen.uid} "
                            f"({len(chosen.frames)} images); choose another with series=N")
    vol.meta["series_index"] = ordered.index(chosen)
    return vol


def _lost_slices(vol: Volume, lost: list[dict[str, str]], n_read: int, path: Any, *, refuse: bool) -> None:
    """Files of the loaded series that could not be read (``lost``, beside the ``n_read``
    frames read) join the slices that could not be decoded in one "slices" assumption;
    past :data:`~ctui.engine.core.assumptions.MAX_DROPPED_SHARE` the series is refused."""
    if not lost:
        return
    prev = next((a for a in vol.assumptions if a.kind == "slices"), None)
    count = len(lost) + (prev.count if prev else 0)
    total = len(lost) + n_read
    refusal = dropped_share_error(count, total)
    if refusal and refuse:
        raise LoadError(f"{refusal} ({lost[0]['file']}: {lost[0]['reason']})", path=path)
    if prev is not None:
        vol.warnings.remove(prev)
    vol.warnings.append(Assumption(f"{count} of {total} slices could not be read and are missing "
                                   f"({lost[0]['file']}: {lost[0]['reason']})", "slices", count, total))


def inspect(path: str | os.PathLike | Sequence[str | os.PathLike], **options: Any) -> Volume:
    """What :func:`load` would give, without decoding the pixels (``ctui info``).

    DICOM: headers and three sample slices only; ``data`` is a zero-byte read-only
    placeholder of the volume's shape and dtype (``np.broadcast_to``), ``meta`` has
    ``headers_only: True`` and ``value_range`` (of the sampled slices, which
    ``Volume.value_range()`` returns). Other inputs are loaded whole. Options as
    :func:`load`.
    """
    return load(path, headers_only=True, **options)


def _rel(p: Path, base: Path | None) -> str:
    return rel(p, base)


def _recognise_ct(vol: Volume) -> None:
    """A non-DICOM volume with no modality is CT when its header's free text says so
    (NIfTI descrip/intent_name, NRRD content) and its values reach below -500, or when
    its values look like Hounsfield units (air near -1000, soft tissue near 0): it then
    gets modality "CT" (HU shown, CT window presets) and the CT default window."""
    if str(vol.modality or "OT").upper() not in ("OT", "") or vol.data.size == 0 or vol.data.dtype.kind not in "if":
        return
    hint = ct_hint(vol.meta.get("content_hint", ""))
    by = "header" if hint and float(np.nanmin(vol.data)) <= -500 else "values" if looks_like_ct(vol.data) else ""
    if by:
        vol.modality = "CT"
        vol.meta["modality_from"] = by
        vol.window = auto_window(vol.data, modality="CT")


def _with_series(vol: Volume) -> Volume:
    """Non-DICOM inputs: ``series`` gets their one entry (as ``scan`` gives it), NaN/inf
    voxels are replaced (:func:`_finite`), and CT is recognised by its header's text or its
    values (:func:`_recognise_ct`)."""
    vol = _finite(vol)
    if not vol.meta.get("headers_only"):
        _recognise_ct(vol)
    if not vol.series:
        vol.series = [{"uid": "", "description": vol.meta.get("format", ""), "modality": vol.modality,
                       "files": int(vol.meta.get("files", 1)), "shape_zyx": list(vol.shape),
                       "spacing_zyx_mm": [round(s, 6) for s in vol.spacing], "kind": vol.meta.get("format", "")}]
    return vol


def scan(path: str | os.PathLike | Sequence[str | os.PathLike], *, shape: Any = None, dtype: Any = None,
         spacing: Any = None, progress: Progress | None = None) -> list[dict[str, Any]]:
    """Series found at ``path``, from headers only (no pixel decoding).

    ``progress(done, total, message)`` is called while DICOM headers are read; it may
    raise :class:`~ctui.engine.core.progress.Cancelled` to stop (the TUI's open screen
    when the user moves on to another folder).

    Returns a list of dicts ``{"uid", "description", "modality", "files",
    "shape_zyx", "spacing_zyx_mm", "kind"}`` (DICOM: one per SeriesInstanceUID, in the
    order ``series=`` indexes; other inputs: one entry, uid ""). Empty when nothing
    loadable is found.
    """
    single, files = _as_paths(path)
    if files is None:
        p = single
        assert p is not None
        if not p.exists():
            raise LoadError("no such file or folder", path=p)
        files = list_files(p) if p.is_dir() else [p]
        base = p if p.is_dir() else p.parent
    else:
        base = single
    if not files:
        return []
    kind = _classify(files, shape=shape)
    if len(files) == 1 and _is_volume_file(files[0]) and shape is None:
        kind = "mhd"
    if len(files) == 1 and files[0].suffix.lower() in IMAGE_SUFFIXES:
        kind = "images"
    if kind == "dicom":
        from ctui.engine.io.series import dicom  # the DICOM loader (a dozen modules) loads when DICOM files are met

        found, _, ids = dicom.read_headers(files, base=base, progress=(
            None if progress is None else lambda done, total: report(progress, done, total, "reading headers")))
        return [dicom.series_summary(s, ids=ids) for s in dicom._ordered_series(found)]
    if kind == "images":
        from ctui.engine.io.series.stacks import image_entries, parse_spacing  # loaded with its format

        entries, _ = image_entries([f for f in files if f.suffix.lower() in IMAGE_SUFFIXES], base)
        if not entries:
            return []

        (h, w), n = Counter((e[2], e[3]) for e in entries).most_common(1)[0]
        sp = parse_spacing(spacing, path) or (1.0, 1.0, 1.0)
        multipage = len({e[0] for e in entries}) == 1 and len(entries) > 1
        return [{"uid": "", "description": "multi-page TIFF" if multipage else "image stack", "modality": "OT",
                 "files": len({e[0] for e in entries}), "shape_zyx": [n, h, w], "spacing_zyx_mm": list(sp),
                 "kind": "tiff" if multipage else "image-stack"}]
    if kind == "mhd":
        vf = next(f for f in files if _is_volume_file(f))
        if vf.suffix.lower() in _MHD:
            from ctui.engine.io.series.metaimage import mhd_spacing, read_mhd_header  # loaded with its format
            from ctui.engine.io.series.stacks import parse_spacing  # loaded with its format

            hdr, _ = read_mhd_header(vf)
            try:
                dims = [int(v) for v in hdr.get("DimSize", "0 0 0").split()] + [1]
            except ValueError:
                raise LoadError("MetaImage header lacks a valid DimSize", path=vf) from None
            sp = mhd_spacing(hdr)[0] if spacing is None else list(parse_spacing(spacing, vf))[::-1]
            return [{"uid": "", "description": "MetaImage",
                     "modality": {"MET_MOD_CT": "CT", "MET_MOD_MR": "MR"}.get(hdr.get("Modality", ""), "OT"),
                     "files": 1, "shape_zyx": [dims[2], dims[1], dims[0]], "spacing_zyx_mm": [sp[2], sp[1], sp[0]],
                     "kind": "mhd"}]
        if vf.name.lower().endswith(GIPL_SUFFIXES):
            from ctui.engine.io.series import gipl  # loaded with its format

            return [gipl.header_info(vf)]
        from ctui.engine.io.series.research import header_info  # loaded with its format

        return [header_info(vf)]
    # raw: geometry from the options
    from ctui.engine.io.series.stacks import parse_dtype, parse_shape, parse_spacing  # loaded with its format

    shp = parse_shape(shape, path)
    dt = parse_dtype(dtype, path)
    sp = parse_spacing(spacing, path) or (1.0, 1.0, 1.0)
    if len(shp) == 2:
        nbytes = shp[0] * shp[1] * dt.itemsize
        n = sum(1 for f in files if f.stat().st_size == nbytes) if len(files) > 1 else files[0].stat().st_size // nbytes
        shp = (n, *shp)
    return [{"uid": "", "description": f"raw {dt.str}", "modality": "OT", "files": len(files),
             "shape_zyx": list(shp), "spacing_zyx_mm": list(sp), "kind": "raw"}]


def estimate(path: Any, **opts: Any) -> dict[str, Any]:
    """Memory a load would need (from headers): ``{"shape_zyx", "bytes", "available", "fits"}``.

    Options as :func:`load` (series, shape, dtype, crop, downsample); the dtype assumed
    for DICOM is 2 bytes per voxel (int16 HU), 4 for float data.
    """
    info = scan(path, shape=opts.get("shape"), dtype=opts.get("dtype"), spacing=opts.get("spacing"))
    if not info:
        raise LoadError("nothing loadable found", path=path)
    s = opts.get("series")
    if s is None:
        entry = max(info, key=lambda d: d["shape_zyx"][0])
    elif isinstance(s, int):
        entry = info[s]
    else:
        entry = next((d for d in info if d["uid"].startswith(str(s))), info[0])
    shp = entry["shape_zyx"]
    plan = make_plan(shp, crop=opts.get("crop"), downsample=opts.get("downsample"), path=path)
    out = plan.out_shape(shp)
    item = 2
    if opts.get("dtype") is not None:
        item = np.dtype(opts["dtype"]).itemsize
    nbytes = int(np.prod(out)) * item
    avail = available_memory()
    return {"shape_zyx": list(out), "bytes": nbytes, "human": fmt_bytes(nbytes), "available": avail,
            "fits": nbytes <= 0.9 * avail}
