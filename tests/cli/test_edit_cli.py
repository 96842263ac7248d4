"""``ctui edit PROJECT.ctui``: the TUI's 3D edits on the command line (same engine
functions), on a phantom project with known voxel counts; bad input exits 2 with one line
and writes nothing."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ctui.cli import main
from ctui.engine.actions.project import load_project, new_project, save_project
from ctui.engine.core.volume import Volume


@pytest.fixture
def blocks(tmp_path):
    """Object 1: block A (z 2..5, y 4..9, x 4..9: 144 voxels) and block B (z 2..5, y 4..9,
    x 14..17: 96 voxels), spacing 2 x 1 x 1 mm."""
    lab = np.zeros((10, 20, 24), np.uint8)
    lab[2:6, 4:10, 4:10] = 1
    lab[2:6, 4:10, 14:18] = 1
    vol = Volume(np.zeros(lab.shape, np.int16), spacing=(2.0, 1.0, 1.0), modality="CT")
    path = tmp_path / "blocks.ctui"
    save_project(path, new_project(vol, labels=lab))
    return path


def _run(capsys, *argv) -> tuple[int, str]:
    rc = main(list(argv))
    return rc, capsys.readouterr()


def test_keep_island_cut_and_smooth(capsys, blocks, tmp_path):
    out = tmp_path / "a.ctui"
    rc, cap = _run(capsys, "edit", str(blocks), "--keep-island", "15,5,3", "--project", str(out), "--json")
    assert rc == 0
    res = json.loads(cap.out)
    assert res["edits"][0]["removed"] == 144 and res["voxels"] == 96
    assert res["volume_ml"] == pytest.approx(96 * 2 / 1000)
    assert int((load_project(str(out)).labels == 1).sum()) == 96
    out2 = tmp_path / "b.ctui"
    rc, cap = _run(capsys, "edit", str(blocks), "--box", "4,4,3,9,9,3", "--cut", "inside", "--project", str(out2))
    assert rc == 0 and "-36" in cap.out
    assert int((load_project(str(out2)).labels == 1).sum()) == 240 - 36
    out3 = tmp_path / "c.ctui"
    rc, cap = _run(capsys, "edit", str(blocks), "--polygon", "4,4;4,9;9,9", "--cut", "inside", "--slices", "2:3",
                   "--project", str(out3))
    assert rc == 0 and int((load_project(str(out3)).labels == 1).sum()) == 240 - 2 * 21
    out4 = tmp_path / "d.ctui"
    rc, cap = _run(capsys, "edit", str(blocks), "--smooth", "opening:5", "--project", str(out4), "--json")
    res = json.loads(cap.out)
    # a ball of 5 mm on 2 x 1 x 1 mm: 5 voxels across in y, x and 3 along z; both blocks
    # hold it, their corners and edges are rounded off
    assert rc == 0 and 0 < res["edits"][0]["removed"] < 240 and res["edits"][0]["added"] == 0


@pytest.mark.parametrize("extra, message", [
    (["--keep-island", "0,0,0"], "not on object 1"),
    (["--box", "4,4,3:4,9,3", "--cut", "inside"], "zero width"),
    (["--box", "0,15,0:3,19,9", "--cut", "inside"], "nothing of object 1"),
    (["--smooth", "blur:3"], "method"),
    (["--object", "4", "--smooth", "median:3"], "no object 4"),
    ([], "nothing to do"),
])
def test_bad_input_one_line_exit_2(capsys, blocks, tmp_path, extra, message):
    out = tmp_path / "bad.ctui"
    rc, cap = _run(capsys, "edit", str(blocks), *extra, "--project", str(out))
    assert rc == 2 and message in cap.err and len(cap.err.strip().splitlines()) == 1
    assert not out.exists()
