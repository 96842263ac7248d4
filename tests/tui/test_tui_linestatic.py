"""LineStatic (the side panel's base): an update that repaints only the changed lines leaves the screen
exactly as a full repaint of the same text does (rows shifted by a wrapped line included), and takes the
partial path when the lines keep their rows."""

from __future__ import annotations

from rich.text import Text
from textual.app import App
from textual.widgets import Static

from ctui.screens.linestatic import LineStatic, text_rows


def _panel(z: int, value: int, note: str = "") -> Text:
    t = Text()
    t.append("ctui", style="bold")
    t.append("  series\n", style="dim")
    t.append(f"Slice {z}/99", style="bold")
    t.append(f"  {z * 2.5:.1f} mm\n")
    t.append("Segment fill slice, neck auto, range T's, else auto, holes filled\n", style="dim")  # wraps
    t.append("Value ", style="bold")
    t.append(f"{value} HU\n")
    t.append(note, style="yellow")
    t.append("\nObjects\n", style="bold underline")
    t.append("██", style="rgb(255,0,0)")
    t.append(f" kidney {value * 3:7d}mm²\n")
    return t


class _PanelApp(App):
    CSS = "LineStatic { width: 30; height: 14; padding: 0 1; background: $panel; }"

    def compose(self):
        yield LineStatic(id="p")


async def test_partial_repaint_equals_a_full_repaint(monkeypatch):
    full_updates = []
    real = Static.update

    def counting(self, content="", *, layout=True):
        full_updates.append(layout)
        return real(self, content, layout=layout)

    app = _PanelApp()
    async with app.run_test(size=(40, 16)) as pilot:
        p = app.query_one(LineStatic)
        p.update(_panel(0, 40), layout=False)
        await pilot.pause()
        monkeypatch.setattr(Static, "update", counting)
        for z, value, note in [(1, 40, ""), (2, 41, ""), (3, 41, "note"), (4, -7, "note"), (5, 1234, "other note")]:
            p.update(_panel(z, value, note), layout=False)
            await pilot.pause()
            partial = app.export_screenshot()
            p.refresh()  # everything repainted from the text
            await pilot.pause()
            assert app.export_screenshot() == partial, (z, value, note)
        assert not full_updates  # every update above only repainted its changed lines
        p.update(Text("short\n"), layout=False)  # fewer lines: a full update
        await pilot.pause()
        assert full_updates == [False] and "short" in app.export_screenshot()


def test_text_rows_counts_wrapped_lines():
    rows = text_rows(_panel(3, 40), 28)
    assert rows is not None and [n for _, n in rows] == [1, 1, 3, 1, 1, 1, 1, 1]
    assert text_rows("not rich text", 28) is None
