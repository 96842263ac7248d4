"""One seed, one organ, on real CT against reference labels (../shared/data/totalseg_example).

Each organ is seeded at its deepest point (the maximum of the distance map of its
reference label, the volume's border counting as outside), with the defaults: the leak
guard's width chosen from the data and, without a range, the range from the seed's
neighbourhood. Before the automatic width (fixed 5 mm neck) the same seeds gave Dice
0.08-0.71 and 0.07x-23x the volume (benchmarks/organs.py prints the full table).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from ctui.engine.actions.opened import open_input
from ctui.engine.actions.segment import SegmentOptions, segment
from ctui.engine.core.errors import CtuiError
from ctui.engine.io.series import load
from support import shared

ORGANS = {"kidney_right": 2, "kidney_left": 3, "spleen": 1, "liver": 5}


@pytest.fixture(scope="module")
def abdomen():
    d = shared("totalseg_example")
    vol = load(d / "ct_abdomen_3mm.nii.gz")
    labels = open_input(d / "ct_abdomen_3mm_labels.nii.gz").labels
    return vol, labels


def deepest(mask: np.ndarray, spacing) -> tuple[int, int, int]:
    """(x, y, z) of the voxel farthest from the mask's boundary (the array border is outside)."""
    dt = ndimage.distance_transform_edt(np.pad(mask, 1), sampling=spacing)[1:-1, 1:-1, 1:-1]
    z, y, x = np.unravel_index(int(np.argmax(dt)), mask.shape)
    return int(x), int(y), int(z)


def dice(a: np.ndarray, b: np.ndarray) -> float:
    return 2.0 * np.count_nonzero(a & b) / (np.count_nonzero(a) + np.count_nonzero(b))


def fine_grid(vol, labels, lab: int, noise: float = 0.0):
    """The CT resampled to 1 x 1 x 3 mm (linear; a thin-pixel series' grid), Gaussian noise of ``noise`` HU
    added (seeded), and label ``lab`` repeated onto that grid: (volume, reference)."""
    from dataclasses import replace

    data = ndimage.zoom(vol.data.astype(np.float32), (1, 3, 3), order=1)
    if noise:
        data += np.random.default_rng(0).normal(0.0, noise, data.shape).astype(np.float32)
    fine = replace(vol, data=np.round(data).astype(np.int16), spacing=(vol.spacing[0], vol.spacing[1] / 3, vol.spacing[2] / 3))
    return fine, np.repeat(np.repeat(labels == lab, 3, 1), 3, 2)


@pytest.mark.shared_data
@pytest.mark.parametrize("mode", ["slice", "3d"])
@pytest.mark.parametrize("with_range", [False, True])
@pytest.mark.parametrize("organ", list(ORGANS))
def test_one_seed_one_organ(abdomen, organ, with_range, mode):
    vol, labels = abdomen
    ref = labels == ORGANS[organ]
    seed = deepest(ref, vol.spacing)
    th = [tuple(np.percentile(vol.data[ref], [5, 95]))] if with_range else []
    res = segment(vol, [seed], th, options=SegmentOptions(mode=mode))
    got = res.segmentation.labels == res.objects[0].id
    d, ratio = dice(got, ref), got.sum() / ref.sum()
    assert d >= 0.85, f"{organ}: Dice {d:.3f}"
    # the goal, 15%, holds everywhere but the liver with its 5-95th percentile range in 3D (1.16: the
    # unenhanced vena cava, portal vein and stomach wall touch it broadly at the liver's own values)
    top = 1.17 if (organ, with_range, mode) == ("liver", True, "3d") else 1.15
    assert 0.85 <= ratio <= top, f"{organ}: volume ratio {ratio:.2f}"
    obj = res.objects[0]
    assert obj.neck["mode"] == "auto" and obj.neck["width_mm"] > 0 and obj.neck["reason"]
    assert (obj.auto_range is None) == with_range
    assert obj.cuts and all(len(c["mm"]) == 3 for c in obj.cuts)  # where the guard cut, in patient mm
    assert obj.warnings == []
    assert obj.denoise == ""  # no specks around these seeds: the fill runs on the values as they are


@pytest.mark.shared_data
def test_fixed_neck_wider_than_the_organ_warns(abdomen):
    """A neck wider than the organ turns the guard off: the result says so instead of returning 18x the organ."""
    vol, labels = abdomen
    ref = labels == 2
    res = segment(vol, [deepest(ref, vol.spacing)], [(-21.0, 36.0)], options=SegmentOptions(mode="3d", neck_mm=40.0))
    assert any("wider than the object" in w for w in res.objects[0].warnings)


@pytest.mark.shared_data
def test_background_seed_out_of_range_warns_and_empty_fails(abdomen):
    vol, labels = abdomen
    ref = labels == 3
    seed = deepest(ref, vol.spacing)
    air = (2, 2, 5)  # outside the body, far out of a kidney's range
    res = segment(vol, [seed], [], background=[air])
    assert any("cannot stop anything" in w for w in res.objects[0].warnings)
    assert not any("does not reach it" in w for w in res.objects[0].warnings)  # one note per seed
    with pytest.raises(CtuiError, match="outside the range"):
        segment(vol, [air], [(0.0, 50.0)])


@pytest.mark.shared_data
def test_auto_range_holds_the_organ(abdomen):
    """The range from the seed's neighbourhood covers most of the organ's own values (its 5-95th percentiles)."""
    vol, labels = abdomen
    for organ, lab in ORGANS.items():
        ref = labels == lab
        res = segment(vol, [deepest(ref, vol.spacing)], [], options=SegmentOptions(mode="3d"))
        lo, hi = res.objects[0].range
        p5, p95 = np.percentile(vol.data[ref], [5, 95])
        inside = np.mean((vol.data[ref] >= lo) & (vol.data[ref] <= hi))
        assert inside >= 0.85, f"{organ}: auto range {lo:.0f}..{hi:.0f} holds {inside:.2f} (5-95th: {p5}..{p95})"
        hist = res.objects[0].auto_range["hist"]
        assert sum(hist) > 20 and max(hist) > 0


@pytest.mark.shared_data
@pytest.mark.parametrize("neck", [None, 0.0])
def test_grow_with_background_seeds_gives_the_kidney(abdomen, neck):
    """The issue's case: one seed in the left kidney and four background seeds in its neighbours gave 2164 mL
    for a 99 mL kidney; the edge competition gives the kidney, with the leak guard and without it."""
    vol, labels = abdomen
    ref = labels == 3
    bg = [(21, 35, 16), (45, 33, 1), (32, 57, 2), (35, 52, 12)]
    res = segment(vol, [(31, 33, 8)], [(-20.0, 45.0)], background=bg,
                  options=SegmentOptions(method="grow", neck_mm=neck))
    got = res.segmentation.labels == res.objects[0].id
    assert dice(got, ref) >= 0.88
    assert 0.9 <= got.sum() / ref.sum() <= 1.1


@pytest.mark.shared_data
def test_mixed_neighbourhood_warns():
    """A seed in a contrast-enhanced kidney (cortex ~250 HU beside medulla ~100 HU; the aorta CT's field of view
    holds its upper pole) gives an automatic range that spans several tissues: the fill takes the liver and
    the muscles (over 800 mL), and the result must say why instead of returning it silently."""
    vol = load(shared("totalseg_example") / "ct_aorta_1p5mm.nii.gz")
    res = segment(vol, [(14, 92, 2)], [], options=SegmentOptions(mode="3d"))
    obj = res.objects[0]
    assert obj.volume_ml > 500
    assert any("not uniform" in w and "give a range" in w for w in obj.warnings), obj.warnings


@pytest.mark.shared_data
@pytest.mark.parametrize("mode", ["slice", "3d"])
def test_noisy_range_fills_on_a_median(mode):
    """Contrast CT at 1.5 mm (noise ~36 HU), a seed in the right kidney's upper pole (the field of view holds
    slices 0-9 of it) and the range 120:400: the liver beside it (~80 HU) shows as in-range specks that
    bridged the fill into the whole series (653 mL over 164 slices in slice mode); the fill now runs on a
    3 x 3 median and keeps to the kidney."""
    vol = load(shared("totalseg_example") / "ct_aorta_1p5mm.nii.gz")
    res = segment(vol, [(16, 96, 2)], [(120.0, 400.0)], options=SegmentOptions(mode=mode))
    obj = res.objects[0]
    assert obj.denoise == "median 3x3" and "median" in obj.message()
    assert 3.0 < obj.volume_ml < 20.0, obj.volume_ml
    assert obj.slices is not None and obj.slices[1] <= 15


@pytest.mark.shared_data
def test_seed_on_a_noise_pixel_starts_beside_it(abdomen):
    """A seed whose own value is noise outside the range, inside the organ, fills the organ from the nearest
    in-range pixel and says so; a seed on another tissue is still refused."""
    vol, labels = abdomen
    ref = labels == 5
    lo, hi = (float(v) for v in np.percentile(vol.data[ref], [5, 95]))
    deep = ndimage.binary_erosion(ref, iterations=4)
    med = ndimage.median_filter(vol.data, size=(1, 3, 3))
    z, y, x = np.argwhere(deep & ((vol.data < lo) | (vol.data > hi)) & (med >= lo) & (med <= hi))[0]
    res = segment(vol, [(int(x), int(y), int(z))], [(lo, hi)], options=SegmentOptions(mode="3d"))
    obj = res.objects[0]
    got = res.segmentation.labels == obj.id
    assert dice(got, ref) >= 0.85
    assert any("so the fill starts at" in w for w in obj.warnings), obj.warnings
    sx, sy, sz = obj.seed
    assert sz == z and max(abs(sx - x), abs(sy - y)) == 1 and lo <= vol.data[sz, sy, sx] <= hi
    fat = np.argwhere((vol.data < -80) & ndimage.binary_erosion(vol.data < -80, iterations=2))[0]
    with pytest.raises(CtuiError, match="outside the range"):
        segment(vol, [(int(fat[2]), int(fat[1]), int(fat[0]))], [(lo, hi)], options=SegmentOptions(mode="3d"))


@pytest.mark.shared_data
@pytest.mark.parametrize("organ, range_on", [("kidney_right", "3mm"), ("liver", "fine")])
def test_fine_grid_gives_the_organ_in_both_modes(abdomen, organ, range_on):
    """The same CT resampled to 1 x 1 x 3 mm (a thin-pixel series' grid), the organ with its 5-95th
    percentile range on the 3 mm or on this grid: slice mode matches 3D mode. The pixel-counting area guard
    stopped the right kidney at its pole (Dice 0.64); a split rule of a whole ball of the radius missed the
    liver's last leak (0.87). (The right kidney with its range on this grid, -23..29 HU instead of -21..36,
    leaks into the liver in both modes, 3.2x: benchmarks/organs.py --grid 3.)"""
    vol, labels = abdomen
    fine, ref = fine_grid(vol, labels, ORGANS[organ])
    th = [tuple(np.percentile(fine.data[ref] if range_on == "fine" else vol.data[labels == ORGANS[organ]], [5, 95]))]
    got = {}
    for mode in ("slice", "3d"):
        res = segment(fine, [deepest(ref, fine.spacing)], th, options=SegmentOptions(mode=mode))
        got[mode] = res.segmentation.labels == res.objects[0].id
        assert not any("leak guard" in w for w in res.objects[0].warnings)
    assert dice(got["slice"], ref) >= 0.88 and dice(got["3d"], ref) >= 0.88
    assert 0.9 <= got["slice"].sum() / ref.sum() <= 1.1


@pytest.mark.shared_data
@pytest.mark.parametrize("mode", ["slice", "3d"])
@pytest.mark.parametrize("with_range", [False, True])
@pytest.mark.parametrize("organ", ["kidney_right", "kidney_left"])
def test_contrast_kidney_one_seed(abdomen, organ, with_range, mode):
    """The abdomen enhanced by its labels (portal-venous phase, renal veins drawn to the vena cava): one
    seed per kidney, with and without 120:400, keeps to the kidney. Before: the automatic width cut the left
    kidney at its own waist (Dice 0.86, no range) and slice mode went through the left renal vein's gap
    (296 mL for a 99 mL kidney, 120:400)."""
    from ctui.engine.segment.phantoms import contrast_abdomen

    vol, labels = abdomen
    cvol = contrast_abdomen(vol, labels)
    ref = labels == ORGANS[organ]
    res = segment(cvol, [deepest(ref, vol.spacing)], [(120.0, 400.0)] if with_range else [],
                  options=SegmentOptions(mode=mode))
    obj = res.objects[0]
    got = res.segmentation.labels == obj.id
    assert dice(got, ref) >= 0.9, f"Dice {dice(got, ref):.3f}"
    assert 0.85 <= got.sum() / ref.sum() <= 1.15
    assert (obj.slices[1] - obj.slices[0] + 1) * vol.spacing[0] <= 150.0
    assert obj.warnings == []


@pytest.mark.shared_data
@pytest.mark.parametrize("mode", ["slice", "3d"])
def test_leak_with_the_guard_off_warns(abdomen, mode):
    """--neck 0 turns the leak guard off; the right kidney then runs into the liver and beyond (1.7-2.1 L for
    a 107 mL kidney). The size check measures the ball that fits at the seed itself when no sweep ran."""
    vol, labels = abdomen
    ref = labels == 2
    res = segment(vol, [deepest(ref, vol.spacing)], [], options=SegmentOptions(mode=mode, neck_mm=0.0))
    obj = res.objects[0]
    assert obj.voxels > 5 * ref.sum()  # the failure the warning is about
    assert any("the ball that fits at the seed" in w and "neck auto" in w for w in obj.warnings), obj.warnings


@pytest.mark.shared_data
def test_leak_into_a_tissue_of_overlapping_values_warns(abdomen):
    """On a noisy 1 x 1 x 3 mm grid (15 HU added) the unenhanced right kidney (~10 HU) and the liver (~46 HU)
    meet across a contact wider than any neck, and one seed takes both (5-13x the kidney). The object's
    median then lies far from its seed's, and the result says so; the kidney itself does not warn."""
    vol, labels = abdomen
    fine, ref = fine_grid(vol, labels, 2, noise=15.0)
    res = segment(fine, [deepest(ref, fine.spacing)], [], options=SegmentOptions(mode="slice"))
    obj = res.objects[0]
    ratio = obj.voxels / ref.sum()
    assert ratio <= 1.15 or any("neighbouring tissue" in w for w in obj.warnings), (ratio, obj.warnings)
    kid = segment(vol, [deepest(labels == 2, vol.spacing)], [], options=SegmentOptions(mode="slice"))
    assert not any("neighbouring tissue" in w for w in kid.objects[0].warnings)


@pytest.mark.shared_data
def test_aorta_one_seed_says_what_it_could_not_do():
    """The aorta of the contrast chest-abdomen CT (a dissection: the reference holds the thrombosed false lumen,
    ~60-120 HU beside a 170-670 HU true lumen) from one seed at its deepest point. The issue's goal, Dice 0.80,
    is not reached (benchmarks/organs.py: 0.55 slice, 0.59 3D; a perfect fill of the in-range lumen would
    score 0.86). What this guards: the defaults keep the lumen they reach without leaking, and say that the
    seed's neighbourhood mixes tissues; with the reference's own 5-95th percentile range (which spans the
    thrombus, so the fill runs into bone and the heart) the result says it leaked."""
    d = shared("totalseg_example")
    vol = load(d / "ct_aorta_1p5mm.nii.gz")
    ref = open_input(d / "ct_aorta_1p5mm_aorta.nii.gz").labels > 0
    seed = deepest(ref, vol.spacing)
    res = segment(vol, [seed], [], options=SegmentOptions(mode="3d"))
    got = res.segmentation.labels == res.objects[0].id
    assert dice(got, ref) >= 0.55 and np.count_nonzero(got & ~ref) < 0.1 * got.sum()
    o = res.objects[0]  # said as a warning, or as a note on the range under MIXED_WARN x the noise (issue 37)
    assert any("not uniform" in w for w in o.warnings) or "not uniform" in o.auto_range["why"]
    rng = tuple(float(v) for v in np.percentile(vol.data[ref], [5, 95]))
    res = segment(vol, [seed], [rng], options=SegmentOptions(mode="slice"))
    obj = res.objects[0]
    assert obj.voxels > 3 * ref.sum()
    assert any("the ball that fits" in w for w in obj.warnings) and any("neighbouring tissue" in w for w in obj.warnings)


@pytest.mark.shared_data
@pytest.mark.parametrize("method", ["fill", "grow"])
def test_background_seed_the_object_does_not_reach_warns(abdomen, method):
    """A background seed in range but where the object never runs (the other kidney) separates nothing: the
    result is the one without it, and says so instead of dropping the seed without a word."""
    vol, labels = abdomen
    seed = deepest(labels == 3, vol.spacing)
    other = deepest(labels == 2, vol.spacing)
    alone = segment(vol, [seed], [], options=SegmentOptions(method=method))
    rng = alone.objects[0].range
    assert rng[0] <= vol.data[other[2], other[1], other[0]] <= rng[1]  # in range: only reach can fail it
    res = segment(vol, [seed], [rng], background=[other], options=SegmentOptions(method=method))
    assert any(w.startswith(f"background seed {other[0]},{other[1]},{other[2]}: the object does not reach it")
               for w in res.objects[0].warnings), res.objects[0].warnings
    a = alone.segmentation.labels == alone.objects[0].id
    b = res.segmentation.labels == res.objects[0].id
    assert dice(a, b) > 0.99


@pytest.mark.shared_data
@pytest.mark.parametrize("dz", [-1, 1])
def test_seed_one_slice_off_the_deepest_point(abdomen, dz):
    """The right kidney on the 1 x 1 x 3 mm grid with its 3 mm range, seeded one slice above or below its
    deepest point. The seed slice's own cut sees only its plane, and on these slices the liver joins the
    kidney in-plane through a contact wider than the neck: the seed slice's object must stay inside what the
    3D sweep joined to the seed (it took the liver in: Dice 0.36-0.39, 3.7-4.2x the volume)."""
    vol, labels = abdomen
    fine, ref = fine_grid(vol, labels, 2)
    x, y, z = deepest(ref, fine.spacing)
    for mode in ("slice", "3d"):
        res = segment(fine, [(x, y, z + dz)], [(-21.0, 36.0)], options=SegmentOptions(mode=mode))
        got = res.segmentation.labels == res.objects[0].id
        assert dice(got, ref) >= 0.88 and got.sum() / ref.sum() <= 1.15, (mode, dice(got, ref), got.sum() / ref.sum())


@pytest.mark.shared_data
@pytest.mark.parametrize("organ", ["kidney_right", "kidney_left"])
def test_medulla_wrapped_in_cortex_warns(abdomen, organ):
    """Arterial (corticomedullary) phase: the kidney's deepest point is medulla (~110 HU) inside a cortex
    of ~220 HU. The range from that seed gives the medulla alone, about half the kidney, and before a check
    nothing said so. Now the segment action tries the range that holds the medulla and its brighter shell
    once: for the left kidney that gives the whole kidney, kept, and the range's why says so; the right
    one's also takes the liver (enhanced to the medulla's values in this copy): the medulla stays, with a
    warning that names the shell, the range that holds both and what trying it gave."""
    import re

    from ctui.engine.segment.phantoms import contrast_abdomen

    vol, labels = abdomen
    cvol = contrast_abdomen(vol, labels, phase="corticomedullary")
    ref = labels == ORGANS[organ]
    seed = deepest(ref, vol.spacing)
    res = segment(cvol, [seed], [], options=SegmentOptions())
    o = res.objects[0]
    got = res.segmentation.labels == o.id
    if organ == "kidney_left":
        assert dice(got, ref) >= 0.9, f"Dice {dice(got, ref):.3f}"
        assert not o.warnings and "wrapped in brighter tissue of the same organ" in o.auto_range["why"]
        assert res.to_dict()["objects"][0]["range_source"] == "auto" and o.range[1] >= 200.0
        return
    assert got.sum() / ref.sum() < 0.6  # the medulla alone
    wrapped = [w for w in o.warnings if "wrapped in brighter tissue" in w]
    assert len(wrapped) == 1 and "kept the first" in wrapped[0], o.warnings
    lo, hi = (float(v) for v in re.search(r"about (-?\d+):(-?\d+)", wrapped[0]).groups())
    assert lo <= 120.0 and hi >= 200.0  # the medulla's values and the cortex's
    again = segment(cvol, [seed], [(lo, hi)], options=SegmentOptions())
    assert any("ball that fits at the seed" in w for w in again.objects[0].warnings)
    assert not any("wrapped" in w for w in again.objects[0].warnings)


@pytest.mark.shared_data
def test_a_seed_near_the_edge_sweeps_as_far_as_the_organs_middle(abdomen):
    """Same organ, same answer (issue 34, point 4): the neck sweep tried radii up to 0.55x the depth within 10 mm
    of the seed, so a seed near the spleen's edge (14.7 mm there, the spleen 21 mm deep) never reached the 18 mm
    neck its last leak closes at, which a deeper seed's sweep cuts (Dice 0.82, 1.32x, with the defaults). The
    sweep now goes on to the organ's depth (the deepest point joined to the seed's through voxels deeper than
    0.8x its local depth), unless that width is wider than the object at the seed itself (a cut at full
    resolution would lose the seed's own part: a right kidney's seed 6.7 mm deep, a 19 mm neck, 0.08x)."""
    vol, labels = abdomen
    ref = labels == ORGANS["spleen"]
    for mode in ("slice", "3d"):
        deep = segment(vol, [(19, 36, 22)], [], options=SegmentOptions(mode=mode))  # a seed 17.7 mm deep
        res = segment(vol, [(13, 50, 18)], [], options=SegmentOptions(mode=mode))
        got = res.segmentation.labels == res.objects[0].id
        assert dice(got, ref) >= 0.86, (mode, dice(got, ref), res.objects[0].neck["reason"])
        assert dice(got, deep.segmentation.labels == deep.objects[0].id) >= 0.95
        assert 0.8 <= got.sum() / ref.sum() <= 1.1
        assert res.objects[0].neck["width_mm"] == deep.objects[0].neck["width_mm"] == 18.0


@pytest.mark.shared_data
def test_right_kidney_seeds_agree_with_the_organs_range(abdomen):
    """Two random interior seeds of the right kidney (benchmarks/organs.py --seeds 10), its 5-95th percentile
    range, slice mode: the same organ. The 3 x 3 median was decided from specks on the seed's slice alone:
    (89, 43, 1) saw 0.057 of its in-range pixels in specks, took the median and leaked into the liver (Dice 0.43,
    3.5x the kidney) while (85, 35, 4) saw none (0.88). The range, 3.9 noise sd wide there, is narrower than the
    automatic range's least (4 sd): its specks are the kidney's own noise, and it no longer takes the median."""
    vol, labels = abdomen
    ref = labels == ORGANS["kidney_right"]
    th = [tuple(float(v) for v in np.percentile(vol.data[ref], [5, 95]))]
    got = []
    for seed in ((89, 43, 1), (85, 35, 4)):
        res = segment(vol, [seed], th, options=SegmentOptions(mode="slice"))
        assert res.objects[0].denoise != "median 3x3"
        got.append(res.segmentation.labels == res.objects[0].id)
        assert dice(got[-1], ref) >= 0.85 and got[-1].sum() <= 1.2 * ref.sum(), seed
    assert dice(got[0], got[1]) >= 0.9
