"""Drift screen (``d``): per-object centroid x and y against slice as a picture, the
flagged slices, and apply/undo of the correction (``ctui.engine.segment.drift``)."""

from __future__ import annotations

from textual import work
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import Footer, Label, Static

from ctui.engine.actions import drift
from ctui.engine.actions.drift import drift_check
from ctui.engine.actions.formats import output_name
from ctui.engine.core.atomic import check_output
from ctui.engine.core.colors import object_color
from ctui.engine.core.errors import CtuiError
from ctui.screens.dialogs import PromptScreen
from ctui.screens.guard import GuardMixin
from ctui.screens.imageview import ImageView
from ctui.screens.keytable import keys
from ctui.screens.messages import DriftReady, Note
from ctui.screens.plot import line_plot
from ctui.screens.projects import opened_of


class DriftScreen(GuardMixin, Screen):
    DEFAULT_CSS = """
    DriftScreen #dr-body { height: 1fr; }
    DriftScreen #dr-plots { width: 1fr; }
    DriftScreen #dr-plots Label { height: 1; }
    DriftScreen #dr-info { width: 40; padding: 0 1; background: $panel; }
    """
    BINDINGS = keys("""
    a         apply      Apply correction
    u         undo       Undo correction
    p         phase      Centroid/phase estimate
    s         save_plot  Save PNG
    escape,d  close      Back
    """)

    def __init__(self, session) -> None:
        super().__init__()
        self.s = session
        self.report: drift.DriftReport | None = None
        self.estimate = "centroid"

    def compose(self) -> ComposeResult:
        with Horizontal(id="dr-body"):
            with Vertical(id="dr-plots"):
                yield Label("Centroid x (mm) against slice; red: flagged slices", id="dr-lx")
                yield ImageView(id="dr-x")
                yield Label("Centroid y (mm) against slice", id="dr-ly")
                yield ImageView(id="dr-y")
            yield Static(id="dr-info")
        yield Footer()

    def on_mount(self) -> None:
        self.analyse()

    def corrections(self) -> list[dict]:
        return list((self.s.drift_info or {}).get("corrections", []))

    @work(thread=True, exclusive=True, group="drift")
    def analyse(self) -> None:
        labels = self.s.labels()
        if labels is None or not labels.any():
            self.post_message(Note("No objects yet: segment one (Enter, p) to check drift."))
            return
        try:
            rep = drift_check(opened_of(self.s)).report  # the same check as `ctui drift`
        except Exception as exc:
            self.app.notify(f"Drift analysis failed: {exc}", severity="error")
            return
        self.post_message(DriftReady(rep))

    def on_note(self, msg: Note) -> None:
        self._info(msg.text)

    def on_drift_ready(self, msg: DriftReady) -> None:
        self._show(msg.report)

    def _info(self, text: str) -> None:
        self.query_one("#dr-info", Static).update(text)

    def _show(self, rep) -> None:
        self.report = rep
        pd = rep.plot_data()
        for axis, wid in (("x", "#dr-x"), ("y", "#dr-y")):
            iv = self.query_one(wid, ImageView)
            series = []
            for o in pd["objects"]:
                col = object_color(o["id"])
                series.append({"x": o["z"], "y": o[f"fit_{axis}_mm"], "color": col, "dim": True})
                series.append({"x": o["z"], "y": o[f"{axis}_mm"], "color": col, "points": True})
            img, lim = line_plot(iv.target_pixels(), series, bands=pd["flagged"])
            iv.set_image(img, token=("drift", axis, len(pd["flagged"])))
            lab = self.query_one(f"#dr-l{axis}", Label)
            lab.update(f"Centroid {axis} (mm), {lim[2]:.1f}..{lim[3]:.1f} mm over slices {lim[0] + 1:.0f}..{lim[1] + 1:.0f}"
                       + ("; red = flagged" if pd["flagged"] else ""))
        lines = ["[b]Slice drift[/b]", f"threshold {rep.threshold_mm:.2f} mm", ""]
        if rep.flagged:
            lines.append(f"[b red]{len(rep.flagged)} flagged slice(s)[/b red]")
            for o in rep.objects:
                for z in o.flagged[:12]:
                    i = list(o.slices).index(z)
                    lines.append(f" obj {o.object_id} slice {z}: {o.distance_mm[i]:.1f} mm")
        else:
            lines.append("no slice beyond the threshold")
        corr = self.corrections()
        lines += ["", f"[b]Correction[/b] ({self.estimate} estimate)"]
        if corr:
            for c in corr[:12]:
                lines.append(f" slice {c['slice']}: dx {c['dx']:+.2f} dy {c['dy']:+.2f} px")
            lines.append("[green]applied[/green] (u undoes)")
        else:
            lines.append(" none applied (a applies)")
        lines += ["", "[dim]a apply, u undo, p centroid/phase,", "s save PNG, Esc back[/dim]"]
        self._info("\n".join(lines))

    def on_resize(self) -> None:
        if self.report is not None:
            self._show(self.report)

    def action_phase(self) -> None:
        self.estimate = "phase" if self.estimate == "centroid" else "centroid"
        if self.report is not None:
            self._show(self.report)

    def action_apply(self) -> None:
        if self.report is None or not self.report.flagged:
            self.app.notify("No flagged slices to correct", timeout=3)
            return
        if self.corrections():
            self.app.notify("A correction is already applied (u undoes it first)", severity="warning")
            return
        s = self.s
        try:
            corr = drift.corrections_from_report(self.report, estimate=self.estimate, volume=s.volume)
            new_data = drift.apply_corrections(s.volume.data, corr)
            new_labels = drift.apply_corrections(s.seg.labels, corr, interpolation="nearest")
        except Exception as exc:
            self.app.notify(f"Correction failed: {exc}", severity="error")
            return
        s.original_data = s.volume.data
        s.volume.data = new_data
        s.seg.apply_region((slice(None), slice(None), slice(None)), new_labels, label="drift correction")
        s.drift_info = {"corrections": corr, "estimate": self.estimate, "flagged": list(self.report.flagged)}
        s.dirty = True
        self.app.notify(f"Shifted {len(corr)} slice(s)")
        self.analyse()

    def action_undo(self) -> None:
        corr = self.corrections()
        s = self.s
        if not corr:
            self.app.notify("No correction applied", timeout=3)
            return
        orig = s.original_data
        s.volume.data = orig if orig is not None else drift.apply_corrections(s.volume.data, drift.invert_corrections(corr))
        s.original_data = None
        new_labels = drift.apply_corrections(s.seg.labels, drift.invert_corrections(corr), interpolation="nearest")
        s.seg.apply_region((slice(None), slice(None), slice(None)), new_labels, label="undo drift correction")
        s.drift_info = {}
        s.dirty = True
        self.app.notify("Correction undone")
        self.analyse()

    def action_save_plot(self) -> None:
        if self.report is None:
            return

        def done(path: str | None) -> None:
            if path:
                self._save(path.strip())

        self.app.push_screen(PromptScreen("Save the drift plot (PNG)",
                                     output_name(self.s.project_path or self.s.source_path, ".png", tag="drift")), done)

    @work(thread=True, group="drift-save")
    def _save(self, path: str) -> None:
        try:
            check_output(path, inputs=[self.s.source_path, self.s.project_path], label="the plot")
            if self.report is None:
                raise CtuiError("no drift report yet")
            drift.plot_drift(self.report, path)
        except Exception as exc:
            self.app.notify(f"Plot not saved: {exc}", severity="error")
            return
        self.app.notify(f"Saved {path}")

    def action_close(self) -> None:
        self.app.pop_screen()
