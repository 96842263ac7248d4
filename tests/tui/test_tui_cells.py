"""The numpy-to-terminal renderer: geometry of the fit, exact cell colours, the cursor,
the ascii ramp, and graphics-mode selection."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.screens import cells, graphics


def test_fit_keeps_physical_aspect_and_letterboxes():
    # 100 x 200 pixels of 1 x 0.5 mm: physically square -> square in a 160x100 grid
    (x0, y0, x1, y1), vm = cells.fit_view((100, 200), (160, 100), spacing_yx=(1.0, 0.5))
    assert (x0, y0, x1, y1) == (0, 0, 200, 100)
    assert vm.w == 100 and vm.h == 100
    assert vm.ox == 30 and vm.oy == 0
    # the image centre maps to the grid centre and back
    xd, yd = vm.to_display(99.5, 49.5)
    assert abs(xd - 80) < 1e-6 and abs(yd - 50) < 1e-6
    xi, yi = vm.to_image(xd, yd)
    assert abs(xi - 99.5) < 1e-6 and abs(yi - 49.5) < 1e-6


def test_zoom_crops_around_centre_and_clamps():
    (x0, y0, x1, y1), vm = cells.fit_view((512, 512), (100, 100), zoom=4, center=(10, 500))
    assert x1 - x0 == 128 and y1 - y0 == 128
    assert x0 == 0 and y1 == 512  # clamped inside the image
    (x0, y0, x1, y1), _ = cells.fit_view((512, 512), (100, 100), zoom=4, center=(255, 255))
    assert (x0 + x1) / 2 == pytest.approx(256, abs=1)


def test_render_view_downsamples_exactly_with_area_interpolation():
    img = np.zeros((4, 4), np.uint8)
    img[:2, :2] = 200  # top-left quarter bright
    grid, vm = cells.render_view(img, (2, 2))
    assert grid.shape == (2, 2, 3)
    assert grid[0, 0].tolist() == [200, 200, 200]
    assert grid[1, 1].tolist() == [0, 0, 0]


def test_halfblock_cells_carry_top_and_bottom_pixels():
    rng = np.random.default_rng(1)
    grid = rng.integers(0, 256, (6, 5, 3), dtype=np.uint8)
    strips = cells.halfblock_strips(grid)
    assert len(strips) == 3
    for r, strip in enumerate(strips):
        assert strip.cell_length == 5
        col = 0
        for seg in strip:
            for _ in seg.text:
                assert seg.text[0] == cells.UPPER_HALF
                fg = seg.style.color.triplet
                bg = seg.style.bgcolor.triplet
                assert (fg.red, fg.green, fg.blue) == tuple(grid[2 * r, col])
                assert (bg.red, bg.green, bg.blue) == tuple(grid[2 * r + 1, col])
                col += 1
        assert col == 5


def test_halfblock_merges_runs():
    grid = np.full((4, 80, 3), 77, np.uint8)
    strips = cells.halfblock_strips(grid)
    assert all(len(list(s)) == 1 for s in strips)
    assert strips[0].cell_length == 80


def test_cursor_circle_is_red_and_centred():
    grid = np.zeros((50, 50, 3), np.uint8)
    _, vm = cells.fit_view((50, 50), (50, 50))
    cells.draw_cursor(grid, vm, 20, 30)
    red = np.all(grid == (255, 40, 40), axis=2)
    ys, xs = np.nonzero(red)
    assert red[30, 20]  # centre dot on the pixel
    assert abs(xs.mean() - 20) < 1 and abs(ys.mean() - 30) < 1
    assert xs.max() - xs.min() >= 4  # a circle, not a dot


def test_ascii_ramp_orders_brightness_and_marks_cursor():
    grid = np.zeros((2, 10), np.uint8)
    grid[:, :] = np.linspace(0, 255, 10, dtype=np.uint8)[None, :]
    (strip,) = cells.ascii_strips(grid, cursor_cell=(3, 0))
    text = "".join(seg.text for seg in strip)
    assert len(text) == 10
    assert text[0] == " " and text[-1] == "@"
    assert text[3] == "+"
    ramp = [cells.ASCII_RAMP.index(c) for i, c in enumerate(text) if i != 3]
    assert ramp == sorted(ramp)


@pytest.mark.parametrize("mode", ["halfblock", "ascii"])
def test_prepare_graphics_overrides(monkeypatch, mode):
    monkeypatch.setattr(graphics, "_chosen", None)
    assert graphics.prepare_graphics(mode) == mode
    assert graphics.graphics_mode() == mode
    monkeypatch.setenv("CTUI_GRAPHICS", mode)
    assert graphics.prepare_graphics(None) == mode


def test_prepare_graphics_rejects_unknown(monkeypatch):
    monkeypatch.setattr(graphics, "_chosen", None)
    with pytest.raises(ValueError):
        graphics.prepare_graphics("vt100")


def test_colour_advice_only_below_truecolor(monkeypatch):
    monkeypatch.setenv("SSH_CONNECTION", "1.2.3.4 5 6.7.8.9 22")
    assert graphics.colour_advice("truecolor") is None
    msg = graphics.colour_advice("256")
    assert "TEXTUAL_COLOR_SYSTEM=truecolor" in msg and "SendEnv COLORTERM" in msg and "SSH" in msg
