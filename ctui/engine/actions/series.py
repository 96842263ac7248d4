"""A series and what an editor keeps over it, for the front ends: loading and scanning
series (:func:`load`, :func:`scan`; :func:`preview`: the middle slice before the rest is
read), the bundled sample (:func:`sample_path`,
:func:`write_demo`, :func:`load_truth`), the filter pipeline run on its slices
(:class:`Pipeline`, :data:`FILTERS`) and the label volume being edited
(:class:`Segmentation`).

These are the engine's own types and functions, re-exported so that ``ctui.screens`` and
``ctui.commands`` import only ``ctui.engine.actions`` and ``ctui.engine.core`` (the
import-linter contract "The UI talks to the engine through actions and core").
"""

from __future__ import annotations

from ctui.engine.io.phantom import load_truth, sample_path, write_demo
from ctui.engine.io.series import load, scan
from ctui.engine.io.series.preview import Preview, preview
from ctui.engine.segment.filters import FILTERS, PARAMS
from ctui.engine.segment.pipeline import Pipeline, parse_filter_spec
from ctui.engine.segment.selection import Segmentation, label_counts

__all__ = ["FILTERS", "PARAMS", "Pipeline", "Preview", "Segmentation", "label_counts", "load",
           "load_truth", "parse_filter_spec", "preview", "sample_path", "scan", "write_demo"]
