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
from typing import Any

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


@dataclass
class Session:
    volume: Volume
    source_path: str = ""
    source_options: dict = field(default_factory=dict)
    z: int | None = None  # None: the middle slice / centre pixel
    x: int | None = None
    y: int | None = None
    window: tuple[float, float] = (40.0, 400.0)
    view: str = "overlay"
    project_path: str | None = None
    dirty: bool = False
    tolerance: float = 60.0
    range_: tuple[float, float] | None = None
    connectivity: int = 8
    prop_mode: str = "slice"  # or "3d" (engine's one-pass 3D flood fill)
    current: int = 1
    pipeline: Any = None
    seg: Any = None
    drift_info: dict | None = None
    original_data: Any = None  # volume data before a drift correction
    plane: str = "axial"  # "axial" | "sagittal" | "coronal" (ctui.screens.planes)
    edit_mode: str = "add"  # fill/paint mode: "add" | "replace" | "subtract"
    brush: float | None = None  # brush/eraser radius in mm (None: 3 pixels of the finest in-plane spacing)
    limits: EditLimits = field(default_factory=EditLimits)  # where edits and propagation may write
    # voxel indices (x, y, z) on the file's grid: the other side of a fill / grow (actions.segment)
    background_seeds: list[tuple[int, int, int]] = field(default_factory=list)
    # the segmentation panel's options (G): method, neck (None = auto), range ("auto" | "given" | (lo, hi)),
    # fill_holes, keep_largest, min_island, interpolate; see ctui.screens.segpanel.options_for
    segment_options: dict = field(default_factory=dict)
    # ((z0, z1), (y0, y1), (x0, x1)) inclusive voxel ranges: fills, propagation, painting and edits stay inside
    roi_box: tuple[tuple[int, int], tuple[int, int], tuple[int, int]] | None = None
    zoom: float = 1.0  # the slice view's zoom (1: the whole plane; the workspace's ViewState changes it)
    # a project opened without its series (labels only): the series' recorded identity,
    # kept when the project is saved (the stand-in zeros must not replace it)
    source_identity: dict | None = None
    _lock: Any = field(default_factory=threading.RLock)

    def __post_init__(self) -> None:
        nz, ny, nx = self.volume.shape
        self.z = nz // 2 if self.z is None else int(min(max(self.z, 0), nz - 1))
        self.x = nx // 2 if self.x is None else int(self.x)
        self.y = ny // 2 if self.y is None else int(self.y)
        self.clamp()
        if self.brush is None:
            self.brush = 3.0 * float(min(self.volume.spacing[1:]))
        if self.volume.window:
            self.window = tuple(float(v) for v in self.volume.window)  # type: ignore[assignment]
        if self.pipeline is None:
            self.pipeline = Pipeline()
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
        if self.pipeline is None or not (getattr(self.pipeline, "steps", None) or []):
            return None
        with self._lock:
            image = self.pipeline.final_slice(self.volume, self.z)
        return float(image[self.y, self.x])

    def brush_px(self, axis: int = 0) -> float:
        """The brush radius in pixels of the finer in-plane spacing of the plane across ``axis``."""
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
    def labels(self) -> np.ndarray | None:
        if self.seg is None:
            return None
        return getattr(self.seg, "labels", None)

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
        if self.pipeline is None:
            return []
        out = []
        for i, st in enumerate(getattr(self.pipeline, "steps", []) or []):
            d = st if isinstance(st, dict) else (st.to_dict() if hasattr(st, "to_dict") else vars(st))
            params = d.get("params") or {}
            ptxt = " ".join(f"{k}={v}" for k, v in params.items() if v is not None and k != "kernel")
            if params.get("kernel") is not None:
                ptxt += " kernel=custom"
            out.append(f"{i + 1}. s{d.get('stage', 1)} {d.get('name') or d.get('filter')} {ptxt}".rstrip())
        return out

    def window_presets(self) -> list[tuple[str, tuple[float, float]]]:
        items = []
        if self.volume.window:
            items.append(("default", tuple(self.volume.window)))
        if self.volume.modality == "CT":
            items += list(CT_PRESETS.items())
        else:
            items.append(("auto", auto_window(self.volume.data, modality=self.volume.modality)))
        return items  # type: ignore[return-value]
