"""Leaks found where they enter (issue 34, item 3): a piece joined to the object through a narrow neck is flagged
at the neck's slice and place, with a background voxel that removes it; correct organs carry no flag.
Figures: python3 benchmarks/organs_sets.py --set abdomen,spleen --no-peers --clicks (the "leak flags" lines)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from ctui.engine.actions.opened import open_input
from ctui.engine.actions.segment import SegmentOptions, segment
from ctui.engine.core.volume import Volume
from ctui.engine.io.series import load
from ctui.engine.segment import review
from ctui.engine.segment.leaks import find_leaks
from support import shared

TUBE_Z = (33, 48)  # the tube's own slices (between the blobs' faces)


def dumbbell() -> tuple[Volume, np.ndarray, np.ndarray]:
    """Two balls (radius 12 voxels, 1 mm, 100 HU on 0 HU) at z 20 and 60, joined along z by a tube 2 voxels in
    radius: (volume, first ball, second ball)."""
    z, y, x = np.mgrid[:80, :64, :64]
    a = (z - 20) ** 2 + (y - 32) ** 2 + (x - 32) ** 2 <= 144
    b = (z - 60) ** 2 + (y - 32) ** 2 + (x - 32) ** 2 <= 144
    tube = ((y - 32) ** 2 + (x - 32) ** 2 <= 4) & (z >= 20) & (z <= 60)
    data = np.where(a | b | tube, 100.0, 0.0).astype(np.float32)
    data += np.random.default_rng(0).normal(0, 3, data.shape).astype(np.float32)
    return Volume(data=data, spacing=(1.0, 1.0, 1.0), modality="CT"), a, b


def test_find_leaks_names_the_tube_and_a_voxel_in_the_second_blob():
    vol, a, b = dumbbell()
    mask = vol.data > 50
    found = find_leaks(mask, vol.spacing, (20, 32, 32))
    assert len(found) == 1, found
    lk = found[0]
    assert 30 <= lk.slice <= TUBE_Z[1] and lk.at[:2] == (32, 32)
    assert 4 <= lk.volume_ml <= 10  # the second ball (7.2 mL) and part of the tube
    assert lk.neck_mm <= 6
    x, y, z = lk.click
    assert b[z, y, x] and not a[z, y, x]
    assert find_leaks(a, vol.spacing, (20, 32, 32)) == []  # one ball: nothing


def test_segment_flags_the_leak_and_its_click_removes_the_second_blob():
    vol, a, b = dumbbell()
    opts = SegmentOptions(neck_mm=0)  # the leak guard off: the fill runs through the tube
    res = segment(vol, [(32, 32, 20)], [(50, 200)], options=opts)
    o = res.objects[0]
    got = res.segmentation.labels == o.id
    assert got[b].mean() > 0.9  # it leaked
    leaks = o.to_dict()["neck"]["leaks"]
    assert len(leaks) == 1 and TUBE_Z[0] - 3 <= leaks[0]["slice"] <= TUBE_Z[1]
    assert any("leak of" in w and "background seed at" in w for w in o.warnings)
    assert f"leak at slice {leaks[0]['slice']}" in o.message()
    # the review strip's marks name the entry slice
    stack = review.of_labels(res.segmentation.labels, o.id, 20)
    found = review.marks(stack, leaks=res.segmentation.objects[o.id].settings["leaks"])
    assert any(m.z == leaks[0]["slice"] and "leak" in m.kind for m in found)
    # one background click at the suggested voxel removes the second blob
    again = segment(vol, [(32, 32, 20)], [(50, 200)], background=[tuple(leaks[0]["click"])], options=opts)
    got2 = again.segmentation.labels == again.objects[0].id
    assert got2[b].mean() < 0.1 and got2[a].mean() > 0.95


@pytest.fixture(scope="module")
def abdomen():
    d = shared("totalseg_example")
    return load(d / "ct_abdomen_3mm.nii.gz"), open_input(d / "ct_abdomen_3mm_labels.nii.gz").labels


@pytest.mark.shared_data
@pytest.mark.parametrize("label", [1, 2, 3, 5])  # spleen, kidneys, liver
def test_correct_organs_carry_no_leak_flag(abdomen, label):
    """The shared abdomen's kidneys, spleen and liver from their deepest point (Dice 0.89-0.94): no flag."""
    vol, labels = abdomen
    ref = labels == label
    dt = ndimage.distance_transform_edt(ref, sampling=vol.spacing)
    z, y, x = np.unravel_index(int(np.argmax(dt)), ref.shape)
    o = segment(vol, [(int(x), int(y), int(z))], []).objects[0]
    assert o.neck.get("leaks") == [], o.neck.get("leaks")


async def test_the_review_strip_marks_where_the_leak_enters(monkeypatch, tmp_path):
    """An accepted leaky object: the strip draws ``L`` at the entry slice, ``}`` goes there and the message line
    names the background seed."""
    from ctui.screens import graphics
    from ctui.screens.app import CtuiApp
    from ctui.screens.session import Session
    from ctui.screens.strip import ReviewStrip
    from ctui.screens.testing import wait_workspace

    monkeypatch.setenv("CTUI_AUTOSAVE_DIR", str(tmp_path / "autosave"))
    monkeypatch.chdir(tmp_path)
    vol, _a, _b = dumbbell()
    s = Session(vol, source_path="synthetic", z=20)
    with graphics.using_graphics("halfblock"):
        app = CtuiApp(session=s, autosave_s=1e9)
        async with app.run_test(size=(120, 40)) as pilot:
            await wait_workspace(pilot, app)
            ws = app.workspace
            res = segment(vol, [(32, 32, 20)], [(50, 200)], options=SegmentOptions(neck_mm=0), segmentation=s.seg)
            entry = res.objects[0].neck["leaks"][0]["slice"]
            s.current = res.objects[0].id
            s.seg.objects[s.current].seeds.append((32, 32, 20))
            ws.volumes.version += 1
            ws.refresh_view()
            ws.review.update_strip()
            strip = ws.query_one("#strip", ReviewStrip)
            assert "on" in strip.classes and entry in strip.leaked
            for _ in range(4):
                if s.z == entry:
                    break
                await pilot.press("right_curly_bracket")
            assert s.z == entry
            status = str(ws.query_one("#status").render())
            assert "leak enters here" in status and "background seed at" in status, status
            assert not app.internal_errors


@pytest.mark.shared_data
def test_a_liver_leak_is_flagged_and_its_click_takes_it_back(abdomen):
    """The liver with a range 20 HU wider than its 5-95th percentiles leaks (1.34x, Dice 0.84): the flag's
    voxel lies outside the reference, and a background seed there shrinks the result towards it (Dice 0.86)."""
    vol, labels = abdomen
    ref = labels == 5
    dt = ndimage.distance_transform_edt(np.pad(ref, 1), sampling=vol.spacing)[1:-1, 1:-1, 1:-1]
    z, y, x = (int(v) for v in np.unravel_index(int(np.argmax(dt)), ref.shape))
    lo, hi = np.percentile(vol.data[ref], [5, 95])
    th = [(lo - 20, hi + 20)]
    res = segment(vol, [(x, y, z)], th)
    got = res.segmentation.labels == res.objects[0].id
    leaks = res.objects[0].neck["leaks"]
    assert got.sum() > 1.2 * ref.sum() and leaks
    cx, cy, cz = leaks[0]["click"]
    assert not ref[cz, cy, cx] and got[cz, cy, cx]
    again = segment(vol, [(x, y, z)], th, background=[(cx, cy, cz)])
    got2 = again.segmentation.labels == again.objects[0].id
    d0 = 2 * (got & ref).sum() / (got.sum() + ref.sum())
    d1 = 2 * (got2 & ref).sum() / (got2.sum() + ref.sum())
    assert got2.sum() < got.sum() - leaks[0]["volume_ml"] / 2 / (np.prod(vol.spacing) / 1000) and d1 > d0 + 0.01
