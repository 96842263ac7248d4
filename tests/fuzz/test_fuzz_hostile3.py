"""Hostile files and options, round three (issue 26): one regression case per defect the
outside campaign found. Each drives the command (or the reader) with the hostile input
and checks the real outcome: a one-line error naming the file, or the right result,
and never a renamed device, a hang, a runaway allocation or a control character on the
terminal."""

from __future__ import annotations

import gzip
import json
import os
import stat
from pathlib import Path

import numpy as np
import pytest

from ctui.cli import main

SEED = "24,24,8"


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    from test_privacy import write_series

    d = tmp_path_factory.mktemp("hostile3")
    series = write_series(d / "series", broken=False, description="evil\x1b]52;c;ZXZpbA==\x07\x1b[2J desc")
    assert main(["segment", str(series), "--seed", SEED, "--range", "200:400", "--project", str(d / "p.ctui")]) == 0
    return {"dir": d, "series": series, "project": d / "p.ctui"}


def _err(capsys, argv: list) -> str:
    capsys.readouterr()
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse: one line too (cli._Parser)
        rc = exc.code
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and lines[0].startswith(f"ctui {argv[0]}: "), (rc, err, out)
    return lines[0]


# ----------------------------------------------------------------- 1: non-regular outputs
def test_outputs_never_replace_devices_fifos_or_links_to_them(files, capsys, tmp_path):
    """`--plot /dev/null`, a FIFO, a symlink to a device: refused in one line, the
    node left as it was; a symlink to a regular file is written through (link kept)."""
    fifo = tmp_path / "fifo.png"
    os.mkfifo(fifo)
    link = tmp_path / "null.csv"  # (a link to /proc/self/fd/1 is a link to whatever fd 1 is under pytest)
    link.symlink_to("/dev/null")
    assert "character device" in _err(capsys, ["drift", files["project"], "--plot", "/dev/null"])
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    assert "FIFO" in _err(capsys, ["drift", files["project"], "--plot", fifo])
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert "symbolic link" in _err(capsys, ["measure", files["project"], "--path", "auto", "--csv", link])
    assert link.is_symlink()
    real = tmp_path / "real.csv"
    real.write_text("old")
    (tmp_path / "via.csv").symlink_to(real)
    assert main(["measure", str(files["project"]), "--path", "auto", "--csv", str(tmp_path / "via.csv")]) == 0
    assert (tmp_path / "via.csv").is_symlink() and real.read_text() != "old" and "," in real.read_text()


# ----------------------------------------------------------------- 2: NRRD detached / inflating data
NRRD_HDR = ("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 10 8 12\nspace: left-posterior-superior\n"
            "space directions: (1,0,0) (0,1,0) (0,0,2)\n")


@pytest.mark.parametrize("case", ["dev-zero", "fifo", "bomb", "line-skip"])
def test_nrrd_data_is_read_with_bounds(case, capsys, tmp_path):
    """/dev/zero or a FIFO as the data file, a gzip stream inflating past the declared 960
    voxels, line skip 99999999: one line each, no hang, no runaway allocation."""
    if case == "dev-zero":
        p = tmp_path / "z.nhdr"
        p.write_text(NRRD_HDR + "encoding: gzip\ndata file: /dev/zero\n\n")
    elif case == "fifo":
        os.mkfifo(tmp_path / "pipe")
        p = tmp_path / "f.nhdr"
        p.write_text(NRRD_HDR + "encoding: raw\nline skip: 1\ndata file: pipe\n\n")
    elif case == "bomb":
        p = tmp_path / "b.nrrd"
        p.write_bytes((NRRD_HDR + "encoding: gzip\n\n").encode() + gzip.compress(bytes(20_000_000)))
    else:
        p = tmp_path / "s.nrrd"
        p.write_bytes((NRRD_HDR + "encoding: raw\nline skip: 99999999\n\n").encode() + bytes(1000))
    line = _err(capsys, ["info", p, "--json"])
    assert p.name in line


def test_nrrd_gzip_ascii_and_line_skip_still_read(tmp_path):
    """The bounded reader gives pynrrd's voxels for gzip, ascii and line-skip files."""
    import nrrd

    from ctui.engine.io.series import load

    vals = (np.arange(960) * 7 % 256).astype(np.uint8)
    cases = {"g.nrrd": (NRRD_HDR + "encoding: gzip\n\n").encode() + gzip.compress(vals.tobytes()),
             "a.nrrd": (NRRD_HDR + "encoding: ascii\n\n").encode() + " ".join(map(str, vals)).encode(),
             "l.nrrd": (NRRD_HDR + "encoding: raw\nline skip: 2\n\n").encode() + b"x\ny\n" + vals.tobytes()}
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        ref, _ = nrrd.read(str(tmp_path / name), index_order="C")
        got = load(tmp_path / name)
        assert got.shape == (12, 8, 10) and np.array_equal(got.data, ref), name


# ----------------------------------------------------------------- 3, 18: DICOM-SEG frame counts
@pytest.mark.parametrize("frames", [2**31 - 1, 1])
def test_seg_number_of_frames_checked_before_highdicom(frames, capsys, tmp_path):
    """NumberOfFrames 2**31-1 (or 1 for 3 frames) in the dcmqi liver SEG: refused in one line."""
    from support import shared
    import pydicom

    src = shared("dcmqi_seg/liver.dcm")
    ds = pydicom.dcmread(str(src))
    ds.NumberOfFrames = frames
    p = tmp_path / "seg.dcm"
    ds.save_as(str(p))
    line = _err(capsys, ["measure", p, "--json", "--no-mesh"])
    assert "NumberOfFrames" in line and "seg.dcm" in line


# ----------------------------------------------------------------- 4: terminal escapes
def test_text_from_files_cannot_drive_the_terminal(files, capsys):
    """A SeriesDescription holding OSC 52 and ESC[2J is printed escaped by `ctui info`."""
    capsys.readouterr()
    assert main(["info", str(files["series"])]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\x07" not in out
    assert "evil\\x1b]52;c;ZXZpbA==\\x07\\x1b[2J desc" in out


def test_printable_and_csv_cell():
    from ctui.engine.core.safetext import csv_cell, printable

    assert printable("a\x1b[2Jb\x9b\u202e\n") == "a\\x1b[2Jb\\x9b\\u202e\\x0a"
    assert printable("l1\nl2\tx", keep_newlines=True) == "l1\nl2\tx"
    assert [csv_cell(v) for v in ("=HYPERLINK(1)", "@SUM(A1)", "+1+2", "-x", "-1.5", "kidney", 3.0)] == \
        ["'=HYPERLINK(1)", "'@SUM(A1)", "'+1+2", "'-x", "-1.5", "kidney", 3.0]


# ----------------------------------------------------------------- 5, 13: numeric options
@pytest.mark.parametrize("spec", ["clahe:tiles=0", "clahe:tiles=100000", "gaussian:sigma=nan", "gaussian:sigma=1e308",
                                  "erode:iterations=100000", "opening:size=1e21"])
def test_filter_parameters_are_bounded(spec, files, capsys):
    """`--filter clahe:tiles=0` killed the process with SIGFPE inside OpenCV; the others
    raised or ran for minutes: all refused in one line naming the parameter."""
    line = _err(capsys, ["segment", files["series"], "--seed", SEED, "--range", "200:400", "--filter", spec])
    assert spec.split(":")[1].split("=")[0] in line


@pytest.mark.parametrize("argv", [
    ["mesh", "{series}", "--iso", "nan", "--out", "{tmp}/o.stl"], ["mesh", "{series}", "--iso", "inf", "--out", "{tmp}/o.stl"],
    ["segment", "{series}", "--seed", SEED, "--range", "200:400", "--neck", "nan"],
    ["segment", "{series}", "--seed", SEED, "--range", "200:400", "--neck", "inf"],
    ["segment", "{series}", "--seed", SEED, "--range", "200:400", "--neighbourhood", "100000"],
    ["segment", "{series}", "--seed", SEED, "--range", "nan:400"],
    ["segment", "{series}", "--seed", SEED, "--tolerance", "inf"],
    ["render", "{project}", "--azimuth", "inf", "--out", "{tmp}/o.png"],
    ["render", "{project}", "--roll", "inf", "--out", "{tmp}/o.png"],
    ["render", "{project}", "--turntable", "3", "--fps", "nan", "--out", "{tmp}/o.gif"],
    ["render", "{project}", "--flythrough", "auto", "--fov", "0", "--out", "{tmp}/o.gif"],
    ["render", "{project}", "--slice", "x:nan", "--out", "{tmp}/o.png"],
    ["render", "{project}", "--turntable", "100000", "--size", "40x40", "--out", "{tmp}/o.gif"],
    ["render", "{project}", "--flythrough", "auto", "--frames", "1000000", "--out", "{tmp}/o.gif"],
    ["measure", "{project}", "--path", "auto", "--step", "nan"],
    ["measure", "{project}", "--path", "1e308,0,0;0,0,0"],
    ["measure", "{project}", "--path", "auto", "--between", "nan,nan"],
    ["drift", "{project}", "--threshold", "nan"],
    ["mesh", "{project}", "--out", "{tmp}/o.stl", "--smooth", "100000000"],
])
def test_numeric_options_refused_in_one_line(argv, files, capsys, tmp_path):
    """Every number an option takes is finite, in range and bounded in work: one line, exit 2,
    before anything is computed or written."""
    subs = {"{series}": str(files["series"]), "{project}": str(files["project"])}
    args = [subs.get(a, a.replace("{tmp}", str(tmp_path))) for a in argv]
    _err(capsys, args)
    assert not list(tmp_path.iterdir())


def test_engine_checks_numbers_too(files, tmp_path):
    """The engine refuses the same numbers when called directly (the TUI, scripts)."""
    from ctui.engine.actions.measure import measure_object
    from ctui.engine.actions.render import render_view
    from ctui.engine.core.errors import CtuiError

    with pytest.raises(CtuiError, match="turntable"):
        render_view(files["project"], out=tmp_path / "o.gif", turntable=100000)
    with pytest.raises(CtuiError, match="azimuth"):
        render_view(files["project"], out=tmp_path / "o.png", azimuth=float("inf"))
    with pytest.raises(CtuiError, match="step"):
        measure_object(files["project"], path="auto", step_mm=float("nan"))


# ----------------------------------------------------------------- 6: undecodable compressed pixels
@pytest.mark.parametrize("syntax", ["RLELossless", "JPEGBaseline8Bit", "JPEG2000Lossless"])
def test_info_of_undecodable_compressed_pixels(syntax, files, tmp_path, capsys):
    """Garbage RLE/JPEG/J2K fragments: `ctui info` gives the headers, 'values unknown' and a
    warning naming the decoder's fault, no traceback."""
    import pydicom
    import pydicom.uid
    from pydicom.encaps import encapsulate

    out = tmp_path / "enc"
    out.mkdir()
    for f in sorted(files["series"].glob("*.dcm"))[:4]:
        ds = pydicom.dcmread(f)
        ds.file_meta.TransferSyntaxUID = getattr(pydicom.uid, syntax)
        ds.PixelData = encapsulate([bytes(range(256)) * 2])
        ds["PixelData"].VR = "OB"
        ds.save_as(out / f.name, enforce_file_format=True)
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["value_range"] is None and d["shape_zyx"] == [4, 48, 48]
    assert any("could not be decoded" in w for w in d["warnings"])


# ----------------------------------------------------------------- 7: NaN / inf voxels
def test_nan_voxels_never_reach_a_mesh(tmp_path, capsys):
    """A raw float32 volume with NaN and inf voxels: the loader replaces them (a warning),
    `mesh --iso` writes finite vertices and a finite volume (the 4x6x7 mm box: 0.168 mL)."""
    a = np.zeros((10, 12, 14), np.float32)
    a[3:7, 3:9, 3:10] = 100
    a[0, 0, :5] = np.nan
    a[1, 1, 1] = np.inf
    a[9, 11, 13] = -np.inf
    a.tofile(tmp_path / "v.raw")
    capsys.readouterr()
    assert main(["mesh", str(tmp_path / "v.raw"), "--shape", "10,12,14", "--dtype", "float32", "--iso", "50",
                 "--out", str(tmp_path / "o.stl"), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["volume_ml"] is not None and abs(d["volume_ml"] - 0.168) < 0.03
    from ctui.engine.io.meshes import load_mesh

    assert np.isfinite(load_mesh(tmp_path / "o.stl").vertices).all()
    from ctui.engine.io.series import load

    vol = load(tmp_path / "v.raw", shape=(10, 12, 14), dtype="float32")
    assert np.isfinite(vol.data).all() and any("NaN" in w for w in vol.warnings)


# ----------------------------------------------------------------- 8: MONOCHROME1
def test_monochrome1_ct_keeps_its_hounsfield_units(files, tmp_path, capsys):
    """MONOCHROME1 is display polarity only: info and the loader give the same HU range as
    the MONOCHROME2 original (0..300 HU for the sphere phantom)."""
    import pydicom

    from ctui.engine.io.series import load

    out = tmp_path / "m1"
    out.mkdir()
    for f in files["series"].glob("*.dcm"):
        ds = pydicom.dcmread(f)
        ds.PhotometricInterpretation = "MONOCHROME1"
        ds.save_as(out / f.name)
    ref = load(files["series"])
    vol = load(out)
    np.testing.assert_array_equal(vol.data, ref.data)
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["value_range"] == [float(ref.data.min()), float(ref.data.max())]


# ----------------------------------------------------------------- 10: implausible scaling
def test_implausible_spacing_and_slope(files, tmp_path, capsys):
    """PixelSpacing 1e-30 and RescaleSlope 1e-300 are replaced with a warning (not 0.00 mL and
    zeroed voxels); a project with spacing 1e-300 is refused on open in one line."""
    import pydicom
    import zipfile

    from ctui.engine.io.series import load

    out = tmp_path / "sc"
    out.mkdir()
    for f in files["series"].glob("*.dcm"):
        ds = pydicom.dcmread(f)
        ds.PixelSpacing, ds.RescaleSlope = ["1e-30", "1e-30"], "1e-300"
        ds.save_as(out / f.name)
    vol = load(out)
    assert vol.spacing[1:] == (1.0, 1.0) and vol.data.max() == 300
    assert any("RescaleSlope" in w and "PixelSpacing" in w for w in vol.warnings)
    with zipfile.ZipFile(files["project"]) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    doc = json.loads(members["project.json"])
    doc["geometry"]["spacing_zyx_mm"] = [1e-300, 1.0, 1.0]
    members["project.json"] = json.dumps(doc).encode()
    bad = tmp_path / "tiny.ctui"
    with zipfile.ZipFile(bad, "w") as zf:
        for n, b in members.items():
            zf.writestr(n, b)
    for cmd in (["measure", bad], ["mesh", bad, "--out", tmp_path / "o.stl"], ["export", bad, "--format", "csv",
                                                                               "--out", tmp_path / "o.csv"]):
        assert "spacing" in _err(capsys, cmd)


# ----------------------------------------------------------------- 20: stdout closed
def test_stdout_closed(files):
    """`ctui info X --json >&-`: exit 0, no AttributeError traceback."""
    import subprocess
    import sys

    r = subprocess.run(f"{sys.executable} -m ctui info {files['series']} --json >&-", shell=True,
                       capture_output=False, stderr=subprocess.PIPE, text=True, timeout=120)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr


# ----------------------------------------------------------------- 11: sheared geometry
def test_sheared_headers(tmp_path, capsys):
    """A NIfTI sform and a MetaImage TransformMatrix with shear: the series loads with
    orthonormal directions and a warning; a sheared label map is refused in one line."""
    import nibabel as nib

    from ctui.engine.io.series import load

    a = np.zeros((10, 12, 14), np.int16)
    a[2:8, 3:9, 4:10] = 500
    aff = np.array([[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1.0]])
    nib.save(nib.Nifti1Image(a, aff), tmp_path / "s.nii.gz")
    (tmp_path / "s.mhd").write_text("ObjectType = Image\nNDims = 3\nDimSize = 10 12 14\nElementType = MET_SHORT\n"
                                    "ElementSpacing = 1 1 2\nTransformMatrix = 1 5 0 0 1 0 0 0 1\nElementDataFile = s.raw\n")
    a.transpose(2, 1, 0).astype("<i2").tofile(tmp_path / "s.raw")
    for name in ("s.nii.gz", "s.mhd"):
        vol = load(tmp_path / name)
        np.testing.assert_allclose(vol.direction.T @ vol.direction, np.eye(3), atol=1e-9)
        assert any("right angles" in w for w in vol.warnings), name
    nib.save(nib.Nifti1Image((a > 0).astype(np.uint8), aff), tmp_path / "lab.nii.gz")
    for out in ("o.stl", "o.ply", "o.obj"):
        assert "right angles" in _err(capsys, ["mesh", tmp_path / "lab.nii.gz", "--out", tmp_path / out])


# ----------------------------------------------------------------- 12, 23: NIfTI voxel types, negative pixdim
def test_nifti_complex_rgb_and_negative_pixdim(tmp_path):
    import nibabel as nib

    from ctui.engine.actions.info import describe_series
    from ctui.engine.io.series import load

    c = np.zeros((6, 5, 4), np.complex64)
    c[1:4, 1:3, 1:3] = 3 + 4j
    nib.save(nib.Nifti1Image(c, np.eye(4)), tmp_path / "c.nii.gz")
    vol, d = describe_series(tmp_path / "c.nii.gz")
    assert d["value_range"] == [0.0, 5.0] and any("magnitude" in w for w in vol.warnings)
    rgb = np.zeros((6, 5, 4), dtype=[("R", "u1"), ("G", "u1"), ("B", "u1")])
    rgb["R"], rgb["G"], rgb["B"] = 100, 200, 50
    nib.save(nib.Nifti1Image(rgb, np.eye(4)), tmp_path / "rgb.nii.gz")
    vol = load(tmp_path / "rgb.nii.gz")
    assert abs(float(vol.data.max()) - (0.299 * 100 + 0.587 * 200 + 0.114 * 50)) < 1e-3
    img = nib.Nifti1Image(np.zeros((6, 5, 4), np.int16), None)
    img.header["pixdim"][1:4] = [-2, 1, 3]
    img.header.set_qform(None, code=0)
    img.header.set_sform(None, code=0)
    nib.save(img, tmp_path / "neg.nii")
    vol = load(tmp_path / "neg.nii")
    assert vol.spacing == (3.0, 1.0, 2.0) and any("negative pixdim" in w for w in vol.warnings)


# ----------------------------------------------------------------- 14: batch manifests
def test_batch_hostile_manifests(files, tmp_path, capsys):
    """/dev/zero, a FIFO, a field over 131,072 characters, a file:// scheduler: one line each;
    a Latin-1 and a UTF-16 manifest run; a RESULTS.csv of binary garbage is rewritten; a
    name starting with '=' is neutralised in RESULTS.csv."""
    os.mkfifo(tmp_path / "fifo.csv")
    (tmp_path / "big.csv").write_text("series,seed,range\n" + "x" * 140_000 + ",1,2\n")
    for m in ("/dev/zero", tmp_path / "fifo.csv", tmp_path / "big.csv"):
        _err(capsys, ["batch", m, "--out", tmp_path / "r.csv"])
    row = f'{files["series"]},"{SEED}",200:400,=HYPERLINK("x")caf\u00e9\n'
    (tmp_path / "lat.csv").write_bytes(("series,seed,range,name\n" + row).encode("latin-1"))
    (tmp_path / "u16.csv").write_bytes(("series,seed,range,name\n" + row).encode("utf-16"))
    assert "scheduler" in _err(capsys, ["batch", tmp_path / "lat.csv", "--out", tmp_path / "r.csv",
                                        "--scheduler", "file:///etc/passwd"])
    for m in ("lat.csv", "u16.csv"):
        res = tmp_path / f"{m}.results.csv"
        res.write_bytes(os.urandom(3000))
        capsys.readouterr()
        assert main(["batch", str(tmp_path / m), "--out", str(res), "--threads", "--workers", "1"]) == 0
        import csv

        rows = list(csv.reader(res.open(encoding="utf-8")))
        assert rows[1][rows[0].index("status")] == "ok" and "caf\u00e9" in rows[1][1]
        assert not any(c.startswith(("=", "+", "@")) for r in rows for c in r)


# ----------------------------------------------------------------- 16: slow paths
def test_measure_of_many_islands_is_linear(tmp_path):
    """mesh_stats of 3,000 tetrahedra: per-component figures by bincount (was a pass over the
    whole mesh per component); each island's volume is 1/6 mm^3."""
    from ctui.engine.core.meshdata import Mesh
    from ctui.engine.measure.stats import mesh_stats

    n = 3000
    base = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    off = np.stack(np.meshgrid(np.arange(15), np.arange(15), np.arange(15)), -1).reshape(-1, 3)[:n] * 3.0
    m = Mesh(vertices=(base[None] + off[:, None]).reshape(-1, 3),
             faces=(faces[None] + 4 * np.arange(n)[:, None, None]).reshape(-1, 3))
    st = mesh_stats(m)
    assert st["n_components"] == n and st["closed"]
    assert abs(st["volume_mm3"] - n / 6) < 1e-6 and all(abs(c["volume_mm3"] - 1 / 6) < 1e-9 for c in st["components"])


def test_info_of_a_folder_with_a_huge_sparse_file(tmp_path, capsys):
    """A 20 GB sparse file of zeros is not parsed as DICOM to its end: one line, quickly."""
    with open(tmp_path / "big.bin", "wb") as fh:
        fh.truncate(20 << 30)
    assert "nothing loadable" in _err(capsys, ["info", tmp_path])


# ----------------------------------------------------------------- 17: CSV formula injection
def test_export_csv_neutralises_formulas(files, tmp_path, capsys):
    import zipfile

    with zipfile.ZipFile(files["project"]) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    doc = json.loads(members["project.json"])
    doc["objects"][0]["name"] = '=HYPERLINK("http://evil","x")'
    members["project.json"] = json.dumps(doc).encode()
    p = tmp_path / "evil.ctui"
    with zipfile.ZipFile(p, "w") as zf:
        for n, b in members.items():
            zf.writestr(n, b)
    assert main(["export", str(p), "--format", "csv", "--out", str(tmp_path / "o.csv")]) == 0
    import csv

    rows = list(csv.DictReader((tmp_path / "o.csv").open()))
    assert rows[0]["name"] == "'" + doc["objects"][0]["name"] and float(rows[0]["volume_voxels_ml"]) > 4


# ----------------------------------------------------------------- 19: degenerate meshes
def test_meshes_without_area_are_refused(tmp_path, capsys):
    import struct

    b = b"ctui".ljust(80, b" ") + struct.pack("<I", 2)
    for _ in range(2):
        b += struct.pack("<12fH", 0, 0, 0, 1, 1, 1, 1, 1, 1, 2, 2, 2, 0)
    (tmp_path / "d.stl").write_bytes(b)
    (tmp_path / "e.stl").write_bytes(b"x" * 80 + struct.pack("<I", 0))
    assert "degenerate" in _err(capsys, ["measure", tmp_path / "d.stl", "--json"])
    assert "no triangles" in _err(capsys, ["measure", tmp_path / "e.stl", "--json"])


# ----------------------------------------------------------------- 22: loader options everywhere
def test_segment_and_drift_take_loader_options(files, tmp_path, capsys):
    """A raw volume segmented with --shape/--dtype/--spacing (4.09 mL as from the DICOM
    series); a cropped series segmented and drift-checked; a NIfTI CT meshed with --iso."""
    import nibabel as nib

    from ctui.engine.io.series import load

    vol = load(files["series"])
    vol.data.astype("<i2").tofile(tmp_path / "v.raw")
    capsys.readouterr()
    assert main(["segment", str(tmp_path / "v.raw"), "--shape", "16,48,48", "--dtype", "int16", "--spacing",
                 ",".join(map(str, vol.spacing)), "--seed", SEED, "--range", "200:400", "--json"]) == 0
    assert abs(json.loads(capsys.readouterr().out)["objects"][0]["volume_ml"] - 4.09) < 0.01
    assert main(["segment", str(files["series"]), "--crop", "2,14,,,,", "--seed", "24,24,6", "--range", "200:400",
                 "--project", str(tmp_path / "c.ctui")]) == 0
    assert main(["drift", str(files["series"]), "--crop", "2,14,,,,", "--seed", "24,24,6", "--range", "200:400",
                 "--json"]) == 0
    ct = np.full((30, 30, 20), -1000, np.int16)
    ct[5:25, 5:25, 5:15] = 500
    nib.save(nib.Nifti1Image(ct, np.eye(4)), tmp_path / "ct.nii.gz")
    capsys.readouterr()
    assert main(["mesh", str(tmp_path / "ct.nii.gz"), "--iso", "-250", "--out", str(tmp_path / "ct.stl"),
                 "--json"]) == 0
    assert abs(json.loads(capsys.readouterr().out)["volume_ml"] - 4.0) < 0.1  # the 20x20x10 mm box


# ----------------------------------------------------------------- 15: info samples large volume files
@pytest.mark.slow
def test_info_samples_a_huge_compressed_nifti(tmp_path):
    """A small .nii.gz declaring 2000x2000x1000 uint8 (and vox_offset 0): info reads the
    header and the first slice only (sampled range, a warning), well under the memory the
    volume would take; a 94 MB .nii is sampled at 3 slices."""
    import nibabel as nib

    from ctui.engine.actions.info import describe_series

    h = nib.Nifti1Image(np.zeros((2, 2, 2), np.uint8), np.eye(4)).header
    h.set_data_shape((2000, 2000, 1000))
    with gzip.open(tmp_path / "huge.nii.gz", "wb") as fh:
        fh.write(h.binaryblock + bytes(4))
        for _ in range(8):
            fh.write(bytes(8 << 20))
    import tracemalloc

    tracemalloc.start()
    vol, d = describe_series(tmp_path / "huge.nii.gz")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert d["shape_zyx"] == [1000, 2000, 2000] and d["value_range_sampled"] and d["sampled_slices"] == 1
    assert peak < 200 << 20 and any("vox_offset" in w for w in vol.warnings)
    a = (np.arange(300 * 300 * 600) % 997).astype(np.int16).reshape(300, 300, 600)
    nib.save(nib.Nifti1Image(a, np.eye(4)), tmp_path / "big.nii")
    vol, d = describe_series(tmp_path / "big.nii")
    assert d["shape_zyx"] == [600, 300, 300] and d["sampled_slices"] == 3 and d["value_range"][1] <= 996
    assert not any("vox_offset" in w for w in vol.warnings)


def test_export_prints_object_names_escaped(files, tmp_path, capsys):
    """An object name holding ESC[2J and OSC 52 (from a hostile project) reaches the
    terminal escaped when `ctui export` lists what it wrote."""
    import zipfile

    with zipfile.ZipFile(files["project"]) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    doc = json.loads(members["project.json"])
    doc["objects"][0]["name"] = "\x1b[2Jkid\x1b]52;c;ZXZpbA==\x07ney"
    members["project.json"] = json.dumps(doc).encode()
    p = tmp_path / "esc.ctui"
    with zipfile.ZipFile(p, "w") as zf:
        for n, b in members.items():
            zf.writestr(n, b)
    capsys.readouterr()
    assert main(["export", str(p), "--format", "stl", "--out", str(tmp_path / "o.stl")]) == 0
    out, err = capsys.readouterr()
    assert "\x1b" not in out + err and "\x07" not in out + err


# ----------------------------------------------------------------- 21: TUI open dialog, long names
async def test_open_dialog_long_path_component(tmp_path, monkeypatch):
    """A typed path component over 255 bytes: a notification, not "Internal error in stat"."""
    from textual.widgets import Input

    from ctui.screens import graphics
    from ctui.screens.app import CtuiApp
    from ctui.screens.testing import wait_workspace

    monkeypatch.setattr(graphics, "_chosen", "halfblock")
    monkeypatch.setenv("CTUI_AUTOSAVE_DIR", str(tmp_path / "autosave"))
    monkeypatch.chdir(tmp_path)
    app = CtuiApp()
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        await pilot.press("o")
        await pilot.pause()
        scr = app.screen
        assert type(scr).__name__ == "OpenScreen"
        scr.query_one("#op-path", Input).value = str(tmp_path / ("x" * 300) / "y")
        scr.action_open_typed()
        await pilot.pause()
        assert app.screen is scr and len(app.errors) == 1 and "File name too long" in app.errors[0], app.errors
        assert not any("Internal error" in e for e in app.errors)


def test_info_samples_a_huge_gzip_nrrd(tmp_path):
    """A gzip NRRD declaring 2000x2000x1000 uint8: info inflates the first slice only."""
    from ctui.engine.actions.info import describe_series

    with open(tmp_path / "h.nrrd", "wb") as fh:
        fh.write(b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2000 2000 1000\nencoding: gzip\n\n")
        fh.write(gzip.compress(bytes(16 << 20)))
    import tracemalloc

    tracemalloc.start()
    vol, d = describe_series(tmp_path / "h.nrrd")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert d["shape_zyx"] == [1000, 2000, 2000] and d["sampled_slices"] == 1 and d["value_range"] == [0.0, 0.0]
    assert peak < 100 << 20
