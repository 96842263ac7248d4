"""One loader-option syntax (comma-separated z,y,x lists) for every command, with a clear
one-line error for the old ZxYxX form; every action default in one place."""

from __future__ import annotations

import pytest

from ctui.cli import main
from ctui.engine.actions.options import load_options
from ctui.engine.core.errors import CtuiError


def test_load_options_parse():
    kw = load_options(series="3", spacing="2,0.5,0.5", shape="40,64,64", dtype=">u2", offset=0,
                      crop="0,10,,,,", downsample="1,2,2", resample=False)
    assert kw == {"series": 3, "spacing": (2.0, 0.5, 0.5), "shape": (40, 64, 64), "dtype": ">u2", "offset": 0,
                  "crop": (0, 10, None, None, None, None), "downsample": (1, 2, 2), "resample": False}
    assert load_options(spacing="0.7", downsample=2) == {"spacing": (0.7, 0.7, 0.7), "downsample": 2}
    assert load_options(series="1.2.840.113619") == {"series": "1.2.840.113619"}


@pytest.mark.parametrize("kw,needle", [
    ({"shape": "40x64x64"}, "not with 'x'"),
    ({"spacing": "2x1x1"}, "not with 'x'"),
    ({"shape": "40,64"}, None),
    ({"shape": "40,64,0"}, ">= 1"),
    ({"spacing": "1,nan,1"}, "finite"),
    ({"crop": "0,1,2"}, "6 integers"),
    ({"downsample": "0"}, ">= 1"),
    ({"offset": -1}, ">= 0"),
])
def test_load_options_errors(kw, needle):
    if needle is None:
        assert load_options(**kw)["shape"] == (40, 64)
        return
    with pytest.raises(CtuiError, match=needle):
        load_options(**kw)


@pytest.mark.parametrize("command", ["info", "render"])
def test_old_shape_syntax_refused_on_one_line(tmp_path, capsys, command):
    raw = tmp_path / "v.raw"
    raw.write_bytes(bytes(2 * 4 * 4))
    argv = [command, str(raw), "--shape", "2x4x4", "--dtype", "uint8"]
    if command == "render":
        argv += ["--out", str(tmp_path / "v.png")]
    rc = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--shape" in err[0] and "commas" in err[0]


def test_one_section_step_for_cli_and_tui():
    from ctui.commands import measure
    from ctui.engine.actions import defaults

    import argparse

    parser = argparse.ArgumentParser()
    measure.register(parser.add_subparsers())
    args = parser.parse_args(["measure", "x.ctui"])
    assert args.step == defaults.SECTION_STEP_MM == 0.5


def test_one_path_from_an_error_to_the_cli_line():
    from ctui.cli import error_line

    assert error_line(CtuiError("bad spacing", path="/a/b.nii")) == ("/a/b.nii: bad spacing", 2)
    assert error_line(KeyboardInterrupt()) == ("interrupted", 130)
    assert error_line(MemoryError())[1] == 2
    msg, code = error_line(PermissionError(13, "Permission denied", "/x/out.stl"))
    assert code == 2 and msg == "/x/out.stl: Permission denied"
    assert error_line(ValueError("a bug")) is None  # a bug keeps its traceback
