"""Hostile codestreams, round four (issue 41): deflated datasets and JPEG-LS frames.

Deflated Explicit VR Little Endian: a valid deflated series loads voxel for voxel like its
uncompressed twin (it was refused: "no pixel data"), and a deflate bomb (a small file
inflating to hundreds of MB of zeros behind a 48x48 header) is inflated only as far as the
header's claim, never whole (it took 2.9 GB RSS and 16 s)."""

from __future__ import annotations

import resource
from pathlib import Path

import numpy as np
import pytest

pydicom = pytest.importorskip("pydicom")


@pytest.fixture(scope="module")
def series(tmp_path_factory) -> Path:
    from test_privacy import write_series

    return write_series(tmp_path_factory.mktemp("codestreams") / "orig", broken=False)


def _deflated_copy(series: Path, out: Path, pixels: bytes | None = None, which=None) -> Path:
    out.mkdir()
    for k, f in enumerate(sorted(series.glob("*.dcm"))):
        ds = pydicom.dcmread(f)
        ds.file_meta.TransferSyntaxUID = pydicom.uid.DeflatedExplicitVRLittleEndian
        if pixels is not None and (which is None or k in which):
            ds.PixelData = pixels
        ds.save_as(out / f.name, enforce_file_format=True)
    return out


def test_valid_deflated_series_loads_like_its_twin(series, tmp_path):
    from ctui.engine.io.series import load

    a, b = load(series), load(_deflated_copy(series, tmp_path / "d"))
    assert b.shape == a.shape and not b.skipped
    np.testing.assert_array_equal(a.data, b.data)
    assert b.spacing == a.spacing and b.origin == a.origin


def test_deflate_bomb_is_inflated_only_as_far_as_the_header_claims(series, tmp_path, monkeypatch):
    from ctui.engine.io.series import dicom_deflate
    from ctui.engine.io.series import load

    bomb = _deflated_copy(series, tmp_path / "bomb", pixels=b"\0" * (64 << 20), which={0})
    assert (bomb / sorted(p.name for p in bomb.iterdir())[0]).stat().st_size < 200_000
    sizes = []
    real = dicom_deflate.inflate

    def spy(path, limit):
        data, more = real(path, limit)
        sizes.append(len(data))
        return data, more

    monkeypatch.setattr(dicom_deflate, "inflate", spy)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    vol = load(bomb)  # the bomb's slice cannot be decoded (too many bytes for 48x48): left out, said
    assert max(sizes) < 8 << 20, sizes  # never the 64 MiB
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 200 << 10  # kB
    assert vol.shape[0] == 15 and any(a.kind == "slices" for a in vol.assumptions)  # the end slice lost


def test_corrupt_deflate_stream_is_one_skip_reason(series, tmp_path):
    from ctui.engine.io.series import load

    d = _deflated_copy(series, tmp_path / "c")
    f = sorted(d.glob("*.dcm"))[5]
    raw = bytearray(f.read_bytes())
    raw[-200:] = b"\xff" * 200
    f.write_bytes(bytes(raw))
    vol = load(d)
    assert vol.shape[0] == 16 and any(a.kind == "slices" for a in vol.assumptions)


def _jpeg_ls_copy(series: Path, out: Path, cut=None) -> Path:
    pytest.importorskip("jpeg_ls", reason="JPEG-LS needs pyjpegls (ctui[codecs])")
    from pydicom.encaps import encapsulate, generate_frames
    from pydicom.uid import JPEGLSLossless

    out.mkdir()
    for k, f in enumerate(sorted(series.glob("*.dcm"))):
        ds = pydicom.dcmread(f)
        ds.compress(JPEGLSLossless)
        if cut is not None and k in cut:
            fr = next(generate_frames(ds.PixelData, number_of_frames=1))
            ds.PixelData = encapsulate([cut[k](fr)])
        ds.save_as(out / f.name, enforce_file_format=True)
    return out


def test_jpeg_ls_truncated_frames_are_refused_before_charls(series, tmp_path):
    """Truncated JPEG-LS frames cost CharLS 5-13 s each to fail (2 frames: 10.1 s); they are
    refused by their markers (no EOI, another size in SOF-55) before decoding; the intact
    frames decode to the uncompressed twin's voxels."""
    from ctui.engine.io.series import load

    ok = load(_jpeg_ls_copy(series, tmp_path / "ok"))
    np.testing.assert_array_equal(ok.data, load(series).data)

    def other_size(fr: bytes) -> bytes:
        i = fr.find(b"\xff\xf7")
        return fr[:i + 5] + (47).to_bytes(2, "big") + fr[i + 7:]

    cut = {3: lambda fr: fr[: len(fr) // 2], 4: lambda fr: fr[:-40], 9: other_size}
    vol = load(_jpeg_ls_copy(series, tmp_path / "cut", cut))
    reasons = {d["file"]: d["reason"] for d in vol.skipped}
    assert "no end-of-image marker" in reasons["slice003.dcm"] and "no end-of-image marker" in reasons["slice004.dcm"]
    assert "47x48 under a 48x48 header" in reasons["slice009.dcm"]
    a = next(a for a in vol.assumptions if a.kind == "slices")
    assert (a.count, a.total) == (3, 16)
