"""Label files from other tools over their series: dcmqi DICOM-SEGs (3D Slicer's converter),
a SimpleITK NIfTI, and label maps whose geometry does not match (refused, said how)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from support import shared

from ctui.engine.actions.measure import measure_object
from ctui.engine.actions.opened import open_input
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.geometry import Geometry
from ctui.engine.io.imports import label_kind, place_on_grid, read_label_file
from ctui.engine.io.phantom import make_phantom, write_series
from ctui.engine.io.series import load


@pytest.fixture(scope="module")
def dcmqi():
    d = shared("dcmqi_seg")
    return d, load(d / "ct-3slice")


def _nrrd_masks(paths, grid) -> dict[int, np.ndarray]:
    out = {}
    for p in paths:
        imp = read_label_file(p, grid=grid)
        for o in imp.objects:
            out[o["id"]] = imp.mask(o["id"])
    return out


def test_dcmqi_binary_seg_equals_its_nrrd(dcmqi):
    d, ct = dcmqi
    imp = read_label_file(d / "liver.dcm", grid=ct)
    assert imp.kind == "dicom-seg" and [o["name"] for o in imp.objects] == ["Liver"]
    ref = _nrrd_masks([d / "liver_seg.nrrd"], ct)
    np.testing.assert_array_equal(imp.mask(1), ref[1])
    assert imp.voxel_counts() == {1: 107098}


def test_dcmqi_overlapping_segments_each_keep_their_voxels(dcmqi):
    d, ct = dcmqi
    imp = read_label_file(d / "partial_overlaps.dcm", grid=ct)
    assert [o["name"] for o in imp.objects] == ["GREEN", "ORANGE", "PURPLE", "LIGHT_BLUE", "DARK_BLUE"]
    ref = _nrrd_masks([d / f"partial_overlaps-{i}.nrrd" for i in (1, 2, 3)], ct)
    assert sorted(ref) == [1, 2, 3, 4, 5]
    for k, m in ref.items():
        np.testing.assert_array_equal(imp.mask(k), m, err_msg=f"segment {k}")
    assert imp.voxel_counts() == {k: int(m.sum()) for k, m in ref.items()}
    assert any("overlapping" in w for w in imp.warnings)
    # the label map gives an overlapped voxel to the later segment
    both = ref[1] & ref[2] & ~ref[3] & ~ref[4] & ~ref[5]
    assert both.any() and np.all(imp.labels[both] == 2)


def test_dcmqi_labelmap_seg_on_its_own_geometry(dcmqi):
    d, ct = dcmqi
    seg = read_label_file(d / "sparse-labelmap-noppv.dcm")
    ref = read_label_file(d / "sparse_labelmap_noppv_seg.nrrd")
    assert seg.geometry.same_grid(ref.geometry)
    assert [o["name"] for o in seg.objects] == ["Liver"]  # the LABELMAP's segment 0 is its background
    np.testing.assert_array_equal(seg.labels, ref.labels)
    assert seg.voxel_counts() == {1: 630}
    # drawn on another grid than ct-3slice: refused with how the grids differ
    with pytest.raises(CtuiError, match="spacing") as err:
        read_label_file(d / "sparse-labelmap-noppv.dcm", grid=ct)
    assert "Resample" in str(err.value)


def test_open_and_measure_seg_over_series(dcmqi):
    d, ct = dcmqi
    opened = open_input(d / "ct-3slice", labels=d / "partial_overlaps.dcm")
    assert opened.object_ids == [1, 2, 3, 4, 5] and opened.volume is not None
    assert opened.object_colors()[1] == [128, 174, 128]
    vox_ml = float(np.prod(ct.spacing)) / 1000.0
    r = measure_object(opened, object=1, mesh=False)  # GREEN: partly under ORANGE in the label map
    assert r.volume_ml["voxels"] == pytest.approx(9602 * vox_ml)


def test_measure_cli_with_labels(dcmqi, capsys):
    from ctui.cli import main

    d, ct = dcmqi
    assert main(["measure", str(d / "ct-3slice"), "--labels", str(d / "liver.dcm"), "--no-mesh", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["volume_ml"]["voxels"] == pytest.approx(107098 * float(np.prod(ct.spacing)) / 1000.0, rel=1e-6)


@pytest.fixture(scope="module")
def phantom(tmp_path_factory):
    root = tmp_path_factory.mktemp("imp")
    vol, truth = make_phantom(shape=(24, 52, 52), spacing=(8.0, 5.0, 5.0), noise_sd=0, drift=False, supersample=2)
    write_series(root / "series", vol)
    return root, load(root / "series"), truth


def _sitk_labels(v, labels):
    sitk = pytest.importorskip("SimpleITK")
    img = sitk.GetImageFromArray(labels)  # numpy (z, y, x) -> ITK (x, y, z)
    img.SetSpacing(tuple(float(s) for s in v.spacing[::-1]))
    img.SetOrigin(tuple(float(o) for o in v.origin))
    img.SetDirection(tuple(float(c) for c in v.direction.ravel()))
    return sitk, img


def test_simpleitk_nifti_opens_and_measures_right(phantom):
    root, v, truth = phantom
    from scipy import ndimage

    spine = next(o for o in truth["objects"] if o["name"] == "spine")
    comp, _ = ndimage.label((v.data > 370) & (v.data < 1100))  # half-way to the soft tissue (40 HU)
    labels = (comp == comp[tuple(spine["seed_zyx"])]).astype(np.uint8) * 3  # the spine (700 HU), id 3
    sitk, img = _sitk_labels(v, labels)
    path = root / "spine.nii.gz"
    sitk.WriteImage(img, str(path))
    assert label_kind(path) == "nifti"
    opened = open_input(root / "series", labels=path)
    np.testing.assert_array_equal(opened.labels, labels)
    r = measure_object(opened, object=3)
    n = int((labels == 3).sum())
    assert r.volume_ml["voxels"] == pytest.approx(n * 8 * 5 * 5 / 1000.0)
    assert r.volume_ml["mesh"] == pytest.approx(spine["volume_ml"], rel=0.03)
    # the same label map flipped along x by SimpleITK (another axis order on disk) still lands right
    flipped = sitk.Flip(img, [True, False, False])
    sitk.WriteImage(flipped, str(root / "flipped.nii.gz"))
    np.testing.assert_array_equal(read_label_file(root / "flipped.nii.gz", grid=v).labels, labels)


def test_mismatched_nifti_is_refused_with_how(phantom):
    root, v, _ = phantom
    labels = np.zeros(v.shape, np.uint8)
    labels[10, 20:30, 20:30] = 1
    sitk, img = _sitk_labels(v, labels)
    img.SetOrigin(tuple(o + 2.5 for o in v.origin))  # half a voxel off in-plane
    sitk.WriteImage(img, str(root / "shifted.nii.gz"))
    with pytest.raises(CtuiError, match="fraction of a voxel.*origin"):
        open_input(root / "series", labels=root / "shifted.nii.gz")
    img = sitk.GetImageFromArray(labels[:, ::2, ::2].copy())
    img.SetSpacing((10.0, 10.0, 8.0))
    img.SetOrigin(tuple(float(o) for o in v.origin))
    sitk.WriteImage(img, str(root / "coarse.nrrd"))
    with pytest.raises(CtuiError, match=r"spacing \(z, y, x\) \(8, 10, 10\)"):
        read_label_file(root / "coarse.nrrd", grid=v)


def test_place_on_grid_crops_and_offsets():
    dst = Geometry((10, 20, 30), (2.0, 1.0, 1.0), (0.0, 0.0, 0.0))
    box = np.ones((3, 4, 5), np.uint8)
    src = Geometry((3, 4, 5), (2.0, 1.0, 1.0), tuple(dst.index_to_mm((2, 5, 7))))
    out = place_on_grid(box, src, dst)
    assert out.sum() == box.size and out[2:5, 5:9, 7:12].all()
    far = Geometry((3, 4, 5), (2.0, 1.0, 1.0), tuple(dst.index_to_mm((9, 5, 7))))
    with pytest.raises(CtuiError, match="outside the series"):
        place_on_grid(box, far, dst)


def test_dcmqi_seg_written_again_by_ctui(dcmqi, tmp_path):
    """Real series: dcmqi's liver SEG opened over ct-3slice, exported as DICOM-SEG and RTSTRUCT, read back equal."""
    from ctui.engine.actions.export import export

    d, ct = dcmqi
    opened = open_input(d / "ct-3slice", labels=d / "liver.dcm")
    for fmt in ("dicom-seg", "rtstruct"):
        out = tmp_path / f"{fmt}.dcm"
        export(opened, format=fmt, out=out)
        back = read_label_file(out, grid=ct)
        assert [o["name"] for o in back.objects] == ["Liver"]
        np.testing.assert_array_equal(back.labels, opened.labels)


def test_broken_or_foreign_label_files_are_one_line_errors(phantom, tmp_path):
    from ctui.engine.actions.export import export
    from ctui.engine.actions.project import new_project, save_project
    from ctui.engine.core.errors import FormatError

    root, v, _ = phantom
    labels = np.zeros(v.shape, np.uint8)
    labels[8:12, 20:30, 20:30] = 1
    save_project(tmp_path / "p.ctui", new_project(v, source_path=root / "series", labels=labels))
    for fmt in ("dicom-seg", "rtstruct"):
        good = tmp_path / f"{fmt}.dcm"
        export(tmp_path / "p.ctui", format=fmt, out=good)
        raw = good.read_bytes()
        (tmp_path / "cut.dcm").write_bytes(raw[: len(raw) // 2])
        with pytest.raises(FormatError):
            read_label_file(tmp_path / "cut.dcm", grid=v)
    ct_slice = min((root / "series").iterdir())
    with pytest.raises(FormatError, match="not a segmentation"):
        read_label_file(ct_slice, grid=v)
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(FormatError, match="not a label file"):
        read_label_file(tmp_path / "notes.txt", grid=v)


def test_overlapping_segments_written_back_overlapping(dcmqi, tmp_path):
    """dcmqi's five overlapping segments through ctui and out as DICOM-SEG and RTSTRUCT: every segment keeps
    its voxels."""
    from ctui.engine.actions.export import export

    d, ct = dcmqi
    opened = open_input(d / "ct-3slice", labels=d / "partial_overlaps.dcm")
    for fmt in ("dicom-seg", "rtstruct"):
        export(opened, format=fmt, out=tmp_path / f"again-{fmt}.dcm")
        back = read_label_file(tmp_path / f"again-{fmt}.dcm", grid=ct)
        assert [o["name"] for o in back.objects] == ["GREEN", "ORANGE", "PURPLE", "LIGHT_BLUE", "DARK_BLUE"]
        assert back.voxel_counts() == {1: 9602, 2: 11888, 3: 10743, 4: 6693, 5: 4713}, fmt


@pytest.mark.filterwarnings("ignore::UserWarning")  # pydicom's notes on the broken files
def test_fuzzed_seg_and_rtstruct_never_crash(phantom, tmp_path):
    """Flipped bytes and cut files: a one-line CtuiError or a clean read, never a traceback."""
    from ctui.engine.actions.export import export
    from ctui.engine.actions.project import new_project, save_project

    root, v, _ = phantom
    labels = np.zeros(v.shape, np.uint8)
    labels[8:12, 20:30, 20:30] = 1
    labels[9, 24:26, 24:26] = 0
    save_project(tmp_path / "p.ctui", new_project(v, source_path=root / "series", labels=labels))
    rng = np.random.default_rng(7)
    for fmt in ("dicom-seg", "rtstruct"):
        good = tmp_path / f"{fmt}.dcm"
        export(tmp_path / "p.ctui", format=fmt, out=good)
        raw = bytearray(good.read_bytes())
        for n in range(25):
            bad = bytearray(raw)
            for i in rng.integers(132, len(bad), size=int(rng.integers(1, 8))):
                bad[i] = int(rng.integers(0, 256))
            if n % 5 == 4:
                bad = bad[: int(rng.integers(132, len(bad)))]
            (tmp_path / "f.dcm").write_bytes(bytes(bad))
            try:
                imp = read_label_file(tmp_path / "f.dcm", grid=v)
            except CtuiError as exc:
                assert "\n" not in str(exc)
            else:
                assert imp.labels.shape == v.shape


def test_seg_too_big_for_memory_is_refused_before_reading(dcmqi, monkeypatch):
    d, ct = dcmqi
    monkeypatch.setenv("CTUI_MEMORY_LIMIT", str(1_000_000))
    with pytest.raises(CtuiError, match="memory"):
        read_label_file(d / "liver.dcm", grid=ct)


def test_tui_open_with_labels_session(phantom):
    """`ctui open SERIES --labels FILE` builds the TUI session from the label file; more objects
    than the TUI edits are refused with what to use instead."""
    from ctui.commands.open import _labels_session

    root, v, _ = phantom
    labels = np.zeros(v.shape, np.uint8)
    labels[10, 20:30, 20:30] = 2
    sitk, img = _sitk_labels(v, labels)
    sitk.WriteImage(img, str(root / "two.nrrd"))
    s = _labels_session(str(root / "series"), str(root / "two.nrrd"), {})
    assert sorted(s.seg.objects) == [2] and int((s.seg.labels == 2).sum()) == 100
    many = np.zeros(v.shape, np.uint8)
    for k in range(1, 13):
        many[k, 5:8, 5:8] = k
    sitk, img = _sitk_labels(v, many)
    sitk.WriteImage(img, str(root / "many.nii.gz"))
    with pytest.raises(CtuiError, match="measure/mesh/render"):
        _labels_session(str(root / "series"), str(root / "many.nii.gz"), {})
