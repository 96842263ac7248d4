"""The engine must stay usable without a terminal: importing every ctui.engine module
must not import textual, rich or textual_image."""

from __future__ import annotations

import pkgutil
import subprocess
import sys
import textwrap
from pathlib import Path

import ctui.engine


def test_engine_modules_exist():
    names = [m.name for m in pkgutil.iter_modules(ctui.engine.__path__)]
    assert {"core", "io", "segment", "mesh", "measure", "render"} <= set(names)
    core = [m.name for m in pkgutil.iter_modules([str(Path(ctui.engine.__path__[0]) / "core")])]
    assert "volume" in core and "atomic" in core and "geometry" in core


def test_engine_imports_no_ui_packages():
    code = textwrap.dedent(
        """
        import importlib, pkgutil, sys
        import ctui.engine
        names = []
        for m in pkgutil.walk_packages(ctui.engine.__path__, "ctui.engine."):
            importlib.import_module(m.name)
            names.append(m.name)
        bad = sorted(k for k in sys.modules if k.split(".")[0] in ("textual", "rich", "textual_image"))
        print(len(names))
        if bad:
            print("UI modules imported:", bad)
            sys.exit(1)
        """
    )
    root = Path(__file__).resolve().parents[2]
    res = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    assert int(res.stdout.split()[0]) >= 3


def test_cli_help_imports_nothing_heavy():
    """`ctui --help` must answer fast: building the parser may not import numpy,
    textual, scipy, numba, cv2, pydicom or moderngl (each costs 50-500 ms)."""
    code = textwrap.dedent(
        """
        import sys, contextlib, io
        from ctui.cli import main
        with contextlib.redirect_stdout(io.StringIO()) as out:
            try:
                main(["--help"])
            except SystemExit:
                pass
        heavy = sorted({k.split(".")[0] for k in sys.modules} & {"numpy", "textual", "scipy", "numba", "cv2", "pydicom", "moderngl", "skimage", "PIL"})
        assert "info" in out.getvalue(), out.getvalue()
        print(heavy)
        sys.exit(1 if heavy else 0)
        """
    )
    root = Path(__file__).resolve().parents[2]
    res = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
