"""One slice of a series before the rest is read: what the TUI shows while it loads.

:func:`preview` reads the middle slice of what :func:`ctui.engine.io.series.load` would give
(same voxel values, in-plane spacing, direction, and the origin of that slice), at a small
part of the cost of the whole read:

* a DICOM folder (or list of files): every header (the fast header path: ~0.06 s for 300
  slices), the series ``load`` would choose, and that one file decoded through the
  loader's own code (a one-slice crop), when the series lies on a regular grid as it is
  (no resampling of uneven slices, no gantry-tilt correction: then None);
* a NIfTI, NRRD or uncompressed MetaImage file: the header's shape, then a one-slice crop
  through the format's reader (NIfTI reads its gzip stream only up to the slice; in a
  compressed file the slice lies within the first :data:`COMPRESSED_REACH` bytes: the
  middle one, or an earlier one of a large file).

The window is the full read's when the header gives one or the data is CT (the CT
default); otherwise it is the one slice's percentile window (the whole volume's may
differ). Anything else (image stacks, raw data, loader options that change the grid, an
error: the full read reports it) gives None.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ctui.engine.core.errors import CtuiError
from ctui.engine.core.volume import Volume
from ctui.engine.io.series._common import list_files

__all__ = ["Preview", "preview"]

#: decompressed bytes a preview slice of a compressed NIfTI/NRRD may lie beyond (the full read
#: inflates the file again: a middle slice of a 1 GB .nii.gz would add half of it)
COMPRESSED_REACH = 32 << 20
#: load options a preview can follow (others change the grid: no preview)
_FOLLOWED = {"series", "spacing", "resample", "memory_limit"}


@dataclass
class Preview:
    """Slice ``z`` of the volume :func:`load` gives for the same path and options.

    volume : Volume, data (1, ny, nx); spacing, direction and modality as the full volume's,
        origin that of slice ``z`` (LPS mm)
    z : index of the slice in the full volume (the middle one, or an earlier one of a large
        compressed file)
    depth : slices of the full volume (nz)
    """

    volume: Volume
    z: int
    depth: int


def preview(path: Any, *, min_voxels: int = 0, **options: Any) -> Preview | None:
    """The middle slice of the series at ``path`` (see the module docstring), or None
    when it cannot be had cheaply or exactly, or the whole volume has fewer than
    ``min_voxels`` voxels (it loads about as fast as its preview). ``options``:
    :func:`load`'s keywords; any beyond ``series``, ``spacing``, ``resample`` and
    ``memory_limit`` (crop, downsample, raw shape...) give None."""
    from ctui.engine.io.series import _as_paths, _classify, _is_volume_file  # the package imports this lazily

    if set(k for k, v in options.items() if v is not None) - _FOLLOWED:
        return None
    try:
        single, files = _as_paths(path)
        if files is None and single is not None and single.is_file() and _is_volume_file(single):
            return _volume_file(single, min_voxels=min_voxels, spacing=options.get("spacing"),
                                memory_limit=options.get("memory_limit"))
        if files is None:
            if single is None or not single.is_dir():
                return None
            files = list_files(single, skipped=[])
            base: Path | None = single
        else:
            base = single
        if not files or _classify(files, shape=None) != "dicom":
            return None
        return _dicom(files, base=base, label=path, min_voxels=min_voxels, **options)
    except (CtuiError, OSError):  # the full read says what is wrong
        return None


def _dicom(files: list[Path], *, base: Path | None, label: Any, min_voxels: int, series: Any = None,
           spacing: Any = None, resample: bool = True, memory_limit: int | None = None) -> Preview | None:
    from ctui.engine.io.series import _finite, dicom  # the DICOM loader loads when DICOM files are met

    found, _, ids = dicom.read_headers(files, base=base, remember=True)  # the full load reads them once
    if not found:
        return None
    ordered = dicom._ordered_series(found)
    summaries = [dicom.series_summary(s, ids=ids) for s in ordered]
    chosen = dicom.pick_series(ordered, series, label, slices=[d["shape_zyx"][0] for d in summaries])
    prep = dicom.prepare_series(chosen, path=label, base=base, skipped=[], resample=resample, spacing=spacing,
                                check=False)
    if prep.grid.grid is not None or prep.grid.shifts_yx is not None:
        return None  # resampled or tilt-corrected: a slice of the files is not a slice of the volume
    depth = len(prep.zsel)
    if depth * prep.frames[0].rows * prep.frames[0].cols < min_voxels:
        return None
    z = depth // 2
    vol = dicom.load_series(chosen, path=label, base=base, skipped=[], ids=ids, crop=(z, z + 1, None, None, None, None),
                            resample=resample, spacing=spacing, memory_limit=memory_limit, all_series=summaries)
    vol = _finite(vol)
    if vol.shape[0] != 1:
        return None
    return Preview(volume=vol, z=z, depth=depth)


def _volume_file(p: Path, *, min_voxels: int, spacing: Any, memory_limit: int | None) -> Preview | None:
    from ctui.engine.io.series import _load_volume_file, _with_series  # the package imports this lazily
    from ctui.engine.io.series.sampled import _declared  # the header's shape, as ctui info samples it

    d = _declared(p)
    if d is None:
        return None
    (depth, ny, nx), itemsize, compressed = d
    if depth < 1 or depth * ny * nx < min_voxels:
        return None
    z = depth // 2
    if compressed:  # inflated up to the slice, then again by the full read: not far in
        z = min(z, max(0, COMPRESSED_REACH // max(ny * nx * itemsize, 1) - 1))
    vol = _load_volume_file(p, skipped=[], spacing=spacing, crop=(z, z + 1, None, None, None, None),
                            memory_limit=memory_limit)
    vol = _with_series(vol)
    if vol.shape[0] != 1:
        return None
    return Preview(volume=vol, z=z, depth=depth)
