"""`ctui info` and `ctui demo` through the real command line."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from support import ROOT, shared
from ctui.engine.io.phantom import SAMPLE_DIR, load_truth


def ctui(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "ctui", *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=120)


def test_info_json_on_sample():
    r = ctui("info", SAMPLE_DIR, "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    for key in ("shape_zyx", "spacing_zyx_mm", "modality", "series", "skipped", "warnings"):
        assert key in d
    truth = load_truth()
    assert d["shape_zyx"] == truth["shape_zyx"]
    assert d["spacing_zyx_mm"] == pytest.approx(truth["spacing_zyx_mm"])
    assert d["modality"] == "CT" and d["orientation"] == "axial"
    assert d["skipped"] == [{"file": "truth.json", "reason": "not a DICOM file or image"}]
    assert d["warnings"] == []
    assert d["series"][0]["files"] == 80 and d["series"][0]["shape_zyx"] == truth["shape_zyx"]
    # privacy: the synthetic patient name and ID never reach the output
    assert "PHANTOM^SYNTHETIC" not in r.stdout and "SYNTHETIC-0000" not in r.stdout


def test_info_human_output(tmp_path):
    r = ctui("info", SAMPLE_DIR)
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert "80 x 128 x 128" in out and "2.5 x 2 x 2 mm" in out and "axial" in out
    assert "truth.json: not a DICOM file or image" in out and "window      centre 40, width 400" in out
    assert "-1024 .." in out and "HU" in out


def test_info_nothing_loadable_exits_2(tmp_path):
    (tmp_path / "a.txt").write_text("hello")
    r = ctui("info", tmp_path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ctui info: ") and str(tmp_path) in lines[0]
    assert r.stdout == ""
    r = ctui("info", tmp_path / "nope")
    assert r.returncode == 2 and "no such file" in r.stderr and "Traceback" not in r.stderr


def test_info_raw_options_and_warnings():
    d = shared("cthead_unc")
    r = ctui("info", d, "--shape", "256,256", "--dtype", ">u2", "--json")
    assert r.returncode == 0, r.stderr
    j = json.loads(r.stdout)
    assert j["shape_zyx"] == [113, 256, 256]
    assert any("default spacing" in w for w in j["warnings"])
    assert j["skipped"] == [{"file": "desc.txt.orig", "reason": "size 1489 bytes, expected 131072 for a 256x256 >u2 slice"}]
    r = ctui("info", d, "--shape", "256,256", "--dtype", ">u2", "--spacing", "2,1,1", "--crop", "0,10,,,,", "--downsample", "2", "--json")
    j = json.loads(r.stdout)
    assert j["shape_zyx"] == [10, 128, 128] and j["spacing_zyx_mm"] == [2.0, 2.0, 2.0]
    assert not any("default spacing" in w for w in j["warnings"])


def test_info_series_option(tmp_path):
    r = ctui("info", SAMPLE_DIR, "--series", "3")
    assert r.returncode == 2 and "out of range" in r.stderr


def test_info_no_positions_warning():
    r = ctui("info", shared("ball_phantom_no_geometry"), "--json")
    j = json.loads(r.stdout)
    assert any("InstanceNumber" in w for w in j["warnings"]) and j["shape_zyx"] == [129, 128, 129]


@pytest.mark.slow
def test_demo_writes_series_and_truth(tmp_path):
    out = tmp_path / "ph"
    r = ctui("demo", out, "--no-drift", "--seed", "3")
    assert r.returncode == 0, r.stderr
    assert len(list(out.glob("*.dcm"))) == 80 and (out / "truth.json").is_file()
    t = load_truth(out)
    assert t["drift"]["slices"] == [] and t["seed"] == 3
    assert "kidney_left" in r.stdout
    r = ctui("info", out, "--json")
    assert json.loads(r.stdout)["shape_zyx"] == [80, 128, 128]
    (tmp_path / "file").write_text("x")
    r = ctui("demo", tmp_path / "file")
    assert r.returncode == 2 and "not a folder" in r.stderr


def test_info_reads_headers_and_three_slices_only(tmp_path, monkeypatch):
    """`ctui info` (actions.describe_series) decodes three sample slices, not the series,
    and reports the geometry a full load gives (here a tilted, unevenly spaced series)."""
    import numpy as np

    from ctui.engine.actions.info import describe_series
    from ctui.engine.io.series import dicom, load
    from test_load_geometry import write_slices

    t = np.radians(15.0)
    row, col = (1.0, 0.0, 0.0), (0.0, float(np.cos(t)), float(np.sin(t)))
    z = [0, 1, 2, 3, 4, 5, 8, 11, 14, 17, 20, 23]
    images = [np.full((24, 20), 10 * k, np.int16) for k in range(len(z))]
    write_slices(tmp_path / "s", images, [[0.0, 0.0, float(v)] for v in z], iop=(*row, *col))
    full = load(tmp_path / "s")
    calls = []
    real = dicom._decode_frame
    monkeypatch.setattr(dicom, "_decode_frame", lambda *a, **k: calls.append(1) or real(*a, **k))
    vol, d = describe_series(tmp_path / "s")
    assert len(calls) == 3
    assert vol.shape == full.shape and vol.data.strides == (0, 0, 0)  # a zero-byte placeholder
    assert vol.spacing == pytest.approx(full.spacing) and vol.origin == pytest.approx(full.origin)
    assert np.allclose(vol.direction, full.direction) and vol.warnings == full.warnings
    assert d["value_range"] == [0.0, 110.0] and d["meta"]["headers_only"] is True
    assert any("grown" in w for w in d["warnings"]) and any("regular" in w for w in d["warnings"])
    json.dumps(d, allow_nan=False, default=str)


def test_header_fast_path_table_matches_pydicom_and_files():
    """The fast header path's element table is pydicom's dictionary, and it reads the
    sample series' headers exactly as the pydicom path does."""
    import dataclasses

    import numpy as np
    from pydicom.datadict import dictionary_VR, tag_for_keyword

    from ctui.engine.io.series import dicom_headers
    from ctui.engine.io.series.dicom_quick import ELEMENTS, quick_parse

    for kw, (tag, vr) in ELEMENTS.items():
        assert tag_for_keyword(kw) == tag and dictionary_VR(tag) == vr, kw
    files = sorted(SAMPLE_DIR.glob("*.dcm"))[:10]
    assert files
    for f in files:
        assert quick_parse(f.read_bytes()[:32768]) is not None
        fast, ids_fast = dicom_headers.read_header(f)
        orig = dicom_headers.quick_parse
        try:
            dicom_headers.quick_parse = lambda buf: None
            slow, ids_slow = dicom_headers.read_header(f)
        finally:
            dicom_headers.quick_parse = orig
        assert [str(i) for i in ids_fast] == [str(i) for i in ids_slow]
        for a, b in zip(fast, slow):
            for fld in dataclasses.fields(a):
                u, v = getattr(a, fld.name), getattr(b, fld.name)
                assert (np.array_equal(u, v) if isinstance(u, np.ndarray) else u == v), fld.name
