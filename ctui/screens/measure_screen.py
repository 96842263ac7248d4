"""Measure screen (``M``): volume (voxels, mesh by the Gauss theorem, partial volume) and
area per object, and for a tubular object the section-area plot along its centreline,
all from :func:`ctui.engine.actions.measure.measure_object`, the action ``ctui measure``
calls, with the same defaults (section step :data:`ctui.engine.actions.defaults.SECTION_STEP_MM`),
so the TUI and the CLI report the same numbers. Workers post messages to this screen;
a late answer after the screen closed is dropped."""

from __future__ import annotations

import math

import numpy as np
from textual import on, work
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import DataTable, Static

from ctui.engine.actions.defaults import SECTION_STEP_MM
from ctui.engine.actions.formats import output_name
from ctui.engine.actions.measure import (LINE_AXES, MeasureResult, find_steps, line_through, measure_object,
                                         save_sections)
from ctui.engine.core.colors import object_color
from ctui.engine.core.errors import CtuiError
from ctui.screens.dialogs import ChoiceScreen, PromptScreen
from ctui.screens.guard import GuardMixin
from ctui.screens.imageview import ImageView
from ctui.screens.keybar import KeyBar
from ctui.screens.keytable import keys
from ctui.screens.messages import JobFailed, MeasuredRow, Saved, SectionsFailed, SectionsReady, Status
from ctui.screens.plot import line_plot
from ctui.screens.projects import opened_of
from ctui.screens.vessel_tool import report_lines


def is_tubular(stats: dict) -> bool:
    """Elongated objects (longest principal axis >= 3x the second) get a section plot."""
    axes = stats.get("principal_axes_mm")
    ax = sorted((float(v) for v in ([] if axes is None else list(axes))), reverse=True)
    return len(ax) >= 2 and ax[1] > 0 and ax[0] / ax[1] >= 3.0


COLUMNS = ("obj", "name", "voxels", "vol ml", "PV ml", "PV-vox %", "area mm²", "closed", "axes mm", "slices")
NARROW_COLUMNS = ("obj", "name", "vol ml", "PV ml", "PV-vox %", "area mm²", "axes mm", "slices")
_YES_NO: dict[object, str] = {True: "yes", False: "no"}  # a mesh's "closed" (None: not meshed)


def no_sections_reason(res, stats: dict | None = None) -> str:
    """Why an object got no cross-sections along its automatic centreline (``res`` a
    :class:`~ctui.engine.actions.measure.MeasureResult`), and what to do instead."""
    length = float(res.path_length_mm or 0.0)
    hint = ("x: a section through the cursor (normal to the object's axis or a plane's), l: sections along "
            "a line (P at one end, click the other), or ctui measure FILE --object N --path 'x,y,z;x,y,z' (mm)")
    axes = sorted((float(a) for a in (res.principal_axes_mm or (stats or {}).get("principal_axes_mm") or [])),
                  reverse=True)
    shape = ""
    if len(axes) >= 2 and axes[1] > 0:
        ratio = axes[0] / axes[1]
        if ratio < 3.0:
            shape = f"it has no elongated axis (longest/second axis {axes[0]:.0f}/{axes[1]:.0f} mm = {ratio:.1f} < 3)"
    flags = (res.section_flags or {}).get("counts") or {}
    if length <= 0:
        why = "no centreline could be traced" + (f": {shape}" if shape else " through the object")
    elif flags:
        left = ", ".join(f"{n} {k}" for k, n in sorted(flags.items()))
        why = (f"every section along its {length:.0f} mm centreline is an end cap, a branch or outside ({left}): "
               f"the object is too short for its width" + (f"; {shape}" if shape else ""))
    else:
        why = f"its {length:.0f} mm centreline is too short for a section every {res.step_mm:g} mm"
    return f"No cross-sections: {why}. Sections suit tubes (vessels, ureters, bowel); {hint}"


class MeasureScreen(GuardMixin, Screen):
    DEFAULT_CSS = """
    MeasureScreen #ms-head { height: auto; }
    MeasureScreen #ms-table { height: auto; max-height: 14; }
    MeasureScreen #ms-body { height: 1fr; }
    MeasureScreen #ms-plot { width: 1fr; }
    MeasureScreen #ms-info { width: 42; padding: 0 1; background: $panel; }
    MeasureScreen.narrow #ms-info { width: 30; }
    MeasureScreen #ms-status { height: auto; max-height: 3; background: $boost; padding: 0 1; }
    """
    BINDINGS = keys("""
    c         sections      Sections of selected
    x         section_here  Section at the cursor
    l         section_line  Sections along a line (P, click)
    g         toggle_grey   Sections: mask / grey levels
    s         save          Save CSV+PNG
    escape,M  close         Back
    """)

    def __init__(self, session) -> None:
        super().__init__()
        self.s = session
        self.stats: dict[int, dict] = {}
        self.sections: list[dict] | None = None
        self.sections_obj: int | None = None
        self.grey = False  # sections on the partial-volume fraction from the grey levels
        self.result: MeasureResult | None = None  # the sections shown
        self.columns: tuple[str, ...] = COLUMNS
        self.sections_pending: int | None = None  # object whose sections are being computed

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static("[b]Measurements[/b]: vol = voxels x voxel size; PV = partial-volume estimate from the grey "
                         "levels (PV-vox: how far the drawn edge is from it); the surface keeps the voxel volume",
                         id="ms-head")
            yield DataTable(id="ms-table", cursor_type="row")
            with Horizontal(id="ms-body"):
                yield ImageView(id="ms-plot")
                yield Static(id="ms-info")
            yield Static("", id="ms-status")
        yield KeyBar()  # wraps at 80 columns instead of cutting the last keys

    def on_mount(self) -> None:
        t = self.query_one(DataTable)
        narrow = self.app.size.width < 100  # 80x24: the columns that matter, all readable
        self.columns = NARROW_COLUMNS if narrow else COLUMNS
        t.add_columns(*self.columns)
        self.set_class(narrow, "narrow")
        t.focus()
        self.measure()

    def _status(self, text: str) -> None:
        self.query_one("#ms-status", Static).update(text)

    @on(Status)
    def _status_msg(self, msg: Status) -> None:
        self._status(msg.text)

    @on(JobFailed)
    def _failed(self, msg: JobFailed) -> None:
        self.app.notify(f"{msg.what}: {msg.reason}", severity="error")

    @on(SectionsFailed)
    def _sections_failed(self, msg: SectionsFailed) -> None:
        self.sections_pending = None
        self.app.notify(f"Sections of object {msg.oid}: {msg.reason}", severity="error")

    @on(MeasuredRow)
    def _row(self, msg: MeasuredRow) -> None:
        self._add_row(msg.oid, msg.stats)

    @on(SectionsReady)
    def _sections_ready(self, msg: SectionsReady) -> None:
        self._show_sections(msg.oid, msg.result)

    @on(Saved)
    def _saved(self, msg: Saved) -> None:
        self.app.notify(msg.text)

    @work(thread=True, exclusive=True, group="measure")
    def measure(self) -> None:
        s = self.s
        labels = s.labels()
        if labels is None or not labels.any():
            self.post_message(Status("No objects yet: fill (Enter) and propagate (p) first"))
            return
        opened = opened_of(s)
        ids = opened.object_ids
        measured: dict[int, dict] = {}
        for oid in ids:
            self.post_message(Status(f"Measuring object {oid} ..."))
            try:
                try:  # partial-volume volume from the grey levels (needs contrast with the surroundings)
                    res = measure_object(opened, object=oid, partial_volume=True)
                except CtuiError:  # no contrast with the surroundings: no grey-level estimate
                    res = measure_object(opened, object=oid)
            except Exception as exc:
                self.post_message(JobFailed(f"Object {oid}", str(exc)))
                continue
            st = dict(res.stats or {})
            st.pop("mesh", None)
            st["volume_pv_ml"] = res.volume_ml.get("partial_volume")
            st["warnings"] = list(res.warnings)
            measured[oid] = st
            self.post_message(MeasuredRow(oid, st))
        self.post_message(Status("c: sections along the centreline of the selected object; s saves"))
        tub = [oid for oid, st in measured.items() if self._vessel(oid) or is_tubular(st)]
        if tub:
            self._sections_of(tub[0])

    def _add_row(self, oid: int, st: dict) -> None:
        self.stats[oid] = st
        name = self.s.seg.objects[oid].name if self.s.seg and oid in self.s.seg.objects else f"object {oid}"
        rng = self.s.seg.slice_range(oid) if self.s.seg else None
        pa = st.get("principal_axes_mm")
        axes = "/".join(f"{float(a):.0f}" for a in ([] if pa is None else list(pa)))

        def f(key, fmt="{:.2f}"):
            val = st.get(key)
            return "-" if val is None or (isinstance(val, float) and math.isnan(val)) else fmt.format(val)

        vox, pv = st.get("volume_voxels_ml"), st.get("volume_pv_ml")
        # the voxel count against the grey levels' estimate: a comparison that can differ
        # (the mesh volume is kept equal to the voxel volume by construction)
        pv_diff = f"{100.0 * (pv - vox) / vox:+.1f}" if vox and pv is not None and math.isfinite(pv) else "-"
        c = object_color(oid)
        narrow = self.columns is NARROW_COLUMNS
        cells = {"obj": f"[rgb({c[0]},{c[1]},{c[2]})]██[/] {oid}", "name": name[:8] if narrow else name[:12],
                 "voxels": str(st.get("voxels")), "vol ml": f("volume_voxels_ml"), "PV ml": f("volume_pv_ml"),
                 "PV-vox %": pv_diff, "area mm²": f("area_mm2", "{:.0f}"),
                 "closed": _YES_NO.get(st.get("mesh_closed"), "-"), "axes mm": axes,
                 "slices": f"{rng[0]}..{rng[1]}" if rng else "-"}
        self.query_one(DataTable).add_row(*(cells[k] for k in self.columns), key=str(oid))
        warn = list(st.get("warnings") or [])
        if warn:
            self.app.notify(f"Object {oid}: {'; '.join(warn)}", severity="warning", timeout=6)

    def action_sections(self) -> None:
        t = self.query_one(DataTable)
        if not self.stats:
            return
        try:
            oid = int(t.coordinate_to_cell_key(t.cursor_coordinate).row_key.value or "")
        except Exception:
            oid = min(self.stats)
        self.sections_worker(oid)

    def _selected(self) -> int | None:
        """The object of the table's selected row (else the workspace's current one)."""
        t = self.query_one(DataTable)
        try:
            return int(t.coordinate_to_cell_key(t.cursor_coordinate).row_key.value or "")
        except Exception:
            return self.s.current if self.s.seg is not None and self.s.current in self.s.seg.objects else None

    def action_section_here(self) -> None:
        """x: one section through the workspace's cursor, normal to the object's axis or an index axis."""
        s, oid = self.s, self._selected()
        if oid is None or s.seg is None or s.seg.labels[s.zyx] != oid:
            self._status(f"Put the workspace's cursor on object {oid} first (Esc, click it, M): "
                         f"the cursor {s.x},{s.y},{s.z} is not on it")
            return
        words = {"object": "the object's longest axis", "z": "the slices' axis (an axial section)",
                 "y": "the y axis (a coronal section)", "x": "the x axis (a sagittal section)"}
        def chosen(axis: str | None) -> None:
            if axis:
                self.cursor_section_worker(oid, axis, s.zyx)

        self.app.push_screen(ChoiceScreen(f"Section of object {oid} through the cursor, normal to",
                                          [(a, words.get(a, a)) for a in LINE_AXES]), chosen)

    def action_section_line(self) -> None:
        """l: sections along the line between the first two points of the workspace's polygon
        (P, then a click) on its slice: a two-click line, no coordinates typed."""
        ws = self.app.workspace  # type: ignore[attr-defined]  # the CtuiApp's (app.py imports this screen: no annotation without a circle)
        pts = list(ws.edit_tools.polygon)[:2] if ws is not None else []
        oid = self._selected()
        if len(pts) < 2 or oid is None:
            self._status("A line: in the workspace press P at one end and click the other (or P twice), then M and l")
            return
        z = self.s.z
        path = np.array([(z, y, x) for x, y in pts], dtype=np.float64)
        self.path_sections_worker(oid, path)

    @work(thread=True, exclusive=True, group="sections")
    def cursor_section_worker(self, oid: int, axis: str, zyx: tuple[int, int, int]) -> None:
        v = self.s.volume
        half = 2 * SECTION_STEP_MM
        self.sections_pending = oid
        try:
            mask = self.s.seg.labels == oid if axis == "object" else None
            path = line_through(zyx, axis, half_mm=half, step_mm=SECTION_STEP_MM / 4, mask=mask, spacing=v.spacing,
                                origin=v.origin, direction=v.direction)
            res = measure_object(opened_of(self.s), object=oid, path=path, partial_volume=self.grey, mesh=False)
        except Exception as exc:
            self.post_message(SectionsFailed(oid, str(exc)))
            return
        mid = min(res.rows, key=lambda r: abs(r["s_mm"] - half)) if res.rows else None
        self.post_message(SectionsReady(oid, res))
        if mid is None or mid.get("status") != "ok":
            why = "no section" if mid is None else mid.get("status")
            self.post_message(Status(f"No section of object {oid} at the cursor normal to {axis}: {why}"))
            return
        self.post_message(Status(
            f"Section of object {oid} at x {zyx[2]} y {zyx[1]} z {zyx[0]}, normal to {axis}: area "
            f"{mid['area_mm2']:.1f} mm², diameter {mid['eq_diameter_mm']:.1f} mm (min {mid['min_diameter_mm']:.1f}, "
            f"max {mid['max_diameter_mm']:.1f})"))

    @work(thread=True, exclusive=True, group="sections")
    def path_sections_worker(self, oid: int, path_zyx) -> None:
        self.sections_pending = oid
        try:
            res = measure_object(opened_of(self.s), object=oid, path=path_zyx, path_voxels=True,
                                 partial_volume=self.grey, mesh=False)
        except Exception as exc:
            self.post_message(SectionsFailed(oid, str(exc)))
            return
        self.post_message(SectionsReady(oid, res))

    def action_toggle_grey(self) -> None:
        self.grey = not self.grey
        how = "the grey levels (partial volume)" if self.grey else "the object's mask"
        self._status(f"Sections from {how}")
        if self.sections_obj is not None:
            self.sections_worker(self.sections_obj)

    @work(thread=True, exclusive=True, group="sections")
    def sections_worker(self, oid: int) -> None:
        self._sections_of(oid)

    def _sections_of(self, oid: int) -> None:
        """Centreline and sections of object ``oid`` (in the worker), as ``ctui measure --path auto``."""
        self.sections_pending = oid
        self.post_message(Status(f"Centreline and sections of object {oid} ..."))
        try:
            res = measure_object(opened_of(self.s), object=oid, path="auto", partial_volume=self.grey)
        except Exception as exc:
            self.post_message(SectionsFailed(oid, str(exc)))
            return
        self.post_message(SectionsReady(oid, res))

    def _show_sections(self, oid: int, res) -> None:
        # the cross-sections only (as `ctui measure` reports them): caps, branches and
        # sections outside the object are counted, not drawn as areas
        rows = [r for r in res.rows if r.get("status", "ok") == "ok"]
        left_out = len(res.rows) - len(rows)
        self.sections, self.sections_obj, self.result = rows, oid, res
        self.sections_pending = None
        iv = self.query_one("#ms-plot", ImageView)
        if not rows:
            iv.set_image(None, token=("sections", oid, 0))
            why = no_sections_reason(res, self.stats.get(oid))
            self.query_one("#ms-info", Static).update("\n".join([*self._vessel(oid), f"[b]Sections of object {oid}[/b]",
                                                                  "", why]))
            self._status(why)
            return
        sm = [r["s_mm"] for r in rows]
        area = [r["area_mm2"] for r in rows]
        # the y axis from 0: a 1% change over a cursor's 2 mm path is not drawn from the bottom to the top, and a
        # narrowing to half shows as half the height
        top = max((float(v) for v in area if np.isfinite(v)), default=1.0)
        img, lim = line_plot(iv.target_pixels(), [{"x": sm, "y": area, "color": object_color(oid), "points": len(sm) <= 60}],
                             ylim=(0.0, top if top > 0 else 1.0))
        iv.set_image(img, token=("sections", oid, len(rows)))
        a = np.array(area, float)
        ok = a[np.isfinite(a)]
        length = float(sm[-1]) if sm else 0.0
        src = "grey levels (partial volume)" if self.grey else "mask"
        lines = [f"[b]Sections of object {oid}[/b] from the {src}", f"path {length:.1f} mm, {len(rows)} sections"
                 + (f" ({left_out} at caps/branches left out)" if left_out else ""), "",
                 f"area 0..{lim[3]:.0f} mm² (y axis)", f"arc 0..{length:.0f} mm (x axis)"]
        if ok.size:
            lines += ["", f"min area {ok.min():.1f} mm²", f"max area {ok.max():.1f} mm²", f"mean     {ok.mean():.1f} mm²"]
        try:
            steps = find_steps(np.array(sm), a)
            if steps:
                lines += ["", "[b]steps[/b]"]
                for st in steps[:6]:
                    lines.append(" " + ", ".join(f"{k} {val:.1f}" for k, val in st.items() if isinstance(val, (int, float))))
        except Exception:
            pass
        lines += ["", "[dim]c sections of selected row, g mask / grey levels, s save CSV + PNG, Esc back[/dim]"]
        self.query_one("#ms-info", Static).update("\n".join([*self._vessel(oid), *lines]))
        self._status(f"Sections of object {oid}: {len(rows)} along {length:.0f} mm")

    def _vessel(self, oid: int) -> list[str]:
        """A vessel object's report (``ctui vessel``, the vessel tool), then a blank line; else []."""
        info = self.s.seg.objects.get(oid) if self.s.seg is not None else None
        rec = (getattr(info, "settings", None) or {}).get("vessel") if info is not None else None
        return [*report_lines(rec), ""] if rec else []

    def action_save(self) -> None:
        if not self.sections:
            if self.sections_pending is not None:
                msg = f"Sections of object {self.sections_pending} are still being computed: s once they show"
            elif self.result is not None:
                msg = f"Nothing to save for object {self.sections_obj}: " + no_sections_reason(self.result).split(": ", 1)[1]
            else:
                msg = "No sections yet: select an object's row and press c"
            self.app.notify(msg, timeout=6)
            self._status(msg)
            return

        def done(path: str | None) -> None:
            if path:
                self._save(path.strip())

        self.app.push_screen(PromptScreen("Save sections as CSV (a PNG plot is written beside it)",
                                     output_name(self.s.project_path or self.s.source_path, ".csv",
                                                 tag=f"sections{self.sections_obj}")), done)

    @work(thread=True, group="ms-save")
    def _save(self, path: str) -> None:
        png = path.rsplit(".", 1)[0] + ".png"
        try:
            if self.result is None:
                raise CtuiError("no sections shown")
            save_sections(self.result, csv=path, plot=png,
                          inputs=[str(p) for p in (self.s.source_path, self.s.project_path) if p])
        except Exception as exc:
            self.post_message(JobFailed("Not saved", str(exc)))
            return
        self.post_message(Saved(f"Saved {path} and {png}"))

    def action_close(self) -> None:
        self.app.pop_screen()
