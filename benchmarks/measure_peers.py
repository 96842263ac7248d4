"""Benchmark: ctui's measurements of the shared aorta against peers, side by side.

On ``../shared/data/totalseg_example/ct_aorta_1p5mm_aorta.nii.gz`` (TotalSegmentator's
aorta mask, 1.5 mm voxels; closed at the arch, open at the bottom) and on the same mask
cropped to slices 5..70 (the descending aorta, open at both ends):

* centreline length: ctui's automatic centreline against a scikit-image 3D skeleton
  (``skeletonize``: the longest geodesic route through its voxels, smoothed by the same
  spline as ctui's) and, on the crop, the slice-centroid line (a tube running through
  every slice: each slice's centroid is on its axis);
* section areas: ctui's sections (partial-volume and contour areas) against VTK's
  cut (``vtkCutter`` + ``vtkStripper``) of VTK's own surface of the mask
  (``vtkFlyingEdges3D`` at 0.5) by the same planes: the loop around the path point;
* volume and surface area: ctui's voxel count and mesh (Gauss theorem) against
  ``vtkMassProperties`` of VTK's flying-edges surface (closed by a voxel of padding where
  the object meets the volume's boundary).

Usage: python benchmarks/measure_peers.py [--step 2] [--data ../shared/data]
Needs the ``bench`` extras (vtk, scikit-image). Prints one table per measure.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ctui.engine.core.geometry import Geometry  # noqa: E402
from ctui.engine.io.labels import load_labels  # noqa: E402
from ctui.engine.measure.paths import path_length, spline_resample  # noqa: E402
from ctui.engine.measure.summary import measure_object  # noqa: E402


# =========================================================================== peers
def skeleton_line(mask: np.ndarray, g: Geometry, *, step_mm: float) -> np.ndarray:
    """scikit-image's 3D skeleton: its longest geodesic route (voxel graph), in mm, smoothed
    by a spline with ctui's default smoothing (half the largest voxel side)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra
    from skimage.morphology import skeletonize

    sk = skeletonize(mask)
    pts = np.argwhere(sk)
    index = -np.ones(mask.shape, np.int64)
    index[tuple(pts.T)] = np.arange(len(pts))
    sp = np.asarray(g.spacing)
    rows, cols, w = [], [], []
    for d in np.argwhere(np.ones((3, 3, 3))) - 1:
        if not d.any():
            continue
        q = pts + d
        ok = np.all((q >= 0) & (q < mask.shape), axis=1)
        j = index[tuple(q[ok].T)]
        good = j >= 0
        rows.append(np.flatnonzero(ok)[good])
        cols.append(j[good])
        w.append(np.full(int(good.sum()), float(np.linalg.norm(d * sp))))
    graph = coo_matrix((np.concatenate(w), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(len(pts), len(pts))).tocsr()
    d0 = dijkstra(graph, indices=0)
    a = int(np.nanargmax(np.where(np.isfinite(d0), d0, -1)))
    da, pred = dijkstra(graph, indices=a, return_predecessors=True)
    b = int(np.nanargmax(np.where(np.isfinite(da), da, -1)))
    route = [b]
    while route[-1] != a:
        route.append(int(pred[route[-1]]))
    mm = g.index_to_mm(pts[route[::-1]].astype(np.float64))
    return spline_resample(mm, step_mm, smooth_mm=0.5 * float(sp.max()))


def slice_centroid_line(mask: np.ndarray, g: Geometry) -> np.ndarray | None:
    """Each slice's centroid (mm), when the object is one piece on every slice it is on."""
    from scipy import ndimage as ndi

    zs = np.flatnonzero(mask.any(axis=(1, 2)))
    if any(ndi.label(mask[z])[1] != 1 for z in zs):
        return None
    c = np.array([np.r_[z, np.argwhere(mask[z]).mean(axis=0)] for z in zs])
    return g.index_to_mm(c)


def vtk_surface(mask: np.ndarray, g: Geometry, *, pad: bool = False):
    """VTK's surface of the mask (``vtkFlyingEdges3D`` at 0.5) in patient mm, as a
    vtkPolyData; ``pad``: one voxel of background around it first, so that the surface is
    closed where the object meets the volume's boundary (for volumes)."""
    import vtk
    from vtk.util import numpy_support as ns

    if pad:
        mask = np.pad(mask, 1)
    img = vtk.vtkImageData()
    nz, ny, nx = mask.shape
    img.SetDimensions(nx, ny, nz)
    img.GetPointData().SetScalars(ns.numpy_to_vtk(np.ascontiguousarray(mask, np.uint8).ravel(), deep=True))
    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputData(img)
    fe.SetValue(0, 0.5)
    fe.ComputeNormalsOff()
    fe.Update()
    poly = fe.GetOutput()
    xyz = ns.vtk_to_numpy(poly.GetPoints().GetData()).astype(np.float64)  # index x, y, z
    mm = g.index_to_mm(xyz[:, ::-1] - (1.0 if pad else 0.0))
    poly.GetPoints().SetData(ns.numpy_to_vtk(mm, deep=True))
    return poly


def vtk_smoothed(poly, *, passband: float = 0.01, iterations: int = 20):
    """``vtkWindowedSincPolyDataFilter`` as 3D Slicer smooths a segment's surface
    (smoothing factor 0.5: pass band 10**-2, 20 iterations, normalised coordinates)."""
    import vtk

    f = vtk.vtkWindowedSincPolyDataFilter()
    f.SetInputData(poly)
    f.SetNumberOfIterations(iterations)
    f.SetPassBand(passband)
    f.BoundarySmoothingOff()
    f.FeatureEdgeSmoothingOff()
    f.NonManifoldSmoothingOn()
    f.NormalizeCoordinatesOn()
    f.Update()
    return f.GetOutput()


def vtk_mass(poly) -> tuple[float, float]:
    """(volume mL, surface area mm^2) by vtkMassProperties (after vtkTriangleFilter)."""
    import vtk

    tri = vtk.vtkTriangleFilter()
    tri.SetInputData(poly)
    mp = vtk.vtkMassProperties()
    mp.SetInputConnection(tri.GetOutputPort())
    mp.Update()
    return mp.GetVolume() / 1000.0, mp.GetSurfaceArea()


def vtk_section_areas(poly, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Area (mm^2) of the loop of the surface's cut by each plane (point, normal) that
    holds the point; NaN when none does."""
    import vtk
    from vtk.util import numpy_support as ns

    plane = vtk.vtkPlane()
    cutter = vtk.vtkCutter()
    cutter.SetInputData(poly)
    cutter.SetCutFunction(plane)
    strip = vtk.vtkStripper()
    strip.SetInputConnection(cutter.GetOutputPort())
    strip.JoinContiguousSegmentsOn()
    out = np.full(len(points), np.nan)
    for i, (p, n) in enumerate(zip(points, normals)):
        plane.SetOrigin(*p)
        plane.SetNormal(*n)
        strip.Update()
        res = strip.GetOutput()
        if res.GetNumberOfPoints() == 0:
            continue
        xyz = ns.vtk_to_numpy(res.GetPoints().GetData()).astype(np.float64)
        u = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        uv = np.column_stack([(xyz - p) @ u, (xyz - p) @ v])
        lines = res.GetLines()
        lines.InitTraversal()
        ids = vtk.vtkIdList()
        while lines.GetNextCell(ids):
            loop = uv[[ids.GetId(k) for k in range(ids.GetNumberOfIds())]]
            if _contains(loop, (0.0, 0.0)):
                x, y = loop[:, 0], loop[:, 1]
                out[i] = 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
                break
    return out


def _contains(poly: np.ndarray, pt) -> bool:
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = (y > pt[1]) != (yn > pt[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = x + (pt[1] - y) * (xn - x) / (yn - y)
    return bool(np.count_nonzero(cross & (pt[0] < xc)) % 2)


# =========================================================================== report
def _pct(a: float, b: float) -> str:
    return f"{100.0 * (a / b - 1.0):+.2f}%"


def compare(name: str, mask: np.ndarray, g: Geometry, step: float) -> None:
    print(f"\n== {name}: {mask.shape} voxels of {g.spacing} mm, {int(mask.sum())} in the object")
    t = time.perf_counter()
    res = measure_object(mask.astype(np.uint8), 1, spacing=g.spacing, origin=g.origin, direction=g.direction,
                         path="auto", step_mm=step, mesh=True)
    t_ctui = time.perf_counter() - t
    path = np.asarray(res["path_mm"])
    L = path_length(path)
    t = time.perf_counter()
    sk = skeleton_line(mask, g, step_mm=0.5)
    t_sk = time.perf_counter() - t
    print(f"centreline length        ctui {L:8.1f} mm ({t_ctui:.1f} s with sections and mesh)")
    from scipy.spatial import cKDTree

    i0, i1 = sorted(int(cKDTree(path).query(q)[1]) for q in (sk[0], sk[-1]))
    Ls = path_length(sk)
    dev = cKDTree(path).query(sk)[0]
    print(f"                         skimage skeleton {Ls:8.1f} mm ({t_sk:.1f} s; a skeleton stops about a radius "
          f"short of each end): ctui between the skeleton's ends {path_length(path[i0:i1 + 1]):.1f} mm "
          f"{_pct(path_length(path[i0:i1 + 1]), Ls)}, skeleton to ctui's path median {np.median(dev):.2f} mm, "
          f"max {dev.max():.2f} mm")
    line = slice_centroid_line(mask, g)
    if line is not None:
        idx = g.mm_to_index(path)
        inside = (idx[:, 0] >= 0) & (idx[:, 0] <= mask.shape[0] - 1)
        Lc, Li = path_length(line), path_length(path[inside])
        print(f"                         slice-centroid line {Lc:8.1f} mm  ctui between the end slices {Li:.1f} mm "
              f"{_pct(Li, Lc)}")
    rows = [r for r in res["rows"] if r.get("status") == "ok"]
    pts = np.array([r["point_mm"] for r in rows])
    nrm = np.array([r["normal"] for r in rows])
    surf = vtk_surface(mask, g)
    t = time.perf_counter()
    vtk_a = vtk_section_areas(surf, pts, nrm)
    t_cut = time.perf_counter() - t
    for key in ("area_mm2", "contour_area_mm2"):
        ours = np.array([r.get(key, np.nan) for r in rows], dtype=float)
        ok = np.isfinite(ours) & np.isfinite(vtk_a)
        d = 100.0 * (ours[ok] / vtk_a[ok] - 1.0)
        if d.size:
            print(f"sections ({key:16s}) {ok.sum():4d} planes: ctui vs VTK cut median {np.median(d):+.2f}%, "
                  f"|median| {np.median(np.abs(d)):.2f}%, p95 |d| {np.percentile(np.abs(d), 95):.2f}% "
                  f"(VTK {t_cut:.1f} s)")
    vox = float(res["volume_ml"]["voxels"])
    mesh_v, mesh_a = res["volume_ml"]["mesh"], res["area_mm2"]
    closed = vtk_surface(mask, g, pad=True)  # closed where the object meets the boundary
    fe_v, fe_a = vtk_mass(closed)
    sm_v, sm_a = vtk_mass(vtk_smoothed(closed))
    print(f"volume                   ctui voxels {vox:.3f} mL, mesh {mesh_v:.3f} mL ({_pct(mesh_v, vox)})")
    print(f"                         VTK flying edges (closed) {fe_v:.3f} mL ({_pct(fe_v, vox)} of the voxels; "
          f"ctui's mesh {_pct(mesh_v, fe_v)})")
    print(f"surface area             ctui mesh {mesh_a:.1f} mm2; VTK flying edges (closed) {fe_a:.1f} mm2 "
          f"(ctui {_pct(mesh_a, fe_a)}: a staircase); smoothed as 3D Slicer does {sm_a:.1f} mm2 "
          f"(ctui {_pct(mesh_a, sm_a)}), its volume {sm_v:.3f} mL (ctui's mesh {_pct(mesh_v, sm_v)})")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"), help="the shared data folder")
    ap.add_argument("--step", type=float, default=2.0, help="section step (mm) for the comparison")
    args = ap.parse_args()
    f = Path(args.data) / "totalseg_example" / "ct_aorta_1p5mm_aorta.nii.gz"
    if not f.exists():
        print(f"missing {f}", file=sys.stderr)
        return 2
    lab, vol = load_labels(f)
    g = Geometry.of(vol)
    mask = lab > 0
    compare("shared aorta (closed at the arch, open at the bottom)", mask, g, args.step)
    z0, z1 = 5, 70
    crop = Geometry(mask[z0:z1].shape, g.spacing, tuple(g.index_to_mm(np.array([[z0, 0, 0.0]]))[0]), g.direction)
    compare(f"the same cropped to slices {z0}..{z1 - 1} (open at both ends)", mask[z0:z1], crop, args.step)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
