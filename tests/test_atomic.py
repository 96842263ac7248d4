from __future__ import annotations

import os

import pytest

from ctui.engine.core.atomic import atomic_write, write_bytes
from ctui.engine.core.errors import CtuiError


def test_atomic_write_replaces_whole_file(tmp_path):
    p = tmp_path / "a.bin"
    write_bytes(p, b"old")
    write_bytes(p, b"new content")
    assert p.read_bytes() == b"new content"
    assert os.listdir(tmp_path) == ["a.bin"]


def test_atomic_write_failure_keeps_previous(tmp_path):
    p = tmp_path / "a.txt"
    write_bytes(p, b"previous")
    with pytest.raises(RuntimeError):
        with atomic_write(p, "w") as fh:
            fh.write("partial")
            raise RuntimeError("crash in the middle")
    assert p.read_bytes() == b"previous"
    assert os.listdir(tmp_path) == ["a.txt"]


def test_atomic_write_unwritable_folder(tmp_path):
    with pytest.raises(CtuiError) as err:
        write_bytes(tmp_path / "missing" / "x.bin", b"1")
    assert "x.bin" in str(err.value)
