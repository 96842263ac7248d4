"""The type checker (mypy) and the linter (ruff) over the engine's core and actions and the TUI's screens.

Both are configured in pyproject.toml ([tool.mypy]: the packages checked, each exception with its reason;
[tool.ruff]: the rules) and installed by the test extras, which ``.ci/run`` installs. A run prints the
tool's own report, so a failure reads like the tool's output.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: the packages the issue names at least; [tool.mypy] files lists the same
CHECKED = ["ctui/engine/core", "ctui/engine/actions", "ctui/screens"]


def _tool(module: str) -> list[str]:
    try:
        __import__(module)
    except ImportError:
        pytest.skip(f"{module} is not installed (pip install -e '.[test]' installs it)")
    return [sys.executable, "-m", module]


def _run(cmd: list[str], timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False)


@pytest.mark.slow
def test_mypy_is_clean_on_core_actions_and_screens() -> None:
    out = _run(_tool("mypy") + ["--no-error-summary", *CHECKED])
    assert out.returncode == 0, f"mypy found type errors:\n{out.stdout}{out.stderr}"


def test_ruff_is_clean_on_ctui() -> None:
    if shutil.which("ruff") is None:
        _tool("ruff")
    out = _run(_tool("ruff") + ["check", "--no-cache", "ctui"], timeout=120)
    assert out.returncode == 0, f"ruff found problems:\n{out.stdout}{out.stderr}"


def test_mypy_settings_check_the_three_packages() -> None:
    """The checked packages stay in [tool.mypy] files; the mixins' exemption names only attr-defined."""
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["mypy"]
    assert set(CHECKED) <= set(cfg["files"])
    assert cfg.get("warn_unused_ignores") is True
    for o in cfg.get("overrides", []):
        assert o.get("disable_error_code") in (None, ["attr-defined"]), o
        assert "ignore_errors" not in o, f"a module is exempt from every check: {o}"


def test_every_type_ignore_names_its_code_and_reason() -> None:
    """``# type: ignore[code]  # reason``: the code says what is hidden, the reason why."""
    bad = []
    for path in sorted((ROOT / "ctui").rglob("*.py")):
        for no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            m = re.search(r"#\s*type:\s*ignore(\[[^\]]+\])?(.*)$", line)
            if m and (not m.group(1) or not re.match(r"\s*#\s*\S", m.group(2))):
                bad.append(f"{path.relative_to(ROOT)}:{no}: {line.strip()}")
    assert not bad, "type: ignore without [code] or without '# reason':\n" + "\n".join(bad)
