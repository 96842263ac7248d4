"""Drift check: per-slice object centroids, slices off a smooth fit, and the shifts that
realign them (:func:`drift_check`), for ``ctui drift`` and the TUI's drift screen."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Sequence

from ctui.engine.actions import defaults
from ctui.engine.actions.opened import Opened, open_input
from ctui.engine.core.errors import CtuiError
from ctui.engine.segment.drift import (DriftReport, analyze_drift, apply_corrections, corrections_from_report,
                                      invert_corrections, plot_drift)

# apply/undo a correction and its plot: re-exported for the TUI's drift screen
__all__ = ["DriftResult", "apply_corrections", "corrections_from_report", "drift_check", "invert_corrections",
           "plot_drift"]


@dataclass
class DriftResult:
    """``report`` (DriftReport), ``corrections`` [{slice, dx, dy} px], and the settings used."""

    path: str
    report: DriftReport
    corrections: list = field(default_factory=list)
    fit: str = defaults.DRIFT_FIT
    estimate: str = defaults.DRIFT_ESTIMATE
    notes: list = field(default_factory=list)

    @property
    def threshold_mm(self) -> float:
        return float(self.report.threshold_mm)

    @property
    def flagged(self) -> list[int]:
        return list(self.report.flagged)

    def project_drift(self) -> dict:
        """The ``drift`` entry of a project (corrections recorded, not applied)."""
        return {"threshold_mm": self.threshold_mm, "flagged": self.flagged, "corrections": self.corrections,
                "method": self.fit, "estimate": self.estimate, "applied": False}

    def centroids(self) -> list[dict]:
        out = []
        for o in self.report.objects:
            for k, z in enumerate(o.slices):
                out.append({"object_id": o.object_id, "slice": int(z),
                            "centroid_mm": [round(float(v), 3) for v in o.centroid_mm[k]],
                            "deviation_mm": round(float(o.distance_mm[k]), 3), "flagged": int(z) in o.flagged})
        return out

    def to_dict(self) -> dict:
        return {"path": self.path, "threshold_mm": self.threshold_mm, "flagged": self.flagged,
                "corrections": self.corrections, "centroids": self.centroids(),
                "objects": self.report.to_dict()["objects"]}


def drift_check(source: str | os.PathLike | Opened, *, objects: Sequence[int] | None = None,
                threshold_mm: float | None = None, fit: str = defaults.DRIFT_FIT,
                fit_window: int = defaults.DRIFT_FIT_WINDOW, estimate: str = defaults.DRIFT_ESTIMATE,
                plot: str | os.PathLike | None = None) -> DriftResult:
    """Check a project's (or an :class:`Opened` series + labels') objects for drifted slices.

    Works from a project alone (its recorded geometry); ``estimate="phase"`` needs the
    series' grey levels. ``plot``: a PNG of centroids and deviations.
    """
    if fit_window < 3:
        raise CtuiError("the fit window must be at least 3 slices", option="fit_window")
    if threshold_mm is not None and threshold_mm <= 0:
        raise CtuiError("the drift threshold must be above 0 mm", option="threshold_mm")
    if isinstance(source, Opened):
        opened = source
    else:
        opened = open_input(source, kind="project", require_labels=True,
                            with_series=True if estimate == "phase" else None)
    if opened.labels is None:
        raise CtuiError("no label volume to check", path=opened.path)
    if estimate == "phase" and opened.volume is None:
        raise CtuiError("the phase estimate needs the source series' grey levels", path=opened.path,
                        option="estimate")
    spacing: Any = opened.geometry.spacing if opened.geometry is not None else None
    report = analyze_drift(opened.labels, None, spacing=spacing, object_ids=list(objects) if objects else None,
                           threshold_mm=threshold_mm, method=fit, window=fit_window)
    corrections = corrections_from_report(report, estimate=estimate, volume=opened.volume)
    if plot:
        plot_drift(report, plot)
    return DriftResult(opened.path, report, corrections, fit=fit, estimate=estimate, notes=list(opened.notes))
