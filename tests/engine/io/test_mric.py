"""MRIC contour files: byte layout, round trip, and rejection of corrupted files."""

from __future__ import annotations

import os
import struct
import tracemalloc

import numpy as np
import pytest

from ctui.engine.core.errors import FormatError
from ctui.engine.io.mric import SIGNATURE, read_mric, write_mric


def _spec_bytes(width, height, axis, image, slices) -> bytes:
    """The format written out field by field with struct, straight from the spec."""
    out = bytearray(b"VAJIRA-MRICUBE-V8")
    out += struct.pack("<iiiii", width, height, len(slices), axis[0], axis[1])
    out += bytes(image.astype(np.uint8).ravel())
    for objects in slices:
        out += struct.pack("<i", len(objects))
        for borders in objects:
            out += struct.pack("<i", len(borders))
            for b in borders:
                out += struct.pack("<i", len(b))
                for x, y in b:
                    out += struct.pack("<hhB", int(x), int(y), 255)
    return bytes(out)


def _sample(rng, width=23, height=17, n_slices=4):
    slices = []
    for _ in range(n_slices):
        objs = []
        for _ in range(int(rng.integers(0, 3))):
            objs.append([rng.integers(0, [width + 1, height + 1], size=(int(rng.integers(0, 9)), 2)) for _ in range(int(rng.integers(0, 3)))])
        slices.append(objs)
    image = rng.integers(0, 256, size=(height, width)).astype(np.uint8)
    return slices, image


def test_bytes_match_the_prototype_layout(tmp_path):
    rng = np.random.default_rng(1)
    slices, image = _sample(rng)
    p = write_mric(tmp_path / "a.mric", slices, width=23, height=17, axis=(5, -3), image=image)
    assert p.read_bytes() == _spec_bytes(23, 17, (5, -3), image, slices)
    assert len(SIGNATURE) == 17


def test_known_tiny_file(tmp_path):
    # one slice, one object, one border with two points: hand-computed bytes
    write_mric(tmp_path / "t.mric", [[[np.array([[1, 2], [3, 0]])]]], width=4, height=2, axis=(0, 0), image=np.array([[7, 9, 0, 1], [2, 3, 4, 5]]))
    expected = (
        b"VAJIRA-MRICUBE-V8"
        + bytes.fromhex("04000000" "02000000" "01000000" "00000000" "00000000")
        + b"\x07\x09\x00\x01\x02\x03\x04\x05"
        + bytes.fromhex("01000000" "01000000" "02000000")
        + bytes.fromhex("0100" "0200" "ff" "0300" "0000" "ff")
    )
    assert (tmp_path / "t.mric").read_bytes() == expected


def test_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    slices, image = _sample(rng, 40, 30, 12)
    write_mric(tmp_path / "r.mric", slices, width=40, height=30, axis=(11, 12), image=image)
    m = read_mric(tmp_path / "r.mric")
    assert (m.width, m.height, m.axis) == (40, 30, (11, 12))
    assert np.array_equal(m.image, image) and m.image.dtype == np.uint8
    assert len(m.slices) == len(slices)
    for s_read, s_src in zip(m.slices, slices):
        assert len(s_read) == len(s_src)
        for o_read, o_src in zip(s_read, s_src):
            assert len(o_read) == len(o_src)
            for b_read, b_src in zip(o_read, o_src):
                assert b_read.shape == (len(b_src), 2)
                assert np.array_equal(b_read, np.asarray(b_src).reshape(-1, 2))
    assert m.n_points() == sum(len(b) for s in slices for o in s for b in o)


def test_float_points_are_rounded_and_default_image(tmp_path):
    write_mric(tmp_path / "f.mric", [[[np.array([[1.4, 2.6], [0.0, 3.0]])]]], width=5, height=5)
    m = read_mric(tmp_path / "f.mric")
    assert m.slices[0][0][0].tolist() == [[1, 3], [0, 3]]
    assert m.image.shape == (5, 5) and not m.image.any()


def test_writer_rejects_points_outside(tmp_path):
    with pytest.raises(FormatError, match="outside"):
        write_mric(tmp_path / "o.mric", [[[np.array([[6, 0]])]]], width=5, height=5)
    with pytest.raises(FormatError, match="outside"):
        write_mric(tmp_path / "o.mric", [[[np.array([[0, -1]])]]], width=5, height=5)
    assert not os.listdir(tmp_path)


def _small_file(tmp_path) -> bytes:
    slices = [[[np.array([[0, 0], [3, 1], [2, 2]])], [np.array([[4, 4]]), np.array([[1, 1], [2, 1]])]], [], [[[]]]]
    write_mric(tmp_path / "s.mric", slices, width=5, height=4, axis=(1, 2), image=np.arange(20).reshape(4, 5))
    return (tmp_path / "s.mric").read_bytes()


def test_truncated_at_every_length_is_rejected(tmp_path):
    good = _small_file(tmp_path)
    read_mric(tmp_path / "s.mric")
    bad = tmp_path / "bad.mric"
    for n in range(len(good)):
        bad.write_bytes(good[:n])
        with pytest.raises(FormatError) as err:
            read_mric(bad)
        msg = str(err.value)
        assert "bad.mric" in msg and "\n" not in msg


def test_trailing_garbage_is_rejected(tmp_path):
    good = _small_file(tmp_path)
    (tmp_path / "x.mric").write_bytes(good + b"\0")
    with pytest.raises(FormatError, match="trailing"):
        read_mric(tmp_path / "x.mric")


def test_wrong_signature(tmp_path):
    good = _small_file(tmp_path)
    (tmp_path / "x.mric").write_bytes(b"VAJIRA-MRICUBE-V7" + good[17:])
    with pytest.raises(FormatError, match="signature"):
        read_mric(tmp_path / "x.mric")


def _patch(good: bytes, off: int, fmt: str, value) -> bytes:
    b = bytearray(good)
    struct.pack_into(fmt, b, off, value)
    return bytes(b)


@pytest.mark.parametrize(
    "field_off,value,match",
    [
        (17, 0, "slice size"),  # width 0
        (21, -4, "slice size"),  # negative height
        (17, 2**31 - 1, "slice size"),  # huge width
        (25, 2**31 - 1, "slice count"),  # huge slice count
        (25, -1, "negative slice count"),
    ],
)
def test_bad_header_counts(tmp_path, field_off, value, match):
    good = _small_file(tmp_path)
    (tmp_path / "x.mric").write_bytes(_patch(good, field_off, "<i", value))
    with pytest.raises(FormatError, match=match):
        read_mric(tmp_path / "x.mric")


def test_huge_counts_never_allocate(tmp_path):
    good = _small_file(tmp_path)
    first = 17 + 20 + 20  # first slice's object count
    cases = {
        "object": _patch(good, first, "<i", 2**31 - 1),
        "border": _patch(good, first + 4, "<i", 2**31 - 1),
        "point": _patch(good, first + 8, "<i", 2**31 - 1),
        "negative": _patch(good, first + 8, "<i", -7),
    }
    for name, data in cases.items():
        (tmp_path / "h.mric").write_bytes(data)
        tracemalloc.start()
        with pytest.raises(FormatError, match="count"):
            read_mric(tmp_path / "h.mric")
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        # tracemalloc counts every thread of the test process (a daemon of an earlier test may allocate
        # meanwhile: 113,589 B seen under 5 suites in parallel); a count of 2**31 read as allocated would
        # be gigabytes, so 1 MB still tells the two apart
        assert peak < 1024 * 1024, (name, peak)


def test_bad_marker_and_coordinates(tmp_path):
    good = _small_file(tmp_path)
    first_point = 17 + 20 + 20 + 12
    with pytest.raises(FormatError, match="marker"):
        (tmp_path / "m.mric").write_bytes(_patch(good, first_point + 4, "<B", 254))
        read_mric(tmp_path / "m.mric")
    with pytest.raises(FormatError, match="outside"):
        (tmp_path / "m.mric").write_bytes(_patch(good, first_point, "<h", 6))  # x = 6 > width 5
        read_mric(tmp_path / "m.mric")
    with pytest.raises(FormatError, match="outside"):
        (tmp_path / "m.mric").write_bytes(_patch(good, first_point + 2, "<h", -1))
        read_mric(tmp_path / "m.mric")


def test_not_a_file(tmp_path):
    with pytest.raises(FormatError, match="folder"):
        read_mric(tmp_path)
    with pytest.raises(FormatError, match="cannot read"):
        read_mric(tmp_path / "missing.mric")
    (tmp_path / "empty.mric").write_bytes(b"")
    with pytest.raises(FormatError):
        read_mric(tmp_path / "empty.mric")
    fifo = tmp_path / "fifo.mric"
    os.mkfifo(fifo)
    with pytest.raises(FormatError, match="regular"):
        read_mric(fifo)  # must not block


def test_overwrite_is_atomic_and_leaves_no_temp(tmp_path):
    p = tmp_path / "a.mric"
    write_mric(p, [[]], width=3, height=3)
    write_mric(p, [[], []], width=3, height=3)
    assert read_mric(p).n_slices == 2
    assert os.listdir(tmp_path) == ["a.mric"]


# --------------------------------------------------------------------------- true size
def _kidney_like(shape=(24, 70, 60)):
    """An ellipsoid label map (z, y, x) and its voxel count."""
    z, y, x = np.mgrid[: shape[0], : shape[1], : shape[2]]
    m = ((x - 30) / 22.0) ** 2 + ((y - 35) / 28.0) ** 2 + ((z - 12) / 9.5) ** 2 <= 1
    return m.astype(np.uint8)


def test_true_size_round_trip(tmp_path):
    """Written with the labels' spacing, an MRIC meshes at its true size when read back
    alone (it used to mesh at 1 mm: 38 mL for a 130 mL kidney)."""
    from ctui.engine.actions.mesh import mesh_objects
    from ctui.engine.core.borders import borders_for_mric
    from ctui.engine.io.mric import sidecar_path

    lab = _kidney_like()
    spacing, origin = (2.5, 0.7, 0.7), (-40.0, 12.5, 300.0)
    f = tmp_path / "kidney.mric"
    write_mric(f, borders_for_mric(lab), width=60, height=70, spacing=spacing, origin=origin)
    assert f.read_bytes().startswith(SIGNATURE) and sidecar_path(f).name == "kidney.mric.json"
    back = read_mric(f)
    assert back.spacing == spacing and back.origin == origin
    mesh = mesh_objects(f).mesh
    truth_ml = lab.sum() * np.prod(spacing) / 1000
    v = mesh.vertices
    vol_ml = float(np.einsum("ij,ij->i", v[mesh.faces[:, 0]], np.cross(v[mesh.faces[:, 1]], v[mesh.faces[:, 2]])).sum()) / 6e3
    assert abs(vol_ml) == pytest.approx(truth_ml, rel=0.02)
    # placed at the labels' origin: x extent starts near origin + 8 px * 0.7 mm
    assert v[:, 0].min() == pytest.approx(origin[0] + 8 * 0.7, abs=1.0)
    # the user's --spacing wins over the sidecar
    half = mesh_objects(f, spacing=(1.25, 0.7, 0.7)).mesh
    vh = half.vertices
    vol_h = float(np.einsum("ij,ij->i", vh[half.faces[:, 0]], np.cross(vh[half.faces[:, 1]], vh[half.faces[:, 2]])).sum()) / 6e3
    assert abs(vol_h) == pytest.approx(truth_ml / 2, rel=0.03)


def test_without_spacing_refused_unless_given(tmp_path):
    from ctui.engine.actions.mesh import mesh_objects
    from ctui.engine.core.borders import borders_for_mric
    from ctui.engine.core.errors import CtuiError
    from ctui.engine.io.mric import sidecar_path

    lab = _kidney_like()
    f = tmp_path / "k.mric"
    write_mric(f, borders_for_mric(lab), width=60, height=70, spacing=(2.0, 1.0, 1.0))
    write_mric(f, borders_for_mric(lab), width=60, height=70)  # replaced without geometry: stale sidecar gone
    assert not sidecar_path(f).exists() and read_mric(f).spacing is None
    with pytest.raises(CtuiError) as exc:
        mesh_objects(f)
    assert exc.value.option == "spacing" and "voxel spacing" in str(exc.value) and str(f) in str(exc.value)
    assert mesh_objects(f, spacing=(2.0, 1.0, 1.0)).mesh.n_faces > 0


@pytest.mark.parametrize("text", ['{"spacing_zyx_mm": [1, "nan", 1]}', '{"spacing_zyx_mm": [0, 1, 1]}', "not json",
                                  '{"spacing_zyx_mm": [1, 1, 1], "shape_zyx": [3, 9, 9]}'])
def test_bad_sidecar_one_line(tmp_path, text):
    from ctui.engine.io.mric import sidecar_path

    f = tmp_path / "b.mric"
    write_mric(f, [[]], width=60, height=70)
    sidecar_path(f).write_text(text)
    with pytest.raises(FormatError) as exc:
        read_mric(f)
    assert "\n" not in str(exc.value) and "b.mric.json" in str(exc.value)


def test_segment_cli_mric_meshes_at_true_size(tmp_path, capsys):
    """`ctui segment --mric` then `ctui mesh FILE.mric` with no --spacing: the series' size."""
    import json

    from ctui.cli import main
    from ctui.engine.core.volume import Volume
    from ctui.engine.io.phantom import write_series

    lab = _kidney_like((16, 48, 40))
    data = np.where(lab > 0, 200, -100).astype(np.int16)
    write_series(tmp_path / "s", Volume(data=data, spacing=(3.0, 0.8, 0.8), modality="CT", window=(40, 400)))
    mric = tmp_path / "k.mric"
    rc = main(["segment", str(tmp_path / "s"), "--seed", "20,24,8", "--range", "100:300", "--mric", str(mric),
               "--json"])
    assert rc == 0, capsys.readouterr().err
    capsys.readouterr()
    rc = main(["mesh", str(mric), "--out", str(tmp_path / "k.stl"), "--json"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    truth_ml = lab.sum() * 3.0 * 0.8 * 0.8 / 1000
    assert json.loads(out)["volume_ml"] == pytest.approx(truth_ml, rel=0.05)
