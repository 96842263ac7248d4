"""numpy images to terminal cells: the fast path of every image ctui shows.

* :func:`fit_view` maps an image (with pixel spacing, zoom and pan) onto a target
  pixel grid, keeping the physical aspect ratio (letterboxed).
* :func:`render_view` crops, resizes (OpenCV INTER_AREA when shrinking, nearest when
  magnifying so zoomed voxels stay crisp) and pastes into the grid.
* :func:`halfblock_strips` turns an RGB image of 2*rows x cols pixels into Textual
  Strips of U+2580 cells (foreground = top pixel, background = bottom pixel), merging
  runs of identical cells and caching Rich Styles.
* :func:`ascii_strips`: the same grid as a character ramp, no colour.

A 160x50 terminal shows only 160x100 half-block pixels, so a 512x512 slice is
resized once (well under a millisecond) and ~8000 cells are emitted.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from rich.color import Color
from rich.segment import Segment
from rich.style import Style
from textual.strip import Strip

UPPER_HALF = "\u2580"
ASCII_RAMP = " .:-=+*#%@"


@dataclass
class ViewMap:
    """How image pixel coordinates map to the target grid.

    ``x_disp = (x_img + 0.5 - x0) * sx + ox`` (and the same for y), ``x0, y0`` the
    crop origin in image pixels, ``sx, sy`` display pixels per image pixel, ``ox, oy``
    the letterbox offsets in display pixels, ``w, h`` the drawn size.
    """

    x0: float
    y0: float
    sx: float
    sy: float
    ox: int
    oy: int
    w: int
    h: int

    def to_display(self, x: float, y: float) -> tuple[float, float]:
        return ((x + 0.5 - self.x0) * self.sx + self.ox, (y + 0.5 - self.y0) * self.sy + self.oy)

    def to_image(self, xd: float, yd: float) -> tuple[float, float]:
        return ((xd - self.ox) / self.sx + self.x0 - 0.5, (yd - self.oy) / self.sy + self.y0 - 0.5)


def fit_view(
    img_shape: tuple[int, int],
    out_size: tuple[int, int],
    *,
    spacing_yx: tuple[float, float] = (1.0, 1.0),
    pixel_aspect: float = 1.0,
    zoom: float = 1.0,
    center: tuple[float, float] | None = None,
) -> tuple[tuple[int, int, int, int], ViewMap]:
    """Crop rectangle and mapping for showing an image in a target grid.

    Parameters
    ----------
    img_shape : (h, w) image pixels
    out_size : (W, H) target pixels
    spacing_yx : (dy, dx) mm per image pixel (physical aspect)
    pixel_aspect : height/width of one target pixel (1.0 for half-block cells with
        2:1 cells, and for sixel/kitty pixels)
    zoom : >= 1 magnification; 1 shows the whole image
    center : (x, y) image pixel to centre on when zoomed (clamped to stay inside)

    Returns
    -------
    (x0, y0, x1, y1) integer crop in image pixels, and a :class:`ViewMap`.
    """
    h, w = int(img_shape[0]), int(img_shape[1])
    W, H = max(int(out_size[0]), 1), max(int(out_size[1]), 1)
    dy, dx = float(spacing_yx[0]), float(spacing_yx[1])
    zoom = max(float(zoom), 1.0)
    # physical size of the visible region (mm), and scale mm -> target pixels
    vis_w = w / zoom
    vis_h = h / zoom
    scale = min(W / (vis_w * dx), H * pixel_aspect / (vis_h * dy))
    # crop region in image pixels: all that fits in the target at this scale
    cw = min(w, W / (scale * dx))
    ch = min(h, H * pixel_aspect / (scale * dy))
    if center is None:
        cx, cy = w / 2.0, h / 2.0
    else:
        cx, cy = float(center[0]) + 0.5, float(center[1]) + 0.5
    x0 = min(max(cx - cw / 2.0, 0.0), w - cw)
    y0 = min(max(cy - ch / 2.0, 0.0), h - ch)
    ix0, iy0 = int(np.floor(x0)), int(np.floor(y0))
    ix1, iy1 = min(int(np.ceil(x0 + cw)), w), min(int(np.ceil(y0 + ch)), h)
    ix1, iy1 = max(ix1, ix0 + 1), max(iy1, iy0 + 1)
    sx = scale * dx
    sy = scale * dy / pixel_aspect
    dw = max(1, min(W, int(round((ix1 - ix0) * sx))))
    dh = max(1, min(H, int(round((iy1 - iy0) * sy))))
    ox, oy = (W - dw) // 2, (H - dh) // 2
    vm = ViewMap(float(ix0), float(iy0), dw / (ix1 - ix0), dh / (iy1 - iy0), ox, oy, dw, dh)
    return (ix0, iy0, ix1, iy1), vm


def render_view(
    rgb: np.ndarray,
    out_size: tuple[int, int],
    *,
    spacing_yx: tuple[float, float] = (1.0, 1.0),
    pixel_aspect: float = 1.0,
    zoom: float = 1.0,
    center: tuple[float, float] | None = None,
    background: tuple[int, int, int] = (0, 0, 0),
) -> tuple[np.ndarray, ViewMap]:
    """Resize (and crop when zoomed) an (h, w, 3) or (h, w) uint8 image into an
    (H, W, 3) uint8 target grid. Returns the grid and its :class:`ViewMap`."""
    if rgb.ndim == 2:
        rgb = rgb[:, :, None].repeat(3, axis=2)
    (x0, y0, x1, y1), vm = fit_view(
        rgb.shape[:2], out_size, spacing_yx=spacing_yx, pixel_aspect=pixel_aspect, zoom=zoom, center=center
    )
    W, H = max(int(out_size[0]), 1), max(int(out_size[1]), 1)
    crop = np.ascontiguousarray(rgb[y0:y1, x0:x1])
    shrinking = vm.w <= crop.shape[1] and vm.h <= crop.shape[0]
    interp = cv2.INTER_AREA if shrinking else cv2.INTER_NEAREST
    small = cv2.resize(crop, (vm.w, vm.h), interpolation=interp)
    if small.ndim == 2:
        small = small[:, :, None].repeat(3, axis=2)
    if vm.w == W and vm.h == H:
        return small, vm
    out = np.empty((H, W, 3), np.uint8)
    out[:] = background
    out[vm.oy : vm.oy + vm.h, vm.ox : vm.ox + vm.w] = small
    return out, vm


def physical_image(rgb: np.ndarray, spacing_yx: tuple[float, float], *, max_side: int = 4096) -> np.ndarray:
    """An (h, w[, 3]) image resampled to square pixels of its finer spacing (mm), so a
    saved view has the physical aspect ratio the screen shows (a 512x134 coronal view of
    3 mm slices at 0.7 mm pixels becomes 512x574). Linear interpolation along the
    stretched axis; the longer side is kept at most ``max_side`` pixels. Unchanged
    (the same array) when the pixels are already square."""
    dy, dx = float(spacing_yx[0]), float(spacing_yx[1])
    h, w = rgb.shape[:2]
    if not (dy > 0 and dx > 0) or abs(dy - dx) <= 1e-6 * max(dy, dx):
        return rgb
    fine = min(dy, dx)
    nw, nh = w * dx / fine, h * dy / fine
    shrink = min(1.0, max_side / max(nw, nh))
    size = (max(1, int(round(nw * shrink))), max(1, int(round(nh * shrink))))
    return cv2.resize(np.ascontiguousarray(rgb), size, interpolation=cv2.INTER_LINEAR)


def draw_cursor(grid: np.ndarray, vm: ViewMap, x: float, y: float, *, color=(255, 40, 40), radius: int | None = None) -> None:
    """Draw the red cursor (in place) at image pixel (x, y) on a target grid.

    The glyph scales with the zoom: where an image pixel is drawn at least 2 display
    pixels wide, a circle around it (radius 1.5 image pixels) with a centre dot; on a
    small view (one display pixel shows one or more image pixels) four 2-pixel ticks
    around the pixel and the dot, leaving the anatomy next to it visible (a ring of
    5 display pixels covered a kidney at 80x24). ``radius`` forces the circle.
    """
    xd, yd = vm.to_display(x, y)
    c = (int(np.floor(xd)), int(np.floor(yd)))
    h, w = grid.shape[:2]
    scale = max(vm.sx, vm.sy)
    if radius is None and scale < 2.0:
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            for k in (2, 3):
                px, py = c[0] + dx * k, c[1] + dy * k
                if 0 <= py < h and 0 <= px < w:
                    grid[py, px] = color
    else:
        if radius is None:
            radius = int(max(2, round(1.5 * scale)))
        cv2.circle(grid, c, radius, color, 1, lineType=cv2.LINE_8)
    if 0 <= c[1] < h and 0 <= c[0] < w:
        grid[c[1], c[0]] = color


_STYLE_CACHE: dict[int, Style] = {}
_COLOR_CACHE: dict[int, Color] = {}


def _color(v: int) -> Color:
    c = _COLOR_CACHE.get(v)
    if c is None:
        c = Color.from_rgb((v >> 16) & 255, (v >> 8) & 255, v & 255)
        _COLOR_CACHE[v] = c
    return c


def _style(key: int) -> Style:
    s = _STYLE_CACHE.get(key)
    if s is None:
        if len(_STYLE_CACHE) > 400_000:  # bound memory on colourful images
            _STYLE_CACHE.clear()
        s = Style(color=_color(key >> 24), bgcolor=_color(key & 0xFFFFFF))
        _STYLE_CACHE[key] = s
    return s


_RUNS = [UPPER_HALF * n for n in range(1024)]  # the text of a run of n cells


def halfblock_strips(grid: np.ndarray) -> list[Strip]:
    """(2R, C, 3) uint8 RGB -> R Strips of C half-block cells.

    An odd last row is paired with black. Runs of identical cells become one Segment.
    The runs of every row are found at once; each distinct cell colour pair looks its Style
    up once per call.
    """
    g = grid.astype(np.int64, copy=False)
    if g.shape[0] % 2:
        g = np.concatenate([g, np.zeros((1,) + g.shape[1:], np.int64)], axis=0)
    packed = (g[:, :, 0] << 16) | (g[:, :, 1] << 8) | g[:, :, 2]
    keys = (packed[0::2] << 24) | packed[1::2]  # (R, C)
    rows, cols = keys.shape
    if rows == 0 or cols == 0:
        return [Strip([], cols) for _ in range(rows)]
    change = np.ones(keys.shape, bool)  # a run starts here
    change[:, 1:] = keys[:, 1:] != keys[:, :-1]
    rr, cc = np.nonzero(change)  # row-major: the runs of row 0, then row 1...
    ends = np.empty_like(cc)
    ends[:-1] = cc[1:]
    last = np.ones(len(cc), bool)  # the last run of its row
    last[:-1] = rr[1:] != rr[:-1]
    ends[last] = cols
    uniq, inverse = np.unique(keys[rr, cc], return_inverse=True)
    cache = _STYLE_CACHE
    styles = [cache.get(k) or _style(k) for k in uniq.tolist()]
    runs = _RUNS
    segs = [Segment(runs[n] if n < 1024 else UPPER_HALF * n, styles[i])
            for n, i in zip((ends - cc).tolist(), inverse.ravel().tolist())]
    strips: list[Strip] = []
    a = 0
    for b in (np.flatnonzero(last) + 1).tolist():
        strips.append(Strip(segs[a:b], cols))
        a = b
    return strips


_ASCII_STYLE = Style()
_ASCII_CURSOR = Style(reverse=True, bold=True)


def ascii_strips(grid: np.ndarray, *, cursor_cell: tuple[int, int] | None = None) -> list[Strip]:
    """(2R, C, 3) or (2R, C) uint8 -> R Strips of ramp characters (no colour).

    Each cell shows the mean luminance of its two pixels; ``cursor_cell`` (col, row)
    is drawn as a reversed ``+``.
    """
    if grid.ndim == 3:
        lum = grid[:, :, 0] * 0.299 + grid[:, :, 1] * 0.587 + grid[:, :, 2] * 0.114
    else:
        lum = grid.astype(np.float32)
    if lum.shape[0] % 2:
        lum = np.concatenate([lum, np.zeros((1, lum.shape[1]), lum.dtype)])
    cells = (lum[0::2] + lum[1::2]) * 0.5
    idx = np.clip((cells * (len(ASCII_RAMP) / 256.0)).astype(np.int32), 0, len(ASCII_RAMP) - 1)
    lut = np.array(list(ASCII_RAMP))
    chars = lut[idx]
    strips = []
    cols = chars.shape[1]
    for r in range(chars.shape[0]):
        text = "".join(chars[r].tolist())
        if cursor_cell is not None and cursor_cell[1] == r and 0 <= cursor_cell[0] < cols:
            c = cursor_cell[0]
            segs = [Segment(text[:c], _ASCII_STYLE), Segment("+", _ASCII_CURSOR), Segment(text[c + 1 :], _ASCII_STYLE)]
        else:
            segs = [Segment(text, _ASCII_STYLE)]
        strips.append(Strip(segs, cols))
    return strips
