"""Writers of section tables: JSON-ready rows, CSV, JSON and the area plot (PNG / RGB).

Rows are the dicts of :func:`ctui.engine.measure.sections.sections_along_path`. Only
rows whose ``status`` is "ok" are written as numbers (the others are sections of an
end cap or a branch, or no section at all); :func:`flag_summary` says how many were
left out and where. JSON goes through :mod:`ctui.engine.core.jsonio`, files through
:mod:`ctui.engine.core.atomic` (atomic writes; ``inputs=`` refuses to overwrite an
input). Imports only ``core``.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from ctui.engine.core.atomic import atomic_path, check_output, write_text
from ctui.engine.core.jsonio import dumps, to_jsonable

SECTION_KEYS = ("s_mm", "area_mm2", "eq_diameter_mm", "min_diameter_mm", "max_diameter_mm")


def is_ok(row: dict[str, Any]) -> bool:
    """True for a section reported as numbers: status "ok" (rows without a status:
    when the area is a finite number)."""
    st = row.get("status")
    if st is not None:
        return st == "ok"
    a = row.get("area_mm2")
    return a is not None and math.isfinite(float(a))


def ok_rows(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows reported as numbers (:func:`is_ok`)."""
    return [r for r in rows if is_ok(r)]


def flag_summary(rows: Iterable[dict[str, Any]]) -> dict[str, Any]:
    """``{"counts": {status: n}, "ranges": [{"status", "from_s_mm", "to_s_mm"}]}`` of the
    rows that are not "ok" (consecutive rows of one status make one range)."""
    counts: dict[str, int] = {}
    ranges: list[dict[str, Any]] = []
    prev = None
    for r in rows:
        st = r.get("status") or ("ok" if is_ok(r) else "outside")
        if st != "ok":
            counts[st] = counts.get(st, 0) + 1
            if st == prev:
                ranges[-1]["to_s_mm"] = float(r["s_mm"])
            else:
                ranges.append({"status": st, "from_s_mm": float(r["s_mm"]), "to_s_mm": float(r["s_mm"])})
        prev = st
    return {"counts": counts, "ranges": ranges}


def sections_table(rows: Iterable[dict[str, Any]], *, keys: Sequence[str] = SECTION_KEYS,
                   only_ok: bool = True) -> list[dict[str, Any]]:
    """JSON-ready rows (only ``keys``; NaN -> None; :mod:`~ctui.engine.core.jsonio`
    rounding); ``only_ok``: the "ok" rows only."""
    rows = ok_rows(rows) if only_ok else list(rows)
    return [{k: to_jsonable(r.get(k)) for k in keys} for r in rows]


def write_sections_csv(path, rows: Iterable[dict[str, Any]], *, keys: Sequence[str] = SECTION_KEYS,
                       inputs: Iterable = ()) -> None:
    """Write the "ok" sections as CSV (atomic); refuses a ``path`` that is one of ``inputs``."""
    check_output(path, inputs=inputs, label="section table")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(keys)
    for r in sections_table(rows, keys=keys):
        w.writerow(["" if r[k] is None else r[k] for k in keys])
    write_text(path, buf.getvalue())


def path_table(path_mm: Any) -> list[dict[str, float]]:
    """The centreline / path points as rows {index, s_mm (arc length from the first point), x_mm, y_mm, z_mm}."""
    p = np.asarray(path_mm, dtype=np.float64).reshape(-1, 3)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]) if len(p) else np.zeros(0)
    return [{"index": i, "s_mm": round(float(s[i]), 4), "x_mm": round(float(q[0]), 4), "y_mm": round(float(q[1]), 4),
             "z_mm": round(float(q[2]), 4)} for i, q in enumerate(p)]


def write_path_csv(path, path_mm: Any, *, inputs: Iterable = ()) -> None:
    """Write the path's points (patient mm, with arc length) as CSV (atomic)."""
    check_output(path, inputs=inputs, label="path table")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    keys = ("index", "s_mm", "x_mm", "y_mm", "z_mm")
    w.writerow(keys)
    for r in path_table(path_mm):
        w.writerow([r[k] for k in keys])
    write_text(path, buf.getvalue())


def write_sections_json(path, rows: Iterable[dict[str, Any]], *, inputs: Iterable = (), **extra: Any) -> None:
    """Write ``{**extra, "sections": [...ok rows], "section_flags": ...}`` as JSON (atomic)."""
    check_output(path, inputs=inputs, label="section table")
    rows = list(rows)
    doc = {**extra, "sections": sections_table(rows), "section_flags": flag_summary(rows)}
    write_text(path, dumps(doc, indent=1) + "\n")


def _sections_figure(rows, *, quantity, references, band, title, size, dpi):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    s = np.array([r["s_mm"] for r in rows], dtype=np.float64)
    y = np.array([r.get(quantity, np.nan) if is_ok(r) else np.nan for r in rows], dtype=np.float64)
    fig = Figure(figsize=size, dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(s, y, "-", color="#1f77b4", lw=1.2, label=quantity)  # gaps where sections are not "ok"
    for ref in references or ():
        ax.axhline(ref, color="#d62728", ls="--", lw=0.8)
        if band:
            ax.axhspan(ref * (1 - band), ref * (1 + band), color="#d62728", alpha=0.12, lw=0)
    ax.set_xlabel("arc length (mm)")
    unit = "mm²" if quantity.endswith("mm2") else "mm"
    ax.set_ylabel(f"{quantity.rsplit('_', 1)[0].replace('_', ' ')} ({unit})")
    if title:
        ax.set_title(title)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def plot_sections(
    path,
    rows: Sequence[dict[str, Any]],
    *,
    quantity: str = "area_mm2",
    references: Sequence[float] | None = None,
    band: float | None = 0.02,
    title: str | None = None,
    size=(8.0, 4.0),
    dpi: int = 100,
    inputs: Iterable = (),
) -> None:
    """PNG plot of a section quantity of the "ok" sections against arc length
    (matplotlib Agg, atomic; refuses a ``path`` that is one of ``inputs``).

    ``quantity``: any numeric row key ("area_mm2", "eq_diameter_mm",
    "min_diameter_mm", ...). ``references``: horizontal reference values (same unit),
    drawn as dashed lines with a +-``band`` relative band, like the thesis's figure 7.11.
    """
    check_output(path, inputs=inputs, label="plot")
    fig = _sections_figure(rows, quantity=quantity, references=references, band=band, title=title, size=size, dpi=dpi)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png")


def sections_plot_image(
    rows: Sequence[dict[str, Any]],
    *,
    quantity: str = "area_mm2",
    references: Sequence[float] | None = None,
    band: float | None = 0.02,
    title: str | None = None,
    size_px: tuple[int, int] = (800, 400),
) -> np.ndarray:
    """The same plot as :func:`plot_sections`, as an RGB image (h, w, 3) uint8 (for the TUI)."""
    dpi = 100
    fig = _sections_figure(rows, quantity=quantity, references=references, band=band, title=title,
                           size=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
