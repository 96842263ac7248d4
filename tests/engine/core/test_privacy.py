"""Privacy: no patient identifier from the source reaches any output.

A DICOM CT series carrying distinctive identifiers (PatientName, PatientID,
PatientBirthDate, AccessionNumber, InstitutionName, plus referring physician and
station name) goes through every CLI command and engine export; then every output
file (also inside .nii.gz gzip streams, NRRD gzip data and .ctui zip members), the
stdout and stderr of each command, the HOME/cache folder the commands ran with, and the
loaded Volume's metadata are searched for those strings.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ctui.engine.core.privacy import find_strings, scrub

ROOT = Path(__file__).resolve().parents[3]
SECRETS = {
    "PatientName": "ZZSECRET^NAME",
    "PatientID": "ID-98765-SECRET",
    "PatientBirthDate": "19010203",
    "AccessionNumber": "ACC-XYZ-777",
    "InstitutionName": "SECRET HOSPITAL",
    "ReferringPhysicianName": "DRSECRET^WHO",
    "StationName": "SECRETSTATION",
}
NEEDLES = [*SECRETS.values(), "1901-02-03", "ZZSECRET", "98765"]
SHAPE = (16, 48, 48)  # z, y, x
CENTRE = (8, 24, 24)


def write_series(folder: Path, *, broken: bool = True, secrets: dict | None = None, description: str = "privacy test",
                 study_description: str | None = None, private_text: str | None = None) -> Path:
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian

    folder.mkdir(parents=True, exist_ok=True)
    nz, ny, nx = SHAPE
    zz, yy, xx = np.mgrid[:nz, :ny, :nx]
    r2 = ((zz - CENTRE[0]) * 2.0) ** 2 + (yy - CENTRE[1]) ** 2 + (xx - CENTRE[2]) ** 2
    hu = np.where(r2 <= 10.0**2, 300, 0).astype(np.int16)
    for k in range(nz):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = f"1.2.826.0.1.3680043.8.498.77.{k + 1}"
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = Dataset()
        ds.file_meta = meta
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.StudyInstanceUID = "1.2.826.0.1.3680043.8.498.78"
        ds.SeriesInstanceUID = "1.2.826.0.1.3680043.8.498.79"
        ds.FrameOfReferenceUID = "1.2.826.0.1.3680043.8.498.80"  # DICOM-SEG/RTSTRUCT exports need it
        ds.SeriesNumber = 3
        ds.StudyDate, ds.StudyTime = "20240101", "120000"
        for kw, v in (SECRETS if secrets is None else secrets).items():
            setattr(ds, kw, v)
        ds.Modality = "CT"
        ds.SeriesDescription = description
        if study_description is not None:
            ds.StudyDescription = study_description
        if private_text is not None:  # a private block, as scanners write: creator + free text
            block = ds.private_block(0x0011, "ZYX PRIVATE", create=True)
            block.add_new(0x01, "LO", private_text)
            block.add_new(0x02, "LT", f"operator note: {private_text}")
        ds.InstanceNumber = k + 1
        ds.ImagePositionPatient = [-30.0, -40.0, 2.0 * k]
        ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
        ds.PixelSpacing = [1.0, 1.0]
        ds.SliceThickness = 2.0
        ds.Rows, ds.Columns = ny, nx
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated = 16
        ds.BitsStored = 16
        ds.HighBit = 15
        ds.PixelRepresentation = 1
        ds.RescaleSlope = 1
        ds.RescaleIntercept = 0
        ds.PixelData = hu[k].tobytes()
        ds.save_as(folder / f"slice{k:03d}.dcm", enforce_file_format=True)
    if broken:
        # a broken file whose identifiers a careless error/warning message would echo
        good = (folder / "slice000.dcm").read_bytes()
        i = good.find(b"SECRET HOSPITAL")
        (folder / "broken.dcm").write_bytes(good[: i + 8])
        b = bytearray(good)
        j = good.find(b"1.2.840.10008.1.2.1")  # transfer syntax value: corrupt its length
        b[j - 2 : j] = (400).to_bytes(2, "little")
        (folder / "broken2.dcm").write_bytes(bytes(b))
    return folder


def _has_command(name: str) -> bool:
    r = subprocess.run([sys.executable, "-m", "ctui", name, "--help"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    return r.returncode == 0


@pytest.fixture(scope="module")
def series(tmp_path_factory) -> Path:
    return write_series(tmp_path_factory.mktemp("privacy") / "series")


def test_series_really_carries_the_identifiers(series):
    assert find_strings([series], NEEDLES), "the test input must contain the identifiers"


def test_scrub_drops_identifying_keys():
    d = {"PatientName": "x", "patient_name": "y", "Institution Name": "z", "nested": [{"AccessionNumber": 1, "ok": 2}], "ok": 3}
    assert scrub(d) == {"nested": [{"ok": 2}], "ok": 3}


def test_volume_metadata_logs_and_warnings_clean(series, caplog):
    import logging
    import warnings

    from ctui.engine.io.series import load

    caplog.set_level(logging.DEBUG)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        vol = load(series)
    logged = [r.getMessage() for r in caplog.records] + [str(w.message) for w in caught]
    assert find_strings([], NEEDLES, texts=logged) == [], "identifiers in log records / warnings"
    assert vol.shape == SHAPE
    assert vol.skipped, "the broken files must be reported as skipped"
    blob = json.dumps(
        {k: v for k, v in vars(vol).items() if k not in ("data", "direction", "slice_positions")}, default=str
    ) + json.dumps(vol.describe(), default=str)
    assert find_strings([], NEEDLES, texts=[blob, repr(vol.skipped), repr(vol.warnings)]) == []


@pytest.mark.slow
def test_every_command_and_export_is_clean(series, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    home = tmp_path / "home"
    home.mkdir()
    env = {**os.environ, "HOME": str(home), "XDG_CACHE_HOME": str(home / ".cache"), "CTUI_AUTOSAVE_DIR": str(home / "autosave"), "PYTHONWARNINGS": "default"}
    seed = f"{CENTRE[2]},{CENTRE[1]},{CENTRE[0]}"
    o = lambda name: str(out / name)
    plan = [
        ("info", ["info", str(series), "--json"]),
        ("info", ["info", str(series)]),
        ("info", ["info", str(series / "broken.dcm")]),
        ("segment", ["segment", str(series), "--seed", seed, "--range", "200:400", "--project", o("p.ctui"), "--mask", o("m.nii.gz"), "--mric", o("c.mric"), "--json"]),
        ("segment", ["segment", str(series), "--seed", seed, "--tolerance", "50", "--mask", o("m.seg.nrrd")]),
        ("segment", ["segment", str(series), "--seed", seed, "--range", "200:400", "--mask", o("m.nrrd"), "--mric", o("c2.mric")]),
        ("drift", ["drift", str(series), "--seed", seed, "--range", "200:400", "--json", "--plot", o("drift.png"), "--project", o("d.ctui")]),
        ("drift", ["drift", o("p.ctui"), "--json"]),
        ("mesh", ["mesh", o("p.ctui"), "--out", o("obj.stl"), "--json"]),
        ("mesh", ["mesh", o("p.ctui"), "--out", o("obj_ascii.stl"), "--ascii"]),
        ("mesh", ["mesh", o("p.ctui"), "--out", o("obj.ply")]),
        ("mesh", ["mesh", o("p.ctui"), "--out", o("obj.obj")]),
        ("mesh", ["mesh", str(series), "--iso", "150", "--out", o("iso.stl"), "--json"]),
        ("mesh", ["mesh", o("c.mric"), "--out", o("contours.stl"), "--json"]),
        ("measure", ["measure", o("p.ctui"), "--json", "--path", "auto", "--csv", o("sec.csv"), "--plot", o("sec.png")]),
        ("measure", ["measure", o("m.nii.gz"), "--json"]),
        ("measure", ["measure", o("obj.stl"), "--json"]),
        ("render", ["render", o("obj.stl"), "--out", o("render.png"), "--size", "160x120"]),
        ("render", ["render", str(series), "--mode", "mip", "--out", o("mip.png"), "--size", "160x120"]),
        ("render", ["render", o("p.ctui"), "--out", o("turn.gif"), "--turntable", "3", "--size", "96x72"]),
    ]
    available = {name: _has_command(name) for name in {p[0] for p in plan}}
    ran, skipped, texts, failures = [], [], [], []
    for name, args in plan:
        if not available[name]:
            skipped.append(f"{name}: command not available (`ctui {name} --help` failed)")
            continue
        r = subprocess.run([sys.executable, "-m", "ctui", *args], capture_output=True, text=True, cwd=ROOT, env=env, timeout=600)
        texts += [r.stdout, r.stderr]
        ran.append((" ".join(args[:1]), r.returncode))
        expected_fail = args[1].endswith("broken.dcm") or (name == "render" and "EGL" in r.stderr)
        if r.returncode != 0 and not expected_fail:
            failures.append(f"ctui {' '.join(args)} -> {r.returncode}: {r.stderr.strip()[-300:]}")
    # engine-level exports and autosave of the project the CLI wrote
    from ctui.engine.io.labels import save_labels
    from ctui.engine.io.project import autosave, load_project, save_project
    from ctui.engine.io.series import load

    if (out / "p.ctui").exists():
        proj = load_project(out / "p.ctui")
        autosave(proj, out / "p.ctui")
        save_project(out / "copy.ctui", proj)
        vol = load(series)
        if proj.labels is not None:
            save_labels(out / "engine.seg.nrrd", proj.labels, vol)
            save_labels(out / "engine.nii", proj.labels, vol)
    try:
        load(series / "broken.dcm")
    except Exception as exc:  # noqa: BLE001 - the message itself is checked
        texts.append(str(exc))
    print("privacy: ran", ran, "skipped", skipped)
    produced = sorted(p.name for p in out.iterdir())
    print("privacy: outputs", produced)
    leaks = find_strings([out, home], NEEDLES, texts=texts)
    assert leaks == [], leaks
    assert not failures, failures
    assert "p.ctui" in produced and "m.nii.gz" in produced and "c.mric" in produced
    assert "p.ctui.autosave" in produced


# --------------------------------------------------------------------- names in folder, descriptions, private tags
NAME = "Zyxwv^Qwerty"
FOLDER = "Zyxwv_Qwerty_1970"
NAMED = {"PatientName": NAME, "PatientID": "QX44719", "PatientBirthDate": "19700101"}
NAMED_NEEDLES = ["Zyxwv", "Qwerty", "QX44719", "19700101", "1970-01-01", FOLDER]


def test_scrub_text_whole_words_of_own_identifiers_only():
    from ctui.engine.core.privacy import identifier_tokens, scrub_text

    ids = [NAME, "QX44719", "19700101", "ANN^HEAD"]
    assert scrub_text("CT Zyxwv Qwerty abdomen", ids) == "CT [removed] [removed] abdomen"
    assert scrub_text(f"/data/{FOLDER}/ct", ids) == "/data/[removed]_[removed]_1970/ct"
    assert scrub_text("zyxwv^QWERTY qx44719 b.19700101", ids) == "[removed]^[removed] [removed] b.[removed]"
    # harmless words are kept: substrings, common words, short tokens
    assert scrub_text("SCANNER HEAD 3 mm, Annotated", ids) == "SCANNER HEAD 3 mm, Annotated"
    assert scrub_text("Zyxwvish Qwertys", ids) == "Zyxwvish Qwertys"
    assert "HEAD" not in identifier_tokens(["ANN^HEAD"]) and "ANN" in identifier_tokens(["ANN^HEAD"])
    assert identifier_tokens(["LI^BO", "123"]) == []  # too short to scrub without garbling text


def test_hide_path():
    from ctui.engine.core.privacy import hide_path

    assert hide_path(f"DICOM CT series, 3 files, from /x/{FOLDER}", [f"/x/{FOLDER}/"]) == "DICOM CT series, 3 files, from <input>"


@pytest.fixture(scope="module")
def named_series(tmp_path_factory) -> Path:
    return write_series(tmp_path_factory.mktemp("named") / FOLDER, broken=False, secrets=NAMED,
                        description=f"CT {NAME.replace('^', ' ')} abdomen", study_description="Qwerty study 1970",
                        private_text=f"{NAME} 19700101")


def test_named_series_carries_the_name(named_series):
    assert find_strings([named_series], ["Zyxwv", "QX44719", "19700101"])
    blob = b"".join(f.read_bytes() for f in named_series.iterdir())
    assert b"operator note: Zyxwv^Qwerty" in blob and b"Qwerty study" in blob and b"CT Zyxwv Qwerty" in blob


def _project_without_source_path(p: Path) -> bytes:
    """The project's bytes with its source_path value cut out: the project is the one
    output that references the series by path (it must reopen it)."""
    import zipfile

    with zipfile.ZipFile(p) as zf:
        d = json.loads(zf.read("project.json"))
        rest = b"".join(zf.read(n) for n in zf.namelist() if n != "project.json")
    d.pop("source_path", None)
    if isinstance(d.get("source"), dict):
        d["source"].pop("path", None)
    return json.dumps(d).encode() + rest


@pytest.mark.slow
def test_named_series_reaches_no_output(named_series, tmp_path, capsys, monkeypatch):
    from ctui.cli import main
    from ctui.engine.render import egl_available

    out = tmp_path / "out"
    out.mkdir()
    monkeypatch.setenv("CTUI_AUTOSAVE_DIR", str(tmp_path / "autosave"))
    s = str(named_series)
    seed = f"{CENTRE[2]},{CENTRE[1]},{CENTRE[0]}"
    o = lambda name: str(out / name)
    plan = [
        ["info", s], ["info", s, "--json"],
        ["segment", s, "--seed", seed, "--range", "200:400", "--project", o("p.ctui"), "--mask", o("m.nii.gz"),
         "--mric", o("c.mric"), "--json"],
        ["segment", s, "--seed", seed, "--range", "200:400", "--mask", o("m.seg.nrrd")],
        ["drift", s, "--seed", seed, "--range", "200:400", "--json", "--plot", o("drift.png")],
        ["drift", o("p.ctui"), "--json"],
        ["mesh", o("p.ctui"), "--out", o("obj.stl"), "--json"],
        ["mesh", o("p.ctui"), "--out", o("obj.ply"), "--ascii"],
        ["mesh", s, "--iso", "150", "--out", o("iso.obj"), "--json"],
        ["measure", o("p.ctui"), "--json", "--path", "auto", "--csv", o("sec.csv"), "--plot", o("sec.png")],
        ["measure", o("m.nii.gz"), "--json"],
        *[["export", o("p.ctui"), "--format", fmt, "--out", o(f"e.{ext}"), "--json"]
          for fmt, ext in (("dicom-seg", "seg.dcm"), ("rtstruct", "rt.dcm"), ("csv", "csv"), ("nrrd", "nrrd"),
                           ("obj", "obj"), ("mric", "mric"))],
    ]
    if egl_available():
        plan += [["render", s, "--mode", "mip", "--out", o("mip.png"), "--size", "64x48"],
                 ["render", o("obj.stl"), "--out", o("r.png"), "--size", "64x48"]]
    texts, failures = [], []
    for argv in plan:
        rc = main(argv)
        r = capsys.readouterr()
        texts += [r.out, r.err]
        if rc != 0:
            failures.append(f"ctui {' '.join(argv)} -> {rc}: {r.err.strip()[-300:]}")
    assert not failures, failures
    files = [f for f in out.iterdir() if not f.name.endswith(".ctui")]
    leaks = find_strings(files + [tmp_path / "autosave"], NAMED_NEEDLES, texts=texts)
    projects = [_project_without_source_path(f) for f in out.iterdir() if f.name.endswith(".ctui")]
    leaks += find_strings([], NAMED_NEEDLES, texts=[b.decode("latin-1") for b in projects])
    assert leaks == [], leaks
