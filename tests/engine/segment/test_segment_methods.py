"""The segment action: fill / grow / levelset with background seeds on the leak phantoms,
bad input refused before any change, progress and cancel, and the CLI's new options."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ctui.cli import main
from ctui.engine.actions.segment import SegmentOptions, segment
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.progress import Cancelled
from ctui.engine.segment.phantoms import KINDS, leak_case
from ctui.engine.segment.selection import Segmentation


@pytest.fixture(scope="module", params=KINDS)
def case(request):
    return leak_case(request.param)


def _check(case, labels, oid=1, tol=0.05):
    got = labels == oid
    n = int(case.truth.sum())
    assert abs(int(got.sum()) - n) / n < tol, case.kind
    bx, by, bz = case.background
    assert not got[bz, by, bx]


@pytest.mark.parametrize("method", ["fill", "grow"])
def test_methods_with_background_seed_within_5_percent(case, method):
    res = segment(case.volume, [case.seed], [case.hu_range], background=[case.background],
                  options=SegmentOptions(method=method))
    _check(case, res.segmentation.labels)
    o = res.objects[0]
    assert o.voxels == res.segmentation.voxels(1) and o.volume_ml == pytest.approx(case.truth_ml, rel=0.05)


def test_levelset_with_background_seed_within_5_percent():
    case = leak_case("bowel")
    res = segment(case.volume, [case.seed], [case.hu_range], background=[case.background],
                  options=SegmentOptions(method="levelset"))
    _check(case, res.segmentation.labels)


def test_background_seed_alone_splits_a_leaky_fill():
    """Without the neck cut (neck 0) the background seed still cuts the object at the bridge."""
    case = leak_case("neck")
    res = segment(case.volume, [case.seed], [case.hu_range], background=[case.background],
                  options=SegmentOptions(neck_mm=0))
    _check(case, res.segmentation.labels)


def test_bad_input_is_one_line_and_changes_nothing():
    case = leak_case("neck")
    vol = case.volume
    seg = Segmentation(vol.shape)
    seg.paint(case.truth[:, :, :40], 3)
    before = seg.labels.copy()
    x, y, z = case.seed
    bad = [
        (dict(seeds=[case.seed, (500, 1, 1)]), "seed 500,1,1 is outside the volume"),
        (dict(seeds=[case.seed], background=[(1, 1, 99)]), "background seed 1,1,99 is outside the volume"),
        (dict(seeds=[case.seed], background=[(x + 3, y, z)]), "lies inside the region of seed"),
        (dict(seeds=[case.seed, (2, 2, 2)]), "outside the range"),
    ]
    for kw, msg in bad:
        with pytest.raises(CtuiError, match=msg) as err:
            segment(vol, thresholds=[case.hu_range], segmentation=seg, **kw)
        assert "\n" not in str(err.value)
        np.testing.assert_array_equal(seg.labels, before)
        assert seg.undo_labels() == ["paint object 3"]


def test_progress_and_cancel_leave_nothing_behind():
    case = leak_case("bowel")
    seen = []
    segment(case.volume, [case.seed], [case.hu_range], progress=lambda d, t, m="": seen.append((d, t)))
    assert seen and seen[-1][0] == seen[-1][1]
    seg = Segmentation(case.volume.shape)
    with pytest.raises(Cancelled):
        segment(case.volume, [case.seed], [case.hu_range], segmentation=seg, progress=lambda d, t, m="": d < 0.2 * t)
    assert not seg.labels.any()


def test_cli_options(capsys, tmp_path):
    from ctui.engine.io.phantom import SAMPLE_DIR, load_truth

    truth = load_truth()
    k = [o for o in truth["objects"] if o["name"] == "kidney_left"][0]
    z, y, x = k["seed_zyx"]
    base = ["segment", str(SAMPLE_DIR), "--seed", f"{x},{y},{z}", "--range", "{}:{}".format(*k["hu_range"]), "--json"]
    assert main(base + ["--slices", f"{z - 3}:{z + 2}", "--keep-largest", "--min-island", "5"]) == 0
    o = json.loads(capsys.readouterr().out)["objects"][0]
    assert o["slices"] == [z - 3, z + 2] and "slice limit" in o["stops"]["forward"]
    assert main(base + ["--method", "grow"]) == 0
    o = json.loads(capsys.readouterr().out)["objects"][0]
    assert o["volume_ml"] == pytest.approx(k["volume_ml"], rel=0.03)
    assert main(base + ["--slices", "9:3"]) == 2
    assert "--slices" in capsys.readouterr().err
    assert main(["segment", str(SAMPLE_DIR), "--seed", f"{x},{y},{z}", "--range", "1:2", "--background", "0,0,999"]) == 2
    err = capsys.readouterr().err
    assert "background seed 0,0,999 is outside the volume" in err and len(err.strip().splitlines()) == 1


def test_help_says_slices_number_from_0(capsys):
    with pytest.raises(SystemExit):
        main(["segment", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "numbered from 0" in out and "--background" in out and "--slices" in out and "--neck" in out


def test_cli_interpolates_a_project_object(capsys, tmp_path):
    """ctui segment PROJECT --interpolate --project NEW: key slices 0, 5 and 10 of a cone are filled between."""
    from ctui.engine.actions.project import new_project, save_project
    from ctui.engine.core.volume import Volume

    n = 40
    yy, xx = np.mgrid[:n, :n]
    labels = np.zeros((11, n, n), np.uint8)
    for z in (0, 5, 10):
        labels[z][(yy - 20) ** 2 + (xx - 20) ** 2 <= (4 + z) ** 2] = 1
    labels[3, 1:3, 1:3] = 1  # a 4-voxel island
    vol = Volume(np.zeros(labels.shape, np.int16), spacing=(2.0, 1.0, 1.0), modality="CT")
    src = tmp_path / "a.ctui"
    save_project(src, new_project(vol, labels=labels, objects=[{"id": 1, "name": "cone"}]))
    out = tmp_path / "b.ctui"
    assert main(["segment", str(src), "--interpolate", "--min-island", "5", "--project", str(out), "--json"]) == 0
    row = json.loads(capsys.readouterr().out)["objects"][0]
    assert row["id"] == 1 and row["added"] > 0 and row["removed"] == 4
    from ctui.engine.io.project import load_project

    got = load_project(out).labels == 1
    assert got.any(axis=(1, 2)).all() and not got[3, 1:3, 1:3].any()
    assert main(["segment", str(src), "--interpolate"]) == 2
    assert "--project" in capsys.readouterr().err


@pytest.mark.slow
def test_segment_progress_bar_on_a_terminal_only(tmp_path):
    """ctui segment draws its bar ("segmenting") on a terminal's stderr; with --json nothing."""
    pytest.importorskip("pty")
    from test_progress_pty import _run_with_tty_stderr

    from ctui.engine.io.phantom import SAMPLE_DIR

    args = ["segment", str(SAMPLE_DIR), "--seed", "94,81,40", "--range", "115:445", "--mode", "3d"]
    rc, out, tty = _run_with_tty_stderr(args, tmp_path)
    assert rc == 0 and "object 1:" in out and "segmenting" in tty
    rc, out, tty = _run_with_tty_stderr([*args, "--json"], tmp_path)
    assert rc == 0 and json.loads(out)["objects"][0]["id"] == 1 and "segmenting" not in tty
