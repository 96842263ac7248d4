"""First run: the bundled sample opens without a warning about its own truth.json; the
colour warning appears only when truecolour is really unavailable, and inside tmux it
gives tmux's one-line fix; a terminal known to draw 24-bit colour gets it without asking."""

from __future__ import annotations

from ctui.screens import graphics
from ctui.screens.app import CtuiApp
from ctui.screens.testing import wait_workspace
from support import SAMPLE_DATA


def test_colour_advice_and_detection(monkeypatch):
    assert graphics.colour_advice("truecolor", {"TMUX": "/tmp/x"}) is None
    advice = graphics.colour_advice("256", {"TMUX": "/tmp/x,1,0"})
    assert graphics.TMUX_FIX in advice and "terminal-overrides" in advice and "-T RGB" in advice
    assert "SendEnv" not in advice  # not over SSH: the tmux fix is the one line to add
    ssh = graphics.colour_advice("256", {"SSH_CONNECTION": "1 2 3 4"})
    assert "SendEnv COLORTERM" in ssh and "tmux" not in ssh
    assert graphics.truecolor_available({"COLORTERM": "truecolor"})
    assert graphics.truecolor_available({"TERM_PROGRAM": "WezTerm", "TERM": "xterm-256color"})
    assert not graphics.truecolor_available({"TERM": "xterm-256color"})
    monkeypatch.setattr(graphics, "tmux_rgb", lambda env=None: True)
    assert graphics.truecolor_available({"TMUX": "x", "TERM": "tmux-256color"})
    monkeypatch.setattr(graphics, "tmux_rgb", lambda env=None: None)  # tmux does not say: ask the user
    assert not graphics.truecolor_available({"TMUX": "x", "TERM": "tmux-256color"})


def test_enable_truecolor_sets_colorterm_only_when_available(monkeypatch):
    monkeypatch.delenv("TEXTUAL_COLOR_SYSTEM", raising=False)
    monkeypatch.delenv("COLORTERM", raising=False)
    monkeypatch.setenv("TMUX", "/tmp/tmux-0/default,1,0")
    monkeypatch.setattr(graphics, "tmux_rgb", lambda env=None: False)
    assert not graphics.enable_truecolor()
    assert "COLORTERM" not in __import__("os").environ
    monkeypatch.setattr(graphics, "tmux_rgb", lambda env=None: True)
    assert graphics.enable_truecolor()
    assert __import__("os").environ["COLORTERM"] == "truecolor"


async def test_sample_opens_without_warning_about_its_own_files(monkeypatch, tmp_path):
    monkeypatch.setattr(graphics, "_chosen", "halfblock")
    monkeypatch.setenv("CTUI_AUTOSAVE_DIR", str(tmp_path / "autosave"))
    sample = SAMPLE_DATA / "phantom"
    assert (sample / "truth.json").is_file()
    said: list[str] = []
    original = CtuiApp.notify

    def notify(self, message, **kw):
        said.append(str(message))
        return original(self, message, **kw)

    monkeypatch.setattr(CtuiApp, "notify", notify)
    app = CtuiApp(str(sample), autosave_s=1e9)
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.pause()
        assert any(sk["file"].endswith("truth.json") for sk in app.session.volume.skipped)  # still recorded
        assert not [m for m in said if "truth.json" in m or "skipped" in m.lower()], said
