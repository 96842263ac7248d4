"""The TUI's working state and its (thin) calls into the engine.

A :class:`Session` holds the loaded volume, the slice pipeline, the segmentation, the
cursor, the view and the editing settings. Every computation is an engine call
(``ctui.engine.io.series``, ``pipeline``, ``selection``, ``propagate``, ``drift``,
``project``...).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from ctui.engine.core.volume import Volume
from ctui.engine.core.windows import CT_PRESETS, apply_window, auto_window
from ctui.engine.actions import series as loaders
from ctui.engine.actions.edit import EditLimits, brush_radius_px
from ctui.engine.actions.series import Pipeline, Segmentation

VIEWS = ("original", "overlay", "intermediate", "final")


def safe_cwd() -> Path:
    """The working directory, or the home directory when it has been deleted meanwhile."""
    try:
        return Path.cwd()
    except OSError:  # FileNotFoundError: the folder ctui started in is gone
        return Path.home()


def sample_source() -> str:
    """Path of the bundled sample series."""
    return str(loaders.sample_path())


def load_volume(path: str | None, *, progress=None, **options: Any) -> Volume:
    """Load a series with ``ctui.engine.io.series.load`` (the bundled sample when None), as the
    memory plan of ``open`` says: in memory, or memory-mapped from the voxel cache (then
    ``meta["memory_plan"]`` is the plan's line, for the status line); refused in one line."""
    if path is None:
        return loaders.load(sample_source(), progress=progress, **options)
    from ctui.engine.actions.opened import memory_plan  # (not at startup)
    from ctui.engine.core.errors import CtuiError

    plan = memory_plan("open", path, **options)
    if plan.mode == "refuse":
        raise CtuiError(plan.reason, path=path, option="memory")
    vol = loaders.load(path, progress=progress, **dict(options, cache=True) if plan.mode == "cache" else options)
    if plan.mode == "cache":
        vol.meta["memory_plan"] = plan.summary()
    return vol


class PanelOptions(TypedDict, total=False):
    """The segmentation panel's (G) choices (``Session.segment_options``; ctui.screens.segpanel.options_for
    turns them into :class:`SegmentOptions`): absent keys take the engine's defaults."""

    method: str  # a name of actions.segment.METHODS
    neck: float | None  # mm; None: automatic
    range: str | tuple[float, float]  # "auto" | "given" (T's range, else auto) | (lo, hi)
    fill_holes: bool
    keep_largest: bool
    min_island: int
    interpolate: bool


@dataclass
class Session:
    volume: Volume
    source_path: str = ""
    source_options: dict[str, Any] = field(default_factory=dict)
    # the cursor voxel; None given: the middle slice / centre pixel (__post_init__ sets an int)
    z: int = None  # type: ignore[assignment]  # None given means "the middle"; always an int after __post_init__
    x: int = None  # type: ignore[assignment]  # as z
    y: int = None  # type: ignore[assignment]  # as z
    window: tuple[float, float] = (40.0, 400.0)
    view: str = "overlay"
    project_path: str | None = None
    dirty: bool = False
    tolerance: float = 60.0
    range_: tuple[float, float] | None = None
    connectivity: int = 8
    prop_mode: str = "slice"  # or "3d" (engine's one-pass 3D flood fill)
    current: int = 1
    pipeline: Pipeline = field(default_factory=Pipeline)
    # the labels on the volume's grid; None given: an empty one (__post_init__)
    seg: Segmentation = None  # type: ignore[assignment]  # its shape is the volume's: made in __post_init__
    drift_info: dict[str, Any] | None = None
    original_data: np.ndarray | None = None  # volume data before a drift correction
    plane: str = "axial"  # "axial" | "sagittal" | "coronal" (ctui.screens.planes)
    edit_mode: str = "add"  # fill/paint mode: "add" | "replace" | "subtract"
    brush: float | None = None  # brush/eraser radius in mm (None: 3 pixels of the finest in-plane spacing)
    limits: EditLimits = field(default_factory=EditLimits)  # where edits and propagation may write
    # voxel indices (x, y, z) on the file's grid: the other side of a fill / grow (actions.segment)
    background_seeds: list[tuple[int, int, int]] = field(default_factory=list)
    # the segmentation panel's options (G): method, neck (None = auto), range ("auto" | "given" | (lo, hi)),
    # fill_holes, keep_largest, min_island, interpolate; see ctui.screens.segpanel.options_for
    segment_options: PanelOptions = field(default_factory=lambda: PanelOptions())
    # ((z0, z1), (y0, y1), (x0, x1)) inclusive voxel ranges: fills, propagation, painting and edits stay inside
    roi_box: tuple[tuple[int, int], tuple[int, int], tuple[int, int]] | None = None
    zoom: float = 1.0  # the slice view's zoom (1: the whole plane; the workspace's ViewState changes it)
    # a project opened without its series (labels only): the series' recorded identity,
    # kept when the project is saved (the stand-in zeros must not replace it)
    source_identity: dict[str, Any] | None = None
    # held while a worker thread and the UI share the pipeline's cache or the labels
    _lock: threading.RLock = field(default_factory=threading.RLock)

    def __post_init__(self) -> None:
        nz, ny, nx = self.volume.shape
        self.z = nz // 2 if self.z is None else int(min(max(self.z, 0), nz - 1))
        self.x = nx // 2 if self.x is None else int(self.x)
        self.y = ny // 2 if self.y is None else int(self.y)
        self.clamp()
        self.brush_px()  # sets the default brush
        if self.volume.window:
            lo, hi = self.volume.window
            self.window = (float(lo), float(hi))
        if self.seg is None:
            self.seg = Segmentation(self.volume.shape)

    # ------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int, int]:
        return self.volume.shape

    def clamp(self) -> None:
        nz, ny, nx = self.shape
        self.z = int(min(max(self.z, 0), nz - 1))
        self.y = int(min(max(self.y, 0), ny - 1))
        self.x = int(min(max(self.x, 0), nx - 1))

    def position_mm(self) -> tuple[float, float, float]:
        p = self.volume.index_to_mm((self.z, self.y, self.x))
        return float(p[0]), float(p[1]), float(p[2])

    @property
    def zyx(self) -> tuple[int, int, int]:
        return int(self.z), int(self.y), int(self.x)

    def value(self) -> float:
        return float(self.volume.data[self.z, self.y, self.x])

    def filtered_value(self) -> float | None:
        """The value the fill uses at the cursor (the pipeline's final image of the slice,
        in its domain: HU or 0..255), or None when no pipeline step is active."""
        if not self.pipeline.steps:
            return None
        with self._lock:
            image = self.pipeline.final_slice(self.volume, self.z)
        return float(image[self.y, self.x])

    def brush_px(self, axis: int = 0) -> float:
        """The brush radius in pixels of the finer in-plane spacing of the plane across ``axis``."""
        if self.brush is None:  # None: 3 pixels of the finest in-plane spacing
            self.brush = 3.0 * float(min(self.volume.spacing[1:]))
        return brush_radius_px(self.brush, self.volume.spacing, axis)

    def toggle_background_seed(self, zyx: tuple[int, int, int] | None = None) -> bool:
        """Place a background seed at voxel ``zyx`` (the cursor), or remove the one there;
        True when placed."""
        z, y, x = self.zyx if zyx is None else zyx
        seed = (int(x), int(y), int(z))
        if seed in self.background_seeds:
            self.background_seeds.remove(seed)
            return False
        self.background_seeds.append(seed)
        return True

    # ------------------------------------------------------------ images
    def labels(self) -> np.ndarray:
        """The (z, y, x) uint8 label volume."""
        return self.seg.labels

    def display(self, image: np.ndarray) -> np.ndarray:
        """A pipeline-domain image as uint8 through the user's display window."""
        if image.dtype == np.uint8:
            return image
        return apply_window(image, self.window)

    def stage_views(self, z: int | None = None):
        """ctui.engine.segment.pipeline.SliceViews of slice z (cached by the engine)."""
        z = self.z if z is None else z
        with self._lock:
            return self.pipeline.run_slice(self.volume, z)

    def pipeline_steps(self) -> list[str]:
        out = []
        for i, st in enumerate(self.pipeline.steps):
            d = st if isinstance(st, dict) else (st.to_dict() if hasattr(st, "to_dict") else vars(st))
            params = d.get("params") or {}
            ptxt = " ".join(f"{k}={v}" for k, v in params.items() if v is not None and k != "kernel")
            if params.get("kernel") is not None:
                ptxt += " kernel=custom"
            out.append(f"{i + 1}. s{d.get('stage', 1)} {d.get('name') or d.get('filter')} {ptxt}".rstrip())
        return out

    def window_presets(self) -> list[tuple[str, tuple[float, float]]]:
        items: list[tuple[str, tuple[float, float]]] = []
        if self.volume.window:
            lo, hi = self.volume.window
            items.append(("default", (float(lo), float(hi))))
        if self.volume.modality == "CT":
            items += list(CT_PRESETS.items())
        else:
            items.append(("auto", auto_window(self.volume.data, modality=self.volume.modality)))
        return items
