from __future__ import annotations

import os
import stat

import pytest

from ctui.engine.core.atomic import atomic_write, current_umask, write_bytes
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
    with pytest.raises(RuntimeError), atomic_write(p, "w") as fh:
        fh.write("partial")
        raise RuntimeError("crash in the middle")
    assert p.read_bytes() == b"previous"
    assert os.listdir(tmp_path) == ["a.txt"]


def test_atomic_write_unwritable_folder(tmp_path):
    with pytest.raises(CtuiError) as err:
        write_bytes(tmp_path / "missing" / "x.bin", b"1")
    assert "x.bin" in str(err.value)


def _with_umask(mask, fn):
    old = os.umask(mask)
    try:
        return fn()
    finally:
        os.umask(old)


@pytest.mark.parametrize("mask, want", [(0o077, 0o600), (0o022, 0o644), (0o002, 0o664)])
def test_new_file_mode_follows_the_umask(tmp_path, mask, want):
    p = tmp_path / "p.ctui"
    _with_umask(mask, lambda: write_bytes(p, b"x"))
    assert stat.S_IMODE(p.stat().st_mode) == want


def test_replaced_file_keeps_its_mode(tmp_path):
    p = tmp_path / "keep.png"
    write_bytes(p, b"1")
    os.chmod(p, 0o640)
    _with_umask(0o022, lambda: write_bytes(p, b"2"))
    assert stat.S_IMODE(p.stat().st_mode) == 0o640 and p.read_bytes() == b"2"


def test_current_umask_is_read_without_changing_it():
    assert _with_umask(0o027, current_umask) == 0o027
    assert _with_umask(0o027, lambda: (current_umask(), current_umask())[1]) == 0o027


def test_writers_through_atomic_path_get_the_umask_mode(tmp_path):
    """Writers that need a file name (nibabel, PIL) go through atomic_path: same rule."""
    from ctui.engine.core.atomic import atomic_path

    def save():
        with atomic_path(tmp_path / "m.nii.gz") as tmp:
            tmp.write_bytes(b"data")

    _with_umask(0o077, save)
    assert stat.S_IMODE((tmp_path / "m.nii.gz").stat().st_mode) == 0o600
