"""Fuzz DICOM loading (ctui.engine.io.series.load) with hostile files.

Seeds: a small valid 3-slice CT series written by pydicom (explicit VR little endian,
16x16 int16). Cases: one file of the series truncated at many offsets, bit-flipped,
overwritten with huge integers, randomly and hypothesis-mutated (loaded alone and
within its folder); elements rewritten with wrong VRs / types / absurd values (Rows,
Columns, PixelSpacing, ImagePositionPatient, NumberOfFrames...) in one slice or all;
file-system oddities (zero-length files, folders named like files, symlink loops,
FIFOs, deep folders). Rule: a Volume (the rest of the series loads, the bad file
skipped with a reason) or one CtuiError line; never another exception, a hang or an
allocation the input cannot justify.
"""

from __future__ import annotations

import pytest

import os
from pathlib import Path

import numpy as np

from test_fuzz_harness import assert_clean, fuzz_examples, run_campaign, standard_campaign

try:
    import ctui.engine.io.series  # noqa: F401

    HAVE_LOADERS = True
except ImportError:  # pragma: no cover
    HAVE_LOADERS = False


def warm_up() -> None:
    import hypothesis  # noqa: F401
    import pydicom  # noqa: F401

    from ctui.engine.io.series import load

    # run the real code path once so lazy imports happen before the memory cap
    d = Path(os.environ.get("TMPDIR", "/tmp")) / f"ctui-fuzz-warm-{os.getpid()}"
    write_series(d)
    load(d)
    import shutil

    shutil.rmtree(d, ignore_errors=True)


def make_slice(i: int, *, rows: int = 16, cols: int = 16, n_frames: int | None = None):
    """A CT slice with distinctive (fake) patient identifiers."""
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian

    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = f"1.2.826.0.1.3680043.8.498.3.{i + 1}"
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID = CTImageStorage
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = "1.2.826.0.1.3680043.8.498.2"
    ds.SeriesInstanceUID = "1.2.826.0.1.3680043.8.498.1"
    ds.PatientName = "ZZSECRET^NAME"
    ds.PatientID = "ID-98765-SECRET"
    ds.PatientBirthDate = "19010203"
    ds.AccessionNumber = "ACC-XYZ-777"
    ds.InstitutionName = "SECRET HOSPITAL"
    ds.Modality = "CT"
    ds.SeriesDescription = "fuzz seed"
    ds.SeriesNumber = 1
    ds.InstanceNumber = i + 1
    ds.ImagePositionPatient = [-10.0, -20.0, 2.5 * i]
    ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
    ds.PixelSpacing = [0.7, 0.7]
    ds.SliceThickness = 2.5
    ds.Rows = rows
    ds.Columns = cols
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated = 16
    ds.BitsStored = 16
    ds.HighBit = 15
    ds.PixelRepresentation = 1
    ds.RescaleSlope = 1
    ds.RescaleIntercept = -1024
    ds.WindowCenter = 40
    ds.WindowWidth = 400
    frames = n_frames or 1
    if n_frames:
        ds.NumberOfFrames = n_frames
    arr = (np.arange(frames * rows * cols, dtype=np.int64).reshape(frames, rows, cols) * 7 + 100 * i).astype(np.int16)
    ds.PixelData = arr.tobytes()
    return ds


def dicom_bytes(ds) -> bytes:
    import io

    buf = io.BytesIO()
    ds.save_as(buf, enforce_file_format=True)
    return buf.getvalue()


def write_series(folder: Path, n: int = 3) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for i in range(n):
        p = folder / f"im{i}.dcm"
        p.write_bytes(dicom_bytes(make_slice(i)))
        out.append(p)
    return out


# (keyword, tag, list of (VR, value)); None VR = delete the element
ELEMENT_CASES = {
    "Rows": (0x00280010, [("US", 0), ("US", 1), ("US", 65535), ("SS", -1), ("LO", "abc"), ("DS", "nan"), ("UL", 4294967295), ("OB", b"\x01"), (None, None)]),
    "Columns": (0x00280011, [("US", 0), ("US", 65535), ("LO", "16.5"), ("FD", float("nan")), (None, None)]),
    "PixelSpacing": (0x00280030, [("DS", "0\\0"), ("DS", "-1\\1"), ("DS", "nan\\nan"), ("DS", "inf\\1"), ("DS", "1e308\\1e308"), ("DS", "1"), ("DS", "1\\2\\3"), ("LO", "a\\b"), ("FD", 0.5), ("SQ", []), (None, None)]),
    "ImagePositionPatient": (0x00200032, [("DS", "x\\y\\z"), ("DS", "1\\2"), ("DS", "nan\\nan\\nan"), ("DS", "1e308\\-1e308\\1e308"), ("DS", ""), ("FD", [1.0, 2.0, 3.0]), ("LO", "1\\2\\3"), (None, None)]),
    "ImageOrientationPatient": (0x00200037, [("DS", "0\\0\\0\\0\\0\\0"), ("DS", "1\\0\\0\\1\\0\\0"), ("DS", "nan\\0\\0\\0\\1\\0"), ("DS", "1\\0\\0"), ("DS", "2\\0\\0\\0\\3\\0"), ("LO", "a"), (None, None)]),
    "NumberOfFrames": (0x00280008, [("IS", "0"), ("IS", "-1"), ("IS", "2"), ("IS", "999999999"), ("IS", "2147483648"), ("LO", "many"), ("US", 65535), ("DS", "1.5")]),
    "BitsAllocated": (0x00280100, [("US", 0), ("US", 1), ("US", 7), ("US", 8), ("US", 32), ("US", 64), ("US", 65535), ("LO", "16")]),
    "BitsStored": (0x00280101, [("US", 0), ("US", 17), ("US", 65535)]),
    "HighBit": (0x00280102, [("US", 0), ("US", 40)]),
    "PixelRepresentation": (0x00280103, [("US", 2), ("US", 65535), ("LO", "signed"), (None, None)]),
    "SamplesPerPixel": (0x00280002, [("US", 0), ("US", 3), ("US", 4), ("US", 65535), (None, None)]),
    "PlanarConfiguration": (0x00280006, [("US", 1), ("US", 7)]),
    "PhotometricInterpretation": (0x00280004, [("CS", "YBR_FULL"), ("CS", "RGB"), ("CS", "PALETTE COLOR"), ("CS", "MONOCHROME1"), ("CS", ""), ("CS", "XYZ"), (None, None)]),
    "RescaleSlope": (0x00281053, [("DS", "0"), ("DS", "nan"), ("DS", "inf"), ("DS", "-1e308"), ("DS", "1e308"), ("LO", "abc"), ("DS", "1\\2")]),
    "RescaleIntercept": (0x00281052, [("DS", "nan"), ("DS", "1e308"), ("LO", "zero")]),
    "SliceThickness": (0x00180050, [("DS", "0"), ("DS", "-5"), ("DS", "nan")]),
    "WindowCenter": (0x00281050, [("DS", "nan"), ("DS", "a"), ("DS", "1\\2\\3"), ("DS", "")]),
    "WindowWidth": (0x00281051, [("DS", "0"), ("DS", "-1"), ("DS", "nan")]),
    "PixelData": (0x7FE00010, [("OW", b""), ("OW", b"\x00" * 10), ("OW", b"\x00" * 513), ("OW", b"\x00" * 100000), ("OB", b"\x00" * 512), ("LO", "pixels"), (None, None)]),
    "SeriesInstanceUID": (0x0020000E, [("UI", ""), ("UI", "1" * 64), ("LO", "not a uid"), (None, None)]),
    "InstanceNumber": (0x00200013, [("IS", "-1"), ("IS", "999999999999"), ("LO", "x")]),
    "Modality": (0x00080060, [("CS", ""), ("CS", "MR"), ("CS", "PT"), ("CS", "XX"), (None, None)]),
    "SOPClassUID": (0x00080016, [("UI", "1.2.840.10008.5.1.4.1.1.66"), ("UI", "1.2.840.10008.5.1.4.1.1.104.1"), (None, None)]),
}
TRANSFER_SYNTAXES = [
    "1.2.840.10008.1.2",  # implicit VR: the file is explicit -> misparse
    "1.2.840.10008.1.2.2",  # big endian
    "1.2.840.10008.1.2.4.50",  # JPEG baseline with raw bytes
    "1.2.840.10008.1.2.4.90",  # JPEG 2000
    "1.2.840.10008.1.2.5",  # RLE
    "1.2.840.10008.1.2.1.99",  # deflate
    "1.2.3.4",  # unknown
]


def _with_element(i: int, tag: int, vr, value) -> bytes | None:
    from pydicom import config
    from pydicom.dataelem import DataElement

    config.settings.writing_validation_mode = config.IGNORE
    ds = make_slice(i)
    try:
        if vr is None:
            if tag in ds:
                del ds[tag]
        else:
            ds[tag] = DataElement(tag, vr, value)
        return dicom_bytes(ds)
    except Exception:  # noqa: BLE001 - pydicom refuses to encode some combinations
        return None


def campaign(ctx) -> None:
    from ctui.engine.io.series import load

    seed = dicom_bytes(make_slice(1))
    series = ctx.tmp("case/series/im0.dcm").parent
    for i in (0, 2):
        (series / f"im{i}.dcm").write_bytes(dicom_bytes(make_slice(i)))

    def load_folder(p: Path):
        return load(p.parent)

    # one mutated file, loaded alone
    standard_campaign(ctx, load, seed, name="one.dcm", tag="dicom-file", flips_every=3, trunc_limit=300, positions=400)
    # the same mutations inside a series folder (the other slices must still load)
    import numpy.random as npr

    from test_fuzz_harness import mutate, truncations

    for t in truncations(seed, 150):
        ctx.check(load_folder, t, name="series/im1.dcm", tag="dicom-series-trunc")
    rng = npr.default_rng(99)
    for _ in range(max(ctx.examples // 2, 10)):
        ctx.check(load_folder, mutate(seed, rng), name="series/im1.dcm", tag="dicom-series-random")
    # wrong VRs / types / values, in one slice and in all slices
    (series.parent / "all").mkdir(exist_ok=True)
    for kw, (tag, variants) in ELEMENT_CASES.items():
        for vr, value in variants:
            b1 = _with_element(1, tag, vr, value)
            if b1 is None:
                ctx.counts["dicom-element:unencodable"] = ctx.counts.get("dicom-element:unencodable", 0) + 1
                continue
            note = f"{kw} {vr} {str(value)[:40]}"
            ctx.check(load_folder, b1, name="series/im1.dcm", tag="dicom-element-one", note=note)
            for i in range(3):
                b = _with_element(i, tag, vr, value)
                (series.parent / "all" / f"im{i}.dcm").write_bytes(b or b"")
            ctx.check(load, series.parent / "all", tag="dicom-element-all", note=note)
    # transfer syntax lies
    from pydicom.uid import UID

    for ts in TRANSFER_SYNTAXES:
        ds = make_slice(1)
        ds.file_meta.TransferSyntaxUID = UID(ts)
        try:
            b = dicom_bytes(ds)
        except Exception:  # noqa: BLE001
            b = None
        if b is None:
            continue
        ctx.check(load, b, name="ts.dcm", tag="dicom-ts")
        ctx.check(load_folder, b, name="series/im1.dcm", tag="dicom-ts")
    # multi-frame with huge declared frame count or size over tiny pixel data
    for frames, rows, cols in ((3, 16, 16), (100000, 16, 16), (2**31 - 1, 1, 1), (1000, 512, 512), (2, 65535, 65535)):
        ds = make_slice(0, n_frames=3)
        ds.NumberOfFrames = frames
        ds.Rows, ds.Columns = rows, cols
        ctx.check(load, dicom_bytes(ds), name="mf.dcm", tag="dicom-multiframe", note=f"frames {frames} rows {rows} cols {cols}")
    # (restore the series folder)
    (series / "im1.dcm").write_bytes(seed)
    fs_cases(ctx, load, series)


def fs_cases(ctx, load, series: Path) -> None:
    """Zero-length files, folders named like files, symlink loops, FIFOs, deep trees."""
    import shutil

    root = ctx.tmp("fs/x").parent
    cases: list[tuple[str, Path]] = []

    def fresh(name: str) -> Path:
        d = root / name
        if d.exists():
            shutil.rmtree(d)
        shutil.copytree(series, d)
        return d

    d = fresh("zero")
    (d / "im1.dcm").write_bytes(b"")
    cases.append(("zero-in-series", d))
    z = root / "zero.dcm"
    z.write_bytes(b"")
    cases.append(("zero-file", z))
    d = fresh("dirlike")
    (d / "im1.dcm").unlink()
    (d / "im1.dcm").mkdir()
    cases.append(("dir-named-like-file", d))
    cases.append(("dir-named-like-file-direct", d / "im1.dcm"))
    d = fresh("selfloop")
    os.symlink("loop.dcm", d / "loop.dcm")
    cases.append(("symlink-self-loop", d))
    cases.append(("symlink-self-loop-direct", d / "loop.dcm"))
    d = fresh("dirloop")
    os.symlink("..", d / "up")
    os.symlink(".", d / "here")
    os.symlink(str(d), d / "abs")
    cases.append(("symlink-dir-loop", d))
    d = fresh("dangling")
    os.symlink("/nonexistent/x.dcm", d / "im9.dcm")
    cases.append(("dangling-symlink", d))
    d = fresh("fifo")
    os.mkfifo(d / "im3.dcm")
    cases.append(("fifo-in-series", d))
    cases.append(("fifo-direct", d / "im3.dcm"))
    d = fresh("devnull")
    os.symlink("/dev/zero", d / "im4.dcm")
    cases.append(("dev-zero-in-series", d))
    e = root / "empty"
    e.mkdir(exist_ok=True)
    cases.append(("empty-folder", e))
    j = root / "junk"
    j.mkdir(exist_ok=True)
    for k in range(5):
        (j / f"f{k}").write_bytes(os.urandom(300))
    (j / "notes.txt").write_text("hello")
    cases.append(("junk-folder", j))
    deep = root / "deep"
    if not deep.exists():  # 1100 nested folders (deeper than Python's recursion limit)
        try:
            p = str(deep)
            os.mkdir(p)
            for _ in range(1100):
                p += "/d"
                os.mkdir(p)
            shutil.copy(series / "im0.dcm", p + "/im0.dcm")
        except OSError:
            pass
    cases.append(("deep-tree", deep))
    cases.append(("missing", root / "does-not-exist"))
    for tag, path in cases:
        ctx.check(load, path, tag=f"dicom-fs-{tag}", size_hint=4096)


@pytest.mark.slow
def test_fuzz_dicom():
    import pytest

    if not HAVE_LOADERS:
        pytest.skip("ctui.engine.io.series not available yet")
    res = run_campaign("test_fuzz_dicom", "campaign", examples=fuzz_examples(400))
    assert_clean("dicom", res, min_cases=2500)
