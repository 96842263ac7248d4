"""Small modal dialogs: prompts, confirmations, choices, help and error text."""

from __future__ import annotations

from rich.text import Text
from textual import events
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.dom import DOMNode
from textual.screen import ModalScreen
from textual.widgets import Button, Input, Label, OptionList, Static
from textual.widgets.option_list import Option

from ctui.screens.guard import GuardMixin


class PromptInput(Input):
    """An Input that runs its own key bindings (Backspace, Ctrl+U, Enter, arrows...) at
    once, in key order. Textual runs bindings only when the key has bubbled up to the
    app, after the characters typed behind it in a burst were already inserted: "5",
    Backspace, "6" gave "6"-less text and Ctrl+U wiped the path pasted after it."""

    async def _on_key(self, event: events.Key) -> None:
        bindings = self._bindings.key_to_bindings.get(event.key)
        if not bindings:
            return  # Input._on_key (inserting the character) runs next
        event.prevent_default()
        event.stop()
        await self.run_action(bindings[0].action)


class PromptScreen(GuardMixin, ModalScreen[str | None]):
    """Ask for one line of text; dismiss with the text (Enter) or None (Escape)."""

    DEFAULT_CSS = """
    PromptScreen { align: center middle; }
    PromptScreen > Vertical { width: 90%; max-width: 100; height: auto; border: round $accent; background: $surface;
                              padding: 0 1; }
    PromptScreen Label { width: 1fr; }
    """
    BINDINGS = [Binding("escape", "cancel", "Cancel")]

    def __init__(self, title: str, value: str = "", placeholder: str = "") -> None:
        super().__init__()
        self.title_text = title
        self.value = value
        self.placeholder = placeholder
        self._typed: str | None = None  # keys typed before the input had focus
        self._done = False

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.title_text)
            yield PromptInput(value=self.value, placeholder=self.placeholder, id="prompt")
            clear = ", Ctrl+U clears it" if self.value else ""  # a pre-filled value: say how to empty it
            yield Label(f"[dim]Enter accepts{clear}, Escape cancels[/dim]")

    def on_mount(self) -> None:
        inp = self.query_one(Input)
        inp.focus()
        if self._typed is not None:  # keys that came before the input could take them
            inp.value = self._typed
            inp.cursor_position = len(self._typed)

    def feed_key(self, key: str, character: str | None) -> None:
        """A key typed in a burst before this prompt was on screen (handed on by the app):
        text replaces the default value (as typing into the selected default does),
        Backspace deletes, Enter accepts, Escape cancels."""
        if key == "enter":
            self._finish(self._typed if self._typed is not None else self.value)
            return
        if key == "escape":
            self._finish(None)
            return
        if key == "backspace":
            self._typed = (self._typed or "")[:-1]
        elif character and character.isprintable():
            self._typed = (self._typed or "") + character
        else:
            return
        inp = self.query(Input).first() if self.is_mounted and self.query(Input) else None
        if inp is not None:
            inp.value = self._typed
            inp.cursor_position = len(self._typed)

    def _finish(self, value: str | None) -> None:
        if not self._done:
            self._done = True
            self.dismiss(value)

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self._finish(event.value)

    def action_cancel(self) -> None:
        self._finish(None)


class ConfirmScreen(GuardMixin, ModalScreen[bool]):
    """Yes/no question; y/n keys, Escape = no."""

    DEFAULT_CSS = """
    ConfirmScreen { align: center middle; }
    ConfirmScreen > Vertical { width: 90%; max-width: 90; height: auto; border: round $warning; background: $surface;
                               padding: 0 1; }
    ConfirmScreen Label { width: 1fr; }
    ConfirmScreen Horizontal { height: auto; }
    ConfirmScreen Button { margin: 0 1; }
    ConfirmScreen.at-bottom { align: center bottom; background: $background 10%; }
    """
    BINDINGS = [
        Binding("y", "answer(True)", "Yes"),
        Binding("n,escape", "answer(False)", "No"),
    ]

    def __init__(self, question: str, yes: str = "Yes", no: str = "No", *, at_bottom: bool = False) -> None:
        """``at_bottom``: at the foot of the screen over a light backdrop, so the image the
        question is about stays in view; the focus starts on "no" there (a destructive
        question: an Enter out of habit keeps the work)."""
        super().__init__(classes="at-bottom" if at_bottom else None)
        self.at_bottom = at_bottom
        self.question = question
        self.yes, self.no = yes, no

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.question)
            with Horizontal():
                yield Button(f"{self.yes} (y)", id="yes", variant="primary")
                yield Button(f"{self.no} (n)", id="no")

    def on_mount(self) -> None:
        if self.at_bottom:
            self.query_one("#no", Button).focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "yes")

    def action_answer(self, value: bool) -> None:
        self.dismiss(value)


class ChoiceScreen(GuardMixin, ModalScreen[str | None]):
    """Pick one of several options (arrow keys + Enter, or the option's hot key)."""

    DEFAULT_CSS = """
    ChoiceScreen { align: center middle; }
    ChoiceScreen > Vertical { width: 90%; max-width: 90; height: auto; max-height: 100%; border: round $accent;
                              background: $surface; padding: 0 1; }
    ChoiceScreen Label { width: 1fr; }
    ChoiceScreen OptionList { height: auto; max-height: 20; }
    ChoiceScreen.small OptionList { max-height: 10; }
    """
    BINDINGS = [Binding("escape", "cancel", "Cancel")]

    def __init__(self, title: str, options: list[tuple[str, str]], *, note: str = "") -> None:
        """options: (id, label) pairs; ``note``: dim text under the list (e.g. why some
        choices are not offered)."""
        super().__init__()
        self.title_text = title
        self.options = options
        self.note = note

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.title_text)
            yield OptionList(*[Option(label, id=oid) for oid, label in self.options])
            if self.note:
                yield Label(Text(self.note, style="dim italic"))

    def on_mount(self) -> None:
        self.query_one(OptionList).focus()
        self.set_class(self.app.size.height < 30, "small")  # 80x24: the list scrolls, the note stays in view

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        self.dismiss(event.option.id)

    def action_cancel(self) -> None:
        self.dismiss(None)


class TextScreen(GuardMixin, ModalScreen[None]):
    """Scrollable text (help, error reasons, reports); Escape/q closes."""

    DEFAULT_CSS = """
    TextScreen { align: center middle; }
    TextScreen > Vertical { width: 90%; height: 90%; border: round $accent; background: $surface; padding: 0 1; }
    TextScreen VerticalScroll { height: 1fr; }
    """
    BINDINGS = [Binding("escape,q,question_mark", "close", "Close")]

    def __init__(self, title: str, body, *, markup: bool = True) -> None:
        super().__init__()
        self.title_text = title
        self.body = body
        self.markup = markup

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(f"[b]{self.title_text}[/b]  [dim](Escape closes)[/dim]")
            with VerticalScroll():
                yield Static(self.body, markup=self.markup)

    def on_mount(self) -> None:
        self.query_one(VerticalScroll).focus()

    def action_close(self) -> None:
        self.dismiss(None)


def bindings_help(screen: DOMNode) -> str:
    """Every binding of a screen (and the app) as help text."""
    lines = []
    seen = set()
    for node in (screen, screen.app):
        for b in getattr(node, "BINDINGS", []):
            if isinstance(b, tuple):
                key, action, desc = (list(b) + ["", ""])[:3]
            else:
                key, action, desc = b.key, b.action, b.description
            if (key, action) in seen:
                continue
            seen.add((key, action))
            shown = []
            for k in key.split(","):
                k = k.strip()
                try:
                    d = screen.app.get_key_display(Binding(k, action, desc or ""))
                except Exception:
                    d = k
                shown.append(d if d == k else f"{d} ({k})")
            keys = f"{', '.join(shown):<34}".replace("[", "\\[")
            lines.append(f"  [b]{keys}[/b] {desc or action}")
    return "\n".join(lines)
