"""Pipeline editor (``f``): add/remove/reorder/toggle steps of
``ctui.engine.segment.pipeline.Pipeline``, edit parameters, a kernel editor grid for custom
structuring elements, and a live preview of the intermediate and final views."""

from __future__ import annotations

import numpy as np
from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Footer, Label, OptionList, Static
from textual.widgets.option_list import Option

from ctui.engine.actions.series import FILTERS, PARAMS
from ctui.screens.dialogs import ChoiceScreen, PromptScreen
from ctui.screens import planes
from ctui.screens.guard import GuardMixin
from ctui.screens.imageview import ImageView
from ctui.screens.keytable import keys
from ctui.screens.messages import StageViewsReady

MORPHOLOGY = ("closing", "opening", "erode", "dilate", "conservative")


def parse_params(text: str) -> dict:
    """'size=5 shape=ellipse sigma=1.5' -> {'size': 5, 'shape': 'ellipse', 'sigma': 1.5}."""
    out: dict = {}
    for tok in text.replace(",", " ").split():
        if "=" not in tok:
            raise ValueError(f"expected name=value, got {tok!r}")
        k, v = tok.split("=", 1)
        v = v.strip()
        val: object
        try:
            val = int(v)
        except ValueError:
            try:
                val = float(v)
            except ValueError:
                val = v
        out[k.strip()] = val
    return out


class KernelEditor(GuardMixin, ModalScreen[list | None]):
    """An n x n grid of 0/1 cells: arrows move, space toggles, +/- resize, Enter accepts."""

    DEFAULT_CSS = """
    KernelEditor { align: center middle; }
    KernelEditor > Vertical { width: auto; min-width: 40; height: auto; border: round $accent; background: $surface; padding: 0 1; }
    """
    BINDINGS = keys("""
    up,k              mv(0,-1)    Up           hidden
    down,j            mv(0,1)     Down         hidden
    left,h            mv(-1,0)    Left         hidden
    right,l           mv(1,0)     Right        hidden
    space             toggle_cell  Toggle cell
    plus,equals_sign  resize(2)   Bigger
    minus             resize(-2)  Smaller
    f                 fill(1)     All on
    c                 fill(0)     All off
    enter             accept      Accept
    escape            cancel      Cancel
    """)

    def __init__(self, kernel=None, size: int = 3) -> None:
        super().__init__()
        k = np.asarray(kernel, dtype=np.uint8) if kernel is not None else np.ones((size, size), np.uint8)
        self.k = k
        self.cx = k.shape[1] // 2
        self.cy = k.shape[0] // 2

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label("Custom kernel (structuring element)")
            yield Static(id="kgrid")
            yield Label("[dim]space toggles, +/- resize, f all on, c all off, Enter accepts[/dim]")

    def on_mount(self) -> None:
        self._draw()

    def _draw(self) -> None:
        t = Text()
        for y in range(self.k.shape[0]):
            for x in range(self.k.shape[1]):
                on = bool(self.k[y, x])
                cur = x == self.cx and y == self.cy
                style = ("reverse " if cur else "") + ("bold green" if on else "dim")
                t.append("█" if on else "·", style=style)
                t.append(" ")
            t.append("\n")
        self.query_one("#kgrid", Static).update(t)

    def action_mv(self, dx: int, dy: int) -> None:
        self.cx = min(max(self.cx + dx, 0), self.k.shape[1] - 1)
        self.cy = min(max(self.cy + dy, 0), self.k.shape[0] - 1)
        self._draw()

    def action_toggle_cell(self) -> None:
        self.k[self.cy, self.cx] ^= 1
        self._draw()

    def action_fill(self, v: int) -> None:
        self.k[:] = v
        self._draw()

    def action_resize(self, d: int) -> None:
        n = self.k.shape[0] + d
        if n < 1 or n > 31:
            return
        new = np.zeros((n, n), np.uint8)
        old = self.k
        o = old.shape[0]
        if n > o:
            off = (n - o) // 2
            new[off:off + o, off:off + o] = old
            shift = off
        else:
            off = (o - n) // 2
            new[:] = old[off:off + n, off:off + n]
            shift = -off
        self.k = new
        self.cx = min(max(self.cx + shift, 0), n - 1)
        self.cy = min(max(self.cy + shift, 0), n - 1)
        self._draw()

    def action_accept(self) -> None:
        if not self.k.any():
            self.app.notify("A kernel needs at least one cell on", severity="error")
            return
        self.dismiss(self.k.astype(int).tolist())

    def action_cancel(self) -> None:
        self.dismiss(None)


class PipelineEditor(GuardMixin, ModalScreen[None]):
    """Edit the session's Pipeline; preview on the current slice."""

    DEFAULT_CSS = """
    PipelineEditor { background: $background 80%; }
    PipelineEditor > Vertical { width: 100%; height: 100%; }
    PipelineEditor #pe-top { height: 1fr; }
    PipelineEditor #pe-left { width: 46; }
    PipelineEditor #pe-steps { height: 1fr; }
    PipelineEditor #pe-help { height: auto; color: $text-muted; }
    PipelineEditor .pe-prev { width: 1fr; }
    PipelineEditor .pe-prev Label { height: 1; color: $text-muted; }
    """
    BINDINGS = keys("""
    a             add        Add step
    delete,x      remove     Remove
    e             edit       Params
    K             kernel     Kernel editor
    s             stage      Stage 1/2
    space         toggle_step  On/off
    shift+up,U    move(-1)   Move up
    shift+down,D  move(1)    Move down
    m             domain     HU/8-bit       hidden
    pageup        slice(1)   Slice +1       hidden
    pagedown      slice(-1)  Slice -1       hidden
    escape,f      close      Done
    """)

    def __init__(self, session) -> None:
        super().__init__()
        self.s = session
        self.p = session.pipeline

    def compose(self) -> ComposeResult:
        with Vertical():
            with Horizontal(id="pe-top"):
                with Vertical(id="pe-left"):
                    yield Label("[b]Filter pipeline[/b]", id="pe-title")
                    yield OptionList(id="pe-steps")
                    yield Static(
                        "a add · x remove · e params · K kernel · s stage · space on/off · "
                        "shift+up/down reorder · m HU/8-bit · PgUp/PgDn slice · Esc done",
                        id="pe-help",
                    )
                with Vertical(classes="pe-prev"):
                    yield Label("intermediate (after stage 1)")
                    yield ImageView(id="pe-inter")
                with Vertical(classes="pe-prev"):
                    yield Label("final (after stage 2): fills threshold this")
                    yield ImageView(id="pe-final")
        yield Footer()

    def on_mount(self) -> None:
        self._fill_list()
        self.query_one("#pe-steps", OptionList).focus()
        self.preview()

    # ------------------------------------------------------------ list
    def _fill_list(self, select: int | None = None) -> None:
        ol = self.query_one("#pe-steps", OptionList)
        ol.clear_options()
        for i, st in enumerate(self.p.steps):
            params = " ".join(f"{k}={v}" for k, v in st.params.items() if k != "kernel" and v is not None)
            if st.params.get("kernel") is not None:
                params += " kernel=custom"
            flag = "" if st.enabled else " (off)"
            ol.add_option(Option(f"{i + 1}. stage {st.stage}  {st.name} {params}{flag}", id=str(i)))
        if not self.p.steps:
            ol.add_option(Option("(no steps: a adds one)", id="none", disabled=True))
        if select is not None and self.p.steps:
            ol.highlighted = min(max(select, 0), len(self.p.steps) - 1)
        dom = "HU values" if self.p.domain == "hu" else "windowed 8-bit values"
        self.query_one("#pe-title", Label).update(f"[b]Filter pipeline[/b] ({dom}), slice {self.s.z}")

    def _index(self) -> int | None:
        ol = self.query_one("#pe-steps", OptionList)
        if not self.p.steps or ol.highlighted is None:
            return None
        return int(ol.highlighted)

    def _changed(self, select: int | None = None) -> None:
        self.s.dirty = True
        self._fill_list(select)
        self.preview()

    # ------------------------------------------------------------ actions
    def action_add(self) -> None:
        def chose(name: str | None) -> None:
            if not name:
                return
            defaults = " ".join(f"{k}={v}" for k, v in PARAMS[name].items() if v is not None)

            def got_params(text: str | None) -> None:
                if text is None:
                    return
                try:
                    params = parse_params(text)
                    stage = int(params.pop("stage", 1))
                    self.p.add(name, stage=stage, **params)
                except (ValueError, TypeError) as exc:
                    self.app.notify(f"Step not added: {exc}", severity="error")
                    return
                self._changed(len(self.p.steps) - 1)

            self.app.push_screen(PromptScreen(f"{name}: parameters (stage=1|2)", f"stage=1 {defaults}".strip()), got_params)

        self.app.push_screen(ChoiceScreen("Add a filter", [(n, f"{n}  ({', '.join(PARAMS[n]) or 'no parameters'})") for n in FILTERS]), chose)

    def action_remove(self) -> None:
        i = self._index()
        if i is None:
            return
        self.p.remove(i)
        self._changed(i)

    def action_edit(self) -> None:
        i = self._index()
        if i is None:
            return
        st = self.p.steps[i]
        cur = " ".join(f"{k}={v}" for k, v in st.params.items() if k != "kernel" and v is not None)

        def done(text: str | None) -> None:
            if text is None:
                return
            try:
                self.p.set_params(i, **parse_params(text))
            except (ValueError, TypeError) as exc:
                self.app.notify(f"Parameters not changed: {exc}", severity="error")
                return
            self._changed(i)

        self.app.push_screen(PromptScreen(f"{st.name}: parameters", cur), done)

    def action_kernel(self) -> None:
        i = self._index()
        if i is None or self.p.steps[i].name not in MORPHOLOGY:
            self.app.notify("Select a morphology step (closing, opening, erode, dilate, conservative)", severity="warning")
            return
        st = self.p.steps[i]

        def done(kernel) -> None:
            if kernel is None:
                return
            try:
                self.p.set_params(i, shape="custom", kernel=kernel)
            except (ValueError, TypeError) as exc:
                self.app.notify(f"Kernel not set: {exc}", severity="error")
                return
            self._changed(i)

        self.app.push_screen(KernelEditor(st.params.get("kernel"), int(st.params.get("size") or 3)), done)

    def action_stage(self) -> None:
        i = self._index()
        if i is None:
            return
        st = self.p.steps[i]
        st.stage = 2 if st.stage == 1 else 1
        self._changed(i)

    def action_toggle_step(self) -> None:
        i = self._index()
        if i is None:
            return
        self.p.steps[i].enabled = not self.p.steps[i].enabled
        self._changed(i)

    def action_move(self, d: int) -> None:
        i = self._index()
        if i is None:
            return
        j = min(max(i + d, 0), len(self.p.steps) - 1)
        if j != i:
            self.p.move(i, j)
            self._changed(j)

    def action_domain(self) -> None:
        self.p.domain = "window8" if self.p.domain == "hu" else "hu"
        self.app.notify(f"Filters now work on {'windowed 8-bit values' if self.p.domain == 'window8' else 'HU values'}; "
                        "fill tolerances are in the same units", timeout=4)
        self._changed(self._index())

    def action_slice(self, d: int) -> None:
        self.s.z += d
        self.s.clamp()
        self._fill_list(self._index())
        self.preview()

    def action_close(self) -> None:
        self.dismiss(None)

    # ------------------------------------------------------------ preview
    @work(thread=True, exclusive=True, group="pe-preview")
    def preview(self) -> None:
        z = self.s.z
        try:
            views = self.s.stage_views(z)
        except Exception as exc:
            self.app.notify(f"Preview failed: {exc}", severity="error")
            return
        self.post_message(StageViewsReady(z, 0, views))

    def on_stage_views_ready(self, msg: StageViewsReady) -> None:
        msg.stop()  # the editor's preview, not the workspace's views
        z, views = msg.z, msg.views
        pv = planes.plane_view(self.s.volume, planes.slice_plane(self.s.volume))  # the patient's frame
        cursor = planes.cursor_in(pv, self.s.zyx, self.s.shape)
        for wid, arr in (("#pe-inter", views.intermediate), ("#pe-final", views.final)):
            self.query_one(wid, ImageView).set_image(planes.orient(self.s.display(arr), pv), token=(z, wid),
                                                     spacing_yx=pv.spacing_yx, cursor=cursor)
