"""The colour-depth advice (a terminal, tmux here, giving 256 colours) at 80x24: on the status line below the
views, not a toast. The 15 s toast of it covered 11 of the 24 rows, the status line and key bar included."""

from __future__ import annotations

import html
import re

import numpy as np
import pytest

from ctui.engine.core.volume import Volume
from ctui.screens import graphics
from ctui.screens.app import CtuiApp
from ctui.screens.session import Session
from ctui.screens.testing import wait_for, wait_workspace

pytestmark = pytest.mark.slow


def _screen_rows(app) -> list[str]:
    """The screen's text, row by row (from Textual's SVG screenshot)."""
    svg = app.export_screenshot()
    rows: dict[float, list[tuple[float, str]]] = {}
    for cls, x, y, text in re.findall(r'<text class="([^"]*)" x="([\d.]+)" y="([\d.]+)"[^>]*>([^<]*)</text>', svg):
        if "title" in cls:  # the window title above the screen
            continue
        rows.setdefault(float(y), []).append((float(x), html.unescape(text).replace("\xa0", " ")))
    return ["".join(t for _, t in sorted(parts)) for _, parts in sorted(rows.items())]


async def test_80x24_colour_advice_on_the_status_line_not_a_toast():
    from textual.widgets._toast import Toast

    s = Session(Volume(np.zeros((4, 32, 32), np.int16), spacing=(1.0, 1.0, 1.0), modality="CT"), source_path="synthetic")
    app = CtuiApp(session=s, autosave_s=1e9)
    advice = graphics.colour_advice("256", {"TMUX": "/tmp/tmux-0/default,1,0"})
    async with app.run_test(size=(80, 24), notifications=True) as pilot:
        await wait_workspace(pilot, app)
        app.colour_note(advice)
        status = app.screen.query_one("#status")
        await wait_for(pilot, lambda: "TEXTUAL_COLOR_SYSTEM" in str(status.render()), what="the colour note")
        await pilot.pause(0.3)
        assert not list(app.screen.query(Toast))  # nothing laid over the views
        keys, views = app.screen.query_one("#keys"), app.screen.query_one("#views")
        assert status.region.height <= 3 and status.region.bottom <= keys.region.y
        assert views.region.bottom <= status.region.y and views.region.height >= 24 - 3 - 3 - 1
        shown = " ".join(r.strip() for r in _screen_rows(app)[status.region.y:status.region.bottom])
        assert "256 colours only" in shown and "terminal-overrides ',*:RGB'" in shown, shown
        assert "TEXTUAL_COLOR_SYSTEM=truecolor" in shown, shown
