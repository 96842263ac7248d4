"""Every default and choice list of the CLI is defined once, in the engine, and read by name.

An ``add_argument(..., default=<literal>)`` or ``choices=<literal>`` in ``ctui/cli.py`` or
``ctui/commands/`` is a second definition of something the engine owns (the action's default, a
registry of names): the two drift apart. The allowed values are names and calls (``defaults.X``,
``METHODS``, ``tuple(FORMATS)``), and the constants that say "nothing given" (None, True, False, "").
"""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CLI_FILES = [ROOT / "ctui" / "cli.py", *sorted((ROOT / "ctui" / "commands").glob("*.py"))]
#: the propagation fields SegmentOptions and PropagationSettings share, defined once in ctui.engine.segment
SHARED = ("mode", "direction", "connectivity", "neighbourhood", "min_area", "leak_factor")
#: constants that are the absence of a value, not a default someone chose
NO_VALUE = (None, True, False, "")


def _literal(node: ast.expr) -> bool:
    """A value written out: a number or string, or a tuple/list/set of them (also negated numbers)."""
    if isinstance(node, ast.Constant):
        return node.value not in NO_VALUE or isinstance(node.value, (int, float)) and not isinstance(node.value, bool)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        return _literal(node.operand)
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return any(_literal(e) or isinstance(e, ast.Constant) for e in node.elts)
    return False


def literal_options(source: str, name: str = "<src>") -> list[str]:
    """``file:line --option default=...`` for each add_argument whose default= or choices= is a literal."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "add_argument"):
            continue
        flag = next((a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str)), "?")
        for kw in node.keywords:
            if kw.arg in ("default", "choices") and _literal(kw.value):
                out.append(f"{name}:{node.lineno} {flag} {kw.arg}={ast.unparse(kw.value)}")
    return out


def test_the_cli_reads_every_default_and_choice_list_from_the_engine() -> None:
    found = [f for p in CLI_FILES for f in literal_options(p.read_text(encoding="utf-8"), str(p.relative_to(ROOT)))]
    assert not found, ("CLI defaults/choices written as literals (define each once in engine/actions/defaults.py "
                       "or its registry and read it by name):\n" + "\n".join(found))


def test_the_finder_flags_literals_and_passes_names() -> None:
    src = '''
p.add_argument("--a", default=2.5)
p.add_argument("--b", choices=("x", "y"), default="x")
p.add_argument("--c", default=-1)
p.add_argument("--d", default=defaults.D, choices=defaults.DS)
p.add_argument("--e", default=None, action="store_true")
p.add_argument("--f", default="", choices=tuple(FORMATS))
p.add_argument("--g", default=0)
'''
    got = [line.split(" ", 1)[1] for line in literal_options(src)]
    assert got == ["--a default=2.5", "--b choices=('x', 'y')", "--b default='x'", "--c default=-1", "--g default=0"]


def test_segment_options_and_propagation_settings_share_their_defaults() -> None:
    """SegmentOptions' propagation fields take PropagationSettings' defaults (one definition each)."""
    from ctui.engine.actions.segment import SegmentOptions
    from ctui.engine.segment.propagate import PropagationSettings

    prop = {f.name: f.default for f in dataclasses.fields(PropagationSettings)}
    # neck_mm and fill_holes differ on purpose: the action's None is "automatic", its holes are filled
    shared = [f for f in dataclasses.fields(SegmentOptions) if f.name in SHARED]
    assert {f.name for f in shared} == set(SHARED)
    for f in shared:
        assert f.default == prop[f.name], f"{f.name}: SegmentOptions {f.default!r}, PropagationSettings {prop[f.name]!r}"
    # written once: the numbers appear in neither class's source, only as names
    for path in ("ctui/engine/actions/segment.py", "ctui/engine/segment/propagate.py"):
        tree = ast.parse((ROOT / path).read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef) and node.name in ("SegmentOptions", "PropagationSettings"):
                for st in node.body:
                    if isinstance(st, ast.AnnAssign) and isinstance(st.target, ast.Name) \
                            and st.target.id in SHARED:
                        assert not isinstance(st.value, ast.Constant), f"{path}: {node.name}.{st.target.id} is a literal"


def test_vessel_lumen_choices_are_the_engines():
    """The CLI keeps ``--lumen``'s choices as a constant (its --help does not load the vessel engine):
    they must be the engine's ``LUMENS``, in order."""
    from ctui.commands.vessel import LUMEN_CHOICES
    from ctui.engine.vessel.build import LUMENS

    assert LUMEN_CHOICES == tuple(LUMENS)
