"""Slice filters for the segmentation pipeline (2D, one slice at a time).

Every filter is ``f(image, **params) -> image``: a 2D array in, a 2D array of the same
shape and dtype out. Two value domains are supported (the pipeline records which one
it uses, see :mod:`ctui.engine.segment.pipeline`):

* ``"hu"`` (default): images are float32 in the data's own units (HU for CT).
  Morphology, median, Gaussian, sharpen and conservative smoothing work directly on
  these values, so thresholds stay in HU. Histogram equalization and CLAHE are defined
  on 8-bit images: they window the slice to 0..255 (``window=(centre, width)``),
  equalize, and map the result back linearly onto the window's HU range
  ``[centre - width/2, centre + width/2]``. ``invert`` mirrors values about the
  window centre (``2*centre - v``).
* ``"window8"``: images are uint8 (the windowed display values, as the prototype
  did); every filter works on 0..255 and thresholds are in 0..255.

OpenCV does the work (its morphology, blur and CLAHE are SIMD-optimised and much
faster than scipy.ndimage on 512x512 slices); scipy is used only for median sizes
OpenCV cannot do on float32 (> 5).

Structuring elements (``shape``): ``"rect"``, ``"ellipse"``, ``"cross"`` of
``size`` x ``size`` pixels, or ``"custom"`` with ``kernel`` a 0/1 matrix (list of
lists, odd sides), as the prototype's kernel editor made.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import cv2
import numpy as np

SHAPES = ("rect", "ellipse", "cross", "custom")

_CV_SHAPES = {"rect": cv2.MORPH_RECT, "ellipse": cv2.MORPH_ELLIPSE, "cross": cv2.MORPH_CROSS}


def make_kernel(*, shape: str = "rect", size: int = 3, kernel: Any = None) -> np.ndarray:
    """Structuring element as a uint8 0/1 array (size, size), or the custom ``kernel``."""
    if shape == "custom" or (kernel is not None and shape not in _CV_SHAPES):
        if kernel is None:
            raise ValueError("shape=custom needs a kernel (0/1 matrix)")
        k = np.asarray(kernel, dtype=np.uint8)
        if k.ndim != 2 or k.shape[0] % 2 == 0 or k.shape[1] % 2 == 0:
            raise ValueError(f"custom kernel must be a 2D 0/1 matrix with odd sides, got shape {k.shape}")
        if not k.any():
            raise ValueError("custom kernel has no 1")
        return (k != 0).astype(np.uint8)
    if shape not in _CV_SHAPES:
        raise ValueError(f"unknown kernel shape {shape!r} (use {', '.join(SHAPES)})")
    size = int(size)
    if size < 1:
        raise ValueError(f"kernel size must be >= 1, got {size}")
    return cv2.getStructuringElement(_CV_SHAPES[shape], (size, size))


def _f32(image: np.ndarray) -> np.ndarray:
    if image.dtype == np.uint8 or image.dtype == np.float32:
        return image
    return image.astype(np.float32)


def _morph(op: int, image: np.ndarray, shape: str, size: int, iterations: int, kernel: Any) -> np.ndarray:
    k = make_kernel(shape=shape, size=size, kernel=kernel)
    return cv2.morphologyEx(_f32(image), op, k, iterations=max(int(iterations), 1))


def erode(image: np.ndarray, *, shape: str = "rect", size: int = 3, iterations: int = 1, kernel: Any = None) -> np.ndarray:
    """Grey-level erosion (minimum over the structuring element)."""
    return _morph(cv2.MORPH_ERODE, image, shape, size, iterations, kernel)


def dilate(image: np.ndarray, *, shape: str = "rect", size: int = 3, iterations: int = 1, kernel: Any = None) -> np.ndarray:
    """Grey-level dilation (maximum over the structuring element)."""
    return _morph(cv2.MORPH_DILATE, image, shape, size, iterations, kernel)


def opening(image: np.ndarray, *, shape: str = "rect", size: int = 3, iterations: int = 1, kernel: Any = None) -> np.ndarray:
    """Erosion then dilation (removes bright details smaller than the element)."""
    return _morph(cv2.MORPH_OPEN, image, shape, size, iterations, kernel)


def closing(image: np.ndarray, *, shape: str = "rect", size: int = 3, iterations: int = 1, kernel: Any = None) -> np.ndarray:
    """Dilation then erosion (fills dark details smaller than the element)."""
    return _morph(cv2.MORPH_CLOSE, image, shape, size, iterations, kernel)


def conservative(image: np.ndarray, *, shape: str = "rect", size: int = 3, kernel: Any = None) -> np.ndarray:
    """Conservative smoothing: clamp each pixel to [min, max] of its neighbours (centre excluded).

    Removes isolated spikes and pits while leaving edges in place.
    """
    k = make_kernel(shape=shape, size=size, kernel=kernel).copy()
    cy, cx = k.shape[0] // 2, k.shape[1] // 2
    k[cy, cx] = 0
    if not k.any():
        return image.copy()
    img = _f32(image)
    lo = cv2.erode(img, k, borderType=cv2.BORDER_REPLICATE)
    hi = cv2.dilate(img, k, borderType=cv2.BORDER_REPLICATE)
    return np.minimum(np.maximum(img, lo), hi)


def median(image: np.ndarray, *, size: int = 3) -> np.ndarray:
    """Median over a size x size square (size odd)."""
    size = int(size)
    if size < 1 or size % 2 == 0:
        raise ValueError(f"median size must be odd and >= 1, got {size}")
    if size == 1:
        return image.copy()
    img = _f32(image)
    if img.dtype == np.uint8 or size <= 5:
        return cv2.medianBlur(img, size)
    # OpenCV's float median stops at 5x5 and scipy's takes ~0.6 s on 512x512 at 7x7.
    # CT slices hold whole HU values: a sliding-histogram (Huang) median in numba gives
    # the exact result in a few ms (tests compare it with scipy).
    lo, hi = float(img.min()), float(img.max())
    if hi - lo < 65536 and np.array_equal(img, np.floor(img)):
        kernel = _huang_kernel()
        if kernel is not None:
            r = size // 2
            padded = np.pad((img - np.float32(lo)).astype(np.int32), r, mode="edge")
            out = np.empty(img.shape, np.int32)
            kernel(padded, size, int(hi - lo) + 1, out)
            return out.astype(np.float32) + np.float32(lo)
    from scipy import ndimage

    return ndimage.median_filter(img, size=size, mode="nearest")


def _huang_median_py(padded, k, nbins, out):  # pragma: no cover - compiled by numba
    ny, nx = out.shape
    rank = (k * k) // 2
    hist = np.zeros(nbins, np.int32)
    for y in range(ny):
        hist[:] = 0
        for yy in range(y, y + k):
            for xx in range(k):
                hist[padded[yy, xx]] += 1
        med = 0
        lt = 0
        while lt + hist[med] <= rank:
            lt += hist[med]
            med += 1
        out[y, 0] = med
        for x in range(1, nx):
            xo = x - 1
            xn = x + k - 1
            for yy in range(y, y + k):
                v = padded[yy, xo]
                hist[v] -= 1
                if v < med:
                    lt -= 1
                v = padded[yy, xn]
                hist[v] += 1
                if v < med:
                    lt += 1
            while lt > rank:
                med -= 1
                lt -= hist[med]
            while lt + hist[med] <= rank:
                lt += hist[med]
                med += 1
            out[y, x] = med


_HUANG = []


def _huang_kernel():
    """The numba-compiled median kernel (compiled once, cached on disk), or None."""
    if not _HUANG:
        try:
            from numba import njit

            _HUANG.append(njit(cache=True, nogil=True)(_huang_median_py))
        except ImportError:  # pragma: no cover - numba is a declared dependency
            _HUANG.append(None)
    return _HUANG[0]


def gaussian(image: np.ndarray, *, sigma: float = 1.0, size: int = 0) -> np.ndarray:
    """Gaussian blur of standard deviation ``sigma`` pixels (size 0: 6*sigma+1)."""
    sigma = float(sigma)
    if sigma <= 0:
        raise ValueError(f"gaussian sigma must be > 0, got {sigma}")
    size = int(size)
    if size and size % 2 == 0:
        raise ValueError(f"gaussian size must be odd, got {size}")
    return cv2.GaussianBlur(_f32(image), (size, size), sigma, borderType=cv2.BORDER_REPLICATE)


def sharpen(image: np.ndarray, *, sigma: float = 1.0, amount: float = 1.0) -> np.ndarray:
    """Unsharp mask: ``image + amount * (image - gaussian(image, sigma))``."""
    img = _f32(image)
    blur = cv2.GaussianBlur(img, (0, 0), float(sigma), borderType=cv2.BORDER_REPLICATE)
    # uint8 results saturate at 0/255; float results are not clipped
    return cv2.addWeighted(img, 1.0 + float(amount), blur, -float(amount), 0)


def _window_bounds(window: tuple[float, float] | None, image: np.ndarray) -> tuple[float, float]:
    if window is None:
        lo, hi = float(image.min()), float(image.max())
        return lo, max(hi, lo + 1e-3)
    c, w = float(window[0]), max(float(window[1]), 1e-3)
    return c - w / 2.0, c + w / 2.0


def _to8(image: np.ndarray, lo: float, hi: float) -> np.ndarray:
    out = (image.astype(np.float32) - np.float32(lo)) * np.float32(255.0 / (hi - lo))
    np.clip(out, 0, 255, out=out)
    return (out + 0.5).astype(np.uint8)


def _from8(image8: np.ndarray, lo: float, hi: float) -> np.ndarray:
    return image8.astype(np.float32) * np.float32((hi - lo) / 255.0) + np.float32(lo)


def equalize(image: np.ndarray, *, window: tuple[float, float] | None = None) -> np.ndarray:
    """Global histogram equalization (on the windowed 8-bit image; mapped back for float)."""
    if image.dtype == np.uint8:
        return cv2.equalizeHist(image)
    lo, hi = _window_bounds(window, image)
    return _from8(cv2.equalizeHist(_to8(image, lo, hi)), lo, hi)


def clahe(image: np.ndarray, *, clip_limit: float = 2.0, tiles: int = 8, window: tuple[float, float] | None = None) -> np.ndarray:
    """Contrast-limited adaptive histogram equalization (OpenCV CLAHE, tiles x tiles grid)."""
    tiles = _bounded("clahe", "tiles", tiles, *_INT_BOUNDS["tiles"], integer=True)  # 0 tiles: SIGFPE in OpenCV
    clip_limit = _bounded("clahe", "clip_limit", clip_limit, *_FLOAT_BOUNDS["clip_limit"], integer=False)
    eq = cv2.createCLAHE(clipLimit=float(clip_limit), tileGridSize=(int(tiles), int(tiles)))
    if image.dtype == np.uint8:
        return eq.apply(image)
    lo, hi = _window_bounds(window, image)
    return _from8(eq.apply(_to8(image, lo, hi)), lo, hi)


def invert(image: np.ndarray, *, window: tuple[float, float] | None = None) -> np.ndarray:
    """Invert: ``255 - v`` for uint8; ``2*centre - v`` (mirror about the window centre) for float."""
    if image.dtype == np.uint8:
        return cv2.bitwise_not(image)
    lo, hi = _window_bounds(window, image)
    return np.float32(lo + hi) - _f32(image)


# name -> (function, parameter names it accepts, whether it needs the window, local reach)
FILTERS: dict[str, Callable[..., np.ndarray]] = {
    "closing": closing,
    "opening": opening,
    "erode": erode,
    "dilate": dilate,
    "equalize": equalize,
    "clahe": clahe,
    "conservative": conservative,
    "invert": invert,
    "sharpen": sharpen,
    "median": median,
    "gaussian": gaussian,
}

PARAMS: dict[str, dict[str, Any]] = {
    "closing": {"shape": "rect", "size": 3, "iterations": 1, "kernel": None},
    "opening": {"shape": "rect", "size": 3, "iterations": 1, "kernel": None},
    "erode": {"shape": "rect", "size": 3, "iterations": 1, "kernel": None},
    "dilate": {"shape": "rect", "size": 3, "iterations": 1, "kernel": None},
    "equalize": {},
    "clahe": {"clip_limit": 2.0, "tiles": 8},
    "conservative": {"shape": "rect", "size": 3, "kernel": None},
    "invert": {},
    "sharpen": {"sigma": 1.0, "amount": 1.0},
    "median": {"size": 3},
    "gaussian": {"sigma": 1.0, "size": 0},
}

_NEEDS_WINDOW = {"equalize", "clahe", "invert"}
_GLOBAL = {"equalize", "clahe"}  # depend on the whole slice (histograms): cannot be cropped


# bounds of the numeric parameters (a slice is at most a few thousand pixels wide: larger
# kernels, iteration counts or tile grids only cost time and memory, or crash OpenCV)
_INT_BOUNDS = {"size": (0, 255), "iterations": (1, 100), "tiles": (1, 64)}
_FLOAT_BOUNDS = {"sigma": (0.0, 100.0), "amount": (-100.0, 100.0), "clip_limit": (0.0, 1000.0)}


def _bounded(name: str, key: str, value: Any, lo: float, hi: float, *, integer: bool) -> float | int:
    """``value`` as a finite number in [lo, hi] (an int when ``integer``), else ValueError."""
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"filter {name}: {key} must be a number, got {value!r}") from None
    if not np.isfinite(v) or not lo <= v <= hi or (integer and v != int(v)):
        kind = "a whole number" if integer else "a finite number"
        raise ValueError(f"filter {name}: {key} must be {kind} from {lo:g} to {hi:g}, got {value!r}")
    return int(v) if integer else v


def check_params(name: str, params: dict[str, Any]) -> dict[str, Any]:
    """Validate a filter's name and parameters; return the full parameter dict (defaults filled).

    Raises ValueError with a one-line message on unknown names/parameters or bad values.
    """
    if name not in FILTERS:
        raise ValueError(f"unknown filter {name!r} (known: {', '.join(FILTERS)})")
    allowed = PARAMS[name]
    unknown = set(params) - set(allowed)
    if unknown:
        raise ValueError(f"filter {name}: unknown parameter(s) {', '.join(sorted(unknown))} (allowed: {', '.join(allowed) or 'none'})")
    full = {**allowed, **params}
    if "shape" in full:
        if full["shape"] not in SHAPES:
            raise ValueError(f"filter {name}: shape must be one of {', '.join(SHAPES)}")
        if full["shape"] == "custom":
            make_kernel(shape="custom", kernel=full["kernel"])
    for key, (lo, hi) in _INT_BOUNDS.items():
        if key in full and full[key] is not None:
            full[key] = _bounded(name, key, full[key], lo, hi, integer=True)
    for key, (lo, hi) in _FLOAT_BOUNDS.items():
        if key in full:
            full[key] = _bounded(name, key, full[key], lo, hi, integer=False)
    if name in ("median",) and (full["size"] < 1 or full["size"] % 2 == 0):
        raise ValueError(f"filter median: size must be odd, got {full['size']}")
    if "size" in full and name not in ("gaussian",) and full["size"] < 1:
        raise ValueError(f"filter {name}: size must be >= 1")
    if name == "gaussian" and full["sigma"] <= 0:
        raise ValueError("filter gaussian: sigma must be > 0")
    if name == "gaussian" and full["size"] and full["size"] % 2 == 0:
        raise ValueError("filter gaussian: size must be odd or 0")
    if "iterations" in full and full["iterations"] < 1:
        raise ValueError(f"filter {name}: iterations must be >= 1")
    return full


def apply_filter(image: np.ndarray, name: str, params: dict[str, Any] | None = None, *, window: tuple[float, float] | None = None) -> np.ndarray:
    """Apply filter ``name`` with ``params`` to a 2D image (uint8 or float32); same shape out."""
    full = check_params(name, dict(params or {}))
    fn = FILTERS[name]
    kwargs = {k: v for k, v in full.items() if not (k == "kernel" and v is None)}
    if name in _NEEDS_WINDOW:
        kwargs["window"] = window
    return fn(image, **kwargs)


def filter_reach(name: str, params: dict[str, Any] | None = None) -> int | None:
    """How far (pixels) a filter's output depends on its input, or None if it is global.

    Used to filter only a crop around an object: a crop with this margin gives the
    same values as filtering the whole slice, inside the margin.
    """
    full = check_params(name, dict(params or {}))
    if name in _GLOBAL:
        return None
    if name in ("invert",):
        return 0
    if name in ("gaussian", "sharpen"):
        size = full.get("size") or 0 if name == "gaussian" else 0
        # OpenCV's automatic kernel size is round(8 sigma + 1) for float images
        return size // 2 if size else int(np.ceil(4 * full["sigma"])) + 1
    if name == "median":
        return full["size"] // 2
    k = make_kernel(shape=full.get("shape", "rect"), size=full.get("size", 3), kernel=full.get("kernel"))
    r = max(k.shape) // 2
    it = full.get("iterations", 1)
    factor = 2 if name in ("opening", "closing") else 1
    return r * it * factor
