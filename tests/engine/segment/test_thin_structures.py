"""A thin structure whose leak's bridges are thinner than the sweep's voxels (issue 37): the MR brain's lateral
ventricles, 1 mm voxels, from the TUI's click and the dark peak picked on its histogram (11:39). The automatic
neck went at the sweep's first opening (4 mm) and cut the ventricles' own horns (Dice 0.586); the sweep's region
alone bounds the leak, so the default gives the ventricles without turning the neck off. Skipped with a reason
when ../shared/data or SimpleITK (the GIPL reader) is absent."""

from __future__ import annotations

import numpy as np
import pytest

from ctui.engine.actions.segment import SegmentOptions, segment
from ctui.engine.core.volume import Volume
from support import shared

SEED = (13, 72, 32)  # benchmarks/tui_tasks_structures.py's click: the section nearest the first slice shown
RANGE = (10.7459, 38.9153)  # the histogram's dark peak up to its valley (two clicks)


@pytest.fixture(scope="module")
def brain():
    sitk = pytest.importorskip("SimpleITK", reason="SimpleITK reads the MR's GIPL")
    d = shared("itksnap_brain_mr")
    img = sitk.ReadImage(str(d / "MRIcrop-orig.gipl.gz"))
    vol = Volume(data=sitk.GetArrayFromImage(img).astype(np.float32),
                 spacing=tuple(float(s) for s in img.GetSpacing()[::-1]), modality="MR")
    return vol, sitk.GetArrayFromImage(sitk.ReadImage(str(d / "MRIcrop-seg.gipl.gz"))) == 1


def dice(a: np.ndarray, b: np.ndarray) -> float:
    return 2.0 * np.count_nonzero(a & b) / (np.count_nonzero(a) + np.count_nonzero(b))


@pytest.mark.shared_data
@pytest.mark.parametrize("method", ["fill", "levelset"])
def test_the_automatic_neck_keeps_the_ventricles_horns(brain, method):
    vol, ref = brain
    res = segment(vol, [SEED], [RANGE], options=SegmentOptions(mode="3d", method=method))
    o = res.objects[0]
    got = res.segmentation.labels == o.id
    assert dice(got, ref) >= 0.9, (o.neck, o.warnings)  # 0.586 (fill) / 0.633 (levelset) cut at 4 mm
    assert o.neck["mode"] == "auto" and o.neck["width_mm"] == 0 and o.neck["reason"].startswith("bounded")
    assert not any("leak guard is off" in w for w in o.warnings)
    # 31x the ball at the seed, but closed by brighter tissue (white matter): not said to have leaked
    assert not any("the ball that fits" in w for w in o.warnings), o.warnings


@pytest.mark.shared_data
def test_a_neck_on_a_coarse_series_still_cuts(brain):
    """The rule needs every axis finer than the sweep's grid: the same MR resampled to 2 mm slices keeps the cut."""
    vol, _ref = brain
    thick = Volume(data=vol.data[::2].copy(), spacing=(2.0, *vol.spacing[1:]), modality="MR")
    o = segment(thick, [(SEED[0], SEED[1], SEED[2] // 2)], [RANGE], options=SegmentOptions(mode="3d")).objects[0]
    assert o.neck["width_mm"] > 0 and not o.neck["reason"].startswith("bounded"), o.neck["reason"]


@pytest.mark.shared_data
@pytest.mark.parametrize("method", ["fill", "levelset"])
def test_correct_ventricles_carry_no_warning(brain, method):
    """Each warning is checked against the data it describes. The ventricles (Dice >= 0.9) carried two false ones:
    "the object's values lie below its seed's" (the seed's 10 mm ball is mostly white matter, median 53, outside
    the range 11:39: the seed's own structure is the object's values in that ball, 20) and "wrapped in brighter
    tissue" (it is: white matter; the range holding both, tried, runs into the brain, so the shell is not the rest
    of the organ). A wrong result from the same seed (grow, 3.8x the ventricles) is still warned."""
    vol, ref = brain
    o = segment(vol, [SEED], [RANGE], options=SegmentOptions(mode="3d", method=method)).objects[0]
    assert o.warnings == [], o.warnings
    res = segment(vol, [SEED], [RANGE], options=SegmentOptions(mode="3d", method="grow"))
    got = res.segmentation.labels == res.objects[0].id
    assert got.sum() / ref.sum() > 2.0 and res.objects[0].warnings  # grow's leak into the sulci: still said
