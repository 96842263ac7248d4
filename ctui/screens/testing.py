"""Helpers for driving the app with Textual's Pilot (tests, benchmarks): wait for
states, move the cursor with the keys a person would press."""

from __future__ import annotations

import contextlib
import time
from typing import TYPE_CHECKING, Any, AsyncIterator

from textual.events import MouseMove, MouseScrollDown, MouseScrollUp
from textual.widgets import OptionList

from ctui.screens import planes
from ctui.screens.graphics import PIXEL_MODES, cell_pixels

if TYPE_CHECKING:
    from ctui.screens.session import Session


async def wait_for(pilot, predicate, *, timeout: float = 90.0, what: str = "condition") -> None:
    """Pause the pilot until ``predicate()`` is true (or raise TimeoutError)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            if predicate():
                return
        except Exception:
            pass
        await pilot.pause(0.02)
    raise TimeoutError(f"timed out waiting for {what}")


async def wait_workspace(pilot, app, timeout: float = 120.0) -> None:
    def ready() -> bool:
        ws = app.workspace
        return ws is not None and app.screen is ws and ws.is_mounted and bool(ws.query("#main"))

    await wait_for(pilot, ready, timeout=timeout, what="the workspace")


@contextlib.asynccontextmanager
async def workspace_of(session: Session, size: tuple[int, int] = (120, 40)) -> AsyncIterator[tuple[Any, Any, Any]]:
    """``async with workspace_of(session, (cols, rows)) as (app, pilot, ws)``: the app on ``session``
    (no autosave) at that terminal size, with its workspace on screen."""
    from ctui.screens.app import CtuiApp  # only when used: benchmarks import this module without the app

    app = CtuiApp(session=session, autosave_s=1e9)
    async with app.run_test(size=size) as pilot:
        await wait_workspace(pilot, app)
        yield app, pilot, app.workspace


async def goto_voxel(pilot, app, z: int, y: int, x: int) -> None:
    """Move to slice z (``g`` + number + Enter) and the cursor to (x, y) with
    shift+h/j/k/l (10 px) and h/j/k/l (1 px)."""
    s = app.session
    await pilot.press("g", *list(str(z)), "enter")
    dx, dy = x - s.x, y - s.y
    keys = (["L"] if dx > 0 else ["H"]) * (abs(dx) // 10) + (["l"] if dx > 0 else ["h"]) * (abs(dx) % 10)
    keys += (["J"] if dy > 0 else ["K"]) * (abs(dy) // 10) + (["j"] if dy > 0 else ["k"]) * (abs(dy) % 10)
    if keys:
        await pilot.press(*keys)
    await pilot.pause()


async def answer_prompt(pilot, text: str) -> None:
    """Replace the focused Input's value with ``text`` and press Enter, once a text input has
    the focus (the prompt may come after a slow step: a cold start's first fill took seconds
    under load, and an Enter sent before the prompt was up filled the slice instead)."""
    await pilot.pause()
    try:
        await wait_for(pilot, lambda: hasattr(pilot.app.focused, "value"), timeout=30, what="a text prompt")
    except TimeoutError:
        pass  # reported below with the screen's name
    inp = pilot.app.focused
    if inp is None or not hasattr(inp, "value"):
        raise AssertionError(f"no text input focused (screen {type(pilot.app.screen).__name__})")
    inp.value = text
    await pilot.press("enter")
    await pilot.pause()


async def choose(pilot, option_id: str) -> None:
    """Pick an option by id in the focused OptionList (a ChoiceScreen)."""
    await pilot.pause()

    ol = pilot.app.screen.query_one(OptionList)
    ids = [ol.get_option_at_index(i).id for i in range(ol.option_count)]
    ol.highlighted = ids.index(option_id)
    await pilot.press("enter")
    await pilot.pause()


def cell_of_voxel(app, zyx, widget_id: str = "#main", plane: str | None = None) -> tuple[int, int]:
    """(column, row) offset in the widget ``widget_id`` of the cell showing voxel ``zyx`` (z, y, x)
    on ``plane`` (the session's plane), through :mod:`ctui.screens.planes` and the view's map."""
    ws = app.workspace
    iv = ws.query_one(widget_id)
    s = app.session
    pv = planes.plane_view(s.volume, plane or s.plane)
    c, r = planes.cursor_in(pv, tuple(zyx), s.shape)
    xd, yd = iv.view_map.to_display(c, r)
    if iv.mode in PIXEL_MODES:
        cw, ch = cell_pixels()
        return int(xd // cw), int(yd // ch)
    return int(xd), int(yd // 2)


async def drag(pilot, widget_id: str, cells: list[tuple[int, int]], *, button: int = 1, shift: bool = False,
               meta: bool = False, control: bool = False) -> None:
    """Press at the first cell of ``cells`` (offsets in ``widget_id``), move through the
    others with the button held, release at the last."""
    await pilot.mouse_down(widget_id, offset=cells[0], button=button, shift=shift, meta=meta, control=control)
    for c in cells[1:]:
        await pilot._post_mouse_events([MouseMove], widget_id, offset=c, button=button, shift=shift, meta=meta,
                                       control=control)
    await pilot.mouse_up(widget_id, offset=cells[-1], shift=shift, meta=meta, control=control)


async def wheel(pilot, widget_id: str, offset: tuple[int, int] = (2, 2), *, up: bool = True, control: bool = False) -> None:
    """One wheel notch over ``widget_id`` (Ctrl held with ``control``)."""
    await pilot._post_mouse_events([MouseScrollUp if up else MouseScrollDown], widget_id, offset=offset,
                                   control=control)
