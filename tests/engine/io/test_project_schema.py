"""Crafted projects: every field of the one project schema is validated on open, with a
one-line error naming the file and the field (no traceback), through the loader and the CLI."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

from ctui.cli import main
from ctui.engine.core.errors import FormatError
from ctui.engine.core.geometry import Geometry
from ctui.engine.io.project import Project, encode_project, load_project

SHAPE = (4, 5, 6)


def _good() -> tuple[dict, bytes]:
    labels = np.zeros(SHAPE, np.uint8)
    labels[1:3, 1:4, 1:5] = 2
    p = Project(source_path="", labels=labels, objects=[{"id": 2, "name": "a", "color": [200, 10, 10]}],
                propagation={"low": 100.0, "high": 300.0, "connectivity": 8, "direction": "both"},
                window=(40.0, 400.0), geometry=Geometry(SHAPE, (2.0, 0.5, 0.5), (1.0, 2.0, 3.0)),
                modality="CT", voxel_hash="blake2b-128:00")
    with zipfile.ZipFile(io.BytesIO(encode_project(p))) as zf:
        return json.loads(zf.read("project.json")), zf.read("labels.npy")


def _write(path, doc: dict, npy: bytes, *, raw_json: str | None = None) -> None:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("project.json", raw_json if raw_json is not None else json.dumps(doc))
        zf.writestr("labels.npy", npy)


def _set(doc: dict, dotted: str, value) -> dict:
    d = json.loads(json.dumps(doc))
    keys = dotted.split(".")
    cur = d
    for k in keys[:-1]:
        cur = cur[int(k)] if isinstance(cur, list) else cur[k]
    last = keys[-1]
    if isinstance(cur, list):
        cur[int(last)] = value
    else:
        cur[last] = value
    return d


CASES = [
    ("geometry.spacing_zyx_mm", "abc", "spacing_zyx_mm"),
    ("geometry.spacing_zyx_mm", [1.0, 2.0], "spacing_zyx_mm"),
    ("geometry.spacing_zyx_mm", [1.0, 0.0, 1.0], "spacing_zyx_mm"),
    ("geometry.spacing_zyx_mm", [1.0, "NaN!", 1.0], "spacing_zyx_mm"),
    ("geometry.origin_xyz_mm", [1.0, 2.0], "origin_xyz_mm"),
    ("geometry.direction", [[1, 0, 0], [0, 1, 0]], "direction"),
    ("geometry.direction", [[1, 0, 0], [0, 1, 0], [0, 0, 5]], "direction"),
    ("geometry.shape_zyx", [4, 5, 7], "does not match the labels"),
    ("geometry.shape_zyx", "4x5x6", "shape_zyx"),
    ("geometry", [1, 2, 3], "geometry"),
    ("source_options.spacing", [1, 2], "source_options.spacing"),
    ("source_options.crop", [0, 1], "source_options.crop"),
    ("source_options.downsample", -2, "source_options.downsample"),
    ("source_options.series", {"a": 1}, "source_options.series"),
    ("source_options", "x", "source_options"),
    ("source_path", 5, "source_path"),
    ("objects", [{"id": "two"}], "objects[0].id"),
    ("objects", [{"id": 2, "color": [1, 2]}], "objects[0].color"),
    ("objects", [{"id": 2}, {"id": 2}], "listed twice"),
    ("objects", ["x"], "objects[0]"),
    ("propagation.connectivity", "eight", "propagation.connectivity"),
    ("propagation.range", [1], "propagation.range"),
    ("propagation.per_object", [5], "propagation.per_object[0]"),
    ("window", [40, -1], "window"),
    ("window", [40], "window"),
    ("modality", 7, "modality"),
    ("voxel_hash", ["x"], "voxel_hash"),
    ("version", "2", "version"),
    ("version", 99, "newer"),
]


@pytest.mark.parametrize("field,value,needle", CASES)
def test_crafted_field_refused_naming_the_field(tmp_path, field, value, needle):
    doc, npy = _good()
    if field.startswith("source_options.") and "source_options" not in doc:
        doc["source_options"] = {}
    f = tmp_path / "c.ctui"
    _write(f, _set(doc, field, value), npy)
    with pytest.raises(FormatError) as e:
        load_project(f)
    msg = str(e.value)
    assert str(f) in msg and needle in msg and "\n" not in msg


@pytest.mark.parametrize("token", ["NaN", "Infinity", "-Infinity"])
def test_non_finite_numbers_anywhere_refused(tmp_path, token):
    doc, npy = _good()
    for where in ('"window": [40.0, 400.0]', '"low": 100.0'):
        raw = json.dumps(doc).replace(where, where.replace("40.0" if "window" in where else "100.0", token))
        assert raw != json.dumps(doc)
        f = tmp_path / "n.ctui"
        _write(f, doc, npy, raw_json=raw)
        with pytest.raises(FormatError, match="not a finite number"):
            load_project(f)


def test_cli_one_line_on_a_crafted_project(tmp_path, capsys):
    doc, npy = _good()
    f = tmp_path / "c.ctui"
    _write(f, _set(doc, "geometry.spacing_zyx_mm", [1, "x", 1]), npy)
    for argv in (["measure", f], ["mesh", f, "--out", tmp_path / "m.stl"], ["drift", f]):
        rc = main([str(a) for a in argv])
        err = capsys.readouterr().err
        assert rc == 2 and len(err.strip().splitlines()) == 1 and "spacing_zyx_mm" in err, (argv, err)


def test_good_project_round_trips_geometry(tmp_path):
    doc, npy = _good()
    f = tmp_path / "g.ctui"
    _write(f, doc, npy)
    p = load_project(f)
    assert p.geometry.spacing == (2.0, 0.5, 0.5) and p.geometry.origin == (1.0, 2.0, 3.0)
    assert p.modality == "CT" and p.voxel_hash == "blake2b-128:00" and p.version == 2


def test_schema_types_every_propagation_setting():
    """The CLI (PropagationSettings) and the TUI write propagation in the one schema."""
    from ctui.engine.io.projectschema import PROPAGATION_KEYS
    from ctui.engine.segment.propagate import PropagationSettings

    assert set(PropagationSettings(100.0, 300.0).to_dict()) <= set(PROPAGATION_KEYS)
    assert {"tolerance", "range", "connectivity", "current", "mode"} <= set(PROPAGATION_KEYS)  # the TUI's keys
