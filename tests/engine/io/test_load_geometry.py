"""DICOM geometry against analytic truths: a gantry-tilted series with uneven gaps keeps
every voxel of its object (grid grows, z step from the smallest gap, as dcm2niix); hostile
slice positions (outliers, thousands of distinct gaps) are skipped or bounded; the
memory limit is checked before the regular grid is allocated; a single slice with a
negative SpacingBetweenSlices gives a positive voxel size."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pydicom = pytest.importorskip("pydicom")

from ctui.engine.core.errors import CtuiError  # noqa: E402
from ctui.engine.io.series import load  # noqa: E402


def write_slices(folder: Path, images, ipps, *, iop=(1, 0, 0, 0, 1, 0), pixel_spacing=(1.0, 1.0), **extra) -> list[Path]:
    """One CT file per (image, ImagePositionPatient); images int16 HU (rows, cols)."""
    from pydicom.dataset import FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

    folder.mkdir(parents=True, exist_ok=True)
    series = generate_uid()
    paths = []
    for k, (img, ipp) in enumerate(zip(images, ipps)):
        img = np.asarray(img, np.int16)
        ds = pydicom.Dataset()
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds.file_meta = meta
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.SeriesInstanceUID = series
        ds.Modality = "CT"
        ds.InstanceNumber = k + 1
        ds.ImagePositionPatient = [float(v) for v in ipp]
        ds.ImageOrientationPatient = [float(v) for v in iop]
        ds.PixelSpacing = [float(v) for v in pixel_spacing]
        ds.Rows, ds.Columns = img.shape
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated = ds.BitsStored = 16
        ds.HighBit = 15
        ds.PixelRepresentation = 1
        ds.RescaleSlope, ds.RescaleIntercept = 1, 0
        for key, value in extra.items():
            setattr(ds, key, value)
        ds.PixelData = img.tobytes()
        p = folder / f"s{k:03d}.dcm"
        ds.save_as(p, enforce_file_format=True)
        paths.append(p)
    return paths


def test_tilted_uneven_series_keeps_every_voxel(tmp_path):
    """18.5 deg gantry tilt, gaps of 1 mm then 3 mm, a sphere close to the field of view's
    edge: the corrected volume holds the whole sphere at its true place and size."""
    t = np.radians(18.5)
    row, col = np.array([1.0, 0, 0]), np.array([0, np.cos(t), np.sin(t)])
    n = 64
    gaps = [1.0] * 14 + [3.0] * 8
    z_table = np.concatenate([[0.0], np.cumsum(gaps)])
    centre, radius = np.array([0.0, 30.0, 30.0]), 9.0
    jj, ii = np.meshgrid(np.arange(n), np.arange(n))
    images, ipps = [], []
    for z in z_table:
        ipp = np.array([-32.0, -20.0, z])
        p = ipp + jj[..., None] * row + ii[..., None] * col
        inside = np.linalg.norm(p - centre, axis=-1) <= radius
        # every object pixel is inside its slice: nothing is lost by the acquisition itself
        assert not (inside[0].any() or inside[-1].any() or inside[:, 0].any() or inside[:, -1].any())
        images.append(np.where(inside, 1000, -1000))
        ipps.append(ipp)
    write_slices(tmp_path / "tilt", images, ipps, iop=(*row, *col))
    vol = load(tmp_path / "tilt")

    text = " ".join(vol.warnings)
    assert "gantry tilt 18.5" in text and "grown" in text and "the smallest gap, as dcm2niix" in text
    # the closely spaced part's step (1 mm of table, cos(t) along the normal), not the median
    assert vol.spacing[0] == pytest.approx(np.cos(t), rel=1e-3)
    assert vol.shape[1] > n  # grown: the shear moves part of the sphere past row 64
    obj = vol.data > 0
    zz, yy, xx = np.nonzero(obj)
    assert yy.max() >= n  # ... which a fixed 64-row field of view would have cut
    mm = vol.index_to_mm(np.column_stack([zz, yy, xx]).astype(float))
    voxel = vol.voxel_volume_mm3()
    assert obj.sum() * voxel == pytest.approx(4 / 3 * np.pi * radius**3, rel=0.05)
    step = max(vol.spacing)
    assert np.allclose(mm.mean(axis=0), centre, atol=step)
    # extent along each patient axis: the sphere's diameter within a voxel
    extent = mm.max(axis=0) - mm.min(axis=0)
    assert np.allclose(extent, 2 * radius, atol=2 * step)


def _even(n: int, size: int = 8) -> tuple[list[np.ndarray], list[list[float]]]:
    images = [np.full((size, size), 10 * k, np.int16) for k in range(n)]
    return images, [[0.0, 0.0, 2.0 * k] for k in range(n)]


def test_far_outlier_slice_is_skipped(tmp_path):
    images, ipps = _even(10)
    images.append(np.zeros((8, 8), np.int16))
    ipps.append([0.0, 0.0, 1e5])  # one slice 100 m away
    write_slices(tmp_path / "o", images, ipps)
    vol = load(tmp_path / "o")
    assert vol.shape == (10, 8, 8)
    assert vol.spacing[0] == pytest.approx(2.0)
    assert [s["file"] for s in vol.skipped] == ["s010.dcm"] and "outlier" in vol.skipped[0]["reason"]
    assert any("far from the rest" in w for w in vol.warnings)


def test_position_beyond_a_kilometre_is_no_position(tmp_path):
    images, ipps = _even(6)
    images.append(np.zeros((8, 8), np.int16))
    ipps.append([0.0, 0.0, 1e7])
    write_slices(tmp_path / "k", images, ipps)
    vol = load(tmp_path / "k")
    assert vol.shape == (6, 8, 8)
    assert len(vol.skipped) == 1 and "ImagePositionPatient" in vol.skipped[0]["reason"]


def test_thousands_of_distinct_gaps_give_a_bounded_grid(tmp_path):
    rng = np.random.default_rng(1)
    nz = 60
    z = np.sort(rng.uniform(0, 300, nz))
    z[1:4] = z[0] + np.array([0.01, 0.02, 0.03])  # a recurring tiny gap would make 30,000 slices
    images = [np.full((4, 4), k, np.int16) for k in range(nz)]
    write_slices(tmp_path / "r", images, [[0.0, 0.0, v] for v in z])
    vol = load(tmp_path / "r")
    assert vol.shape[0] <= 4 * nz
    assert vol.extent_mm()[0] == pytest.approx(z[-1] - z[0] + vol.spacing[0], rel=0.01)
    assert any("coarsened" in w for w in vol.warnings)


def test_regular_grid_checked_against_the_memory_limit(tmp_path, monkeypatch):
    images, ipps = _even(8, size=64)
    ipps = [[0.0, 0.0, v] for v in (0, 1, 2, 3, 8, 9, 10, 11)]  # uneven: resampled to 12 slices
    write_slices(tmp_path / "m", images, ipps)
    monkeypatch.setenv("CTUI_MEMORY_LIMIT", str(150_000))  # decoded 65 kB fits, + the 12-slice grid does not
    with pytest.raises(CtuiError) as exc:
        load(tmp_path / "m")
    msg = str(exc.value)
    assert "\n" not in msg and "memory" in msg and str(tmp_path / "m") in msg


def test_single_slice_negative_spacing_between_slices(tmp_path):
    write_slices(tmp_path / "one", [np.zeros((8, 8), np.int16)], [[0.0, 0.0, 5.0]], SpacingBetweenSlices=-2.5,
                 SliceThickness=3.0)
    vol = load(tmp_path / "one")
    assert vol.spacing[0] == pytest.approx(2.5)
    assert vol.voxel_volume_mm3() > 0


def test_huge_rows_columns_refused_against_memory(tmp_path, monkeypatch):
    """A header claiming 8000x8000 pixels (128 MB) in a small compressed file: refused
    before decoding, the message naming the file."""
    from pydicom.encaps import encapsulate
    from pydicom.uid import RLELossless

    p = write_slices(tmp_path / "h", [np.zeros((8, 8), np.int16)], [[0.0, 0.0, 0.0]])[0]
    ds = pydicom.dcmread(p)
    ds.Rows = ds.Columns = 8000
    ds.file_meta.TransferSyntaxUID = RLELossless
    ds.PixelData = encapsulate([b"\x00" * 200_000])
    ds["PixelData"].VR = "OB"
    ds.save_as(p, enforce_file_format=True)
    monkeypatch.setenv("CTUI_MEMORY_LIMIT", str(64 << 20))
    with pytest.raises(CtuiError) as exc:
        load(p)
    msg = str(exc.value)
    assert "\n" not in msg and str(p) in msg and "memory" in msg
    # in a folder with good slices: that file skipped, named, with the reason
    images, ipps = _even(4)
    write_slices(tmp_path / "f", images, ipps)
    (tmp_path / "f" / "huge.dcm").write_bytes(p.read_bytes())
    vol = load(tmp_path / "f")
    assert vol.shape == (4, 8, 8)
    assert [s["file"] for s in vol.skipped] == ["huge.dcm"] and "memory" in vol.skipped[0]["reason"]


def test_series_over_rlimit_as_refused_before_allocating(tmp_path):
    """Under a process address-space limit (RLIMIT_AS, as `ulimit -v` or a batch
    scheduler sets) a series that does not fit stops with a one-line message, not a
    MemoryError or a crash: the check respects the process's limit, not free RAM."""
    import subprocess
    import sys

    images = [np.full((256, 256), k, np.int16) for k in range(40)]  # 5.2 MB of voxels
    write_slices(tmp_path / "big", images, [[0.0, 0.0, 1.0 * k] for k in range(40)])
    child = f"""
import resource, sys
from pathlib import Path
import numpy as np
from ctui.engine.core.errors import CtuiError
from ctui.engine.io.series import load, inspect
vm = next(int(l.split()[1]) * 1024 for l in Path('/proc/self/status').read_text().splitlines() if l.startswith('VmSize'))
vol = inspect({str(tmp_path / 'big')!r})  # headers + 3 slices: fits
resource.setrlimit(resource.RLIMIT_AS, (vm + (4 << 20), resource.RLIM_INFINITY))
try:
    load({str(tmp_path / 'big')!r})
except CtuiError as exc:
    print("REFUSED", exc)
    sys.exit(0)
print("LOADED")
"""
    # 4 MB of address space over what is mapped after the imports; the series needs 5.2 MB
    r = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, timeout=120,
                       env={**__import__("os").environ, "CTUI_THREADS": "1"})
    assert r.returncode == 0, r.stderr[-2000:]
    assert "REFUSED" in r.stdout and "memory" in r.stdout and "\n" not in r.stdout.strip(), r.stdout
