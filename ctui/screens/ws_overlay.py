"""What the workspace draws over its slice views: background seeds, the ROI box, the polygon, the
brush's footprint and the vessels' paths (on a view's display grid, RGB uint8)."""
from __future__ import annotations

import cv2

from ctui.screens import planes
from ctui.screens.ws_host import WorkspaceHost

SEED_COLOR = (0, 230, 255)
BOX_COLOR = (255, 150, 0)
POLY_COLOR = (255, 220, 60)


def draw_overlay(ws: WorkspaceHost, plane: str, grid, vm) -> None:
    """Background seeds (cyan crosses), the ROI box (orange), with the brush or eraser down its
    footprint (a circle of the brush radius in mm), and the vessels' paths on a display grid."""
    s = ws.s
    pv = planes.plane_view(s.volume, plane)
    idx = s.zyx[pv.normal]

    def disp(zyx):
        c, r = planes.cursor_in(pv, zyx, s.shape)
        return vm.to_display(c, r)

    for x, y, z in s.background_seeds:
        if (z, y, x)[pv.normal] == idx:
            xd, yd = (int(v) for v in disp((z, y, x)))
            cv2.line(grid, (xd - 2, yd - 2), (xd + 2, yd + 2), SEED_COLOR, 1)
            cv2.line(grid, (xd - 2, yd + 2), (xd + 2, yd - 2), SEED_COLOR, 1)
    if s.roi_box is not None:
        lo = tuple(r[0] for r in s.roi_box)
        hi = tuple(r[1] for r in s.roi_box)
        if lo[pv.normal] <= idx <= hi[pv.normal]:
            (x0, y0), (x1, y1) = disp(lo), disp(hi)
            hx, hy = vm.sx / 2, vm.sy / 2
            cv2.rectangle(grid, (int(min(x0, x1) - hx), int(min(y0, y1) - hy)),
                          (int(max(x0, x1) + hx), int(max(y0, y1) + hy)), BOX_COLOR, 1)
    tools = ws.edit_tools
    if tools.box_corner is not None and tools.box_corner[pv.normal] == idx:
        xd, yd = (int(v) for v in disp(tools.box_corner))
        cv2.rectangle(grid, (xd - 2, yd - 2), (xd + 2, yd + 2), BOX_COLOR, 1)
    if tools.polygon and pv.normal == 0:
        pts = [tuple(int(v) for v in disp((idx, y, x))) for x, y in tools.polygon]
        for a, b in zip(pts, pts[1:] + pts[:1] if len(pts) > 2 else pts[1:]):
            cv2.line(grid, a, b, POLY_COLOR, 1)
        for p in pts:
            cv2.rectangle(grid, (p[0] - 1, p[1] - 1), (p[0] + 1, p[1] + 1), POLY_COLOR, 1)
    if tools.pen in ("brush", "eraser"):
        xd, yd = disp(s.zyx)
        r = s.brush or 0.0  # mm (the session sets it when it opens)
        ax = (max(int(round((r / pv.spacing_yx[1] + 0.5) * vm.sx)), 1),
              max(int(round((r / pv.spacing_yx[0] + 0.5) * vm.sy)), 1))
        col = (80, 255, 80) if tools.pen == "brush" else (255, 80, 255)
        cv2.ellipse(grid, (int(xd), int(yd)), ax, 0, 0, 360, col, 1)
    ws.vessel.draw(pv, idx, grid, disp)  # the vessels' paths and points
