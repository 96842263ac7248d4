"""Benchmark: one seed, every shared labelled structure, ctui's defaults (no range) beside two peers.

Sets (``../shared/data``; each loaded with ctui's own loaders, the MR's GIPL with SimpleITK):

* ``abdomen``   totalseg_example/ct_abdomen_3mm: kidneys, spleen, liver, stomach (silver labels)
* ``contrast``  the same CT with its kidneys enhanced cortex / medulla apart (``phantoms.contrast_abdomen``,
                corticomedullary phase: the arterial phase's kidney, a seed's ball holds cortex and medulla)
* ``spleen``    msd_spleen_crop: a portal-venous spleen against the liver at the same HU (expert label)
* ``hn``        openkbp_hn/pt_*: mandible, parotids, spinal cord, brainstem, larynx (clinicians' contours)
* ``brain``     itksnap_brain_mr: lateral ventricles (1), caudates (7) on a T1 MR (manual labels)

Each structure is seeded at its deepest point and at ``--seeds N`` random interior points (at least 6 mm
deep, or half the structure's depth when it is thinner), segmented with ctui's defaults (no range, automatic
neck) in slice and 3d mode. Per structure: Dice, volume ratio and HD95 at the deepest point, the random
seeds' median and lowest Dice, the spread between seeds (lowest pairwise Dice), and for every result outside
0.5-2x the reference volume whether it carried a warning (a silent failure otherwise). Peers from the same
seeds, on a box of ``PEER_MM`` around the seed: SimpleITK ConfidenceConnected (multiplier 2.5, radius 2,
4 iterations) and scikit-image's random walker (the seed's 3x3x3 against the box's faces).

Leak flags (``ctui.engine.segment.leaks``): each result's "a leak of ... enters at slice" warnings are counted, on
correct results (0.8-1.25x the reference, Dice >= 0.8: false flags) and overall; a flagged result prints the Dice
after a background seed at the flag's own suggested voxel.

Run: python3 benchmarks/organs_sets.py [--set abdomen,contrast,spleen,hn,brain] [--seeds N] [--patients K]
     [--no-peers] [--modes slice,3d]
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ctui.engine.actions.opened import open_input  # noqa: E402
from ctui.engine.actions.segment import SegmentOptions, segment  # noqa: E402
from ctui.engine.core.errors import CtuiError  # noqa: E402
from ctui.engine.core.volume import Volume  # noqa: E402
from ctui.engine.io.series import load  # noqa: E402

SHARED = ROOT.parent / "shared" / "data"
PEER_MM = 60.0
SETS = ("abdomen", "contrast", "spleen", "hn", "brain")
HN = ("Mandible", "LeftParotid", "RightParotid", "SpinalCord", "Brainstem", "Larynx")


def deepest(mask: np.ndarray, spacing) -> tuple[int, int, int]:
    dt = ndimage.distance_transform_edt(np.pad(mask, 1), sampling=spacing)[1:-1, 1:-1, 1:-1]
    z, y, x = np.unravel_index(int(np.argmax(dt)), mask.shape)
    return int(x), int(y), int(z)


def dice(a: np.ndarray, b: np.ndarray) -> float:
    s = np.count_nonzero(a) + np.count_nonzero(b)
    return 2.0 * np.count_nonzero(a & b) / s if s else 1.0


def hd95(a: np.ndarray, b: np.ndarray, spacing) -> float:
    if not a.any() or not b.any():
        return float("inf")
    box = tuple(slice(max(min(s.start for s in ss) - 2, 0), max(s.stop for s in ss) + 2) for ss in zip(
        ndimage.find_objects(a.astype(np.uint8))[0], ndimage.find_objects(b.astype(np.uint8))[0]))
    a, b = a[box], b[box]
    sa = a & ~ndimage.binary_erosion(a)
    sb = b & ~ndimage.binary_erosion(b)
    da = ndimage.distance_transform_edt(~sb, sampling=spacing)[sa]
    db = ndimage.distance_transform_edt(~sa, sampling=spacing)[sb]
    return float(np.percentile(np.concatenate([da, db]), 95))


def random_seeds(ref: np.ndarray, spacing, n: int, rng_seed: int = 2) -> list[tuple[int, int, int]]:
    """n seeds at random at least 6 mm inside ``ref`` (half its depth when it is thinner), the same every run."""
    if n <= 0:
        return []
    dt = ndimage.distance_transform_edt(np.pad(ref, 1), sampling=spacing)[1:-1, 1:-1, 1:-1]
    cand = np.argwhere(dt >= min(6.0, 0.5 * float(dt.max())))
    pick = np.random.default_rng(rng_seed).choice(len(cand), min(n, len(cand)), replace=False)
    return [(int(x), int(y), int(z)) for z, y, x in cand[pick]]


def cases(which: set[str], patients: int):
    """(set, name, volume, reference bool mask) for each structure of the chosen sets."""
    tot = SHARED / "totalseg_example"
    if which & {"abdomen", "contrast"} and tot.is_dir():
        vol = load(tot / "ct_abdomen_3mm.nii.gz")
        labels = open_input(tot / "ct_abdomen_3mm_labels.nii.gz").labels
        if "abdomen" in which:
            for name, lab in (("kidney right", 2), ("kidney left", 3), ("spleen", 1), ("liver", 5), ("stomach", 6)):
                yield "abdomen", name, vol, labels == lab
        if "contrast" in which:
            from ctui.engine.segment.phantoms import contrast_abdomen

            cvol = contrast_abdomen(vol, labels, phase="corticomedullary")
            for name, lab in (("kidney right", 2), ("kidney left", 3)):
                yield "contrast", name, cvol, labels == lab
    spl = SHARED / "msd_spleen_crop"
    if "spleen" in which and spl.is_dir():
        vol = load(spl / "sub-spleen2_ct.nii.gz")
        yield "spleen", "spleen", vol, open_input(spl / "sub-spleen2_ct_seg-manual.nii.gz").labels > 0
    hn = SHARED / "openkbp_hn"
    if "hn" in which and hn.is_dir():
        pts = sorted((p for p in hn.iterdir() if p.name.startswith("pt_")), key=lambda p: int(p.name[3:]))
        for p in pts[:patients]:
            vol = load(p / "ct.nii.gz")
            for name in HN:
                f = p / f"{name}.nii.gz"
                if f.exists():
                    ref = open_input(f).labels > 0
                    if ref.sum() >= 20:
                        yield "hn", f"{p.name} {name}", vol, ref
    br = SHARED / "itksnap_brain_mr"
    if "brain" in which and br.is_dir():
        vol, labels = brain_mr(br)
        for name, lab in (("lateral ventricles", 1), ("caudates", 7)):
            yield "brain", name, vol, labels == lab


def brain_mr(folder: Path) -> tuple[Volume, np.ndarray]:
    """The ITK-SNAP tutorial MR and its labels (GIPL: read with SimpleITK; ctui has no GIPL loader)."""
    import SimpleITK as sitk

    img = sitk.ReadImage(str(folder / "MRIcrop-orig.gipl.gz"))
    seg = sitk.ReadImage(str(folder / "MRIcrop-seg.gipl.gz"))
    data = sitk.GetArrayFromImage(img).astype(np.float32)
    return (Volume(data=data, spacing=tuple(float(s) for s in img.GetSpacing()[::-1]), modality="MR"),
            sitk.GetArrayFromImage(seg).astype(np.int32))


def run_ctui(vol, seed, mode: str, background=(), method: str = "fill") -> tuple[np.ndarray | None, list[str], str]:
    """ctui's defaults from one seed: (mask or None when refused, warnings, the refusal or range note)."""
    try:
        res = segment(vol, [seed], [], background=list(background), options=SegmentOptions(mode=mode, method=method))
    except CtuiError as e:
        return None, [str(e)], "refused"
    o = res.objects[0]
    return res.segmentation.labels == o.id, list(o.warnings), f"{o.range[0]:.0f}:{o.range[1]:.0f}"


def peer_box(shape, seed, spacing) -> tuple[slice, slice, slice]:
    x, y, z = seed
    return tuple(slice(max(c - int(PEER_MM / s), 0), min(c + int(PEER_MM / s) + 1, n))
                 for c, s, n in zip((z, y, x), spacing, shape))  # type: ignore[return-value]


def peer_confidence(vol, seed) -> np.ndarray:
    import SimpleITK as sitk

    box = peer_box(vol.data.shape, seed, vol.spacing)
    img = sitk.GetImageFromArray(vol.data[box].astype(np.float32))
    img.SetSpacing(tuple(float(s) for s in vol.spacing[::-1]))
    local = tuple(int(c - b.start) for c, b in zip(seed, box[::-1]))
    out = sitk.ConfidenceConnected(img, seedList=[local], numberOfIterations=4, multiplier=2.5,
                                   initialNeighborhoodRadius=2, replaceValue=1)
    full = np.zeros(vol.data.shape, bool)
    full[box] = sitk.GetArrayFromImage(out) > 0
    return full


def peer_rw(vol, seed) -> np.ndarray:
    from skimage.segmentation import random_walker

    box = peer_box(vol.data.shape, seed, vol.spacing)
    img = vol.data[box].astype(np.float32)
    img = (img - img.mean()) / max(float(img.std()), 1e-6)
    markers = np.zeros(img.shape, np.int32)
    markers[0], markers[-1], markers[:, 0], markers[:, -1], markers[:, :, 0], markers[:, :, -1] = 2, 2, 2, 2, 2, 2
    x, y, z = (int(c - b.start) for c, b in zip(seed, box[::-1]))
    markers[max(z - 1, 0):z + 2, max(y - 1, 0):y + 2, max(x - 1, 0):x + 2] = 1
    lab = random_walker(img, markers, beta=130, mode="cg_j", tol=1e-2, spacing=tuple(vol.spacing))
    full = np.zeros(vol.data.shape, bool)
    full[box] = lab == 1
    return full


def click(got: np.ndarray, ref: np.ndarray, spacing) -> tuple[int, int, int] | None:
    """A user's background click in a leak: the deepest point (x, y, z) of the result's largest piece outside the
    reference (dilated by one voxel)."""
    fp = got & ~ndimage.binary_dilation(ref)
    parts, n = ndimage.label(fp)
    if not n:
        return None
    big = np.argmax(np.bincount(parts.ravel())[1:]) + 1
    return deepest(parts == big, spacing)


def clicks(vol, ref, seed, got, mode: str) -> str:
    """One background click in the leak, under each method: Dice before -> after, or the refusal."""
    b = click(got, ref, vol.spacing)
    if b is None:
        return "no leak piece to click"
    out = [f"bg {b[0]},{b[1]},{b[2]}"]
    for method in ("fill", "grow", "levelset"):
        m, warns, note = run_ctui(vol, seed, mode, background=[b], method=method)
        out.append(f"{method} " + ("refused" if m is None else f"{dice(got, ref):.2f}->{dice(m, ref):.2f}"
                                   f"{' (warned)' if warns and m.sum() == got.sum() else ''}"))
    return ", ".join(out)


def flagged(warns: list[str]) -> list[tuple[int, int, int]]:
    """The background voxels (x, y, z) the leak flags suggest (``ctui.engine.segment.leaks``)."""
    return [tuple(int(v) for v in m.groups()) for w in warns if w.startswith("a leak of")
            for m in [re.search(r"background seed at (\d+),(\d+),(\d+)", w)] if m]


def suggested(vol, ref, seed, got, mode: str, at: tuple[int, int, int]) -> str:
    """The flag's own click: Dice before -> after under the default method."""
    m, _w, _n = run_ctui(vol, seed, mode, background=[at])
    return f"flag's click {at[0]},{at[1]},{at[2]} " + ("refused" if m is None else f"{dice(got, ref):.3f}->{dice(m, ref):.3f}")


def pairwise_min(masks: list[np.ndarray]) -> float:
    got = [m for m in masks if m is not None]
    if len(got) < 2:
        return float("nan")
    return min(dice(a, b) for i, a in enumerate(got) for b in got[i + 1:])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", default=",".join(SETS), help=f"comma-separated, of {', '.join(SETS)}")
    ap.add_argument("--seeds", type=int, default=5, metavar="N", help="random interior seeds per structure")
    ap.add_argument("--patients", type=int, default=20, metavar="K", help="head-and-neck patients (first K)")
    ap.add_argument("--modes", default="slice,3d")
    ap.add_argument("--no-peers", action="store_true")
    ap.add_argument("--clicks", action="store_true",
                    help="for each leak (> 2x) one background click in it, under fill, grow and levelset")
    args = ap.parse_args()
    which = set(args.set.split(","))
    if not SHARED.is_dir():
        print(f"skipped: {SHARED} is missing")
        return 0
    modes = args.modes.split(",")
    print(f"{'set':8s} {'structure':22s} {'mode':5s} {'Dice':>6s} {'vol x':>6s} {'HD95':>6s} | {'rnd med':>7s} "
          f"{'rnd min':>7s} {'spread':>6s} | {'out':>3s} {'warned':>6s} | range (deepest)")
    total = {"runs": 0, "out": 0, "warned": 0, "refused": 0, "ok": 0, "ok_flagged": 0, "flagged": 0, "ok_warned": 0}
    per_set: dict[str, list[float]] = {}
    t0 = time.perf_counter()
    for set_name, name, vol, ref in cases(which, args.patients):
        seeds = [deepest(ref, vol.spacing)] + random_seeds(ref, vol.spacing, args.seeds)
        for mode in modes:
            masks, ds, out, warned = [], [], 0, 0
            first = ""
            for i, s in enumerate(seeds):
                got, warns, note = run_ctui(vol, s, mode)
                total["runs"] += 1
                if got is None:
                    total["refused"] += 1
                    ds.append(0.0)
                    masks.append(None)
                    first = first or note
                    continue
                masks.append(got)
                ds.append(dice(got, ref))
                ratio = got.sum() / ref.sum()
                if not 0.5 <= ratio <= 2.0:
                    out += 1
                    warned += bool(warns)
                flags = flagged(warns)
                total["flagged"] += bool(flags)
                if 0.8 <= ratio <= 1.25 and ds[-1] >= 0.8:  # a correct result: a flag here is a false one
                    total["ok"] += 1
                    total["ok_flagged"] += bool(flags)
                    total["ok_warned"] += bool(warns)  # any warning on a correct result is a false one
                    if warns:
                        print(f"{'':8s} {name:22s} {mode:5s} seed {i}: false warning on a correct result: {warns[0][:90]}")
                if flags:
                    print(f"{'':8s} {name:22s} {mode:5s} seed {i}: {len(flags)} leak flag(s), x{ratio:.2f}, "
                          f"{suggested(vol, ref, s, got, mode, flags[0])}")
                if ratio > 2.0 and args.clicks and i == 0:
                    print(f"{'':8s} {name:22s} {mode:5s} leak {ratio:.1f}x, one click: {clicks(vol, ref, s, got, mode)}")
                if i == 0:
                    first = note
                    head = (dice(got, ref), ratio, hd95(got, ref, vol.spacing))
            if masks[0] is None:
                head = (0.0, 0.0, float("inf"))
            total["out"] += out
            total["warned"] += warned
            per_set.setdefault(f"{set_name} {mode}", []).extend(ds)
            rnd = np.array(ds[1:]) if len(ds) > 1 else np.array([np.nan])
            print(f"{set_name:8s} {name:22s} {mode:5s} {head[0]:6.3f} {head[1]:6.2f} {head[2]:6.1f} | "
                  f"{np.median(rnd):7.3f} {rnd.min():7.3f} {pairwise_min(masks):6.3f} | {out:3d} {warned:6d} | {first}")
            sys.stdout.flush()
        if not args.no_peers:
            for label, f in (("sitk confidence", peer_confidence), ("skimage rw (box)", peer_rw)):
                pd = []
                for s in seeds:
                    try:
                        pd.append(dice(f(vol, s), ref))
                    except Exception:  # noqa: BLE001 (a peer failing is a row of zeros, not a crash)
                        pd.append(0.0)
                print(f"{set_name:8s} {name:22s} {label:17s} Dice deepest {pd[0]:.3f}, median {np.median(pd):.3f}")
                sys.stdout.flush()
    print(f"\nsummary ({time.perf_counter() - t0:.0f} s): {total['runs']} results, {total['refused']} refused, "
          f"{total['out']} outside 0.5-2x the reference volume, {total['warned']} of them warned "
          f"({total['out'] - total['warned']} silent); leak flags on {total['flagged']} results, "
          f"{total['ok_flagged']} of the {total['ok']} correct ones (0.8-1.25x, Dice >= 0.8); any warning on "
          f"{total['ok_warned']} of the correct ones")
    for k, v in per_set.items():
        a = np.array(v)
        print(f"  {k:14s} median Dice {np.median(a):.3f}, >= 0.90: {int((a >= 0.9).sum())}/{len(a)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
