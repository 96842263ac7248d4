"""The auto action: a whole-body model's first draft as named objects over the series (``ctui auto``).

:func:`auto_segment` runs an engine from :data:`ENGINES` (``totalsegmentator``: the user's own
TotalSegmentator, :mod:`ctui.engine.io.totalseg`) on the series, places its label map on the
series' grid (``io.imports.place_on_grid``: axis order, flips and whole-voxel offsets; anything
else is refused with how the grids differ) and merges its classes into the labels the caller
already has, by a policy from :data:`MERGE`:

* ``add`` (default): every class becomes a new object; voxels of existing objects stay theirs;
* ``replace``: a class named like an existing object takes its place (the object's voxels are
  cleared first) and the classes' voxels win over other objects;
* ``keep``: a class named like an existing object is skipped (the user's object stays); the
  others are added as with ``add``.

Objects are named with TotalSegmentator's class names (``liver``, ``kidney_left``: its standard
names, as its label maps and statistics call them) and coloured from its class map; a class keeps
its TotalSegmentator number as object id when that id is free, else takes the lowest free one.
"""

from __future__ import annotations

import re
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.core.colors import object_color
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.progress import Progress, report
from ctui.engine.io import totalseg
from ctui.engine.io.imports import place_on_grid

ENGINES = {"totalsegmentator": "TotalSegmentator (117 CT classes with --task total; MR with total_mr; "
                               "installed by the user with its weights)"}
MERGE = {"add": "new objects beside the existing ones; existing voxels stay theirs",
         "replace": "a class named like an existing object replaces it; the classes' voxels win",
         "keep": "a class named like an existing object is skipped; the others are added"}
DEVICES = ("cpu", "gpu")
MAX_ID = 255
#: Tasks offered by name (any other TotalSegmentator task can be given to ``auto_segment``).
TASKS = {"total": "117 CT classes", "total_mr": "MR classes"}
#: ROI subsets offered (TotalSegmentator class names, in both ``total`` and ``total_mr`` where they exist):
#: each fits the TUI's editing (at most ``core.colors.MAX_OBJECTS`` objects); the first is the default.
ROI_SETS = {
    "abdominal organs": ("liver", "spleen", "kidney_left", "kidney_right", "pancreas", "gallbladder", "stomach"),
    "abdominal vessels": ("aorta", "inferior_vena_cava", "portal_vein_and_splenic_vein", "iliac_artery_left",
                          "iliac_artery_right"),
    "chest": ("heart", "lung_upper_lobe_left", "lung_lower_lobe_left", "lung_upper_lobe_right",
              "lung_middle_lobe_right", "lung_lower_lobe_right", "trachea", "esophagus", "aorta"),
    "pelvis": ("urinary_bladder", "prostate", "colon", "small_bowel", "hip_left", "hip_right", "sacrum"),
}


@dataclass
class AutoResult:
    """What :func:`auto_segment` made: labels (nz, ny, nx) uint8 on the series' grid, the objects (dicts:
    id, name, color, source, voxels, volume_ml), the classes skipped and why, the engine's run."""

    labels: np.ndarray
    objects: list[dict[str, Any]]
    added: list[dict[str, Any]] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    engine: str = defaults.AUTO_ENGINE
    task: str = defaults.AUTO_TASK
    command: list[str] = field(default_factory=list)
    seconds: float = 0.0
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"engine": self.engine, "task": self.task, "objects": self.added, "skipped": list(self.skipped),
                "seconds": round(self.seconds, 2), "warnings": list(self.warnings),
                "command": [Path(self.command[0]).name, *self.command[1:2], "IN", *self.command[3:4], "OUT",
                            *self.command[5:]] if self.command else []}


def auto_segment(volume: Any, *, engine: str = defaults.AUTO_ENGINE, task: str = defaults.AUTO_TASK,
                 roi_subset: Sequence[str] = (), fast: bool = False, device: str = defaults.AUTO_DEVICE,
                 labels: np.ndarray | None = None, objects: Sequence[dict[str, Any]] = (), merge: str = defaults.AUTO_MERGE,
                 max_id: int = MAX_ID, progress: Progress | None = None) -> AutoResult:
    """Run ``engine`` on ``volume`` (data (nz, ny, nx), spacing (dz, dy, dx) mm) and merge its classes into
    ``labels``/``objects`` (the caller's, default none) by ``merge``; see the module docstring.

    ``roi_subset``: class names to keep (TotalSegmentator's ``--roi_subset``); ``fast``: its 3 mm model;
    ``device``: "cpu" or "gpu"; ``max_id``: the highest object id (the TUI edits ids 1..10). Raises
    CtuiError before running when the engine, its weights or a licence for a licensed task is missing,
    and when the run fails.
    """
    if engine not in ENGINES:
        raise CtuiError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}", option="engine")
    if merge not in MERGE:
        raise CtuiError(f"merge must be one of {', '.join(MERGE)}, got {merge!r}", option="merge")
    if device not in DEVICES:
        raise CtuiError(f"device must be one of {', '.join(DEVICES)}, got {device!r}", option="device")
    bad = [n for n in roi_subset if not n or not all(c.isalnum() or c in "_-" for c in n)]
    if bad:
        raise CtuiError(f"class names are letters, digits, _ and -: got {bad[0]!r}", option="roi_subset")
    shape = tuple(volume.data.shape)
    if labels is not None and tuple(labels.shape) != shape:
        raise CtuiError(f"the labels {tuple(labels.shape)} are not on the series' grid {shape}")
    inst = totalseg.find(task)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="ctui-totalseg-") as tmp:
        src, out = Path(tmp) / "series.nii.gz", Path(tmp) / "classes.nii.gz"
        report(progress, 0, 100, "writing the series for TotalSegmentator")
        totalseg.write_input(src, volume)
        cmd = totalseg.command(inst, src, out, task=task, roi_subset=roi_subset, fast=fast, device=device)
        totalseg.run(cmd, progress=_lines(progress))
        if not out.exists():
            raise CtuiError("TotalSegmentator finished but wrote no label map", path=str(out.name))
        got = totalseg.read_output(out)
        placed = place_on_grid(got.labels, Geometry.of(got.volume), Geometry.of(volume), path="TotalSegmentator's output")
    report(progress, 95, 100, "merging the classes")
    res = merge_classes(placed, got.names, got.colours, labels=labels, objects=objects, merge=merge,
                        spacing=_spacing3(volume.spacing), source=f"TotalSegmentator {task}",
                        max_id=max_id)
    res.engine, res.task, res.command, res.seconds = engine, task, cmd, time.perf_counter() - t0
    if task in totalseg.LICENSED_TASKS:
        res.warnings.append(f"{task} is a licensed TotalSegmentator task (free for non-commercial use)")
    report(progress, 100, 100, "")
    return res


def missing(task: str = defaults.AUTO_TASK, *, engine: str = defaults.AUTO_ENGINE) -> str:
    """One line saying what is missing to run ``engine``'s ``task`` (the executable, its weights, a licence
    and how to install them), or "" when it can run."""
    try:
        totalseg.find(task)
    except CtuiError as exc:
        return str(exc)
    return ""


def _lines(progress: Progress | None) -> Any:
    """The engine's output lines as progress: the fraction from "part i of n" / "i/n" when it prints one."""
    if progress is None:
        return None
    state: dict[str, Any] = {"done": 1.0, "text": "running TotalSegmentator"}

    def line(text: str) -> bool | None:
        """A line of output ("" while it prints nothing: the last line stays)."""
        m = re.search(r"(\d+)\s*(?:of|/)\s*(\d+)", text)
        if m and 0 < int(m.group(2)) < 10000 and int(m.group(1)) <= int(m.group(2)):
            state["done"] = max(state["done"], 5 + 85 * int(m.group(1)) / int(m.group(2)))
        state["text"] = text[:120] or state["text"]
        return progress(state["done"], 100, state["text"])

    return line


def _spacing3(spacing: Sequence[float]) -> tuple[float, float, float]:
    dz, dy, dx = (float(v) for v in spacing)
    return dz, dy, dx


def merge_classes(classes: np.ndarray, names: dict[int, str], colours: dict[int, Any], *,
                  labels: np.ndarray | None = None, objects: Sequence[dict[str, Any]] = (), merge: str = defaults.AUTO_MERGE,
                  spacing: tuple[float, float, float] = (1.0, 1.0, 1.0), source: str = "",
                  max_id: int = MAX_ID) -> AutoResult:
    """Merge the label map ``classes`` (uint8 on the series' grid, values named by ``names``) into
    ``labels`` and ``objects`` (not changed: copies are returned) by ``merge``, object ids 1..``max_id``;
    see the module docstring."""
    out = np.zeros(classes.shape, np.uint8) if labels is None else np.array(labels, np.uint8, copy=True)
    objs = [dict(o) for o in objects]
    by_name = {str(o.get("name", "")): o for o in objs}
    counts = np.bincount(classes.ravel(), minlength=256)
    present = [int(v) for v in np.flatnonzero(counts[1:]) + 1]
    used = {int(o["id"]) for o in objs} | {int(v) for v in np.flatnonzero(np.bincount(out.ravel(), minlength=256)[1:]) + 1}
    added, skipped = [], []
    vox_ml = float(np.prod(spacing)) / 1000.0
    for v in present:
        name = names.get(v, f"label {v}")
        old = by_name.get(name)
        if old is not None and merge == "keep":
            skipped.append(f"{name}: kept the existing object {old['id']}")
            continue
        if old is not None and merge == "replace":
            oid = int(old["id"])
            out[out == oid] = 0
            objs.remove(old)
        else:
            oid = v if v not in used and v <= max_id else next((i for i in range(1, max_id + 1) if i not in used), 0)
            if not oid:
                skipped.append(f"{name}: no free object id (at most {max_id})")
                continue
        used.add(oid)
        m = classes == v
        if merge == "replace":
            out[m] = oid
        else:
            out[m & (out == 0)] = oid
        colour = colours.get(v) or object_color(oid)
        obj = {"id": oid, "name": name, "color": [int(c) for c in colour], "source": source, "source_number": v}
        objs.append(obj)
        n = int(np.count_nonzero(out == oid))
        added.append({"id": oid, "name": name, "voxels": n, "volume_ml": round(n * vox_ml, 4), "class": v})
    objs.sort(key=lambda o: int(o["id"]))
    return AutoResult(labels=out, objects=objs, added=added, skipped=skipped)
