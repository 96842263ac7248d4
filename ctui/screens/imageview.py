"""ImageView: one widget that shows a numpy RGB image in any graphics mode.

Half-block and ascii are drawn by ctui's own renderer (:mod:`ctui.screens.cells`)
with Textual's Line API; sixel and kitty hand a pre-sized PIL image (resized with
OpenCV to exactly the widget's pixel size) to textual-image's widgets.

The image may carry pixel spacing (physical aspect), a zoom/pan and a cursor (the red
circle); the widget fits it to whatever size it has, so resizing the terminal just
works.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from textual.geometry import Size
from textual.strip import Strip
from textual.timer import Timer
from textual.widget import Widget

from ctui.screens import cells
from ctui.screens.graphics import PIXEL_MODES, WEB_DEBOUNCE_S, cell_pixels, graphics_mode, pixel_cap


class ImageView(Widget):
    """Shows ``rgb`` (h, w, 3) uint8 fitted to the widget.

    Attributes set by the owner: ``spacing_yx``, ``zoom``, ``center`` (x, y),
    ``cursor`` (x, y) or None. Call :meth:`set_image` (it refreshes). ``painted``
    holds (token, perf_counter time) of the last completed paint, for benchmarks.
    """

    DEFAULT_CSS = """
    ImageView { width: 1fr; height: 1fr; background: black; }
    ImageView > .tii { width: 1fr; height: 1fr; }
    """

    def __init__(self, *, mode: str | None = None, name: str | None = None, id: str | None = None, classes: str | None = None) -> None:
        super().__init__(name=name, id=id, classes=classes)
        self.mode = mode or graphics_mode()
        self.rgb: np.ndarray | None = None
        self.spacing_yx: tuple[float, float] = (1.0, 1.0)
        self.zoom: float = 1.0
        self.center: tuple[float, float] | None = None
        self.cursor: tuple[float, float] | None = None
        self.token: Any = None
        self.painted: tuple[object, float] = (None, 0.0)
        self.view_map: cells.ViewMap | None = None
        self.overlay: Callable[[Any, Any], None] | None = None  # callable(grid, view_map) drawing marks in display pixels (seeds, box, brush)
        self._strips: list[Strip] | None = None
        self._strips_key: tuple | None = None
        self._tii = None  # textual-image child widget for sixel/kitty
        self._tii_key: tuple | None = None
        self._tii_timer: Timer | None = None  # web mode: the pending (throttled) image update
        self._tii_sent = 0.0  # when the last image update went out

    # ----------------------------------------------------------------- public
    def set_image(self, rgb: np.ndarray | None, *, token: object = None, spacing_yx=None, zoom=None, center=None, cursor=...) -> None:
        """Replace the image (and optionally the view parameters); repaints."""
        self.rgb = rgb
        self.token = token
        if spacing_yx is not None:
            self.spacing_yx = (float(spacing_yx[0]), float(spacing_yx[1]))
        self.set_view(zoom=zoom, center=center, cursor=cursor)

    def set_view(self, *, zoom=None, center=None, cursor=...) -> None:
        """Change the zoom, centre (x, y) or cursor (x, y) or None; repaints."""
        if zoom is not None:
            self.zoom = float(zoom)
        if center is not None:
            self.center = center
        if cursor is not ...:
            self.cursor = cursor
        self._invalidate()

    def target_pixels(self) -> tuple[int, int]:
        """(width, height) of this widget in display pixels for the current mode."""
        w, h = self.size.width, self.size.height
        if self.mode in PIXEL_MODES:
            cw, ch = cell_pixels()
            cap = pixel_cap()
            if cap is not None:  # web mode: whole cells within the cap
                w, h = min(w, max(cap[0] // cw, 1)), min(h, max(cap[1] // ch, 1))
            return max(w * cw, 1), max(h * ch, 1)
        return max(w, 1), max(2 * h, 1)

    # --------------------------------------------------------------- internals
    def _invalidate(self) -> None:
        self._strips = None
        if self.mode in PIXEL_MODES:
            wait = WEB_DEBOUNCE_S - (time.perf_counter() - self._tii_sent)
            if pixel_cap() is None or (wait <= 0 and self._tii_timer is None):
                self._flush_tii()
            elif self._tii_timer is None:  # web mode: at most one image per WEB_DEBOUNCE_S, the latest
                self._tii_timer = self.set_timer(max(wait, 0.001), self._flush_tii)
        self.refresh()

    def _flush_tii(self) -> None:
        self._tii_timer = None
        self._tii_sent = time.perf_counter()
        self._update_tii()

    def _grid(self, out_size: tuple[int, int]) -> np.ndarray | None:
        if self.rgb is None:
            return None
        grid, vm = cells.render_view(
            self.rgb, out_size, spacing_yx=self.spacing_yx, zoom=self.zoom, center=self.center
        )
        self.view_map = vm
        if self.cursor is not None and self.mode != "ascii":
            if grid is self.rgb:
                grid = grid.copy()
            cells.draw_cursor(grid, vm, *self.cursor)
        if self.overlay is not None and self.mode != "ascii":
            if grid is self.rgb:
                grid = grid.copy()
            self.overlay(grid, vm)
        return grid

    def compose(self):
        if self.mode in PIXEL_MODES:
            from textual_image.widget import SixelImage, TGPImage

            cls = SixelImage if self.mode == "sixel" else TGPImage
            self._tii = cls(classes="tii")
            yield self._tii

    def on_resize(self) -> None:
        self._invalidate()

    def _update_tii(self) -> None:
        if self._tii is None or self.size.width == 0:
            return
        key = (id(self.rgb), self.token, self.size, self.zoom, self.center, self.cursor)
        if key == self._tii_key:
            return
        self._tii_key = key
        target = self.target_pixels()
        if pixel_cap() is not None:  # the image widget is as large as the capped image
            cw, ch = cell_pixels()
            self._tii.styles.width, self._tii.styles.height = target[0] // cw, target[1] // ch
        grid = self._grid(target)
        if grid is None:
            self._tii.image = None
            return
        from PIL import Image as PILImage

        self._tii.image = PILImage.fromarray(np.ascontiguousarray(grid))
        self.painted = (self.token, time.perf_counter())

    def _ensure_strips(self) -> list[Strip]:
        size = self.size
        key = (size.width, size.height)
        if self._strips is not None and self._strips_key == key:
            return self._strips
        W, H = size.width, size.height
        grid = self._grid((W, 2 * H)) if W and H else None
        if grid is None:
            self._strips = [Strip.blank(W)] * H
        elif self.mode == "ascii":
            cc = None
            if self.cursor is not None and self.view_map is not None:
                xd, yd = self.view_map.to_display(*self.cursor)
                cc = (int(xd), int(yd) // 2)
            self._strips = cells.ascii_strips(grid, cursor_cell=cc)
        else:
            self._strips = cells.halfblock_strips(grid)
        self._strips_key = key
        return self._strips

    def render_line(self, y: int) -> Strip:
        if self.mode in PIXEL_MODES:
            return Strip.blank(self.size.width)
        strips = self._ensure_strips()
        if y == len(strips) - 1:
            self.painted = (self.token, time.perf_counter())
        if 0 <= y < len(strips):
            return strips[y]
        return Strip.blank(self.size.width)

    def render_lines(self, crop):
        """Strips straight from the half-block/ascii renderer.

        Bypasses Textual's per-line style cache and line filters: this widget has no
        border, padding or text styles, its cells are already truecolor, and the
        filter pass (ANSIToTruecolor, lru-cached on 1024 styles) thrashes on the
        thousands of distinct fg/bg pairs of a grey image, costing more than the
        whole render.
        """
        if self.mode in PIXEL_MODES:
            return super().render_lines(crop)
        strips = self._ensure_strips()
        W = self.size.width
        out = []
        x0, x1 = crop.x, crop.x + crop.width
        full = x0 == 0 and x1 >= W
        blank = None
        for y in range(crop.y, crop.y + crop.height):
            if 0 <= y < len(strips):
                st = strips[y]
                out.append(st if full else st.crop(x0, x1))
            else:
                blank = blank or Strip.blank(crop.width)
                out.append(blank)
        if crop.y + crop.height >= len(strips):
            self.painted = (self.token, time.perf_counter())
        return out

    def get_content_height(self, container: Size, viewport: Size, width: int) -> int:
        return container.height

    def display_to_image(self, col: int, row: int) -> tuple[float, float] | None:
        """Image pixel under a widget cell (for mouse clicks)."""
        if self.view_map is None:
            return None
        if self.mode in PIXEL_MODES:
            cw, ch = cell_pixels()
            return self.view_map.to_image((col + 0.5) * cw, (row + 0.5) * ch)
        return self.view_map.to_image(col + 0.5, 2 * row + 1.0)
