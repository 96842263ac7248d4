"""Nothing invented or dropped in silence (issue 41): every assumption the loader makes
(a voxel size replaced, slices dropped, an orientation repaired) is carried with the
Volume (``Volume.assumptions``, typed) and said by every command that uses it (mesh,
segment, render, export, measure; text and ``--json``), kept in the project, and a
series with more than a quarter of its slices undecodable is refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ctui.cli import main
from ctui.engine.core.assumptions import MAX_DROPPED_SHARE, Assumption

SEED, RANGE = "24,24,8", "200:400"


def _mutate(folder: Path, fn, which=None) -> Path:
    import pydicom

    files = sorted(folder.glob("*.dcm")) or sorted(p for p in folder.iterdir() if p.is_file())
    for k, f in enumerate(files):
        if which is None or k in which:
            ds = pydicom.dcmread(f)
            fn(ds)
            ds.save_as(f, enforce_file_format=True)
    return folder


def _series(tmp_path: Path, case: str) -> Path:
    from test_privacy import write_series

    s = write_series(tmp_path / case, broken=False)
    if case == "spacing":
        _mutate(s, lambda ds: setattr(ds, "PixelSpacing", ["1e-30", "1e-30"]))
    elif case == "dropped":  # 2 of 16 slices with their pixel data cut short
        _mutate(s, lambda ds: setattr(ds, "PixelData", ds.PixelData[:100]), which={3, 11})
    elif case == "too_many":  # 6 of 16
        _mutate(s, lambda ds: setattr(ds, "PixelData", ds.PixelData[:100]), which={1, 3, 5, 7, 9, 11})
    elif case == "orientation":
        _mutate(s, lambda ds: setattr(ds, "ImageOrientationPatient", [1, 0, 0, 0.2, 1, 0]))
    return s


KINDS = {"spacing": "spacing", "dropped": "slices", "orientation": "orientation"}


def _run(capsys, argv) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.parametrize("case", sorted(KINDS))
def test_loader_carries_the_assumption_typed(tmp_path, case):
    from ctui.engine.io.series import load

    vol = load(_series(tmp_path, case))
    kinds = [a.kind for a in vol.assumptions]
    assert KINDS[case] in kinds, vol.warnings
    assert all(isinstance(a, Assumption) for a in vol.assumptions)
    if case == "dropped":
        a = next(a for a in vol.assumptions if a.kind == "slices")
        assert (a.count, a.total) == (2, 16) and vol.shape[0] == 16  # the gaps interpolated
    assert {d["kind"] for d in vol.describe()["assumptions"]} >= {KINDS[case]}


@pytest.mark.parametrize("case", sorted(KINDS))
def test_every_command_says_the_assumption(tmp_path, capsys, case):
    """mesh, segment, render, measure and export: text and --json name the assumption."""
    s = _series(tmp_path, case)
    kind = KINDS[case]
    said = f"assumed ({kind})"
    rc, out, _ = _run(capsys, ["mesh", s, "--iso", "150", "--out", tmp_path / "m.stl"])
    assert rc == 0 and said in out, out
    rc, out, _ = _run(capsys, ["mesh", s, "--iso", "150", "--out", tmp_path / "m2.stl", "--json"])
    assert rc == 0 and any(n.startswith(said) for n in json.loads(out)["notes"]), out
    proj = tmp_path / "p.ctui"
    rc, out, _ = _run(capsys, ["segment", s, "--seed", SEED, "--range", RANGE, "--project", proj])
    assert rc == 0 and said in out, out
    rc, out, _ = _run(capsys, ["segment", s, "--seed", SEED, "--range", RANGE, "--json"])
    assert rc == 0 and kind in [a["kind"] for a in json.loads(out)["assumptions"]], out
    # the project keeps it: commands on the project alone say it too
    rc, out, _ = _run(capsys, ["measure", proj])
    assert rc == 0 and said in out, out
    rc, out, _ = _run(capsys, ["export", proj, "--format", "nifti", "--out", tmp_path / "x.nii.gz", "--json"])
    assert rc == 0 and any(said in w for w in json.loads(out)["warnings"]), out
    rc, out, err = _run(capsys, ["render", s, "--out", tmp_path / "r.png", "--size", "64x64"])
    if rc != 0 and "EGL" in err:
        pytest.skip(f"render needs EGL: {err.strip()}")
    assert rc == 0 and said in out, (out, err)


def test_too_many_dropped_slices_are_refused_in_one_line(tmp_path, capsys):
    s = _series(tmp_path, "too_many")
    assert 6 / 16 > MAX_DROPPED_SHARE
    for argv in (["mesh", s, "--iso", "150", "--out", tmp_path / "m.stl"],
                 ["segment", s, "--seed", SEED, "--range", RANGE]):
        rc, out, err = _run(capsys, argv)
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert rc == 2 and len(lines) == 1 and "6 of 16 slices could not be decoded" in lines[0], err
    assert not (tmp_path / "m.stl").exists()


def test_tui_announces_assumptions_first(tmp_path):
    """The TUI's load notifications (app._start_workspace) put the assumptions before other warnings."""
    from ctui.engine.io.series import load

    vol = load(_series(tmp_path, "spacing"))
    vol.warnings.insert(0, "an unrelated warning")
    vol.warnings.insert(0, "another")
    vol.warnings.insert(0, "a third")
    first = sorted(vol.warnings, key=lambda w: w not in vol.assumptions)[:3]
    assert first[0].kind == "spacing"


def test_label_map_of_another_shape_is_refused_even_with_the_same_affine(tmp_path, capsys):
    """The issue's case: `ctui measure CT --labels MASK`, MASK cut to fewer slices on the same affine."""
    import nibabel as nib

    from support import shared

    d = shared("totalseg_example")
    ct = nib.load(d / "ct_abdomen_3mm.nii.gz")
    lab = np.asarray(nib.load(d / "ct_abdomen_3mm_labels.nii.gz").dataobj).astype(np.uint8)
    mask = tmp_path / "mask.nii.gz"
    nib.save(nib.Nifti1Image((lab[:, :, :20] == 5).astype(np.uint8), ct.affine), mask)
    capsys.readouterr()
    rc = main(["measure", str(d / "ct_abdomen_3mm.nii.gz"), "--labels", str(mask)])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and "shape" in lines[0] and "(20, 101, 122)" in lines[0], err
