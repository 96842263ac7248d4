"""Describe a series (``ctui info``): :func:`describe_series`."""

from __future__ import annotations

import math
import os
from typing import Any, Sequence

from ctui.engine.core.volume import Volume
from ctui.engine.io import memplan
from ctui.engine.io.series import inspect


def orientation_name(direction: Any) -> str:
    """'axial', 'coronal', 'sagittal' or 'oblique (near ...)' from the slice normal (direction[:, 2])."""
    n = [abs(float(v)) for v in (direction[0][2], direction[1][2], direction[2][2])]
    k = max(range(3), key=lambda i: n[i])
    name = ("sagittal", "coronal", "axial")[k]
    return name if n[k] > 0.995 else f"oblique (near {name})"


def describe_series(path: str | os.PathLike | Sequence[str], **load_options: Any) -> tuple[Volume, dict]:
    """(Volume, the JSON description of ``ctui info --json``).

    From the headers and three sample slices only (:func:`ctui.engine.io.series.inspect`:
    300 slices of 512x512 in well under a second); the Volume's ``data`` is then a
    placeholder and ``value_range`` that of the sampled slices (``meta["headers_only"]``;
    ``value_range_sampled`` True, ``sampled_slices`` how many; ``value_range`` None when
    none could be decoded). ``non_image_objects``: the skipped files that are DICOM
    objects other than images (DICOM-SEG, RTSTRUCT, SR...), each with its ``object`` kind.
    """
    vol = inspect(path, **load_options)
    d = vol.describe()  # headers-only: value_range from meta, nothing computed on the placeholder
    d["orientation"] = orientation_name(vol.direction)
    sampled = bool(vol.meta.get("headers_only"))
    vr = [float(v) for v in d["value_range"]]
    d["value_range"] = vr if all(math.isfinite(v) for v in vr) else None
    # DICOM: the range of the sampled slices only (a full load may reach further)
    d["value_range_sampled"] = sampled
    if sampled:
        d["sampled_slices"] = len(vol.meta.get("sampled_slices") or [])
    d["non_image_objects"] = [sk for sk in vol.skipped if sk.get("object")]
    if vol.slice_positions is not None:
        d["slice_positions_mm"] = [round(float(v), 4) for v in vol.slice_positions]
    d["meta"] = {k: v for k, v in vol.meta.items() if isinstance(v, (str, int, float, bool, list, dict))}
    d["memory_plan"] = memory_plans(vol.shape, load_options.get("memory_limit"))
    return vol, d


def memory_plans(shape: Sequence[int], memory: Any = None) -> dict:
    """Each command's :class:`~ctui.engine.io.memplan.MemoryPlan` for a series of ``shape``
    (nz, ny, nx): ``{"limit_bytes", "limit_source", command: {"mode", "need_bytes", "reason"}}``."""
    limit, source = memplan.memory_limit(memory)
    out: dict[str, Any] = {"limit_bytes": limit, "limit_source": source}
    if len(shape) == 3:
        for cmd in memplan.REPORTED:
            nz, ny, nx = (int(v) for v in shape)
            p = memplan.decide(cmd, (nz, ny, nx), limit=limit, source=source)
            out[cmd] = {"mode": p.mode, "need_bytes": p.need_bytes, "reason": p.reason}
    return out
