"""The two-stage slice filter pipeline, as data.

A :class:`Pipeline` is an ordered list of :class:`Step` (filter name, stage 1 or 2,
parameters, enabled flag) plus the value domain and window it works in. It is plain
data: :meth:`Pipeline.to_dict` / :meth:`Pipeline.from_dict` round-trip through JSON
(stored in projects), and :meth:`Pipeline.key` hashes it for caching.

A slice has four views, as in the prototype:

* ``original``: the slice in the pipeline's domain;
* ``overlay``: objects coloured over the windowed original (RGB uint8), see
  :func:`overlay`;
* ``intermediate``: after the stage-1 steps;
* ``final``: after the stage-2 steps (flood fill and propagation threshold this view).

Domain (recorded in the pipeline dict as ``"domain"``):

* ``"hu"`` (default): filters work on float32 values in the data's units (HU for
  CT), so fill ranges and tolerances are in HU. Equalization/CLAHE window the slice to
  8 bits, equalize and map back to the window's HU range (see
  :mod:`ctui.engine.segment.filters`).
* ``"window8"``: the slice is first windowed to uint8 (``window`` or the volume's
  default window), and every filter and threshold works on 0..255, as the prototype
  did.

Results are cached per slice, keyed by (volume data identity, pipeline key, slice
index), so changing any step or parameter invalidates them; the cache is bounded in
bytes (call :meth:`Pipeline.clear_cache` after changing ``volume.data`` in place;
a new data array is a new key). Propagation does not fill the cache: it filters only a crop around the object
(:meth:`Pipeline.final_region`), which gives the same values as the full slice as long
as every step is local (:meth:`Pipeline.reach`).
"""

from __future__ import annotations

import hashlib
import json
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ctui.engine.core.colors import MAX_OBJECTS, object_color
from ctui.engine.core.windows import apply_window, auto_window
from ctui.engine.segment import DOMAINS  # the registry, defined once in the package
from ctui.engine.segment import filters as _filters


@dataclass
class Step:
    """One filter step: ``name`` (see :data:`ctui.engine.segment.filters.FILTERS`), ``stage`` 1 or 2."""

    name: str
    stage: int = 1
    params: dict[str, Any] = field(default_factory=dict)
    enabled: bool = True

    def __post_init__(self) -> None:
        if self.stage not in (1, 2):
            raise ValueError(f"filter {self.name}: stage must be 1 or 2, got {self.stage}")
        _filters.check_params(self.name, dict(self.params))  # raises ValueError

    def to_dict(self) -> dict[str, Any]:
        params = {k: (np.asarray(v).astype(int).tolist() if k == "kernel" and v is not None else v) for k, v in self.params.items()}
        return {"name": self.name, "stage": int(self.stage), "params": params, "enabled": bool(self.enabled)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Step:
        return cls(name=str(d["name"]), stage=int(d.get("stage", 1)), params=dict(d.get("params", {})), enabled=bool(d.get("enabled", True)))

    def reach(self) -> int | None:
        return _filters.filter_reach(self.name, self.params)


@dataclass
class SliceViews:
    """The views of one slice. Arrays are (ny, nx) in the pipeline's domain."""

    z: int
    original: np.ndarray
    intermediate: np.ndarray
    final: np.ndarray
    domain: str
    window: tuple[float, float]

    def display(self, view: str = "final") -> np.ndarray:
        """View ``"original"``, ``"intermediate"`` or ``"final"`` as uint8 (ny, nx) for display."""
        return to_display(getattr(self, view), domain=self.domain, window=self.window)

    def overlay(self, labels2d: np.ndarray, *, alpha: float = 0.45, view: str = "original") -> np.ndarray:
        """Objects of ``labels2d`` (uint8 (ny, nx)) coloured over a view: RGB uint8 (ny, nx, 3)."""
        return overlay(self.display(view), labels2d, alpha=alpha)


def to_display(image: np.ndarray, *, domain: str, window: tuple[float, float]) -> np.ndarray:
    """A domain image as uint8 for display (window applied in the "hu" domain)."""
    if domain == "window8" or image.dtype == np.uint8:
        return image
    return apply_window(image, window)


_LUT: np.ndarray | None = None


def _color_lut() -> np.ndarray:
    global _LUT
    if _LUT is None:
        lut = np.zeros((256, 3), dtype=np.float32)
        for i in range(1, 256):
            lut[i] = object_color((i - 1) % MAX_OBJECTS + 1)
        _LUT = lut
    return _LUT


def overlay(gray8: np.ndarray, labels2d: np.ndarray | None, *, alpha: float = 0.45) -> np.ndarray:
    """Blend object colours (:mod:`ctui.engine.core.colors`) over a grey uint8 slice.

    Parameters
    ----------
    gray8 : uint8 (ny, nx)
    labels2d : uint8 (ny, nx) or None; 0 = background, 1..10 objects
    alpha : opacity of the colours (0..1)

    Returns
    -------
    uint8 (ny, nx, 3) RGB.
    """
    rgb = np.repeat(gray8[:, :, None], 3, axis=2)
    if labels2d is None:
        return rgb
    m = labels2d > 0
    if not m.any():
        return rgb
    col = _color_lut()[labels2d[m]]
    rgb[m] = (rgb[m].astype(np.float32) * (1.0 - alpha) + col * alpha + 0.5).astype(np.uint8)
    return rgb


class Pipeline:
    """Ordered filter steps in two stages, with a per-slice cache.

    Parameters
    ----------
    steps : list of Step (or dicts)
    domain : "hu" (float32, data units) or "window8" (uint8 windowed values)
    window : (centre, width) used for windowing (window8 domain, equalization,
        invert); None = the volume's own window.
    cache_bytes : bound of the per-slice cache.
    """

    def __init__(self, steps: list[Step | dict[str, Any]] | None = None, *, domain: str = "hu",
                 window: tuple[float, float] | None = None, cache_bytes: int = 128 * 2**20) -> None:
        if domain not in DOMAINS:
            raise ValueError(f"pipeline domain must be one of {', '.join(DOMAINS)}, got {domain!r}")
        self.steps: list[Step] = [s if isinstance(s, Step) else Step.from_dict(s) for s in (steps or [])]
        self.domain = domain
        self.window = None if window is None else (float(window[0]), float(window[1]))
        self.cache_bytes = int(cache_bytes)
        self._cache: OrderedDict[tuple, SliceViews] = OrderedDict()
        self._cache_used = 0

    # ------------------------------------------------------------- editing
    def add(self, name: str, *, stage: int = 1, enabled: bool = True, **params: Any) -> Step:
        """Append a step (validated); returns it."""
        step = Step(name=name, stage=stage, params=params, enabled=enabled)
        self.steps.append(step)
        return step

    def remove(self, index: int) -> Step:
        return self.steps.pop(index)

    def move(self, index: int, new_index: int) -> None:
        step = self.steps.pop(index)
        self.steps.insert(new_index, step)

    def set_params(self, index: int, **params: Any) -> None:
        """Change parameters of step ``index`` (validated)."""
        step = self.steps[index]
        new = {**step.params, **params}
        _filters.check_params(step.name, new)
        step.params = new

    # ------------------------------------------------------------- data
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: ``{"version", "domain", "window", "steps": [...]}``."""
        return {
            "version": 1,
            "domain": self.domain,
            "window": None if self.window is None else [self.window[0], self.window[1]],
            "steps": [s.to_dict() for s in self.steps],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> Pipeline:
        d = d or {}
        w = d.get("window")
        return cls([Step.from_dict(s) for s in d.get("steps", [])], domain=d.get("domain", "hu"),
                   window=None if w is None else (float(w[0]), float(w[1])))

    def key(self) -> str:
        """Hash of the pipeline's content (changes whenever a step or parameter changes)."""
        return hashlib.sha1(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()[:16]

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Pipeline) and self.to_dict() == other.to_dict()

    def __repr__(self) -> str:
        steps = ", ".join(f"{s.name}@{s.stage}" for s in self.steps if s.enabled)
        return f"Pipeline(domain={self.domain}, steps=[{steps}])"

    def active_steps(self, stage: int | None = None) -> list[Step]:
        """Enabled steps in run order: all stage-1 steps, then all stage-2 steps."""
        out = [s for s in self.steps if s.enabled and s.stage == 1] + [s for s in self.steps if s.enabled and s.stage == 2]
        return out if stage is None else [s for s in out if s.stage == stage]

    def reach(self) -> int | None:
        """Total pixel reach of the enabled steps (None if one is global, e.g. equalization)."""
        total = 0
        for s in self.active_steps():
            r = s.reach()
            if r is None:
                return None
            total += r
        return total

    # ------------------------------------------------------------- running
    def window_for(self, volume: Any) -> tuple[float, float]:
        if self.window is not None:
            return self.window
        w = getattr(volume, "window", None)
        if w is None:
            w = auto_window(volume.data, modality=getattr(volume, "modality", "OT"))
        return (float(w[0]), float(w[1]))

    def prepare(self, image: np.ndarray, window: tuple[float, float]) -> np.ndarray:
        """A raw 2D slice (any dtype) in the pipeline's domain (float32 or uint8)."""
        if self.domain == "window8":
            return apply_window(image, window)
        return image if image.dtype == np.float32 else image.astype(np.float32)

    def run_image(self, image: np.ndarray, *, window: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        """Run the steps on a domain image: returns (intermediate, final)."""
        out = image
        for s in self.active_steps(1):
            out = _filters.apply_filter(out, s.name, s.params, window=window)
        inter = out
        for s in self.active_steps(2):
            out = _filters.apply_filter(out, s.name, s.params, window=window)
        return inter, out

    def run_slice(self, volume: Any, z: int) -> SliceViews:
        """All views of slice ``z`` of ``volume`` (cached)."""
        z = int(z)
        nz = volume.data.shape[0]
        if not 0 <= z < nz:
            raise IndexError(f"slice {z} outside 0..{nz - 1}")
        ck = (id(volume.data), volume.data.shape, self.key(), z)
        hit = self._cache.get(ck)
        if hit is not None:
            self._cache.move_to_end(ck)
            return hit
        window = self.window_for(volume)
        orig = self.prepare(volume.data[z], window)
        inter, final = self.run_image(orig, window=window)
        views = SliceViews(z=z, original=orig, intermediate=inter, final=final, domain=self.domain, window=window)
        self._store(ck, views)
        return views

    def final_slice(self, volume: Any, z: int) -> np.ndarray:
        """The final view of slice ``z`` (cached)."""
        return self.run_slice(volume, z).final

    def final_region(self, volume: Any, z: int, y0: int, y1: int, x0: int, x1: int, *, window: tuple[float, float] | None = None) -> np.ndarray:
        """Final view of slice ``z`` restricted to rows y0:y1, columns x0:x1.

        Filters only a crop grown by :meth:`reach` (exactly equal to the full-slice
        result inside the region); falls back to the whole slice for global steps or
        when the slice is already cached.
        """
        ny, nx = volume.data.shape[1:]
        ck = (id(volume.data), volume.data.shape, self.key(), int(z))
        hit = self._cache.get(ck)
        if hit is not None:
            return hit.final[y0:y1, x0:x1]
        if window is None:
            window = self.window_for(volume)
        r = self.reach()
        if r is None:
            return self.run_slice(volume, z).final[y0:y1, x0:x1]
        cy0, cy1 = max(y0 - r, 0), min(y1 + r, ny)
        cx0, cx1 = max(x0 - r, 0), min(x1 + r, nx)
        crop = self.prepare(volume.data[z, cy0:cy1, cx0:cx1], window)
        if not self.active_steps():
            return crop[y0 - cy0:y1 - cy0, x0 - cx0:x1 - cx0]
        _, final = self.run_image(crop, window=window)
        return final[y0 - cy0:y1 - cy0, x0 - cx0:x1 - cx0]

    def display(self, image: np.ndarray, volume: Any = None) -> np.ndarray:
        """A domain image as uint8 for display."""
        window = self.window if volume is None else self.window_for(volume)
        if window is None:
            window = (float(image.mean()), float(np.ptp(image)) or 1.0)
        return to_display(image, domain=self.domain, window=window)

    # ------------------------------------------------------------- cache
    def _store(self, ck: tuple, views: SliceViews) -> None:
        size = views.original.nbytes + views.intermediate.nbytes + views.final.nbytes
        if size > self.cache_bytes:
            return
        self._cache[ck] = views
        self._cache_used += size
        while self._cache_used > self.cache_bytes and self._cache:
            _, old = self._cache.popitem(last=False)
            self._cache_used -= old.original.nbytes + old.intermediate.nbytes + old.final.nbytes

    def clear_cache(self) -> None:
        self._cache.clear()
        self._cache_used = 0

    def cached_slices(self) -> int:
        """Number of slices in the cache (all pipeline versions)."""
        return len(self._cache)


def parse_filter_spec(spec: str) -> Step:
    """Parse the CLI's compact filter syntax into a :class:`Step`.

    ``NAME[:key=value[,key=value...]]``, e.g. ``opening:size=3,shape=ellipse,stage=1``,
    ``clahe:clip_limit=3,tiles=8,stage=2``, ``median:size=5``,
    ``dilate:shape=custom,kernel=010/111/010`` (custom kernel rows separated by ``/``).
    ``stage`` defaults to 1. Raises ValueError with a one-line message.
    """
    spec = spec.strip()
    name, _, rest = spec.partition(":")
    name = name.strip().lower()
    params: dict[str, Any] = {}
    stage = 1
    enabled = True
    if rest.strip():
        for item in rest.split(","):
            if not item.strip():
                continue
            key, eq, val = item.partition("=")
            key, val = key.strip().lower(), val.strip()
            if not eq or not val:
                raise ValueError(f"filter spec {spec!r}: expected key=value, got {item!r}")
            if key == "stage":
                try:
                    stage = int(val)
                except ValueError:
                    raise ValueError(f"filter spec {spec!r}: stage must be 1 or 2") from None
            elif key == "enabled":
                enabled = val.lower() not in ("0", "false", "no", "off")
            elif key == "kernel":
                rows = [r for r in val.split("/") if r]
                if not rows or any(len(r) != len(rows[0]) or set(r) - {"0", "1"} for r in rows):
                    raise ValueError(f"filter spec {spec!r}: kernel must be rows of 0/1 separated by '/', e.g. 010/111/010")
                params["kernel"] = [[int(c) for c in r] for r in rows]
                params.setdefault("shape", "custom")
            elif key == "shape":
                params[key] = val.lower()
            else:
                try:
                    num = float(val)
                except ValueError:
                    raise ValueError(f"filter spec {spec!r}: {key} must be a number, got {val!r}") from None
                params[key] = int(num) if num.is_integer() and key in ("size", "iterations", "tiles") else num
    return Step(name=name, stage=stage, params=params, enabled=enabled)
