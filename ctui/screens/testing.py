"""Helpers for driving the app with Textual's Pilot (tests, benchmarks): wait for
states, move the cursor with the keys a person would press."""

from __future__ import annotations

import time


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
    """Replace the focused Input's value with ``text`` and press Enter."""
    await pilot.pause()
    inp = pilot.app.focused
    if inp is None or not hasattr(inp, "value"):
        raise AssertionError(f"no text input focused (screen {type(pilot.app.screen).__name__})")
    inp.value = text
    await pilot.press("enter")
    await pilot.pause()


async def choose(pilot, option_id: str) -> None:
    """Pick an option by id in the focused OptionList (a ChoiceScreen)."""
    await pilot.pause()
    from textual.widgets import OptionList

    ol = pilot.app.screen.query_one(OptionList)
    ids = [ol.get_option_at_index(i).id for i in range(ol.option_count)]
    ol.highlighted = ids.index(option_id)
    await pilot.press("enter")
    await pilot.pause()
