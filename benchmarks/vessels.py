"""Benchmark: ``ctui vessel`` on the dissected aorta CT, beside the peers, from the same points.

Data: ``../shared/data/totalseg_example/ct_aorta_1p5mm.nii.gz`` (1.5 mm, a type B dissection),
its aorta mask ``ct_aorta_1p5mm_aorta.nii.gz``, the parts in ``aorta_parts/`` (true and false
lumen, annulus, branches) and ``ct_aorta_report.json`` (landmark diameters, cm; the aorta's
length from its section lengths: 6.8 + 4.4 + 26.0 cm = 372 mm).

Points (voxels X,Y,Z = column, row, slice from 0, as ``ctui segment --seed``), from the masks:
start: the centroid of the aorta 3-6 mm above the plane of ``annulus_proper`` (its principal
plane); end: the centroid of the aorta in its last 3 slices; arch waypoint: the centroid of the
aorta in its top 5 slices. They are printed so a user can reproduce each row with ``ctui vessel``.

Rows: ctui vessel --lumen contrast without and with the waypoint, --lumen wall with it; the peers
from the same points: ctui's one-seed fill (``ctui segment`` at the start, automatic range), SimpleITK
colliding fronts alone (the core chained through the waypoint, in range), a VMTK-style level set
(SimpleITK GeodesicActiveContourLevelSetImageFilter on a sigmoid of the gradient magnitude,
started from a 3 mm tube around ctui's path). Columns: path length (mm) and share of its points
inside the aorta, Dice against the true lumen and the whole aorta, mL beyond the annulus plane
(the left ventricle side), seconds. Then diameters at the report's landmarks and a branch (left
subclavian artery, brachiocephalic trunk) from its origin against its mask.

With ``--parts``: Dice, false positives and false negatives per 40 mm of path for the rows with the
waypoint (where the errors are).

Run: nice -n 10 python3 benchmarks/vessels.py [--no-peers] [--parts]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ctui.engine.actions.segment import segment  # noqa: E402
from ctui.engine.actions.vessel import vessel  # noqa: E402
from ctui.engine.io.series import load  # noqa: E402
from ctui.engine.vessel import path as vpath  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "totalseg_example"
REPORT_LENGTH_MM = 372.0


def mask_of(name: str) -> np.ndarray:
    import SimpleITK as sitk

    return sitk.GetArrayFromImage(sitk.ReadImage(str(DATA / name))) > 0


def dice(a: np.ndarray, b: np.ndarray) -> float:
    return 2.0 * float((a & b).sum()) / max(float(a.sum() + b.sum()), 1.0)


def annulus_plane(annulus: np.ndarray, aorta: np.ndarray, spacing) -> tuple[np.ndarray, np.ndarray]:
    """(centre mm, unit normal towards the aorta) of the annulus' principal plane, in (z, y, x) mm."""
    sp = np.asarray(spacing, dtype=float)
    pa = np.argwhere(annulus) * sp
    c = pa.mean(axis=0)
    n = np.linalg.svd(pa - c)[2][2]
    q = np.argwhere(aorta) * sp
    near = np.linalg.norm(q - c, axis=1) < 30.0
    if float(((q[near] - c) @ n).mean()) < 0:
        n = -n
    return c, n


def points(aorta: np.ndarray, annulus: np.ndarray, spacing) -> dict:
    """start, end, via as voxels (x, y, z) from the masks (module docstring)."""
    sp = np.asarray(spacing, dtype=float)
    c, n = annulus_plane(annulus, aorta, sp)
    q = np.argwhere(aorta) * sp
    sd = (q - c) @ n
    sel = (np.linalg.norm(q - c, axis=1) < 30.0) & (sd > 3.0) & (sd < 6.0)
    zs = np.nonzero(aorta.any(axis=(1, 2)))[0]

    def centroid(zyx: np.ndarray) -> tuple[int, int, int]:
        k = np.rint(zyx).astype(int)
        if not aorta[tuple(k)]:  # the nearest aorta voxel
            _, ind = ndimage.distance_transform_edt(~aorta, return_indices=True)
            k = ind[:, k[0], k[1], k[2]]
        return int(k[2]), int(k[1]), int(k[0])

    top = np.argwhere(aorta[zs[-1] - 4: zs[-1] + 1]).mean(axis=0) + [zs[-1] - 4, 0, 0]
    bottom = np.argwhere(aorta[zs[0]: zs[0] + 3]).mean(axis=0) + [zs[0], 0, 0]
    return {"start": centroid(q[sel].mean(axis=0) / sp), "end": centroid(bottom), "via": centroid(top)}


def path_inside(path_mm: np.ndarray, vol, aorta: np.ndarray) -> float:
    k = np.rint(vol.mm_to_index(path_mm)).astype(int)
    k = np.clip(k, 0, np.asarray(aorta.shape) - 1)
    return float(aorta[k[:, 0], k[:, 1], k[:, 2]].mean())


def beyond_annulus_ml(mask: np.ndarray, plane, spacing) -> float:
    """mL of ``mask`` on the ventricle's side of the annulus plane, within 40 mm of its centre."""
    c, n = plane
    q = np.argwhere(mask) * np.asarray(spacing, dtype=float)
    below = ((q - c) @ n < 0) & (np.linalg.norm(q - c, axis=1) < 40.0)
    return float(below.sum()) * float(np.prod(spacing)) / 1000.0


def row(name: str, mask, secs: float, refs: dict, *, path_mm=None, vol=None, cpu: float | None = None) -> None:
    length = inside = float("nan")
    if path_mm is not None:
        length = float(np.linalg.norm(np.diff(path_mm, axis=0), axis=1).sum())
        inside = path_inside(path_mm, vol, refs["aorta"])
    print(f"{name:34s} {length:7.1f} {100 * inside:6.1f}% {dice(mask, refs['true']):6.3f} "
          f"{dice(mask, refs['aorta']):6.3f} {beyond_annulus_ml(mask, refs['plane'], vol.spacing):7.2f} {secs:6.2f}"
          + ("" if cpu is None else f" {cpu:6.2f}"))


def parts(name: str, res, ref: np.ndarray, vol, every_mm: float = 40.0) -> None:
    """Where the errors are: Dice, false positives and false negatives (voxels) per ``every_mm``
    of path (each voxel of the vessel or the reference goes to its nearest path point)."""
    from scipy.spatial import cKDTree

    path = res.path_mm
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    vox = np.argwhere(res.mask | ref)
    _, j = cKDTree(vol.mm_to_index(path) * vol.spacing).query(vox * np.asarray(vol.spacing))
    got, want = res.mask[tuple(vox.T)], ref[tuple(vox.T)]
    print(f"\n{name}: per {every_mm:.0f} mm of path (s from the start)")
    print(f"{'s mm':>9s} {'ref':>6s} {'ctui':>6s} {'Dice':>6s} {'FP':>6s} {'FN':>6s}")
    for a in np.arange(0.0, s[-1], every_mm):
        k = (s[j] >= a) & (s[j] < a + every_mm)
        tp, fp, fn = (int((k & g & w).sum()) for g, w in ((got, want), (got, ~want), (~got, want)))
        print(f"{a:4.0f}-{a + every_mm:<4.0f} {tp + fn:6d} {tp + fp:6d} {2 * tp / max(2 * tp + fp + fn, 1):6.3f} "
              f"{fp:6d} {fn:6d}")


def peer_core(vol, pts: dict) -> np.ndarray:
    """SimpleITK colliding fronts alone, chained start -> via -> end, in the automatic range."""
    zyx = [tuple(p[::-1]) for p in (pts["start"], pts["via"], pts["end"])]
    box = vpath.crop_box(vol.shape, zyx, vol.spacing)
    off = np.array([s.start for s in box])
    img = np.asarray(vol.data[box], dtype=np.float32)
    rel = [np.subtract(p, off) for p in zyx]
    lo, hi = vpath.auto_range(img, rel, vol.spacing)
    dist, inr = vpath.lumen_distance(img, lo, hi, vol.spacing)
    legs = vpath.order_legs(rel[0], [rel[1]], [rel[2]])
    core = vpath.colliding_fronts(dist, legs, inr, vol.spacing, vpath.minimal_path(dist, legs, vol.spacing)[1])
    out = np.zeros(vol.shape, bool)
    out[box] = core
    return out


def peer_levelset(vol, path_mm: np.ndarray, iterations: int = 300) -> np.ndarray:
    """A VMTK-style level set: SimpleITK geodesic active contour on a sigmoid of the gradient
    magnitude (sigma 1 mm; edges from 40 HU/mm), from a 3 mm tube around ctui's path."""
    import SimpleITK as sitk

    img = sitk.GetImageFromArray(np.asarray(vol.data, dtype=np.float32))
    img.SetSpacing(tuple(float(s) for s in vol.spacing[::-1]))
    grad = sitk.GradientMagnitudeRecursiveGaussian(img, sigma=1.0)
    feature = sitk.Sigmoid(grad, alpha=-10.0, beta=40.0, outputMaximum=1.0, outputMinimum=0.0)
    seeds = np.zeros(vol.shape, np.uint8)
    k = np.clip(np.rint(vol.mm_to_index(path_mm)).astype(int), 0, np.asarray(vol.shape) - 1)
    seeds[k[:, 0], k[:, 1], k[:, 2]] = 1
    tube = ndimage.distance_transform_edt(seeds == 0, sampling=vol.spacing) <= 3.0
    init = sitk.GetImageFromArray(tube.astype(np.uint8))
    init.CopyInformation(img)
    phi0 = sitk.SignedMaurerDistanceMap(init, insideIsPositive=False, useImageSpacing=True)
    gac = sitk.GeodesicActiveContourLevelSetImageFilter()
    gac.SetPropagationScaling(1.0)
    gac.SetCurvatureScaling(1.0)
    gac.SetAdvectionScaling(1.0)
    gac.SetMaximumRMSError(0.01)
    gac.SetNumberOfIterations(iterations)
    out = gac.Execute(sitk.Cast(phi0, sitk.sitkFloat32), sitk.Cast(feature, sitk.sitkFloat32))
    return sitk.GetArrayFromImage(out) < 0


def landmarks(vol, res) -> None:
    """Our equivalent and max diameters at the nearest section to each landmark of the report."""
    rep = json.loads((DATA / "ct_aorta_report.json").read_text())["landmarks"]
    path = res.path_mm
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    rows = [r for r in res.sections if r["branch"] == 0]
    srow = np.array([r["s_mm"] for r in rows])
    print(f"\n{'landmark':28s} {'report mm':>9s} {'eq mm':>6s} {'max mm':>6s} {'s mm':>6s} {'off mm':>6s}")
    for v in rep.values():
        if v.get("start") is None or v.get("diameter") is None:
            continue
        p = (np.asarray(v["start"]) + np.asarray(v["end"])) / 2.0 * [-1.0, -1.0, 1.0]  # RAS -> LPS
        i = int(np.argmin(np.linalg.norm(path - p, axis=1)))
        r = rows[int(np.argmin(np.abs(srow - s[i])))]
        print(f"{v['name']:28s} {10 * v['diameter']:9.0f} {r['eq_diameter_mm']:6.1f} {r['max_diameter_mm']:6.1f} "
              f"{s[i]:6.0f} {float(np.linalg.norm(path[i] - p)):6.1f}")


def branch_points(branch: np.ndarray, aorta: np.ndarray) -> tuple[tuple, tuple, np.ndarray]:
    """(origin, far end) voxels (x, y, z) of a branch mask and the part of the mask they span (its
    26-connected part touching the aorta: a mask may come in pieces). Origin: the centroid of the
    branch's voxels within 2 voxels of the aorta; far end: the centroid of the voxels within 3
    voxels of the one farthest from it along the branch (geodesic, inside the mask)."""
    from skimage.graph import MCP_Geometric

    touch = branch & ndimage.binary_dilation(aorta, iterations=2)
    lab, _ = ndimage.label(branch, structure=np.ones((3, 3, 3)))
    part = lab == np.bincount(lab[touch]).argmax() if touch.any() else branch
    q = np.argwhere(part)
    o = q[int(np.argmin(np.linalg.norm(q - np.argwhere(touch & part).mean(axis=0), axis=1)))]
    acc, _ = MCP_Geometric(np.where(part, 1.0, np.inf), fully_connected=True).find_costs([tuple(o)])
    far = np.unravel_index(int(np.argmax(np.where(np.isfinite(acc), acc, -1))), acc.shape)
    e = q[np.linalg.norm(q - far, axis=1) <= 3].mean(axis=0)
    e = q[int(np.argmin(np.linalg.norm(q - e, axis=1)))]
    return tuple(int(v) for v in o[::-1]), tuple(int(v) for v in e[::-1]), part


def branches(vol, aorta: np.ndarray, path: str) -> None:
    print(f"\n{'branch from its origin':34s} {'start':>14s} {'end':>14s} {'len mm':>7s} {'Dice':>6s} {'vol/ref':>7s} {'s':>5s}")
    for name in ("subclavian_artery_left", "brachiocephalic_trunk"):
        ref = mask_of(f"aorta_parts/{name}.nii.gz")
        a, b, part = branch_points(ref, aorta)
        t = time.perf_counter()
        res = vessel(vol, start=a, ends=[b])
        secs = time.perf_counter() - t
        print(f"{name:34s} {str(a):>14s} {str(b):>14s} {res.path_length_mm[0]:7.1f} {dice(res.mask, part):6.3f} "
              f"{res.voxels / part.sum():7.2f} {secs:5.2f}" + ("" if part.sum() == ref.sum() else
                                                               f"  (its part from the origin: {part.sum()} of "
                                                               f"{ref.sum()} voxels)"))
        print(f"  ctui vessel {path} --start {','.join(map(str, a))} --end {','.join(map(str, b))}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-peers", action="store_true", help="ctui's rows only")
    ap.add_argument("--parts", action="store_true", help="Dice, FP and FN along the path (contrast and wall rows)")
    args = ap.parse_args()
    path = DATA / "ct_aorta_1p5mm.nii.gz"
    shown = "../shared/data/totalseg_example/ct_aorta_1p5mm.nii.gz"
    if not path.exists():
        print(f"skipped: {path} not found")
        return 0
    vol = load(str(path))
    aorta = mask_of("ct_aorta_1p5mm_aorta.nii.gz")
    refs = {"aorta": aorta, "true": mask_of("aorta_parts/aorta_true_lumen.nii.gz"),
            "plane": annulus_plane(mask_of("aorta_parts/annulus_proper.nii.gz"), aorta, vol.spacing)}
    pts = points(aorta, mask_of("aorta_parts/annulus_proper.nii.gz"), vol.spacing)
    xyz = {k: ",".join(map(str, v)) for k, v in pts.items()}
    print(f"points (voxel X,Y,Z): start {xyz['start']}  via {xyz['via']}  end {xyz['end']}")
    print(f"goals: path >= 95% inside, {0.95 * REPORT_LENGTH_MM:.0f}-{1.05 * REPORT_LENGTH_MM:.0f} mm; 0 mL beyond "
          "the annulus; Dice >= 0.90 true lumen (contrast), >= 0.85 aorta (wall); < 10 s\n")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (s: wall clock; cpu s: this process, all "
          "its threads)")
    print(f"{'method':34s} {'len mm':>7s} {'inside':>7s} {'DiceTL':>6s} {'DiceAo':>6s} {'vent mL':>7s} {'s':>6s} "
          f"{'cpu s':>6s}")
    runs = [("ctui vessel contrast, no waypoint", [], "contrast"), ("ctui vessel contrast + arch", [pts["via"]],
                                                                      "contrast"),
            ("ctui vessel wall + arch", [pts["via"]], "wall")]
    best = None
    shown_parts: list = []
    for name, vias, lumen in runs:
        t, c = time.perf_counter(), time.process_time()
        res = vessel(vol, start=pts["start"], ends=[pts["end"]], vias=vias, lumen=lumen)
        row(name, res.mask, time.perf_counter() - t, refs, path_mm=res.path_mm, vol=vol, cpu=time.process_time() - c)
        best = res if vias and lumen == "wall" else best
        if args.parts and vias:
            shown_parts.append((f"{name} against the {'whole aorta' if lumen == 'wall' else 'true lumen'}", res,
                                refs["aorta" if lumen == "wall" else "true"]))
        cmd = f"  ctui vessel {shown} --start {xyz['start']} --end {xyz['end']}"
        print(cmd + (f" --via {xyz['via']}" if vias else "") + f" --lumen {lumen}")
    if not args.no_peers:
        t = time.perf_counter()
        seg = segment(vol, [pts["start"]], [])
        row("ctui segment (one seed, auto)", seg.segmentation.labels == seg.objects[0].id, time.perf_counter() - t,
            refs, vol=vol)
        t = time.perf_counter()
        core = peer_core(vol, pts)
        row("sitk colliding fronts alone", core, time.perf_counter() - t, refs, vol=vol)
        print(f"  (a core: {int(core.sum())} voxels, {100 * (core & refs['true']).sum() / max(core.sum(), 1):.1f}% "
              f"inside the true lumen, {100 * (core & refs['aorta']).sum() / max(core.sum(), 1):.1f}% inside the aorta)")
        t = time.perf_counter()
        row("sitk geodesic active contour", peer_levelset(vol, best.path_mm), time.perf_counter() - t, refs, vol=vol)
    for name, res, ref in shown_parts:
        parts(name, res, ref, vol)
    landmarks(vol, best)
    branches(vol, aorta, shown)
    return 0


if __name__ == "__main__":
    sys.exit(main())
