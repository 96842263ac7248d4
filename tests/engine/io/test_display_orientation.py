"""The slice views show every input in the patient's frame, as radiologists read it
(axial: patient right on screen left, anterior up; coronal: right on the left, superior
up; sagittal: anterior on the left, superior up), whatever the file's axis order and
signs; display <-> voxel conversions are exact both ways and arrow keys move on screen
in the arrow's direction.

Truths: the same DICOM series written as a RAS NIfTI (and with permuted axes) gives the
same rendered pixels in the three views; a patient-space phantom sampled on head-first,
feet-first and sagittal grids gives identical display images and letters.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from ctui.engine.core.volume import Volume
from ctui.engine.core.windows import apply_window
from ctui.engine.io.series import load
from ctui.screens import cells, planes
from support import shared

LETTERS = {"axial": ("R", "L", "A", "P"), "coronal": ("R", "L", "S", "I"), "sagittal": ("A", "P", "S", "I")}


def _view_pixels(vol: Volume, plane: str, zyx, window=(40.0, 400.0)) -> np.ndarray:
    """The view as the TUI draws it: the plane through ``zyx``, windowed, fitted to 200x200 pixels."""
    pv = planes.plane_view(vol, plane)
    gray = apply_window(planes.take(vol.data, pv, zyx[pv.normal]), window)
    grid, _vm = cells.render_view(gray, (200, 200), spacing_yx=pv.spacing_yx)
    return grid


def _write_nifti(vol: Volume, path, *, order=(2, 1, 0), canonical=True) -> None:
    """``vol`` as a NIfTI with a RAS affine; ``order``: the (z, y, x) axes stored as i, j, k."""
    nib = pytest.importorskip("nibabel")
    lps = vol.affine  # (x, y, z) index -> LPS mm
    ras = np.diag([-1.0, -1.0, 1.0, 1.0]) @ lps
    zyx_to_xyz = [2, 1, 0]  # volume axis -> affine column
    aff = ras.copy()
    aff[:, :3] = ras[:, [zyx_to_xyz[a] for a in order]]
    img = nib.Nifti1Image(np.ascontiguousarray(np.transpose(vol.data, order)), aff)
    if canonical:
        img = nib.as_closest_canonical(img)
    nib.save(img, str(path))


@pytest.mark.parametrize("order,canonical", [((2, 1, 0), True), ((1, 2, 0), False), ((2, 1, 0), False)])
def test_dicom_and_nifti_show_the_same_pixels(tmp_path, order, canonical):
    dcm = load(shared("ct_head_phantom_philips"))
    path = tmp_path / "phantom.nii.gz"
    _write_nifti(dcm, path, order=order, canonical=canonical)
    nii = load(path)
    zyx_d = (dcm.shape[0] // 2, 200, 300)  # off-centre so a mirror image would differ
    zyx_n = tuple(int(round(v)) for v in nii.mm_to_index(dcm.index_to_mm(zyx_d)))
    for plane in planes.PLANES:
        pv_d, pv_n = planes.plane_view(dcm, plane), planes.plane_view(nii, plane)
        assert pv_d.letters == pv_n.letters == LETTERS[plane]
        assert pv_d.spacing_yx == pytest.approx(pv_n.spacing_yx, abs=1e-4)
        a, b = _view_pixels(dcm, plane, zyx_d), _view_pixels(nii, plane, zyx_n)
        assert a.std() > 5, plane  # the view shows structure
        assert np.array_equal(a, b), plane
        # the cursor sits on the same screen pixel
        assert planes.cursor_in(pv_d, zyx_d, dcm.shape) == planes.cursor_in(pv_n, zyx_n, nii.shape)


def _phantom_on(direction: np.ndarray, n: int = 21) -> Volume:
    """An asymmetric patient-space phantom sampled on an n^3 1-mm grid centred on 0
    whose index axes (columns: x, y, z) are ``direction``'s."""
    idx = np.indices((n, n, n)).astype(float)  # (z, y, x)
    ijk = np.stack([idx[2], idx[1], idx[0]], axis=-1) - (n - 1) / 2  # (x, y, z) index offsets
    p = ijk @ np.asarray(direction, float).T  # LPS mm
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    # distinct markers: left, posterior, superior, and a value ramp along each axis
    val = 10 * x + 3 * y + 1 * z
    val += 500 * ((x - 6) ** 2 + y**2 + z**2 < 9)  # patient's left
    val += 800 * (x**2 + (y - 6) ** 2 + z**2 < 9)  # posterior
    val += 1100 * (x**2 + y**2 + (z - 6) ** 2 < 9)  # superior
    return Volume(np.rint(val).astype(np.int16), spacing=(1.0, 1.0, 1.0), direction=direction, modality="CT")


_HFS = np.eye(3)  # axial head first: x to L, y to P, slices to S
_FFS = np.array([[-1, 0, 0], [0, 1, 0], [0, 0, -1]], float)  # feet first: x to R, slices to I
_SAG = np.array([[0, 0, 1], [1, 0, 0], [0, -1, 0]], float)  # sagittal: x to P, y to I, slices to L
_SAG_R = np.array([[0, 0, -1], [1, 0, 0], [0, -1, 0]], float)  # sagittal, slices to R
_COR = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float)  # coronal: x to L, y to I, slices to P


def test_feet_first_and_sagittal_series_look_like_head_first():
    ref = _phantom_on(_HFS)
    c = (10, 10, 10)
    for direction in (_FFS, _SAG, _SAG_R, _COR):
        vol = _phantom_on(direction)
        for plane in planes.PLANES:
            pv = planes.plane_view(vol, plane)
            assert pv.letters == LETTERS[plane], (plane, direction)
            assert pv.note == ""
            img = planes.take(vol.data, pv, c[pv.normal])
            want = planes.take(ref.data, planes.plane_view(ref, plane), c[0 if plane == "axial" else 2 if plane == "sagittal" else 1])
            assert np.array_equal(img, want), (plane, direction)
    # the file's slices are the sagittal plane of a sagittal acquisition
    assert planes.slice_plane(_phantom_on(_SAG)) == "sagittal"
    assert planes.slice_plane(ref) == "axial"


def test_screen_directions_and_exact_round_trips():
    """Moving right/down on screen goes to the patient's left/posterior (axial) or
    left/inferior (coronal) or posterior/inferior (sagittal); cursor_in and voxel_of
    invert each other on every voxel of every plane."""
    right_down = {"axial": ((1, 0, 0), (0, 1, 0)), "coronal": ((1, 0, 0), (0, 0, -1)),
                  "sagittal": ((0, 1, 0), (0, 0, -1))}
    for direction in (_HFS, _FFS, _SAG, _SAG_R, _COR):
        vol = Volume(np.zeros((5, 6, 7), np.int16), spacing=(2.0, 1.0, 1.5), direction=direction)
        shape = vol.shape
        for plane in planes.PLANES:
            pv = planes.plane_view(vol, plane)
            start = (2, 3, 3)
            for (dx, dy), want in zip(((1, 0), (0, 1)), right_down[plane]):
                step = vol.index_to_mm(planes.moved(pv, start, dx, dy)) - vol.index_to_mm(start)
                assert np.sign(np.round(step, 6)).tolist() == list(want), (plane, dx, dy)
            img = planes.take(np.arange(np.prod(shape)).reshape(shape), pv, start[pv.normal])
            for zyx in itertools.product(*(range(n) for n in shape)):
                if zyx[pv.normal] != start[pv.normal]:
                    continue
                c, r = planes.cursor_in(pv, zyx, shape)
                assert img[r, c] == np.ravel_multi_index(zyx, shape)  # the pixel shows that voxel
                assert planes.voxel_of(pv, c, r, zyx, shape) == zyx


def test_oblique_stack_gets_a_note():
    vol = load(shared("mr_sagittal_oblique"))
    for plane in planes.PLANES:
        pv = planes.plane_view(vol, plane)
        assert pv.letters == LETTERS[plane]
        assert "oblique" in pv.note
    assert planes.slice_plane(vol) == "sagittal"


def test_nrrd_with_permuted_flipped_axes_shows_the_same_pixels(tmp_path):
    """An NRRD (LPS space directions) storing the axes as (y, x, z) with y reversed."""
    nrrd = pytest.importorskip("nrrd")
    dcm = load(shared("ct_head_phantom_philips"), crop=(10, 18, 100, 420, 60, 460))
    data = dcm.data[:, ::-1, :]  # y reversed: its first voxel is the last row
    origin = np.asarray(dcm.index_to_mm((0, dcm.shape[1] - 1, 0)), float)
    dirs = {v: dcm.direction[:, 2 - v] * dcm.spacing[v] for v in range(3)}
    dirs[1] = -dirs[1]
    order = (1, 2, 0)  # NRRD axes i, j, k = volume y, x, z
    arr = np.transpose(data, order)  # [i, j, k]
    header = {"space": "left-posterior-superior", "space directions": np.array([dirs[v] for v in order]),
              "space origin": origin, "kinds": ["domain"] * 3}
    path = tmp_path / "phantom.nrrd"
    nrrd.write(str(path), np.ascontiguousarray(arr), header, index_order="F")
    vol = load(path)
    zyx_d = (dcm.shape[0] // 2, 140, 230)
    zyx_n = tuple(int(round(v)) for v in vol.mm_to_index(dcm.index_to_mm(zyx_d)))
    for plane in planes.PLANES:
        pv = planes.plane_view(vol, plane)
        assert pv.letters == LETTERS[plane]
        a, b = _view_pixels(dcm, plane, zyx_d), _view_pixels(vol, plane, zyx_n)
        assert a.std() > 5 and np.array_equal(a, b), plane
