"""The ten object colours shared by the slice overlay, the renderer and exports.

Object ids are 1..10 (0 is background in label volumes). ``OBJECT_COLORS[i-1]`` is
object ``i``'s colour as (r, g, b) in 0..255.
"""

from __future__ import annotations

MAX_OBJECTS = 10

OBJECT_COLORS: tuple[tuple[int, int, int], ...] = (
    (230, 60, 60),    # 1 red
    (60, 180, 75),    # 2 green
    (65, 120, 230),   # 3 blue
    (255, 200, 40),   # 4 yellow
    (240, 130, 40),   # 5 orange
    (160, 80, 220),   # 6 purple
    (70, 220, 220),   # 7 cyan
    (240, 80, 200),   # 8 magenta
    (170, 230, 60),   # 9 lime
    (250, 170, 170),  # 10 pink
)


def object_color(object_id: int) -> tuple[int, int, int]:
    """RGB (0..255) of object ``object_id`` (1..10)."""
    return OBJECT_COLORS[(int(object_id) - 1) % MAX_OBJECTS]


def object_color_float(object_id: int) -> tuple[float, float, float]:
    """RGB (0..1) of object ``object_id`` (1..10)."""
    r, g, b = object_color(object_id)
    return (r / 255.0, g / 255.0, b / 255.0)
