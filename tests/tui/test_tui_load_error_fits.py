"""Issue 37 (80x24 is a first-class size): the load screen's title, "Could not open <path>", wraps a long path
inside its box instead of cutting it off at the border (found by opening a GIPL file in tmux at 80x24)."""

from __future__ import annotations

import io

import pytest

from ctui.screens.app import CtuiApp, LoadingScreen
from ctui.screens.testing import wait_for

pytestmark = pytest.mark.slow


def _screen_text(app) -> str:
    """The characters of every cell on screen, one line per row, the line breaks of wrapped text removed."""
    from rich.console import Console

    w, h = app.size
    con = Console(width=w, height=h, file=io.StringIO(), force_terminal=True, record=True, legacy_windows=False)
    con.print(app.screen._compositor.render_update(full=True, screen_stack=app._background_screens))
    return con.export_text(clear=False)


async def test_80x24_could_not_open_shows_the_whole_path(tmp_path):
    bad = tmp_path / "a_folder_with_a_long_name_for_the_study" / "MRIcrop-orig-series-from-another-tool.gipl.gz"
    bad.parent.mkdir()
    bad.write_bytes(b"\x00" * 600)
    app = CtuiApp(str(bad))
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_for(pilot, lambda: app.errors, what="the load error")
        await pilot.pause()
        assert isinstance(app.screen, LoadingScreen)
        title = app.screen.query_one("#load-title")
        box = title.parent.content_region
        assert title.region.right <= box.right and title.region.height >= 2  # wrapped inside the box
        joined = "".join(line.strip(" │") for line in _screen_text(app).splitlines())
        assert f"Could not open{bad}" in joined  # the whole path, its end included (the wrap drops a space)
