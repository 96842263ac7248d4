"""Extract a vessel from a start, waypoints and ends: :func:`vessel` (``ctui vessel``, the TUI's
vessel tool) and :func:`save_vessel` (its project, label map, section table and plot).

Points are voxels (x, y, z) = (column, row, slice), numbered from 0, as ``ctui segment --seed``.
The engine (:mod:`ctui.engine.vessel`): a minimal path on a speed map from the lumen's values
through the points, a colliding-fronts core along each leg, growth plane by plane normal to the
path with a continuity rule and cut planes at both ends, and the sections along the path.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.actions.export import export
from ctui.engine.actions.formats import LABELMAP_KINDS, format_for_path
from ctui.engine.actions.opened import Opened
from ctui.engine.actions.project import new_project, save_project
from ctui.engine.actions.series import Segmentation
from ctui.engine.core.atomic import check_outputs
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.jsonio import to_jsonable
from ctui.engine.core.progress import Progress
from ctui.engine.measure.report import plot_sections, write_sections_csv
from ctui.engine.vessel.build import LUMENS, SECTION_STEP_MM, extract, segment_maxima  # noqa: F401 (LUMENS: the CLI's choices)
from ctui.engine.vessel.wall import CT_FLOOR

VESSEL_KEYS = ("branch", "s_mm", "area_mm2", "eq_diameter_mm", "min_diameter_mm", "max_diameter_mm",
               "inscribed_diameter_mm")


@dataclass
class VesselResult:
    """One vessel (JSON of ``ctui vessel --json`` via :meth:`to_dict`).

    start, ends, vias: the points, voxel (x, y, z); lumen; range (lo, hi) and, with "wall",
    band (floor, lo) (the values inside the wall), in the image's units (HU for CT); path_length_mm per branch (the first: start to the
    first end); voxels, volume_ml; core_voxels (colliding fronts); sections: one row per plane
    (VESSEL_KEYS, mm / mm2); maxima: the largest max diameter per 50 mm and where (arc length);
    warnings (the path out of range for more than 5 mm, where a waypoint would help); seconds.
    mask (z, y, x) bool and path_mm (n, 3) patient mm (x, y, z) are for outputs, not in JSON."""

    input: str
    start: list
    ends: list
    vias: list
    lumen: str
    range: tuple
    band: tuple | None
    path_length_mm: list
    voxels: int
    volume_ml: float
    core_voxels: int
    sections: list = field(default_factory=list)
    maxima: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    seconds: float = 0.0
    mask: np.ndarray | None = field(default=None, repr=False)
    path_mm: np.ndarray | None = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        keys = ("input", "start", "ends", "vias", "lumen", "range", "band", "path_length_mm", "voxels", "volume_ml",
                "core_voxels", "maxima", "warnings", "seconds")
        d = {k: to_jsonable(getattr(self, k)) for k in keys}
        d["sections"] = [{k: to_jsonable(r.get(k)) for k in VESSEL_KEYS} for r in self.sections]
        return d


def _zyx(p: Sequence[int], what: str) -> tuple[int, int, int]:
    if len(p) != 3:
        raise CtuiError(f"{what}: expected X,Y,Z, got {p!r}", option=what)
    return int(p[2]), int(p[1]), int(p[0])


def vessel(volume: Any, *, start: Sequence[int], ends: Sequence[Sequence[int]], vias: Sequence[Sequence[int]] = (),
           value_range: tuple[float, float] | None = None, lumen: str = defaults.VESSEL_LUMEN, step_mm: float = SECTION_STEP_MM,
           source: str = "", progress: Progress | None = None) -> VesselResult:
    """Extract one vessel from ``volume`` (a :class:`~ctui.engine.core.volume.Volume`).

    ``start``, each of ``ends`` and ``vias``: voxels (x, y, z); ``value_range``: the lumen's
    (lo, hi), None = from the values at the points; ``lumen``: "contrast" or "wall" (also what
    lies inside the vessel's wall: a dissection's false lumen, a thrombus; bounded by the fat
    around it, under -30 HU on CT); ``step_mm``: distance between
    the growth planes. Takes about a second per 100 mm of an aorta; ``progress`` may cancel."""
    t0 = time.perf_counter()
    if not ends:
        raise CtuiError("a vessel needs at least one end", option="ends")
    if not step_mm > 0:
        raise CtuiError(f"step must be positive, got {step_mm}", option="step_mm")
    floor = CT_FLOOR if str(getattr(volume, "modality", "")).upper() == "CT" else None
    v = extract(np.asarray(volume.data), volume.spacing, start=_zyx(start, "start"),
                ends=[_zyx(e, "ends") for e in ends], vias=[_zyx(w, "vias") for w in vias],
                value_range=value_range, lumen=lumen, floor=floor, step_mm=step_mm, progress=progress)
    warnings = [f"the path runs {r['length_mm']:.0f} mm outside the lumen's range between voxels "
                f"{_xyz(r['from'])} and {_xyz(r['to'])}: a waypoint (--via) at {_xyz(r['middle'])} in the lumen "
                f"may help" for r in v.outside]
    n = int(v.mask.sum())
    return VesselResult(input=source, start=list(start), ends=[list(e) for e in ends], vias=[list(w) for w in vias],
                        lumen=lumen, range=v.range, band=v.band, path_length_mm=v.lengths, voxels=n,
                        volume_ml=n * float(np.prod(volume.spacing)) / 1000.0, core_voxels=v.core_voxels,
                        sections=v.rows, maxima=segment_maxima(v.rows), warnings=warnings,
                        seconds=time.perf_counter() - t0, mask=v.mask, path_mm=volume.index_to_mm(v.route)
                        if hasattr(volume, "index_to_mm") else v.route)


def _xyz(zyx: Sequence[int]) -> str:
    return f"{int(zyx[2])},{int(zyx[1])},{int(zyx[0])}"


def _mask(result: VesselResult) -> np.ndarray:
    """The vessel's (z, y, x) bool mask (a result read back from JSON has none)."""
    if result.mask is None:
        raise CtuiError("this vessel result carries no mask (results read back from JSON keep only the figures)")
    return result.mask


def save_vessel(result: VesselResult, volume: Any, *, source_path: str = "", project: str | None = None,
                mask: str | None = None, csv: str | None = None, plot: str | None = None,
                source_options: dict | None = None) -> list[str]:
    """Write the vessel as object 1 of a project (``project``: .ctui; the object keeps its
    :func:`vessel_record`, so the TUI draws its path and reports it), a label map (``mask``:
    .nii, .nii.gz, .nrrd, .seg.nrrd, as ``ctui export`` writes it), the section table (``csv``)
    and the equivalent diameter along the path (``plot``: PNG). Returns the paths written."""

    inputs = [source_path] if source_path else []
    check_outputs({"--project": project, "--mask": mask, "--csv": csv, "--plot": plot}, inputs=inputs)
    labels = _mask(result).astype(np.uint8)
    objects = Segmentation(labels.shape, labels=labels, objects=[{"id": 1, "name": "vessel",
                                                                  "vessel": vessel_record(result, volume)}]).object_list()
    proj = new_project(volume, source_path=source_path, source_options=source_options, labels=labels,
                       objects=objects, meta={"vessel": {k: to_jsonable(getattr(result, k)) for k in
                                                         ("start", "ends", "vias", "lumen", "range", "band")}})
    written = []
    if project:
        save_project(project, proj, inputs=inputs)
        written.append(project)
    if mask:
        fmt = format_for_path(mask, kinds=LABELMAP_KINDS)
        if fmt is None:
            raise CtuiError(f"{mask}: a label map's name ends in .nii, .nii.gz, .nrrd or .seg.nrrd", option="mask")
        export(Opened.of_volume(volume, labels, path=source_path, project=proj), format=fmt.name, out=mask)
        written.append(mask)
    if csv:
        write_sections_csv(csv, result.sections, keys=VESSEL_KEYS, inputs=inputs)
        written.append(csv)
    if plot:
        plot_sections(plot, result.sections, quantity="eq_diameter_mm", title="vessel: equivalent diameter",
                      inputs=inputs)
        written.append(plot)
    return written


def vessel_proposal(result: VesselResult, object_id: int) -> Any:
    """The vessel as a pending proposal for object ``object_id`` (the TUI shows it hatched on every
    plane; accepting it makes the object exactly the vessel, one undo step)."""
    from ctui.engine.segment.proposal import Proposal  # the TUI's proposal type (the workspace reviews it)

    start_slice = int(result.start[2])
    return Proposal.of_mask(int(object_id), start_slice, _mask(result),
                            settings={"vessel": {k: to_jsonable(getattr(result, k)) for k in
                                                 ("start", "ends", "vias", "lumen", "range")}})


def vessel_record(result: VesselResult, volume: Any, *, every_mm: float = 1.0) -> dict:
    """What a vessel object keeps (its settings' "vessel" entry; the TUI draws its path on the
    views and shows its report in the measure screen): start, ends, vias (voxels x, y, z),
    lumen, range; ``path`` (k, 3) voxel (z, y, x) float indices about every ``every_mm`` along
    the path; ``report``: length_mm (per branch), volume_ml, sections, area_mm2 (min, max),
    eq_diameter_mm (min, median, max), min_diameter_mm (the smallest), max_diameter_mm and
    max_at_mm (the largest and its arc length), inscribed_diameter_mm (the largest) and
    maxima (the largest max diameter per 50 mm of path and where, as ``maxima``)."""
    rec = {k: to_jsonable(getattr(result, k)) for k in ("start", "ends", "vias", "lumen", "range")}
    path = np.zeros((0, 3))
    if result.path_mm is not None and len(result.path_mm):
        pm = np.asarray(result.path_mm, dtype=float)
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pm, axis=0), axis=1))])
        keep = np.unique(np.searchsorted(s, np.arange(0.0, s[-1] + 1e-9, every_mm)).clip(0, len(pm) - 1))
        path = np.asarray(volume.mm_to_index(pm[keep]) if hasattr(volume, "mm_to_index") else pm[keep], dtype=float)
    rec["path"] = np.round(path, 2).tolist()
    rows = [r for r in result.sections if np.isfinite(r.get("area_mm2", np.nan))]

    def col(k: str) -> np.ndarray:
        return np.array([r[k] for r in rows], dtype=float)

    rep: dict = {"length_mm": to_jsonable(result.path_length_mm), "volume_ml": float(result.volume_ml),
                 "sections": len(rows), "maxima": to_jsonable(result.maxima)}
    if rows:
        area, eq, mx = col("area_mm2"), col("eq_diameter_mm"), col("max_diameter_mm")
        j = int(np.nanargmax(mx))
        rep |= {"area_mm2": [float(area.min()), float(area.max())],
                "eq_diameter_mm": [float(eq.min()), float(np.median(eq)), float(eq.max())],
                "min_diameter_mm": float(np.nanmin(col("min_diameter_mm"))), "max_diameter_mm": float(mx[j]),
                "max_at_mm": float(rows[j]["s_mm"]), "max_branch": int(rows[j].get("branch", 0)),
                "inscribed_diameter_mm": float(np.nanmax(col("inscribed_diameter_mm")))}
    rec["report"] = rep
    return rec
