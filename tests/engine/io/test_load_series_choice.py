"""Which DICOM series the loader chooses: image series only (most slices first); DICOM-SEG,
RTSTRUCT, RT doses/plans, presentation states, SR and KO are listed as non-image objects.
Also `ctui info`'s sampled value range and what ``spacing`` does to a DICOM series."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pydicom
import pytest
from support import ROOT, shared
from test_load_geometry import write_slices

from ctui.engine.core.errors import LoadError
from ctui.engine.io.series import inspect, load, scan

SEG = "1.2.840.10008.5.1.4.1.1.66.4"
RTSTRUCT = "1.2.840.10008.5.1.4.1.1.481.3"
RTDOSE = "1.2.840.10008.5.1.4.1.1.481.2"
GSPS = "1.2.840.10008.5.1.4.1.1.11.1"
SR = "1.2.840.10008.5.1.4.1.1.88.33"
KO = "1.2.840.10008.5.1.4.1.1.88.59"
LABELS_HINT = "DICOM-SEG: open it as labels over its image series"


def _object(path: Path, sop_class: str | None, modality: str) -> None:
    """A DICOM object without pixel data (RTSTRUCT, presentation state, SR, KO)."""
    from pydicom.dataset import FileMetaDataset
    from pydicom.uid import ExplicitVRLittleEndian, generate_uid

    ds = pydicom.Dataset()
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = sop_class or "1.2.840.10008.5.1.4.1.1.7"
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds.file_meta = meta
    if sop_class:
        ds.SOPClassUID = sop_class
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.SeriesInstanceUID = generate_uid()
    ds.Modality = modality
    ds.SeriesDescription = modality
    path.parent.mkdir(parents=True, exist_ok=True)
    ds.save_as(path, enforce_file_format=True)


def _stack(n: int, value: int = 0, dz: float = 2.0) -> tuple[list[np.ndarray], list[list[float]]]:
    return ([np.full((8, 10), value + 10 * k, np.int16) for k in range(n)], [[0.0, 0.0, dz * k] for k in range(n)])


@pytest.fixture
def mixed_folder(tmp_path: Path) -> Path:
    """A CT of 4 slices beside larger non-image objects the old rule (most frames) picked:
    a 6-frame "SEG" series, a 6-frame RT dose, and pixel-less RTSTRUCT, GSPS, SR, KO (and a
    presentation state with no SOP Class UID, known by its Modality); an MR of 2 slices."""
    d = tmp_path / "mixed"
    write_slices(d / "ct", *_stack(4, 100))
    write_slices(d / "mr", *_stack(2, 5), Modality="MR", SOPClassUID="1.2.840.10008.5.1.4.1.1.4")
    write_slices(d / "seg", *_stack(6), Modality="SEG", SOPClassUID=SEG)
    write_slices(d / "dose", *_stack(6), Modality="RTDOSE", SOPClassUID=RTDOSE)
    for name, uid, mod in (("rs.dcm", RTSTRUCT, "RTSTRUCT"), ("pr.dcm", GSPS, "PR"), ("sr.dcm", SR, "SR"),
                           ("ko.dcm", KO, "KO"), ("pr_nouid.dcm", None, "PR")):
        _object(d / "objects" / name, uid, mod)
    return d


def test_image_series_chosen_and_non_image_objects_listed(mixed_folder: Path):
    vol = load(mixed_folder)
    assert vol.modality == "CT" and vol.shape == (4, 8, 10)
    assert float(vol.data[0].max()) == 100 and float(vol.data[-1].max()) == 130
    assert sorted(s["modality"] for s in vol.series) == ["CT", "MR"]
    objects = {sk["file"]: sk for sk in vol.skipped if sk.get("object")}
    assert len(objects) == 6 + 6 + 5
    assert all(objects[f"seg/s{k:03d}.dcm"]["reason"] == LABELS_HINT for k in range(6))
    assert objects["objects/rs.dcm"]["reason"] == "RTSTRUCT: open it as labels over its image series"
    kinds = {f: sk["object"] for f, sk in objects.items()}
    assert kinds["dose/s000.dcm"] == "RT Dose" and kinds["objects/pr.dcm"] == "presentation state"
    assert kinds["objects/pr_nouid.dcm"] == "presentation state"
    assert kinds["objects/sr.dcm"] == "SR" and kinds["objects/ko.dcm"] == "KO"
    # the series list (what --series indexes) holds image series only, in scan's order
    assert [s["uid"] for s in scan(mixed_folder)] == [s["uid"] for s in vol.series]
    mr = next(i for i, s in enumerate(vol.series) if s["modality"] == "MR")
    assert load(mixed_folder, series=mr).shape == (2, 8, 10)


def test_non_image_object_alone_is_not_loadable(mixed_folder: Path):
    with pytest.raises(LoadError, match="DICOM-SEG: open it as labels over its image series"):
        load(mixed_folder / "seg" / "s000.dcm")
    with pytest.raises(LoadError, match=r"only non-image DICOM objects \(KO, RTSTRUCT, SR, presentation state\); "
                                        "open a DICOM-SEG or RTSTRUCT as labels"):
        load(mixed_folder / "objects")


def test_most_slices_wins_over_most_frames(tmp_path: Path):
    """Six frames at three positions (two echoes) count as three slices: the four-slice
    series is the default."""
    imgs, pos = _stack(3)
    write_slices(tmp_path / "echoes", imgs + imgs, pos + pos, Modality="MR", SeriesNumber=1)
    write_slices(tmp_path / "ct", *_stack(4, 100), SeriesNumber=2)
    vol = inspect(tmp_path)
    assert vol.modality == "CT" and vol.shape == (4, 8, 10)
    assert vol.meta["series_index"] == 1


def test_dcmqi_seg_folder_picks_the_ct():
    d = shared("dcmqi_seg")
    vol = inspect(d)
    assert vol.modality == "CT" and vol.shape == (3, 512, 512) and len(vol.series) == 1
    objects = {sk["file"]: sk["reason"] for sk in vol.skipped if sk.get("object")}
    assert objects == {name: LABELS_HINT for name in ("liver.dcm", "partial_overlaps.dcm",
                                                       "sparse-labelmap-noppv.dcm")}
    assert not any("series found" in w for w in vol.warnings)
    full = load(d)
    assert full.shape == vol.shape and full.modality == "CT"
    assert vol.meta["value_range"] == [float(full.data.min()), float(full.data.max())]  # 3 slices: all sampled


def _ctui(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ctui", *map(str, args)], check=False, cwd=ROOT, capture_output=True,
                          text=True, timeout=120)


def test_info_says_value_range_is_sampled(mixed_folder: Path):
    r = _ctui("info", mixed_folder)
    assert r.returncode == 0, r.stderr
    assert "values      100 .. 130 HU   value range (3 sampled slices)" in r.stdout
    assert "non-image   17 DICOM object(s), not volumes" in r.stdout
    assert f"seg/s000.dcm: {LABELS_HINT}" in r.stdout
    r = _ctui("info", mixed_folder, "--json")
    d = json.loads(r.stdout)
    assert d["value_range"] == [100.0, 130.0] and d["value_range_sampled"] is True and d["sampled_slices"] == 3
    assert len(d["non_image_objects"]) == 17 and d["modality"] == "CT"
    assert d["meta"]["sampled_slices"] == [0, 2, 3]


def test_info_value_range_not_sampled_for_stacks(tmp_path: Path):
    from PIL import Image

    for k in range(3):
        Image.fromarray(np.full((6, 7), 10 * k + 1, np.uint8)).save(tmp_path / f"i{k}.png")
    d = json.loads(_ctui("info", tmp_path, "--json").stdout)
    assert d["value_range"] == [1.0, 21.0] and d["value_range_sampled"] is False


class _Guard(np.ndarray):
    """A placeholder that fails on any computation (dtype, shape and strides still work)."""

    def __array_ufunc__(self, *a, **k):
        raise AssertionError("computed on the placeholder data")

    def __array_function__(self, *a, **k):
        raise AssertionError("computed on the placeholder data")

    def min(self, *a, **k):
        raise AssertionError("computed on the placeholder data")

    max = min


def test_info_computes_nothing_on_the_placeholder(mixed_folder: Path, monkeypatch):
    from ctui.commands.info import _lines
    from ctui.engine.actions import info as info_action

    def guarded(path, **kw):
        vol = inspect(path, **kw)
        vol.data = vol.data.view(_Guard)
        return vol

    monkeypatch.setattr(info_action, "inspect", guarded)
    vol, d = info_action.describe_series(mixed_folder)
    assert d["value_range"] == [100.0, 130.0]
    text = "\n".join(_lines(vol, d))
    assert "value range (3 sampled slices)" in text and "int16" in text


def test_spacing_dz_for_dicom(tmp_path: Path):
    """--spacing's dz: the grid step of a tilted series, the slice step without positions,
    and said to be unused on an evenly spaced series."""
    imgs, pos = _stack(5, dz=2.0)
    write_slices(tmp_path / "even", imgs, pos)
    vol = load(tmp_path / "even", spacing=(1.0, 1.0, 1.0))
    assert vol.spacing[0] == pytest.approx(2.0) and vol.shape[0] == 5
    assert any("spacing dz 1 mm not used" in w for w in vol.warnings)

    t = np.radians(15.0)
    iop = (1.0, 0.0, 0.0, 0.0, float(np.cos(t)), float(np.sin(t)))
    normal = np.cross(iop[:3], iop[3:])
    col = np.array(iop[3:])
    tilt_pos = [list(k * 2.0 * normal + k * 0.8 * col) for k in range(5)]  # in-plane drift: gantry tilt
    write_slices(tmp_path / "tilt", imgs, tilt_pos, iop=iop)
    plain = load(tmp_path / "tilt")
    assert plain.spacing[0] == pytest.approx(2.0) and plain.shape[0] == 5
    vol = load(tmp_path / "tilt", spacing=1.0)
    assert vol.spacing[0] == pytest.approx(1.0) and vol.shape[0] == 9
    assert any("tilted series: resampled to a regular 1 mm grid" in w for w in vol.warnings)
    assert vol.shape[1:] == plain.shape[1:]

    write_slices(tmp_path / "nopos", imgs, pos)
    for p in (tmp_path / "nopos").iterdir():
        ds = pydicom.dcmread(p)
        del ds.ImagePositionPatient
        ds.save_as(p)
    vol = load(tmp_path / "nopos", spacing=3.0)
    assert vol.spacing[0] == pytest.approx(3.0)
    assert any("slice step 3 mm from the spacing asked for" in w for w in vol.warnings)
