"""Uneven slice gaps are resampled at dcm2niix's step (the smallest gap, at most 2x the
slices), and `ctui info` says which step and why (issue 25, item 6)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pydicom")

from ctui.cli import main  # noqa: E402
from ctui.engine.io.series import load  # noqa: E402
from test_load_geometry import write_slices  # noqa: E402


def _series(folder, gaps):
    z = np.concatenate([[0.0], np.cumsum(gaps)])
    images = [np.full((8, 8), int(10 * v), np.int16) for v in z]  # value = 10 x table position
    write_slices(folder, images, [[0.0, 0.0, float(v)] for v in z])
    return z


def test_dense_part_keeps_its_resolution_and_info_says_so(tmp_path, capsys):
    """Gaps 1.08, 1.5, 2.0, then ten of 4.0 and one of 6.99 mm (a GE head CT's pattern): the
    smallest recurring gap was 4.0 mm; dcm2niix takes the smallest gap, 1.08 mm, coarsened
    to 2x the 15 slices: 51.57 / 29 = 1.778 mm."""
    gaps = [1.08, 1.5, 2.0] + [4.0] * 10 + [6.99]
    z = _series(tmp_path / "s", gaps)
    vol = load(tmp_path / "s")
    step = sum(gaps) / (2 * len(z) - 1)
    assert vol.spacing[0] == pytest.approx(step, rel=1e-4)
    assert vol.shape[0] == 2 * len(z)
    assert vol.meta["z_grid"]["rule"].startswith("the smallest gap 1.08 mm coarsened to 2x")
    # linear along the normal: the values follow the table position
    pos = vol.index_to_mm(np.column_stack([np.arange(vol.shape[0]), np.zeros((vol.shape[0], 2))]))[:, 2]
    assert np.allclose(vol.data[:, 4, 4], 10 * pos, atol=2.0)  # source values truncated to integers
    assert main(["info", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert f"resampled to a regular {step:.4g} mm grid" in out and "as dcm2niix" in out


def test_smallest_gap_when_the_grid_stays_small(tmp_path):
    gaps = [1.0] * 6 + [3.0] * 4
    _series(tmp_path / "s", gaps)
    vol = load(tmp_path / "s")
    assert vol.spacing[0] == pytest.approx(1.0) and vol.shape[0] == 19
    assert vol.meta["z_grid"] == {"step_mm": 1.0, "slices": 19, "source_slices": 11, "gaps_mm": [1.0, 3.0],
                                  "rule": "the smallest gap, as dcm2niix chooses"}
