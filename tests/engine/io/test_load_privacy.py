"""Privacy at load: the Volume's source, series list and description carry none of the
headers' own patient identifiers, whether they sit in SeriesDescription, the folder
name or a private tag; harmless words in descriptions are kept."""

from __future__ import annotations

import json

import numpy as np
import pytest

pydicom = pytest.importorskip("pydicom")

from ctui.engine.io.series import load, scan  # noqa: E402

NAME, PID, BIRTH = "Zyxwv^Qwerty", "QX44719", "19700101"


def test_identifiers_scrubbed_from_source_and_series(tmp_path):
    from test_load_geometry import write_slices

    folder = tmp_path / "Zyxwv_Qwerty_QX44719"
    images = [np.full((8, 8), k, np.int16) for k in range(4)]
    paths = write_slices(folder, images, [[0.0, 0.0, 2.0 * k] for k in range(4)], PatientName=NAME, PatientID=PID,
                         PatientBirthDate=BIRTH, SeriesDescription=f"HEAD CT Zyxwv Qwerty {BIRTH} contrast",
                         StudyDescription=f"Qwerty study {PID}")
    for p in paths:  # a private tag's text with the name: never read into the Volume
        ds = pydicom.dcmread(p)
        ds.add_new(0x00091010, "LO", f"operator note: {NAME}")
        ds.save_as(p)
    vol = load(folder)
    text = json.dumps({"source": vol.source, "series": vol.series, "describe": vol.describe(), "meta": vol.meta,
                       "skipped": vol.skipped, "warnings": vol.warnings}, default=str)
    for needle in ("Zyxwv", "Qwerty", PID, BIRTH, "operator note"):
        assert needle.lower() not in text.lower(), needle
    # harmless words of the description stay
    assert "HEAD CT" in vol.source and "contrast" in vol.source
    assert "HEAD CT" in vol.series[0]["description"]
    listed = json.dumps(scan(folder))
    assert "Zyxwv" not in listed and PID not in listed and "HEAD CT" in listed
