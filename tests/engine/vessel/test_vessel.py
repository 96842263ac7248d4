"""``ctui vessel``: the path, the growth along it and its cut planes, on an analytic U-bend
(lengths and voxels known) and on the shared dissected aorta CT against its reference masks."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial import cKDTree

from ctui.engine.actions.vessel import save_vessel, vessel
from ctui.engine.core.volume import Volume

R_BEND, RADIUS, Z_TOP, Z0 = 12.0, 4.0, 30.0, 14  # U-bend: legs at y = 20 and 44 up to z = 30, cut at z = 14


def u_bend(*, blob: bool = True, noise: float = 15.0, seed: int = 0) -> tuple[Volume, np.ndarray, float]:
    """(volume 1 mm, the tube between the two cut planes z = Z0, length mm of its axis there).

    A tube of radius 4 mm (400 HU in 40 HU) up one leg, round a half circle of radius 12 mm and
    down the other, both legs running on below the cut planes to z = 3; with ``blob``, a bright
    ball of radius 9 mm (a ventricle) joined to the first leg below its cut plane."""
    shape = (50, 60, 60)
    t = np.linspace(0.0, np.pi, 400)
    arc = np.stack([Z_TOP + R_BEND * np.sin(t), 32.0 - R_BEND * np.cos(t), np.full_like(t, 30.0)], axis=1)
    zz = np.linspace(3.0, Z_TOP, 200)
    leg1 = np.stack([zz, np.full_like(zz, 20.0), np.full_like(zz, 30.0)], axis=1)
    leg2 = np.stack([zz[::-1], np.full_like(zz, 44.0), np.full_like(zz, 30.0)], axis=1)
    axis = np.concatenate([leg1, arc, leg2])
    grid = np.indices(shape).reshape(3, -1).T.astype(float)
    d, _ = cKDTree(axis).query(grid)
    tube = (d <= RADIUS).reshape(shape)
    rng = np.random.default_rng(seed)
    data = np.where(tube, 400.0, 40.0) + rng.normal(0.0, noise, shape)
    if blob:
        ball = np.linalg.norm(grid - [4.0, 20.0, 30.0], axis=1).reshape(shape) <= 9.0
        data[ball] = 400.0 + rng.normal(0.0, noise, int(ball.sum()))
    truth = tube & (np.indices(shape)[0] >= Z0)
    return Volume(data.astype(np.float32), spacing=(1.0, 1.0, 1.0), modality="CT"), truth, 2 * (Z_TOP - Z0) + np.pi * R_BEND


def dice(a: np.ndarray, b: np.ndarray) -> float:
    return 2.0 * float((a & b).sum()) / float(a.sum() + b.sum())


def test_u_bend_path_and_voxels_between_the_cut_planes():
    vol, truth, length = u_bend()
    res = vessel(vol, start=(30, 20, Z0), ends=[(30, 44, Z0)])
    assert res.path_length_mm[0] == pytest.approx(length, rel=0.03)
    assert dice(res.mask, truth) >= 0.9
    below = res.mask[: Z0 - 1].sum()  # behind the cut planes: the legs' ends and the ball
    assert below == 0
    ok = [r for r in res.sections if np.isfinite(r["eq_diameter_mm"])]
    eq = np.median([r["eq_diameter_mm"] for r in ok])
    assert eq == pytest.approx(2 * RADIUS, rel=0.1)
    assert np.median([r["inscribed_diameter_mm"] for r in ok]) == pytest.approx(2 * RADIUS, rel=0.15)
    assert res.warnings == []


def test_waypoint_across_a_gap_and_the_warning_without_it():
    vol, truth, _ = u_bend(blob=False, noise=0.0)
    vol.data[35:40] = 40.0  # the bend's top cut by 5 mm of tissue: the lumen is interrupted
    res = vessel(vol, start=(30, 20, Z0), ends=[(30, 44, Z0)])
    assert res.warnings and "waypoint" in res.warnings[0]


def test_outputs_are_an_ordinary_object(tmp_path):
    from ctui.engine.actions.measure import measure_object
    from ctui.engine.io.project import load_project
    from ctui.engine.actions.opened import open_input

    vol, _, _ = u_bend(noise=0.0)
    res = vessel(vol, start=(30, 20, Z0), ends=[(30, 44, Z0)])
    out = save_vessel(res, vol, project=str(tmp_path / "v.ctui"), csv=str(tmp_path / "v.csv"))
    assert len(out) == 2
    m = measure_object(open_input(str(tmp_path / "v.ctui")), object=1)
    assert m.volume_ml["voxels"] == pytest.approx(res.volume_ml, rel=1e-6)
    rec = load_project(str(tmp_path / "v.ctui")).objects[0]["vessel"]  # the TUI draws and reports it
    path = np.asarray(rec["path"])  # voxels (z, y, x) about 1 mm apart, on the tube's axis (x = 30)
    assert np.abs(path[:, 2] - 30).max() <= 1.0 and len(path) == pytest.approx(res.path_length_mm[0], abs=3)
    assert rec["report"]["eq_diameter_mm"][1] == pytest.approx(2 * RADIUS, rel=0.1)
    rows = (tmp_path / "v.csv").read_text().splitlines()
    assert rows[0].startswith("branch,s_mm,area_mm2") and len(rows) > 40
    json.dumps(res.to_dict())


def test_cli_json_and_mask(tmp_path):
    import SimpleITK as sitk

    from ctui.cli import main

    vol, truth, _ = u_bend(noise=0.0)
    src = tmp_path / "u.nii.gz"
    sitk.WriteImage(sitk.GetImageFromArray(vol.data), str(src))
    mask = tmp_path / "v.nii.gz"
    assert main(["vessel", str(src), "--start", f"30,20,{Z0}", "--end", f"30,44,{Z0}", "--mask", str(mask)]) == 0
    got = sitk.GetArrayFromImage(sitk.ReadImage(str(mask))) > 0
    assert dice(got, truth) >= 0.9
    assert main(["vessel", str(src), "--start", "30,20,99", "--end", "30,44,14"]) == 2  # outside the volume


@pytest.mark.slow
@pytest.mark.shared_data
def test_aorta_from_root_to_distal_end():
    """The shared dissected aorta: from just above the annulus, through the arch, to the last slice."""
    import SimpleITK as sitk
    from support import shared

    base = shared("totalseg_example")
    from ctui.engine.io.series import load

    vol = load(str(base / "ct_aorta_1p5mm.nii.gz"))
    read = lambda n: sitk.GetArrayFromImage(sitk.ReadImage(str(base / n))) > 0  # noqa: E731
    aorta, true = read("ct_aorta_1p5mm_aorta.nii.gz"), read("aorta_parts/aorta_true_lumen.nii.gz")
    res = vessel(vol, start=(56, 47, 83), vias=[(61, 77, 148)], ends=[(48, 77, 1)])
    k = np.clip(np.rint(vol.mm_to_index(res.path_mm)).astype(int), 0, np.asarray(vol.shape) - 1)
    assert aorta[k[:, 0], k[:, 1], k[:, 2]].mean() >= 0.95
    assert res.path_length_mm[0] == pytest.approx(372.0, rel=0.05)
    assert dice(res.mask, true) >= 0.89  # 0.908 measured (benchmarks/vessels.py)
    wall = vessel(vol, start=(56, 47, 83), vias=[(61, 77, 148)], ends=[(48, 77, 1)], lumen="wall")
    assert dice(wall.mask, aorta) >= 0.87  # 0.892 measured: the false lumen inside the wall
    pa = np.argwhere(read("aorta_parts/annulus_proper.nii.gz")) * 1.5  # the annulus' principal plane, mm (z, y, x)
    c = pa.mean(axis=0)
    n = np.linalg.svd(pa - c)[2][2]
    n = n if (np.argwhere(true[90:100]).mean(axis=0) * 1.5 + [135, 0, 0] - c) @ n > 0 else -n
    for m in (res.mask, wall.mask):
        q = np.argwhere(m) * 1.5
        assert not (((q - c) @ n < 0) & (np.linalg.norm(q - c, axis=1) < 40)).any()  # nothing in the ventricle


def test_wall_takes_the_thrombus_inside_the_wall_not_the_fat():
    """A tube whose outer half is a grey thrombus (60 HU) in fat (-100 HU): --lumen wall takes the
    whole tube, contrast only its bright lumen."""
    from scipy import ndimage as ndi

    vol, _, _ = u_bend(blob=False, noise=0.0)
    vol.data[:] = np.where(vol.data > 200, 60.0, -100.0)  # the tube's whole section: thrombus, in fat

    lumen = ndi.binary_erosion(vol.data > 0, iterations=2)  # the bright lumen: the inner 2 mm less
    vol.data[lumen] = 400.0
    tube = vol.data > 0
    truth_w = tube & (np.indices(tube.shape)[0] >= Z0)
    wall = vessel(vol, start=(30, 20, Z0), ends=[(30, 44, Z0)], lumen="wall")
    contrast = vessel(vol, start=(30, 20, Z0), ends=[(30, 44, Z0)])
    assert dice(wall.mask, truth_w) >= 0.85
    assert wall.voxels > 1.5 * contrast.voxels
    assert not (wall.mask & ~ndi.binary_dilation(tube, iterations=2)).any()  # no fat taken


def test_batch_row_with_start_via_end(tmp_path):
    """A ``ctui batch`` manifest row with start, via and end columns runs the vessel action."""
    import SimpleITK as sitk

    from ctui.engine.actions.batch import read_manifest, run_job

    vol, truth, length = u_bend(noise=0.0)
    src = tmp_path / "u.nii.gz"
    sitk.WriteImage(sitk.GetImageFromArray(vol.data), str(src))
    (tmp_path / "m.csv").write_text(f'series,start,via,end,sections\nu.nii.gz,"30,20,{Z0}","30,32,42","30,44,{Z0}",auto\n')
    (job,) = read_manifest(tmp_path / "m.csv", default_outdir=str(tmp_path / "out"))
    assert job.vessel == ((30, 20, Z0), [(30, 44, Z0)], [(30, 32, 42)]) and not job.error
    row = run_job(job)
    assert row["status"] == "ok", row["error"]
    assert row["voxels"] == pytest.approx(truth.sum(), rel=0.1)
    assert row["path_length_mm"] == pytest.approx(length, rel=0.1)  # measure's own centreline of the vessel


def test_bifurcation_two_ends_mr_values():
    """Two --end: a tree from one start (an aortic bifurcation in MR-like values, no HU): the first
    branch runs from the start to the first end, the second from where it leaves the first's vessel."""
    shape = (80, 60, 60)

    def seg(a, b):
        t = np.linspace(0.0, 1.0, 200)[:, None]
        return np.asarray(a, float) * (1 - t) + np.asarray(b, float) * t

    grid = np.indices(shape).reshape(3, -1).T.astype(float)
    d_trunk, _ = cKDTree(seg((75, 30, 30), (40, 30, 30))).query(grid)
    d_legs, _ = cKDTree(np.vstack([seg((40, 30, 30), (5, 30, 12)), seg((40, 30, 30), (5, 30, 48))])).query(grid)
    tube = ((d_trunk <= 6) | (d_legs <= 4)).reshape(shape)
    data = np.where(tube, 900.0, 200.0) + np.random.default_rng(0).normal(0.0, 20.0, shape)
    vol = Volume(data.astype(np.float32), spacing=(1.0, 1.0, 1.0), modality="MR")
    res = vessel(vol, start=(30, 30, 70), ends=[(14, 30, 9), (46, 30, 9)])
    z = np.indices(shape)[0]
    truth = tube & (z >= 9) & (z <= 70)
    assert dice(res.mask, truth) >= 0.93
    assert res.path_length_mm[0] == pytest.approx(30 + np.hypot(31, 18 * 31 / 35), rel=0.03)
    assert {r["branch"] for r in res.sections} == {0, 1}
    assert 20 < res.path_length_mm[1] < 36  # the second leg from the bifurcation (36 mm from its centre)
