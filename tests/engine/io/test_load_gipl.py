"""GIPL (.gipl, .gipl.gz) read by ctui against ITK's reader (SimpleITK): voxel for voxel, spacing and
origin, on ITK-SNAP's MR brain and segmentation (../shared/data/itksnap_brain_mr) and on files ITK
writes; the segmentation as labels over the MR (``--labels``); broken files refused in one line."""

from __future__ import annotations

import gzip
import struct
import subprocess
import sys

import numpy as np
import pytest

from support import ROOT, shared
from ctui.engine.core.errors import CtuiError
from ctui.engine.io.series import load, scan

sitk = pytest.importorskip("SimpleITK")


def _itk(path):
    img = sitk.ReadImage(str(path))
    return sitk.GetArrayFromImage(img), img.GetSpacing()[::-1], img.GetOrigin()


def _brain(name):
    return shared("itksnap_brain_mr") / f"MRIcrop-{name}.gipl.gz"


@pytest.mark.parametrize("name", ["orig", "seg"])
def test_itksnap_brain_voxel_for_voxel_with_itk(name):
    path = _brain(name)
    ref, ref_spacing, ref_origin = _itk(path)
    vol = load(path)
    assert vol.data.shape == ref.shape == (64, 110, 78)
    assert vol.data.dtype == ref.dtype  # values as stored: int16 MR, uint8 labels
    assert np.array_equal(vol.data, ref)
    assert vol.spacing == pytest.approx(ref_spacing) and tuple(vol.origin) == pytest.approx(ref_origin)
    assert np.allclose(vol.direction, np.eye(3))
    assert [a.kind for a in vol.assumptions] == ["orientation"]
    assert scan(path)[0]["shape_zyx"] == [64, 110, 78]


def test_itksnap_segmentation_as_labels_over_the_mr():
    from ctui.engine.actions.opened import open_input

    ref, _, _ = _itk(_brain("seg"))
    opened = open_input(_brain("orig"), labels=_brain("seg"))
    assert np.array_equal(opened.labels, ref)
    assert opened.object_ids == sorted(int(v) for v in np.unique(ref) if v)
    assert any("orientation" in n for n in opened.notes)
    # names and colours from ITK-SNAP's label description beside it (MRIcrop-seg.label)
    objects = {o["id"]: o for o in opened.project.objects}
    assert objects[1]["name"] == "vent-lat" and objects[1]["color"] == [0, 30, 255]
    assert objects[8]["name"] == "corpus-callosum" and objects[8]["color"] == [255, 8, 186]


def test_itksnap_label_description_beside_a_gipl(tmp_path):
    from ctui.engine.io.imports import read_label_file

    arr = np.zeros((3, 4, 5), np.uint8)
    arr[1, 1:3, 1:4], arr[2, 0, 0] = 2, 7
    _write_itk(tmp_path / "seg.gipl.gz", arr, (1.0, 1.0, 2.0), (0.0, 0.0, 0.0))
    (tmp_path / "seg.label").write_text('# IDX -R- -G- -B- -A-- VIS MSH LABEL\n'
                                        '    0  0 0 0 0.00 0 0 "Clear"\n'
                                        '    2  10 20 300 1.00 1 1 "left kidney"\n'
                                        'not a label line\n')
    imp = read_label_file(tmp_path / "seg.gipl.gz")
    assert np.array_equal(imp.labels, arr) and imp.kind == "gipl"
    assert [(o["id"], o["name"], o["color"]) for o in imp.objects][0] == (2, "left kidney", [10, 20, 255])
    assert imp.objects[1]["id"] == 7 and imp.objects[1]["name"] == "object 7"  # not described: ctui's own


def _write_itk(path, arr, spacing_xyz, origin):
    img = sitk.GetImageFromArray(arr)
    img.SetSpacing(spacing_xyz)
    img.SetOrigin(origin)
    sitk.WriteImage(img, str(path), useCompression=str(path).endswith(".gz"))


@pytest.mark.parametrize("dtype", ["int16", "uint16", "uint8", "int8", "float32", "float64"])
@pytest.mark.parametrize("suffix", [".gipl", ".gipl.gz"])
def test_files_itk_writes(tmp_path, dtype, suffix):
    rng = np.random.default_rng(7)
    arr = (rng.normal(0, 50, (7, 9, 11)) + (100 if dtype.startswith("u") else 0)).clip(*(
        (0, 255) if dtype == "uint8" else (-128, 127) if dtype == "int8" else (-1000, 3000))).astype(dtype)
    path = tmp_path / f"x{suffix}"
    _write_itk(path, arr, (0.5, 0.75, 2.5), (10.0, -20.0, 30.5))
    ref, ref_spacing, ref_origin = _itk(path)
    vol = load(path)
    assert vol.data.dtype == ref.dtype and np.array_equal(vol.data, ref) and np.array_equal(vol.data, arr)
    assert vol.spacing == pytest.approx((2.5, 0.75, 0.5)) == ref_spacing
    assert tuple(vol.origin) == pytest.approx((10.0, -20.0, 30.5)) == ref_origin


@pytest.mark.parametrize("suffix", [".gipl", ".gipl.gz"])
def test_crop_and_downsample_read_the_same_voxels(tmp_path, suffix):
    arr = np.arange(8 * 10 * 12, dtype=np.int16).reshape(8, 10, 12)
    path = tmp_path / f"x{suffix}"
    _write_itk(path, arr, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0))
    vol = load(path, crop=(2, 6, 1, 9, 3, 11), downsample=(1, 2, 2))
    assert np.array_equal(vol.data, arr[2:6, 1:9:2, 3:11:2])
    assert vol.spacing == pytest.approx((3.0, 4.0, 2.0))
    assert tuple(vol.origin) == pytest.approx((3 * 1.0, 1 * 2.0, 2 * 3.0))  # first voxel read, x y z mm


def _header(*, dims=(4, 3, 2, 1), code=15, spacing=(1.0, 1.0, 1.0), magic=0xEFFFE9B0) -> bytearray:
    h = bytearray(256)
    h[0:8] = struct.pack(">4H", *dims)
    h[8:10] = struct.pack(">H", code)
    h[10:26] = struct.pack(">4f", *spacing, 0.0)
    h[252:256] = struct.pack(">I", magic)
    return h


def _refused(path, *words):
    with pytest.raises(CtuiError) as exc:
        load(path)
    msg = str(exc.value)
    assert "\n" not in msg and path.name in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


def test_zero_spacing_is_an_assumption_and_the_older_magic_reads(tmp_path):
    path = tmp_path / "old.gipl"
    path.write_bytes(bytes(_header(spacing=(0.0, 0.8, float("nan")), magic=0x2AE389B8)) + bytes(range(48)))
    vol = load(path)
    assert np.array_equal(vol.data, np.frombuffer(bytes(range(48)), ">i2").reshape(2, 3, 4))
    assert vol.spacing == pytest.approx((1.0, 0.8, 1.0))
    assert sorted(a.kind for a in vol.assumptions) == ["orientation", "spacing"]


def test_fuzz_broken_files_refused_in_one_line(tmp_path):
    data = bytes(2 * 4 * 3 * 2)
    cases = {
        "short.gipl": bytes(_header())[:100],  # truncated header
        "magic.gipl": bytes(_header(magic=0x12345678)) + data,  # wrong magic
        "type.gipl": bytes(_header(code=99)) + data,  # unknown image type
        "complex.gipl": bytes(_header(code=192)) + data,
        "empty.gipl": bytes(_header(dims=(0, 3, 2, 1))) + data,
        "cut.gipl": bytes(_header()) + data[:-5],  # voxels cut short
        "huge.gipl": bytes(_header(dims=(65535, 65535, 65535, 1))) + data,  # header lies: refused before allocating
        "shorthead.gipl.gz": gzip.compress(bytes(_header())[:200]),
        "magic.gipl.gz": gzip.compress(bytes(_header(magic=0)) + data),
        "cut.gipl.gz": gzip.compress(bytes(_header()) + data)[:-30],  # gzip stream cut
        "short.gipl.gz": gzip.compress(bytes(_header()) + data[:10]),  # whole stream, too few voxels
        "huge.gipl.gz": gzip.compress(bytes(_header(dims=(65535, 65535, 65535, 1))) + data),
        "notgzip.gipl.gz": bytes(_header()) + data,
    }
    words = {"short.gipl": ["truncated GIPL header"], "magic.gipl": ["not a GIPL file", "0x12345678"],
             "type.gipl": ["image type 99"], "complex.gipl": ["complex"], "cut.gipl": ["truncated"],
             "huge.gipl": ["truncated"], "shorthead.gipl.gz": ["truncated GIPL header"],
             "magic.gipl.gz": ["not a GIPL file"], "short.gipl.gz": ["truncated"], "huge.gipl.gz": ["more than"],
             "notgzip.gipl.gz": ["not a gzip file"]}
    for name, blob in cases.items():
        p = tmp_path / name
        p.write_bytes(blob)
        _refused(p, *words.get(name, []))
        from ctui.engine.io.labels import load_labels

        with pytest.raises(CtuiError) as exc:
            load_labels(p)
        assert "\n" not in str(exc.value) and name in str(exc.value)


def test_cli_info_opens_the_brain_and_says_the_orientation_assumption():
    r = subprocess.run([sys.executable, "-m", "ctui", "info", str(_brain("orig"))], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "64 x 110 x 78" in r.stdout and "0 .. 269" in r.stdout and "GIPL stores no orientation" in r.stdout
