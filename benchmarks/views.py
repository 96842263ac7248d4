"""The three slice views as the TUI draws them, written as PNGs to look at, and the time
each view takes to compose (the windowed reformat in the patient's frame, objects and
proposal overlay, fitted to the view at its physical aspect).

For each input the real app is started headless at a 160x50 terminal; for the axial,
sagittal and coronal views (keys 1, 2, 3) the exact pixel grid the half-block renderer
turns into cells (two pixels per cell, cursor included) is saved, enlarged 4x, with the
view's orientation letters written at its edges (left, right, top, bottom) and its
caption. A radiologist expects: axial R on the left, A at the top; coronal R on the
left, S at the top; sagittal A on the left, S at the top, for every input.

Inputs (../shared/data): ``totalseg_example/ct_abdomen_3mm.nii.gz`` (RAS NIfTI) and the
DICOM series ``ct_head_phantom_philips``; or give paths.

    python3 benchmarks/views.py [--out /tmp/ctui-views] [--n 20] [PATH ...]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("TEXTUAL_COLOR_SYSTEM", "truecolor")  # before textual is imported
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

SHARED = Path(os.environ.get("CTUI_SHARED_DATA", ROOT.parent / "shared" / "data"))
DEFAULT_INPUTS = (SHARED / "totalseg_example" / "ct_abdomen_3mm.nii.gz", SHARED / "ct_head_phantom_philips")
SCALE = 4


def annotate(grid: np.ndarray, letters: tuple[str, str, str, str], caption: str) -> np.ndarray:
    """The view's pixel grid enlarged SCALE x (nearest), letters at its edges, caption above."""
    img = cv2.resize(np.ascontiguousarray(grid), (grid.shape[1] * SCALE, grid.shape[0] * SCALE),
                     interpolation=cv2.INTER_NEAREST)
    h, w = img.shape[:2]
    out = np.zeros((h + 40, w, 3), np.uint8)
    out[40:] = img
    font, col = cv2.FONT_HERSHEY_SIMPLEX, (255, 230, 0)
    cv2.putText(out, caption, (8, 28), font, 0.8, (230, 230, 230), 2, cv2.LINE_AA)
    left, right, top, bottom = letters
    cv2.putText(out, left, (8, 40 + h // 2), font, 1.2, col, 3, cv2.LINE_AA)
    cv2.putText(out, right, (w - 36, 40 + h // 2), font, 1.2, col, 3, cv2.LINE_AA)
    cv2.putText(out, top, (w // 2 - 10, 80), font, 1.2, col, 3, cv2.LINE_AA)
    cv2.putText(out, bottom, (w // 2 - 10, 40 + h - 12), font, 1.2, col, 3, cv2.LINE_AA)
    return out[:, :, ::-1]  # RGB -> BGR for cv2.imwrite


async def views_of(path: Path, out: Path, n: int) -> list[str]:
    from ctui.screens import cells, graphics, planes
    from ctui.screens.app import CtuiApp
    from ctui.screens.testing import wait_workspace

    graphics.use_graphics("halfblock")
    os.environ.setdefault("CTUI_AUTOSAVE_DIR", str(out / "autosave"))
    app = CtuiApp(str(path), autosave_s=1e9)
    lines = []
    stem = path.name.split(".")[0]
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        s = ws.s
        for key, plane in (("1", "axial"), ("2", "sagittal"), ("3", "coronal")):
            await pilot.press(key)
            await pilot.pause()
            iv = ws.main_view
            W, H = iv.size.width, 2 * iv.size.height
            grid = iv._grid((W, H))
            pv = planes.plane_view(s.volume, plane)
            caption = f"{stem} {plane} {'zyx'[pv.normal]}={s.zyx[pv.normal]}  {s.volume.modality}"
            if pv.note:
                caption += "  (oblique)"
            dest = out / f"{stem}-{plane}.png"
            cv2.imwrite(str(dest), annotate(grid, pv.letters, caption))
            times = []
            for _ in range(n):
                t0 = time.perf_counter()
                img = ws.plane_image(plane)
                cells.render_view(img, (W, H), spacing_yx=pv.spacing_yx)
                times.append(time.perf_counter() - t0)
            lines.append(f"{stem:24s} {plane:8s} letters {'/'.join(pv.letters)}  image {img.shape[1]}x{img.shape[0]} px "
                         f"-> view {W}x{H}  compose+fit median {statistics.median(times) * 1000:6.2f} ms  {dest}")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*", type=Path)
    ap.add_argument("--out", type=Path, default=Path("/tmp/ctui-views"))
    ap.add_argument("--n", type=int, default=20, help="timed repeats per view")
    args = ap.parse_args()
    paths = args.paths or [p for p in DEFAULT_INPUTS if p.exists()]
    if not paths:
        print(f"no inputs: {SHARED} is missing; give paths", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    for p in paths:
        for line in asyncio.run(views_of(p, args.out, args.n)):
            print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
