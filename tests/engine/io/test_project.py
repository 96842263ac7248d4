"""`.ctui` projects: identical round trip, rejection of corrupt/foreign files and zip
bombs, privacy, and autosave/recovery."""

from __future__ import annotations

import io
import json
import os
import time
import tracemalloc
import zipfile

import numpy as np
import pytest

from ctui.engine.core.errors import FormatError
from ctui.engine.io.project import (
    Project,
    autosave,
    autosave_path,
    find_autosave,
    load_project,
    remove_autosave,
    save_project,
)


def _project(shape=(7, 12, 10)) -> Project:
    rng = np.random.default_rng(3)
    labels = np.zeros(shape, np.uint8)
    labels[2:5, 3:9, 2:8] = 1
    labels[rng.random(shape) > 0.95] = 4
    return Project(
        source_path="/data/series 1/ct",
        source_options={"series": "1.2.3.4", "spacing": [1.0, 0.5, 0.5]},
        pipeline={"version": 1, "values": "windowed8", "steps": [{"stage": 1, "op": "closing", "size": 3, "shape": "ellipse"}]},
        labels=labels,
        objects=[
            {"id": 1, "name": "Kidney L", "color": [230, 60, 60], "seeds": [[4, 5, 3]], "tolerance": 40},
            {"id": 4, "name": "Noise", "color": [255, 200, 40], "seeds": [[1, 1, 1], [2, 2, 2]], "range": [100.5, 300]},
        ],
        propagation={"direction": "both", "leak_factor": 2.5, "connectivity": 8},
        drift={"corrections": {"3": [1.5, -0.5]}, "flagged": [3, 5]},
        window=(40.0, 400.0),
        meta={"note": "ünïcode ok", "n": 3},
    )


def test_round_trip_identical(tmp_path):
    proj = _project()
    p = save_project(tmp_path / "a.ctui", proj)
    assert os.listdir(tmp_path) == ["a.ctui"]
    got = load_project(p)
    assert got == proj
    for name in ("source_path", "source_options", "pipeline", "objects", "propagation", "drift", "meta"):
        assert getattr(got, name) == getattr(proj, name), name
    assert got.window == (40.0, 400.0) and isinstance(got.window, tuple)
    assert got.labels.dtype == np.uint8 and got.labels.flags.writeable
    assert np.array_equal(got.labels, proj.labels)
    # a different label voxel makes them differ (the equality is real)
    got.labels[0, 0, 0] ^= 1
    assert got != proj


def test_round_trip_without_labels_and_numpy_values(tmp_path):
    proj = Project(source_path="x", objects=[{"id": np.int64(2), "seeds": [np.array([1, 2, 3])]}], window=(np.float32(1.5), 2))
    got = load_project(save_project(tmp_path / "b.ctui", proj))
    assert got.labels is None
    assert got.objects == [{"id": 2, "seeds": [[1, 2, 3]]}]
    assert got.window == (1.5, 2)


def test_one_zip_file_with_compressed_labels(tmp_path):
    proj = _project(shape=(60, 128, 128))
    p = save_project(tmp_path / "c.ctui", proj)
    with zipfile.ZipFile(p) as zf:
        assert sorted(zf.namelist()) == ["labels.npy", "project.json"]
        assert zf.getinfo("labels.npy").compress_type == zipfile.ZIP_DEFLATED
    assert p.stat().st_size < proj.labels.nbytes / 5


def test_no_identifiers_stored(tmp_path):
    proj = _project()
    proj.meta = {"PatientName": "ZZSECRET^NAME", "patient_id": "ID-98765-SECRET", "study": {"AccessionNumber": "ACC-1"}, "ok": 1}
    proj.source_options = {"InstitutionName": "SECRET HOSPITAL", "series": "1.2"}
    p = save_project(tmp_path / "d.ctui", proj)
    with zipfile.ZipFile(p) as zf:
        text = zf.read("project.json").decode()
    for s in ("ZZSECRET", "98765", "ACC-1", "SECRET HOSPITAL"):
        assert s not in text
    got = load_project(p)
    assert got.meta == {"study": {}, "ok": 1} and got.source_options == {"series": "1.2"}


def test_truncated_everywhere_rejected(tmp_path):
    p = save_project(tmp_path / "e.ctui", _project())
    good = p.read_bytes()
    bad = tmp_path / "cut.ctui"
    step = max(1, len(good) // 150)
    for n in list(range(0, len(good), step)) + [len(good) - 1]:
        bad.write_bytes(good[:n])
        with pytest.raises(FormatError) as err:
            load_project(bad)
        assert "cut.ctui" in str(err.value) and "\n" not in str(err.value)


def test_flipped_bytes_rejected_or_identical(tmp_path):
    proj = _project()
    good = save_project(tmp_path / "f.ctui", proj).read_bytes()
    rng = np.random.default_rng(5)
    bad = tmp_path / "flip.ctui"
    for _ in range(150):
        b = bytearray(good)
        i = int(rng.integers(0, len(b)))
        b[i] ^= 1 << int(rng.integers(0, 8))
        bad.write_bytes(bytes(b))
        try:
            got = load_project(bad)
        except FormatError:
            continue
        # a flip in a field zip ignores (timestamps, extra) may load: then it must be identical
        assert got == proj


def _zip(members: dict[str, bytes], declared: dict[str, int] | None = None) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for k, v in members.items():
            zf.writestr(k, v)
    return buf.getvalue()


def _npy(arr) -> bytes:
    b = io.BytesIO()
    np.save(b, arr)
    return b.getvalue()


def test_foreign_and_inconsistent_files(tmp_path):
    cases = {
        "empty": b"",
        "text": b"hello world, not a project",
        "other_zip": _zip({"readme.txt": b"hi"}),
        "not_json": _zip({"project.json": b"\xff\xfe{"}),
        "wrong_format": _zip({"project.json": json.dumps({"format": "other", "version": 1}).encode()}),
        "newer": _zip({"project.json": json.dumps({"format": "ctui-project", "version": 99}).encode()}),
        "bad_objects": _zip({"project.json": json.dumps({"format": "ctui-project", "version": 1, "objects": {}}).encode()}),
        "bad_window": _zip({"project.json": json.dumps({"format": "ctui-project", "version": 1, "window": [1]}).encode()}),
        "missing_labels": _zip({"project.json": json.dumps({"format": "ctui-project", "version": 1, "labels": {"shape": [2, 2, 2], "dtype": "uint8"}}).encode()}),
        "shape_mismatch": _zip(
            {
                "project.json": json.dumps({"format": "ctui-project", "version": 1, "labels": {"shape": [2, 2, 2], "dtype": "uint8"}}).encode(),
                "labels.npy": _npy(np.zeros((2, 2, 3), np.uint8)),
            }
        ),
        "dtype_mismatch": _zip(
            {
                "project.json": json.dumps({"format": "ctui-project", "version": 1, "labels": {"shape": [2, 2, 2], "dtype": "uint8"}}).encode(),
                "labels.npy": _npy(np.zeros((2, 2, 1), np.float64)),
            }
        ),
        "negative_shape": _zip({"project.json": json.dumps({"format": "ctui-project", "version": 1, "labels": {"shape": [-1, 2, 2], "dtype": "uint8"}}).encode()}),
    }
    for name, data in cases.items():
        (tmp_path / f"{name}.ctui").write_bytes(data)
        with pytest.raises(FormatError) as err:
            load_project(tmp_path / f"{name}.ctui")
        assert f"{name}.ctui" in str(err.value), name
    with pytest.raises(FormatError, match="newer"):
        load_project(tmp_path / "newer.ctui")
    with pytest.raises(FormatError, match="folder"):
        load_project(tmp_path)


def test_zip_bomb_not_decompressed(tmp_path):
    # 300 MB of zeros (deflates to ~300 kB) but project.json claims a 1x1x1 volume
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("project.json", json.dumps({"format": "ctui-project", "version": 1, "labels": {"shape": [1, 1, 1], "dtype": "uint8"}}))
        with zf.open("labels.npy", "w", force_zip64=True) as fh:
            np.lib.format.write_array_header_1_0(fh, {"descr": "|u1", "fortran_order": False, "shape": (1, 1, 1)})
            zero = bytes(1 << 20)
            for _ in range(300):
                fh.write(zero)
    (tmp_path / "bomb.ctui").write_bytes(buf.getvalue())
    tracemalloc.start()
    with pytest.raises(FormatError, match="does not match"):
        load_project(tmp_path / "bomb.ctui")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 20_000_000  # refused from the header: the 300 MB member is never inflated


def test_write_failure_keeps_previous(tmp_path):
    p = save_project(tmp_path / "g.ctui", _project())
    bad = _project()
    bad.meta = {"x": object()}
    with pytest.raises(FormatError, match="cannot be saved"):
        save_project(p, bad)
    assert load_project(p) == _project()
    assert os.listdir(tmp_path) == ["g.ctui"]


def test_autosave_beside_project_and_recovery(tmp_path):
    proj = _project()
    target = tmp_path / "work.ctui"
    assert autosave_path(target) == tmp_path / "work.ctui.autosave"
    assert find_autosave(target) is None
    save_project(target, proj)
    time.sleep(0.02)
    proj.labels[0, 0, 0] = 9
    a = autosave(proj, target)
    assert a == tmp_path / "work.ctui.autosave"
    assert find_autosave(target) == a
    assert load_project(a) == proj
    # an explicit save newer than the autosave: nothing to recover
    time.sleep(0.02)
    save_project(target, proj)
    assert find_autosave(target) is None
    remove_autosave(target)
    assert not a.exists()
    remove_autosave(target)  # idempotent


def test_autosave_for_unsaved_source(tmp_path, monkeypatch):
    monkeypatch.setenv("CTUI_AUTOSAVE_DIR", str(tmp_path / "auto"))
    src = tmp_path / "My Series (ä)"
    src.mkdir()
    proj = _project()
    proj.source_path = str(src)
    a = autosave(proj)
    assert a.parent == tmp_path / "auto" and a.name.endswith(".ctui.autosave")
    assert autosave_path(src) == a
    assert autosave_path(tmp_path / "other") != a
    assert find_autosave(src) == a
    assert load_project(a) == proj
