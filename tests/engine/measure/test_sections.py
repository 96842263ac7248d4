"""Cross-sections along a path and volume between planes, against analytic phantoms.

Phantoms are built from analytic shapes at 0.5 mm voxels, either as partial-volume
free binary masks (centre of the voxel inside) or as partial-volume fractions (each
voxel's covered fraction, supersampled 4x4x4). A binary mask of a 2-3 voxel radius
tube carries its own discretisation error (its voxel count differs from the analytic
volume by a few %, see `_mask_bias`); per-section accuracy on binary masks is bounded
by that, so binary tests check the mean along the path against the analytic area
corrected by at most the mask's own bias, and the partial-volume tests check every
section.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ctui.engine.measure.between import volume_between
from ctui.engine.measure.centreline import centreline
from ctui.engine.measure.fields import object_field
from ctui.engine.measure.paths import path_points, rotation_minimising_frames
from ctui.engine.measure.planes import feret_diameters, shoelace_area
from ctui.engine.measure.report import (
    plot_sections,
    sections_plot_image,
    write_sections_csv,
    write_sections_json,
)
from ctui.engine.measure.sections import find_steps, sections_along_path

SP = (0.5, 0.5, 0.5)


def _grid(shape, sp=SP, sub=None):
    """Voxel-centre coordinates (x, y, z) mm, optionally offset by sub-voxel ``sub`` (z,y,x) fractions."""
    o = np.zeros(3) if sub is None else np.asarray(sub)
    zz, yy, xx = np.meshgrid(*[(np.arange(n) + o[i]) * sp[i] for i, n in enumerate(shape)], indexing="ij")
    return xx, yy, zz


def _soft(inside, shape, sp=SP, ss=(4, 4, 4)):
    """Partial-volume fraction of each voxel: mean of sub-samples of inside(x, y, z),
    ``ss`` (z, y, x) per voxel. The sub-sampling is itself a (finer) pixel count: 4 per
    axis leaves up to 2.5% error on a 2-voxel disk seen along a grid axis, so straight
    grid-aligned tubes use 16 in-plane."""
    if np.isscalar(ss):
        ss = (ss, ss, ss)
    acc = np.zeros(shape, np.float32)
    for dz in range(ss[0]):
        for dy in range(ss[1]):
            for dx in range(ss[2]):
                o = (np.array([dz, dy, dx]) + 0.5) / np.array(ss) - 0.5
                acc += inside(*_grid(shape, sp, o))
    return acc / np.prod(ss)


def _cylinder(c, a, r, half_len):
    c = np.asarray(c, float)
    a = np.asarray(a, float) / np.linalg.norm(a)

    def inside(x, y, z):
        p = np.stack([x, y, z], -1) - c
        t = p @ a
        d = np.linalg.norm(p - t[..., None] * a, axis=-1)
        return (d <= r) & (np.abs(t) <= half_len)

    return inside, c, a


def _axis_path(c, a, half):
    return np.stack([c + a * t for t in np.arange(-half, half + 1e-9, 0.25)])


def _areas(rows):
    s = np.array([r["s_mm"] for r in rows])
    a = np.array([r["area_mm2"] for r in rows])
    return s, a


# ------------------------------------------------------------------ 2D geometry
def test_shoelace_and_feret_on_known_shapes():
    sq = np.array([[0, 0], [4, 0], [4, 2], [0, 2]], float)
    assert shoelace_area(sq) == pytest.approx(8.0)
    assert shoelace_area(sq[::-1]) == pytest.approx(-8.0)
    dmin, dmax = feret_diameters(sq)
    assert dmin == pytest.approx(2.0) and dmax == pytest.approx(math.hypot(4, 2))
    t = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    ell = np.stack([5 * np.cos(t + 0.3), 2 * np.sin(t + 0.3)], 1) @ np.array([[0.8, 0.6], [-0.6, 0.8]])
    for exact in (False, True):
        dmin, dmax = feret_diameters(ell, exact=exact)
        assert dmin == pytest.approx(4.0, rel=1e-3) and dmax == pytest.approx(10.0, rel=1e-3)
        dmin, dmax = feret_diameters(sq, exact=exact)
        assert dmin == pytest.approx(2.0, rel=1e-4) and dmax == pytest.approx(math.hypot(4, 2), rel=1e-4)
    tri = np.array([[0, 0], [6, 0], [1, 4]], float)  # min width = smallest height = 2 * area / longest side
    dmin, dmax = feret_diameters(tri)
    assert dmin == pytest.approx(24 / math.hypot(5, 4), rel=1e-4)
    assert dmax == pytest.approx(math.hypot(5, 4), rel=1e-4)


def test_rotation_minimising_frames_do_not_flip_on_a_helix():
    t = np.linspace(0, 6 * np.pi, 600)
    pts = np.stack([10 * np.cos(t), 10 * np.sin(t), 3 * t], 1)
    p, tan = path_points(pts, np.linspace(0, 150, 400))
    u, v = rotation_minimising_frames(p, tan)
    for a, b in ((u, v), (u, tan), (v, tan)):
        assert np.abs((a * b).sum(1)).max() < 1e-9
    assert np.allclose(np.linalg.norm(u, axis=1), 1) and np.allclose(np.linalg.norm(v, axis=1), 1)
    # consecutive frames turn little (no flip): u changes by less than the tangent does + a bit
    du = np.linalg.norm(np.diff(u, axis=0), axis=1)
    assert du.max() < 0.1


# ------------------------------------------------------------------ section accuracy
@pytest.mark.parametrize("radius,tol", [(1.0, 0.02), (1.5, 0.01), (2.5, 0.01)])
@pytest.mark.parametrize("axis", [(0.0, 0.0, 1.0), (0.6, 1.0, 2.0)], ids=["straight", "oblique"])
def test_partial_volume_cylinder_every_section(axis, radius, tol):
    """Partial-volume cylinders: every section away from the ends within 2% (r = 1 mm)
    or 1% (r >= 1.5 mm) of pi r^2 along the analytic axis."""
    shape = (56, 28, 28) if axis[0] == 0 else (48, 40, 32)
    ext = np.array(shape[::-1]) * 0.5
    inside, c, a = _cylinder(ext / 2 + np.array([0.13, 0.21, 0.07]), axis, radius, 10.0)
    m = _soft(inside, shape, ss=(1, 16, 16) if axis[0] == 0 else (4, 4, 4))
    rows = sections_along_path(m, _axis_path(c, a, 7.0), spacing=SP, step_mm=0.5)
    s, area = _areas(rows)
    err = area / (math.pi * radius**2) - 1
    assert np.all(np.isfinite(err))
    assert np.abs(err).max() < tol, (np.abs(err).max(), err.mean())
    d = np.array([[r["min_diameter_mm"], r["max_diameter_mm"], r["eq_diameter_mm"]] for r in rows])
    assert np.allclose(d, 2 * radius, rtol=max(2 * tol, 0.03))


def _mask_bias(mask, analytic_volume_mm3):
    return mask.sum() * np.prod(SP) / analytic_volume_mm3 - 1


@pytest.mark.parametrize("radius,tol", [(1.0, 0.02), (1.5, 0.01), (2.5, 0.01)])
@pytest.mark.parametrize("axis", [(0.17, 0.1, 1.0), (0.6, 1.0, 2.0)], ids=["straight-tilted", "oblique"])
def test_binary_cylinder_centreline_sections(axis, radius, tol):
    """Binary cylinders, automatic centreline: mean section within 2% / 1% of pi r^2
    (allowing the mask's own voxel-count bias); each section's scatter is reported."""
    shape = (60, 32, 32) if axis[0] < 0.5 else (48, 40, 32)
    ext = np.array(shape[::-1]) * 0.5
    inside, c, a = _cylinder(ext / 2 + np.array([0.13, 0.21, 0.07]), axis, radius, 11.0)
    mask = inside(*_grid(shape))
    bias = _mask_bias(mask, math.pi * radius**2 * 22.0)
    path = centreline(mask, spacing=SP)
    # the centreline runs on the axis
    q = path - c
    off = np.linalg.norm(q - (q @ a)[:, None] * a, axis=1)
    inner = np.abs(q @ a) < 8
    assert off[inner].max() < 0.25
    rows = sections_along_path(mask, path, spacing=SP, step_mm=0.5)
    s, area = _areas(rows)
    keep = (s > 3) & (s < s[-1] - 3)
    err = area[keep] / (math.pi * radius**2) - 1
    assert np.all(np.isfinite(err))
    assert abs(err.mean() - bias) < tol, (err.mean(), bias)
    assert abs(err.mean()) < tol + abs(bias)
    assert np.percentile(np.abs(err), 95) < 0.15 / radius  # binary masks: scatter ~ voxel aliasing


def _torus(rt, r0, c):
    def inside(x, y, z):
        rho = np.hypot(x - c[0], y - c[1])
        ang = np.arctan2(y - c[1], x - c[0])
        return ((rho - rt) ** 2 + (z - c[2]) ** 2 <= r0 * r0) & (ang > 0.2) & (ang < 2.8)

    return inside


@pytest.mark.parametrize("r0,tol", [(1.0, 0.02), (1.5, 0.01)])
def test_torus_segment_partial_volume(r0, tol):
    c = (20.1, 20.2, 6.05)
    m = _soft(_torus(15.0, r0, c), (24, 80, 80), ss=(8, 4, 4))  # z lies in every section plane: finer
    path = centreline(m > 0.5, spacing=SP)
    rows = sections_along_path(m, path, spacing=SP, step_mm=0.5)
    s, area = _areas(rows)
    keep = (s > 4) & (s < s[-1] - 4)
    err = area[keep] / (math.pi * r0**2) - 1
    assert np.abs(err).max() < tol, np.abs(err).max()
    assert abs(err.mean()) < 0.01
    # path length of the arc (ends continued straight to the end faces)
    assert s[-1] == pytest.approx(15.0 * 2.6, abs=1.5)


def test_stepped_tube_steps_found_at_the_right_places():
    """A rod whose radius steps 3 -> 2 -> 1.5 mm at t = 20 and 40 mm along a tilted axis."""
    shape = (124, 40, 40)
    c = np.array([10.1, 10.2, 0.0])
    a = np.array([0.15, 0.1, 1.0])
    a /= np.linalg.norm(a)
    x, y, z = _grid(shape)
    p = np.stack([x, y, z], -1) - c
    t = p @ a
    d = np.linalg.norm(p - t[..., None] * a, axis=-1)
    rad = np.where(t < 20, 3.0, np.where(t < 40, 2.0, 1.5))
    mask = (d <= rad) & (t > 2) & (t < 58)
    path = centreline(mask, spacing=SP)
    rows = sections_along_path(mask, path, spacing=SP, step_mm=0.5)
    s, area = _areas(rows)
    steps = find_steps(s, area)
    t_path = (path_points(path, [r["s_mm"] for r in steps])[0] - c) @ a if steps else []
    assert len(steps) == 2, steps
    assert sorted(t_path) == pytest.approx([20.0, 40.0], abs=1.0)
    before_after = sorted((st["before"], st["after"]) for st in steps)
    expect = sorted([(math.pi * 4, math.pi * 9), (math.pi * 2.25, math.pi * 4)])
    for got, want in zip(before_after, expect):
        assert got == pytest.approx(want, rel=0.08)


# ------------------------------------------------------------------ volume between
def test_volume_between_excludes_parallel_neighbour():
    shape = (44, 56, 120)
    x, y, z = _grid(shape)
    r = 3.0
    a = np.array([1.0, 0.25, 0.15])
    a /= np.linalg.norm(a)
    c = np.array([30.0, 12.3, 10.2])
    ins1, _, _ = _cylinder(c, a, r, 24.0)
    ins2, _, _ = _cylinder(c + np.array([0.0, 8.0, 0.0]), a, 2.5, 24.0)  # 2.5 mm gap, crosses both planes
    m1 = ins1(x, y, z)
    mask = m1 | ins2(x, y, z)
    path = _axis_path(c, a, 20.0)
    res = volume_between(mask, path, 10.0, 30.0, spacing=SP, return_mesh=True)
    want = math.pi * r * r * 20.0
    assert res["volume_mm3"] == pytest.approx(want, rel=0.02)
    assert res["volume_pv_mm3"] == pytest.approx(want, rel=0.02)
    assert res["closed"]
    assert res["area1_mm2"] == pytest.approx(math.pi * r * r, rel=0.03)
    assert res["area2_mm2"] == pytest.approx(math.pi * r * r, rel=0.03)
    # the region's surface stays within the first cylinder (the neighbour is excluded)
    v = res["mesh"].vertices - c
    dist = np.linalg.norm(v - (v @ a)[:, None] * a, axis=1)
    assert dist.max() < r + 0.5
    assert (v @ a).min() > -10.3 and (v @ a).max() < 10.3
    # and without the neighbour the volume is the same
    alone = volume_between(m1, path, 10.0, 30.0, spacing=SP)
    assert alone["volume_mm3"] == pytest.approx(res["volume_mm3"], rel=1e-3)


def test_volume_between_bad_positions():
    from ctui.engine.core.errors import CtuiError

    mask = np.zeros((20, 20, 40), bool)
    mask[5:15, 5:15, 5:35] = True
    path = np.array([[x, 5.0, 5.0] for x in np.arange(3.0, 17.0, 0.5)])
    with pytest.raises(CtuiError):
        volume_between(mask, path, 2.0, 200.0, spacing=SP)
    with pytest.raises(CtuiError):
        volume_between(mask, path, 3.0, 3.0, spacing=SP)


# ------------------------------------------------------------------ outputs
def test_outputs_csv_json_plot(tmp_path):
    inside, c, a = _cylinder((8.1, 8.2, 10.0), (0, 0, 1), 2.0, 8.0)
    mask = inside(*_grid((40, 32, 32)))
    path = _axis_path(c, a, 6.0)
    rows = sections_along_path(mask, path, spacing=SP, step_mm=1.0)
    write_sections_csv(tmp_path / "s.csv", rows)
    lines = (tmp_path / "s.csv").read_text().splitlines()
    assert lines[0] == "s_mm,area_mm2,eq_diameter_mm,min_diameter_mm,max_diameter_mm"
    assert len(lines) == len(rows) + 1
    write_sections_json(tmp_path / "s.json", rows, path_length_mm=12.0)
    import json

    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["sections"][3]["area_mm2"] == pytest.approx(rows[3]["area_mm2"], abs=1e-3)
    plot_sections(tmp_path / "s.png", rows, references=[math.pi * 4])
    from PIL import Image

    im = np.asarray(Image.open(tmp_path / "s.png").convert("RGB")).astype(int)
    assert im.shape[0] > 100 and im.shape[1] > 200
    # the reference line (red) and the curve (blue) are drawn
    red = (im[..., 0] > 180) & (im[..., 1] < 90) & (im[..., 2] < 90)
    blue = (im[..., 2] > 150) & (im[..., 0] < 80)
    assert red.sum() > 50 and blue.sum() > 50
    arr = sections_plot_image(rows, references=[math.pi * 4], size_px=(640, 320), quantity="eq_diameter_mm")
    assert arr.shape == (320, 640, 3) and arr.dtype == np.uint8
    assert ((arr[..., 2] > 150) & (arr[..., 0] < 80)).sum() > 50


def test_points_outside_object_give_nan():
    mask = np.zeros((30, 30, 30), bool)
    mask[10:20, 10:20, 5:25] = True
    path = np.array([[x, 7.25, 7.25] for x in np.arange(0.0, 14.0, 0.5)])  # x from outside into the box
    rows = sections_along_path(mask, path, spacing=SP, step_mm=1.0)
    area = np.array([r["area_mm2"] for r in rows])
    assert np.isnan(area[0]) and np.isfinite(area[-3])
    assert area[-3] == pytest.approx(25.0, rel=0.02)  # 5 x 5 mm box


def test_field_reused_gives_same_result():
    inside, c, a = _cylinder((8.1, 8.2, 10.0), (0.2, 0, 1), 2.0, 8.0)
    mask = inside(*_grid((40, 32, 32)))
    f = object_field(mask, spacing=SP)
    path = _axis_path(c, a, 5.0)
    r1 = sections_along_path(mask, path, spacing=SP, step_mm=1.0)
    r2 = sections_along_path(None, path, field=f, step_mm=1.0)
    assert [r["area_mm2"] for r in r1] == pytest.approx([r["area_mm2"] for r in r2])


# ------------------------------------------------------------------ the bundled phantom
def test_bundled_phantom_tube_sections_match_truth():
    """The sample series' stepped rod: sections along the truth axis match the truth
    file's cross-sections (partial-volume fraction from the CT values: within 1%;
    the thresholded binary mask: within its own pixel-count bias + 1%), the steps are
    found where the truth puts them, and the automatic centreline runs along the axis."""
    from scipy import ndimage as ndi

    phantom = pytest.importorskip("ctui.engine.io.phantom")
    loaders = pytest.importorskip("ctui.engine.io.series")
    if not (phantom.SAMPLE_DIR / phantom.TRUTH_NAME).exists():
        pytest.skip(f"bundled sample {phantom.SAMPLE_DIR} missing")
    vol = loaders.load(phantom.SAMPLE_DIR)
    truth = phantom.load_truth()
    tube = next(o for o in truth["objects"] if o["name"] == "tube")
    lo, hi = tube["hu_range"]
    lab, _ = ndi.label((vol.data >= lo) & (vol.data <= hi))
    mask = lab == lab[tuple(tube["seed_zyx"])]
    bg = phantom.BODY_HU  # the rod sits in soft tissue
    frac = np.clip((vol.data.astype(np.float32) - bg) / (tube["hu"] - bg), 0, 1) * ndi.binary_dilation(mask, iterations=2)
    ax = tube["axis"]
    p0, d = np.array(ax["point_xyz_mm"]), np.array(ax["direction_xyz"])
    path = np.stack([p0 + d * s for s in np.arange(0.0, ax["length_mm"] + 1e-9, 0.5)])
    geo = dict(spacing=vol.spacing, origin=vol.origin, direction=vol.direction)
    drift_z = [vol.origin[2] + vol.spacing[0] * k for k in truth["drift"]["slices"]]
    for m, tol in ((frac, 0.01), (mask, None)):
        rows = sections_along_path(m, path, step_mm=1.0, **geo)
        s, area = _areas(rows)
        z = p0[2] + s * d[2]
        away_drift = (z < min(drift_z) - 3) | (z > max(drift_z) + 3)
        for st in tube["steps"]:
            k = (s > st["start_mm"] + 5) & (s < st["start_mm"] + st["length_mm"] - 5) & away_drift
            err = area[k] / st["cross_section_mm2"] - 1
            if tol is None:  # binary: the mask's own pixel count in those slices
                zi = np.rint((z[k] - vol.origin[2]) / vol.spacing[0]).astype(int)
                px = np.array([mask[i].sum() for i in zi]) * vol.spacing[1] * vol.spacing[2]
                assert np.abs(area[k] / px - 1).max() < 0.02  # z-smoothing mixes noisy neighbour slices
            else:
                assert np.abs(err).max() < tol, (st, np.abs(err).max())
        steps = find_steps(s, area)
        inner = [x["s_mm"] for x in steps if 5 < x["s_mm"] < ax["length_mm"] - 5]
        assert inner == pytest.approx([st["start_mm"] for st in tube["steps"][1:]], abs=1.0)
    cl = centreline(mask, **geo)
    off = np.hypot(cl[:, 0] - p0[0], cl[:, 1] - p0[1])
    zc = cl[:, 2]
    keep = (zc > p0[2] + 10) & (zc < p0[2] + ax["length_mm"] - 10) & ((zc < min(drift_z) - 8) | (zc > max(drift_z) + 8))
    assert np.median(off[keep]) < 0.5 and off[keep].max() < 1.5


def test_slab_average_reduces_binary_scatter_and_keeps_steps():
    """average_mm: sections averaged over 2 mm of path scatter less on a binary oblique
    tube, keep the mean, and a radius step stays within 1 mm."""
    shape = (48, 40, 32)
    ext = np.array(shape[::-1]) * 0.5
    inside, c, a = _cylinder(ext / 2 + np.array([0.31, 0.12, 0.27]), (0.6, 1.0, 2.0), 1.5, 10.0)
    mask = inside(*_grid(shape))
    path = _axis_path(c, a, 7.0)
    one = np.array([r["area_mm2"] for r in sections_along_path(mask, path, spacing=SP, step_mm=0.5)])
    avg = np.array([r["area_mm2"] for r in sections_along_path(mask, path, spacing=SP, step_mm=0.5, average_mm=2.0)])
    true = math.pi * 1.5**2
    assert np.std(avg / true - 1) < 0.75 * np.std(one / true - 1)
    assert abs(np.mean(avg) / np.mean(one) - 1) < 0.005
    # a step 2.5 -> 1.5 mm at t = 0 along the same axis
    x, y, z = _grid(shape)
    p = np.stack([x, y, z], -1) - c
    t = p @ a
    d = np.linalg.norm(p - t[..., None] * a, axis=-1)
    stepped = (d <= np.where(t < 0, 2.5, 1.5)) & (np.abs(t) < 10)
    rows = sections_along_path(stepped, path, spacing=SP, step_mm=0.5, average_mm=1.0)
    st = find_steps(*_areas(rows), margin_mm=3.0)
    assert len(st) == 1 and st[0]["s_mm"] == pytest.approx(7.0, abs=1.0)


# ------------------------------------------------------------------ section status (issue 17)
def test_cap_sections_flagged_and_writers_report_only_ok_rows(tmp_path):
    """A path that starts outside a rod, crosses its end face and runs along it: the
    sections outside and at the end face are flagged, the rest are true sections, and
    the CSV / JSON / plot writers report only those; they refuse to write over an input."""
    import json

    from ctui.engine.core.errors import CtuiError
    from ctui.engine.measure.report import flag_summary, sections_table

    r = 2.5
    inside, _, _ = _cylinder((10.1, 10.2, 15.0), (0, 0, 1), r, 10.0)  # z 5 .. 25 mm
    m = _soft(inside, (60, 40, 40), ss=(2, 8, 8))
    path = np.array([[10.1, 10.2, z] for z in np.arange(1.0, 20.01, 0.25)])  # enters at z = 5 (s = 4)
    rows = sections_along_path(m, path, spacing=SP, step_mm=0.5)
    s = np.array([rr["s_mm"] for rr in rows])
    status = np.array([rr["status"] for rr in rows])
    assert set(status[s < 3.5]) == {"outside"}
    assert np.all(status[(s > 4.2) & (s < 4.6)] == "cap")  # within a blur width of the end face
    assert np.all(status[s > 6.0] == "ok")
    ok = status == "ok"
    area = np.array([rr["area_mm2"] for rr in rows])
    assert np.abs(area[ok] / (math.pi * r * r) - 1).max() < 0.01  # the first one reported too
    summary = flag_summary(rows)
    assert summary["counts"]["outside"] == int((status == "outside").sum())
    assert summary["ranges"][0]["status"] == "outside" and summary["ranges"][1]["status"] == "cap"
    assert len(sections_table(rows)) == ok.sum()
    write_sections_csv(tmp_path / "s.csv", rows)
    assert (tmp_path / "s.csv").read_text().count("\n") == ok.sum() + 1
    write_sections_json(tmp_path / "s.json", rows)
    doc = json.loads((tmp_path / "s.json").read_text())
    assert len(doc["sections"]) == ok.sum() and doc["section_flags"]["counts"].get("cap", 0) >= 1
    src = tmp_path / "seg.nii.gz"
    src.write_bytes(b"labels")
    for writer in (write_sections_csv, write_sections_json, plot_sections):
        with pytest.raises(CtuiError, match="refusing to overwrite"):
            writer(src, rows, inputs=[src])
    assert src.read_bytes() == b"labels"


def test_stepped_rod_is_not_a_branch_but_a_side_branch_is():
    """A calibre step is above the medians of one side only (ok); a stub joining the
    rod makes the sections it crosses stand out on both sides (branch)."""
    shape = (100, 44, 44)
    x, y, z = _grid(shape)
    rho = np.hypot(x - 11.1, y - 10.9)
    m = (rho <= np.where(z < 25, 3.0, 2.0)) & (z > 3) & (z < 47)
    m |= (np.abs(z - 14.0) <= 1.5) & (np.abs(y - 10.9) <= 1.5) & (x >= 11.1) & (x <= 20.0)  # stub along +x
    path = np.array([[11.1, 10.9, zz] for zz in np.arange(4.0, 46.01, 0.25)])
    rows = sections_along_path(m, path, spacing=SP, step_mm=0.5)
    s = np.array([rr["s_mm"] for rr in rows]) + 4.0  # z of each section
    status = np.array([rr["status"] for rr in rows])
    assert np.any((status == "branch") & (np.abs(s - 14.0) <= 1.5))
    assert not np.any((status == "branch") & (np.abs(s - 14.0) > 3.0))
    assert np.all(status[(s > 20) & (s < 30)] == "ok")  # the step at z = 25 is a step


def _ellipsoid(a=30.0, b=20.0, c=15.0, n=80) -> np.ndarray:
    """A kidney-sized ellipsoid (semi-axes a, b, c mm along x, y, z) on a 1 mm grid, centred at (40, 40, 40) mm."""
    zz, yy, xx = np.mgrid[0:n, 0:n, 0:n].astype(float)
    return ((xx - 40) / a) ** 2 + ((yy - 40) / b) ** 2 + ((zz - 40) / c) ** 2 <= 1.0


def test_a_given_path_keeps_every_section_that_cuts_the_object():
    """A straight path through a kidney-like ellipsoid (no tube: every plane was an 'end cap' and
    8 of 15 sections were dropped without a word): every section inside is kept with its
    ellipse's area, those outside are named with where they lie (s mm) and why."""
    from ctui.engine.measure.summary import measure_object

    mask = _ellipsoid()
    out = measure_object(mask.astype(np.uint8), 1, path="0,40,40;80,40,40", step_mm=5.0, mesh=False)
    rows = out["rows"]
    assert len(rows) == 17
    inside = [r for r in rows if abs(r["point_mm"][0] - 40) < 29]
    assert all(r["status"] == "ok" for r in inside) and len(out["sections"]) >= len(inside) == 11
    for r in inside:  # the ellipse of the plane x: pi * b' * c'
        k = 1 - ((r["point_mm"][0] - 40) / 30.0) ** 2
        assert r["area_mm2"] == pytest.approx(math.pi * 20 * 15 * k, rel=0.05, abs=15)
    assert "cap" not in out["section_flags"]["counts"]
    warned = [w for w in out["warnings"] if "outside the object" in w]
    assert len(warned) == 1 and "(s 0-" in warned[0] and "80 mm" in warned[0]
    # the automatic centreline still leaves its end caps out (a tube's ends are no cross-sections)
    auto = measure_object(mask.astype(np.uint8), 1, path="auto", step_mm=5.0, mesh=False)
    assert all(r.get("flag") is None for r in auto["rows"])


def test_line_through_a_point_along_an_axis_or_the_objects_axis():
    from ctui.engine.measure.paths import line_through, path_length

    mask = _ellipsoid()
    p = line_through((40, 40, 40), "object", half_mm=10.0, mask=mask)
    d = (p[-1] - p[0]) / np.linalg.norm(p[-1] - p[0])
    assert abs(d[0]) > 0.999 and path_length(p) == pytest.approx(20.0, abs=1e-6)  # the longest axis: x
    z = line_through((40, 40, 40), "z", half_mm=2.0, spacing=(3.0, 1.0, 1.0))
    assert np.allclose(z[0], (40, 40, 118)) and np.allclose(z[-1], (40, 40, 122))
    with pytest.raises(Exception):
        line_through((40, 40, 40), "object", half_mm=2.0)  # the object's axis needs its mask
