"""Label-map export: NIfTI / NRRD / .seg.nrrd geometry, checked against the files'
own conventions (nibabel RAS affine, NRRD LPS space directions) and against ITK
(SimpleITK, what 3D Slicer and ITK-SNAP use) when it is installed."""

from __future__ import annotations

import gzip
import os

import numpy as np
import pytest

from ctui.engine.core.errors import FormatError
from ctui.engine.io.labels import load_labels, save_labels
from ctui.engine.core.volume import Volume

EXTS = ["nii", "nii.gz", "nrrd", "seg.nrrd"]


def _rot(ax, ay, az):
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


@pytest.fixture
def oblique():
    """An oblique, anisotropic volume with an asymmetric label pattern."""
    rng = np.random.default_rng(7)
    shape = (6, 9, 11)  # z, y, x all different so any axis swap shows
    labels = np.zeros(shape, np.uint8)
    labels[1:4, 2:7, 3:9] = 2
    labels[4, 0, 10] = 5
    labels[0, 8, 0] = 1
    labels[rng.random(shape) > 0.97] = 7
    vol = Volume(data=labels.astype(np.int16) * 100, spacing=(3.0, 0.6, 0.8), origin=(-120.5, 33.25, 410.0), direction=_rot(0.2, -0.35, 0.5))
    return labels, vol


@pytest.mark.parametrize("ext", EXTS)
def test_round_trip_geometry(tmp_path, oblique, ext):
    labels, vol = oblique
    p = save_labels(tmp_path / f"lab.{ext}", labels, vol)
    assert os.listdir(tmp_path) == [p.name]
    got, gvol = load_labels(p)
    assert got.dtype == np.uint8 and got.shape == labels.shape
    assert np.array_equal(got, labels)
    assert np.allclose(gvol.spacing, vol.spacing, atol=1e-5)
    assert np.allclose(gvol.origin, vol.origin, atol=1e-4)
    assert np.allclose(gvol.direction, vol.direction, atol=1e-5)
    assert np.allclose(gvol.affine, vol.affine, atol=1e-4)


def _check_points(vol, labels, data_xyz, index_to_lps):
    """Every labelled voxel: same value and same patient point in ctui and in the file."""
    zs, ys, xs = np.nonzero(labels)
    for z, y, x in zip(zs, ys, xs):
        assert data_xyz[x, y, z] == labels[z, y, x]
        assert np.allclose(index_to_lps(x, y, z), vol.index_to_mm((z, y, x)), atol=1e-4)


@pytest.mark.parametrize("ext", ["nii", "nii.gz"])
def test_nifti_own_convention(tmp_path, oblique, ext):
    import nibabel as nib

    labels, vol = oblique
    p = save_labels(tmp_path / f"lab.{ext}", labels, vol)
    img = nib.load(str(p))
    hdr = img.header
    assert int(hdr["qform_code"]) == 1 and int(hdr["sform_code"]) == 1
    assert np.allclose(img.get_qform(), img.get_sform(), atol=1e-4)
    assert hdr.get_xyzt_units()[0] == "mm"
    assert img.get_data_dtype() == np.uint8
    data = np.asarray(img.dataobj)
    ras_to_lps = np.diag([-1.0, -1.0, 1.0])

    def to_lps(x, y, z):
        return ras_to_lps @ (img.affine @ [x, y, z, 1.0])[:3]

    _check_points(vol, labels, data, to_lps)
    # the qform (quaternion) alone gives the same mapping
    q = img.get_qform()
    assert np.allclose(ras_to_lps @ (q @ [3, 2, 1, 1.0])[:3], vol.index_to_mm((1, 2, 3)), atol=1e-3)


@pytest.mark.parametrize("ext", ["nrrd", "seg.nrrd"])
def test_nrrd_own_convention(tmp_path, oblique, ext):
    import nrrd

    labels, vol = oblique
    p = save_labels(tmp_path / f"lab.{ext}", labels, vol)
    data, hdr = nrrd.read(str(p), index_order="F")
    assert hdr["space"] == "left-posterior-superior"
    assert list(hdr["sizes"]) == [11, 9, 6]
    sd = np.asarray(hdr["space directions"], float)
    org = np.asarray(hdr["space origin"], float)

    def to_lps(x, y, z):
        return org + x * sd[0] + y * sd[1] + z * sd[2]

    _check_points(vol, labels, data, to_lps)


def test_seg_nrrd_segments(tmp_path, oblique):
    import nrrd

    from ctui.engine.core.colors import object_color_float

    labels, vol = oblique
    p = save_labels(tmp_path / "lab.seg.nrrd", labels, vol, names={2: "Kidney"})
    _, hdr = nrrd.read(str(p))
    ids = sorted(int(i) for i in np.unique(labels) if i)
    assert hdr["Segmentation_MasterRepresentation"] == "Binary labelmap"
    for n, oid in enumerate(ids):
        pre = f"Segment{n}_"
        assert int(hdr[pre + "LabelValue"]) == oid
        assert hdr[pre + "Layer"] == "0"
        assert hdr[pre + "ID"]
        assert np.allclose([float(v) for v in hdr[pre + "Color"].split()], object_color_float(oid), atol=1e-5)
        zz, yy, xx = np.nonzero(labels == oid)
        ext = [int(v) for v in hdr[pre + "Extent"].split()]
        assert ext == [xx.min(), xx.max(), yy.min(), yy.max(), zz.min(), zz.max()]
    assert hdr["Segment1_Name"] == "Kidney"  # ids are 1, 2, 5, 7 -> Segment1 is object 2
    assert "Segment4_ID" not in hdr


@pytest.mark.parametrize("ext", EXTS)
def test_itk_reads_same_geometry(tmp_path, oblique, ext):
    sitk = pytest.importorskip("SimpleITK", reason="SimpleITK (test extra) not installed")
    labels, vol = oblique
    p = save_labels(tmp_path / f"lab.{ext}", labels, vol)
    img = sitk.ReadImage(str(p))
    arr = sitk.GetArrayFromImage(img)  # (z, y, x)
    assert np.array_equal(arr, labels)
    for zyx in [(0, 0, 0), (5, 8, 10), (2, 7, 1)]:
        pt = img.TransformIndexToPhysicalPoint(tuple(int(v) for v in zyx[::-1]))  # ITK: LPS
        assert np.allclose(pt, vol.index_to_mm(zyx), atol=1e-3)


def test_save_rejects_bad_input(tmp_path, oblique):
    labels, vol = oblique
    with pytest.raises(FormatError, match="shape"):
        save_labels(tmp_path / "a.nii.gz", labels[:-1], vol)
    with pytest.raises(FormatError, match="format"):
        save_labels(tmp_path / "a.mha", labels, vol)
    with pytest.raises(FormatError, match="0..255"):
        save_labels(tmp_path / "a.nrrd", labels.astype(np.int16) * 300, vol)
    assert not os.listdir(tmp_path)


def test_load_rejects_non_label_data(tmp_path, oblique):
    import nibabel as nib

    labels, vol = oblique
    nib.save(nib.Nifti1Image(np.full((3, 4, 5), 0.5, np.float32), np.eye(4)), str(tmp_path / "f.nii"))
    with pytest.raises(FormatError, match="whole numbers"):
        load_labels(tmp_path / "f.nii")
    nib.save(nib.Nifti1Image(np.full((3, 4, 5), 300, np.int16), np.eye(4)), str(tmp_path / "big.nii"))
    with pytest.raises(FormatError, match="0..255"):
        load_labels(tmp_path / "big.nii")
    nib.save(nib.Nifti1Image(np.zeros((3, 4), np.uint8), np.eye(4)), str(tmp_path / "2d.nii"))
    with pytest.raises(FormatError, match="3D"):
        load_labels(tmp_path / "2d.nii")
    # a float label map with whole values loads
    nib.save(nib.Nifti1Image(np.full((3, 4, 5), 2.0, np.float32), np.eye(4)), str(tmp_path / "ok.nii"))
    got, _ = load_labels(tmp_path / "ok.nii")
    assert got.shape == (5, 4, 3) and (got == 2).all()


def test_load_rejects_corrupt_and_bombs(tmp_path, oblique):
    labels, vol = oblique
    for ext in EXTS:
        p = save_labels(tmp_path / f"lab.{ext}", labels, vol)
        good = p.read_bytes()
        for n in sorted({0, 1, 10, len(good) // 3, len(good) // 2, len(good) - 5, len(good) - 1}):
            bad = tmp_path / f"cut.{ext}"
            bad.write_bytes(good[:n])
            with pytest.raises(FormatError) as err:
                load_labels(bad)
            assert "cut." in str(err.value)
    # NRRD header declaring a 4096^3 volume over a tiny gzip payload
    hdr = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4096 4096 4096\nencoding: gzip\n\n"
    (tmp_path / "bomb.nrrd").write_bytes(hdr + gzip.compress(b"\0" * 1000))
    with pytest.raises(FormatError, match="more than|too large"):
        load_labels(tmp_path / "bomb.nrrd")
    # a gzip stream expanding far beyond the declared size is rejected without
    # decompressing it all
    import tracemalloc

    hdr = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: gzip\n\n"
    (tmp_path / "long.nrrd").write_bytes(hdr + gzip.compress(b"\1" * 50_000_000))
    tracemalloc.start()
    with pytest.raises(FormatError, match="more than"):
        load_labels(tmp_path / "long.nrrd")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 5_000_000
    with pytest.raises(FormatError, match="folder"):
        load_labels(tmp_path / "dir.nii.gz") if (tmp_path / "dir.nii.gz").mkdir() is None else None


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), 0.0])
@pytest.mark.parametrize("suffix", [".nrrd", ".nii"])
def test_label_map_with_bad_voxel_size_refused_in_one_line(tmp_path, suffix, bad):
    """A label map must match its series voxel for voxel: a NaN, infinite or zero voxel
    size is refused with one line naming the file (never a NaN volume in a report)."""
    labels = np.zeros((3, 4, 5), np.uint8)
    labels[1, 1:3, 1:4] = 1
    p = tmp_path / f"bad{suffix}"
    if suffix == ".nrrd":
        import nrrd

        nrrd.write(str(p), labels.transpose(2, 1, 0).copy(), {"space": "left-posterior-superior",
                                                              "space directions": np.diag([1.0, bad, 2.0])})
    else:
        import nibabel as nib

        nib.save(nib.Nifti1Image(labels.transpose(2, 1, 0).copy(), np.diag([1.0, 1.0, 2.0, 1.0])), p)
        raw = bytearray(p.read_bytes())  # nibabel will not write it: patch srow_y (byte 296), qform_code 0
        raw[296:312] = np.array([0.0, bad, 0.0, 0.0], "<f4").tobytes()
        raw[252:254] = b"\x00\x00"
        p.write_bytes(bytes(raw))
    with pytest.raises(FormatError) as exc:
        load_labels(p)
    assert "\n" not in str(exc.value) and str(p) in str(exc.value)


def test_label_map_over_the_memory_limit_refused(tmp_path, monkeypatch):
    """A label map bigger than the process may allocate: one line naming the file, before
    decompressing (CTUI_MEMORY_LIMIT stands in for RLIMIT_AS / cgroup memory.max)."""
    from ctui.engine.core.errors import CtuiError

    vol = Volume(data=np.zeros((40, 64, 64), np.int16), spacing=(1.0, 1.0, 1.0))
    labels = np.zeros((40, 64, 64), np.uint8)
    labels[10:20, 10:20, 10:20] = 1
    p = save_labels(tmp_path / "m.nii.gz", labels, vol)
    monkeypatch.setenv("CTUI_MEMORY_LIMIT", str(100_000))
    with pytest.raises(CtuiError) as exc:
        load_labels(p)
    msg = str(exc.value)
    assert "\n" not in msg and "m.nii.gz" in msg and "memory" in msg
    monkeypatch.delenv("CTUI_MEMORY_LIMIT")
    assert load_labels(p)[0].sum() == 1000
