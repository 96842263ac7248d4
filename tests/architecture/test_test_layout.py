"""The test tree mirrors the code: ``tests/{engine/<stage>,cli,tui,fuzz,architecture}/``, each folder
with its conftest.py, test module names unique across folders (they import each other by bare name,
support.put_test_folders_on_path), and snapshot folders beside their test module."""

from __future__ import annotations

from collections import Counter

from support import ROOT, TESTS, python_folders

TOP = {"engine", "cli", "tui", "fuzz", "architecture"}
STAGES = {p.name for p in (ROOT / "ctui" / "engine").iterdir() if (p / "__init__.py").is_file()}


def _test_modules():
    return sorted(p for p in TESTS.rglob("test_*.py") if "__pycache__" not in p.parts)


def test_no_test_module_at_the_root_of_tests():
    loose = [p.name for p in TESTS.glob("test_*.py")]
    assert not loose, f"move these into tests/{{engine/<stage>,cli,tui,fuzz,architecture}}/: {loose}"


def test_folders_mirror_the_code_and_each_has_a_conftest():
    for folder in python_folders()[1:]:
        rel = folder.relative_to(TESTS).parts
        assert rel[0] in TOP, folder
        if rel[0] == "engine" and len(rel) > 1:
            assert rel[1] in STAGES, f"{folder}: no stage ctui/engine/{rel[1]}"
        assert (folder / "conftest.py").is_file(), f"{folder} has no conftest.py"


def test_module_names_are_unique():
    twice = [n for n, k in Counter(p.name for p in TESTS.rglob("*.py") if p.name != "conftest.py").items() if k > 1]
    assert not twice, f"module names used twice under tests/: {twice}"
    assert len(_test_modules()) > 100  # the walk found the tree


def test_snapshots_sit_beside_their_test_module():
    for snaps in TESTS.rglob("__snapshots__"):
        for sub in snaps.iterdir():
            assert (snaps.parent / f"{sub.name}.py").is_file(), f"{sub}: no {sub.name}.py beside it"
