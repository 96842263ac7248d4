"""The code figures issue 36 follows ("Must show"), printed for one checkout of ctui.

    python3 benchmarks/code_metrics.py                 # this checkout, with mypy, ruff and lint-imports
    python3 benchmarks/code_metrics.py --no-tools      # the counts only (seconds)
    python3 benchmarks/code_metrics.py --root DIR      # another checkout (e.g. `git archive <commit>` unpacked)

Each line is a count with the rule that made it, so two runs (before and after a change, or after a
merge) print side by side with `paste`. The tools run with their caches in a temporary folder, so the
checkout measured is left as it was. There is no peer to print beside: these are ctui's own figures.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import os
import re
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
CHECKED = ["ctui/engine/core", "ctui/engine/actions", "ctui/screens"]
#: parameter names that carry the workspace screen or the TUI's session
SCREEN_OR_SESSION = {"ws", "screen", "session", "sess", "s"}


def _files(root: Path, under: str) -> list[Path]:
    return sorted((root / under).rglob("*.py"))


def _parse(p: Path) -> ast.Module:
    return ast.parse(p.read_text(encoding="utf-8"), str(p))


def workspace_figures() -> dict[str, int]:
    """Methods of WorkspaceScreen beyond Textual's Screen (own and its mixins'), its key actions (its own
    ``action_*`` and, since issue 36, its owners' that its one ``do`` action runs), bindings."""
    from textual.screen import Screen

    ws = importlib.import_module("ctui.screens.workspace").WorkspaceScreen
    base = set(dir(Screen))
    names = set()
    for cls in ws.__mro__:
        if cls.__module__.startswith("ctui."):
            names |= {n for n, v in vars(cls).items() if callable(v) or isinstance(v, (property, staticmethod, classmethod))}
    methods = {n for n in names if n not in base or n in vars(ws)}
    own = {n[len("action_"):] for n in methods if n.startswith("action_")}
    # the workspace's owners (issue 36): their action_<name> methods are the screen's key actions, reached
    # through its one routed action do('<name>', args); an older checkout has none (its actions are its own)
    actions = set(own) - ({"do"} if "do" in own else set())
    try:
        owner = importlib.import_module("ctui.screens.ws_host").Owner
        action_name = importlib.import_module("ctui.screens.keytable").action_name
    except (ImportError, AttributeError):
        owner = action_name = None
    if owner is not None:
        todo = list(owner.__subclasses__())
        while todo:
            cls = todo.pop()
            todo += cls.__subclasses__()
            if cls.__module__.startswith("ctui."):
                actions |= {n[len("action_"):] for n in vars(cls) if n.startswith("action_")}
        actions |= {action_name(b.action) for b in ws.BINDINGS}  # routed to a screen method (toggle_panel)
    return {"methods beyond Screen": len(methods), "actions (action_*)": len(actions),
            "Textual actions on the screen itself": len(own), "bindings": len(ws.BINDINGS)}


def untyped_screen_params(root: Path) -> tuple[int, int, list[str]]:
    """(free functions, all functions incl. methods) in ctui/screens with a parameter named like the screen
    or session (ws, screen, session, sess, s) that has no annotation or ``Any``."""
    free, every, where = 0, 0, []
    for p in _files(root, "ctui/screens"):
        tree = _parse(p)
        top = {id(n) for n in tree.body}
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            args = fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs
            bad = [a.arg for a in args if a.arg in SCREEN_OR_SESSION
                   and (a.annotation is None or ast.unparse(a.annotation) in ("Any", "object"))]
            if bad:
                every += 1
                if id(fn) in top:
                    free += 1
                    where.append(f"{p.relative_to(root)}:{fn.lineno} {fn.name}({', '.join(bad)})")
    return free, every, where


def thread_calls(root: Path) -> dict[str, int]:
    """call_from_thread(...) calls and generic ``Call(fn)`` messages posted, in ctui/screens."""
    out = {"call_from_thread": 0, "Call(fn) messages": 0}
    for p in _files(root, "ctui/screens"):
        for n in ast.walk(_parse(p)):
            if isinstance(n, ast.Call):
                f = n.func
                if isinstance(f, ast.Attribute) and f.attr == "call_from_thread":
                    out["call_from_thread"] += 1
                elif isinstance(f, ast.Name) and f.id == "Call":
                    out["Call(fn) messages"] += 1
    return out


def cli_literals(root: Path) -> list[str]:
    """The CLI's add_argument default=/choices= written as literals (tests/architecture/test_single_definition.py's rule)."""
    sys.path.insert(0, str(HERE / "tests" / "architecture"))
    try:
        from test_single_definition import literal_options
    finally:
        sys.path.pop(0)
    files = [root / "ctui" / "cli.py", *sorted((root / "ctui" / "commands").glob("*.py"))]
    return [f for p in files if p.exists() for f in literal_options(p.read_text(encoding="utf-8"), str(p.relative_to(root)))]


def repeated_choice_lists(root: Path) -> dict[tuple, list[str]]:
    """Tuples/lists of two or more strings (choice lists) written identically in more than one place in ctui/."""
    seen: dict[tuple, list[str]] = defaultdict(list)
    for p in _files(root, "ctui"):
        for n in ast.walk(_parse(p)):
            if isinstance(n, (ast.Tuple, ast.List)) and len(n.elts) >= 2 \
                    and all(isinstance(e, ast.Constant) and isinstance(e.value, str) for e in n.elts):
                seen[tuple(e.value for e in n.elts)].append(f"{p.relative_to(root)}:{n.lineno}")
    return {k: v for k, v in seen.items() if len(v) > 1}


def propagation_defaults_written(root: Path) -> int:
    """How many of SegmentOptions' and PropagationSettings' leak_factor, neighbourhood, min_area are literals."""
    n = 0
    for rel in ("ctui/engine/actions/segment.py", "ctui/engine/segment/propagate.py"):
        for node in ast.walk(_parse(root / rel)):
            if isinstance(node, ast.ClassDef) and node.name in ("SegmentOptions", "PropagationSettings"):
                n += sum(isinstance(st, ast.AnnAssign) and isinstance(st.target, ast.Name)
                         and st.target.id in ("leak_factor", "neighbourhood", "min_area")
                         and isinstance(st.value, ast.Constant) for st in node.body)
    return n


def screen_cycles(root: Path) -> list[list[str]]:
    import grimp

    sys.path.insert(0, str(HERE / "tests" / "architecture"))
    try:
        from test_import_cycles import import_cycles
    finally:
        sys.path.pop(0)
    graph = grimp.build_graph("ctui", include_external_packages=False, exclude_type_checking_imports=True)
    return import_cycles(graph, "ctui.screens")


def type_ignores(root: Path) -> dict[str, int]:
    total = coded = reasoned = 0
    for p in _files(root, "ctui"):
        for line in p.read_text(encoding="utf-8").splitlines():
            m = re.search(r"#\s*type:\s*ignore(\[[^\]]+\])?(.*)$", line)
            if m:
                total += 1
                coded += bool(m.group(1))
                reasoned += bool(m.group(1)) and bool(re.match(r"\s*#\s*\S", m.group(2)))
    return {"total": total, "with [code]": coded, "with [code] and reason": reasoned}


def session_getattr_defaults(root: Path) -> int:
    """getattr(x, "field", default) in ctui/screens where "field" is a declared Session field or method."""
    src = (root / "ctui/screens/session.py").read_text(encoding="utf-8")
    cls = next(n for n in ast.parse(src).body if isinstance(n, ast.ClassDef) and n.name == "Session")
    fields = {n.target.id for n in cls.body if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name)}
    held = {"steps": "pipeline", "labels": "seg"}  # the typed fields' own: Pipeline.steps, Segmentation.labels
    n = 0
    for p in _files(root, "ctui/screens"):
        for c in ast.walk(_parse(p)):
            if isinstance(c, ast.Call) and isinstance(c.func, ast.Name) and c.func.id == "getattr" and len(c.args) == 3 \
                    and isinstance(c.args[1], ast.Constant):
                name, owner = c.args[1].value, ast.unparse(c.args[0])
                n += name in fields or (name in held and owner.endswith(held[name]))
    return n


def _tool(cmd: list[str], root: Path, env: dict[str, str]) -> tuple[int, str]:
    try:
        out = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=900, env=env, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return -1, f"not run: {exc}"
    text = (out.stdout + out.stderr).strip().splitlines()
    summary = [t for t in text if re.search(r"Found \d+ error|All checks passed|Success:|Contracts:", t)]
    return out.returncode, (summary or text or [""])[-1]


def tools(root: Path) -> None:
    with tempfile.TemporaryDirectory(prefix="ctui-metrics-") as tmp:
        env = {**os.environ, "PYTHONPATH": str(root)}
        has_cfg = "[tool.mypy]" in (root / "pyproject.toml").read_text(encoding="utf-8")
        cfg = [] if has_cfg else ["--config-file", str(HERE / "pyproject.toml")]  # an older checkout: these settings
        rc, last = _tool([sys.executable, "-m", "mypy", "--cache-dir", str(Path(tmp) / "mypy"), *cfg, *CHECKED], root, env)
        print(f"mypy on {', '.join(CHECKED)}: exit {rc}: {last}")
        rc, last = _tool([sys.executable, "-m", "ruff", "check", "--no-cache", "--config", str(HERE / "pyproject.toml")
                          if not has_cfg else str(root / "pyproject.toml"), "ctui"], root, env)
        print(f"ruff check ctui: exit {rc}: {last}")
        rc, last = _tool(["lint-imports", "--no-cache"], root, env)
        print(f"lint-imports: exit {rc}: {last}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", default=str(HERE), help="the checkout to measure (default: this one)")
    ap.add_argument("--no-tools", action="store_true", help="skip mypy, ruff and lint-imports (slow)")
    ap.add_argument("--list", action="store_true", help="also list the free functions and repeated lists found")
    args = ap.parse_args(argv)
    root = Path(args.root).resolve()
    sys.path.insert(0, str(root))
    for k, v in workspace_figures().items():
        print(f"WorkspaceScreen {k}: {v}")
    free, every, where = untyped_screen_params(root)
    print(f"screens: free functions taking an untyped ws/screen/session: {free} (with methods: {every})")
    for k, v in thread_calls(root).items():
        print(f"screens: {k}: {v}")
    lits = cli_literals(root)
    print(f"CLI default=/choices= written as literals: {len(lits)}")
    reps = repeated_choice_lists(root)
    print(f"string lists (2+ items) written identically in 2+ places in ctui/: {len(reps)} lists, "
          f"{sum(len(v) for v in reps.values())} places")
    print(f"SegmentOptions/PropagationSettings leak_factor, neighbourhood, min_area as literals: "
          f"{propagation_defaults_written(root)}")
    cyc = screen_cycles(root)
    print(f"import circles in ctui/screens: {len(cyc)} ({', '.join(str(len(c)) + ' modules' for c in cyc) or 'none'})")
    print("# type: ignore in ctui/: " + ", ".join(f"{k} {v}" for k, v in type_ignores(root).items()))
    print(f"screens: getattr(x, '<Session field>', default): {session_getattr_defaults(root)}")
    if args.list:
        print("\n".join(["", "free functions:", *where, "", "CLI literals:", *lits, "", "repeated lists:"]
                        + [f"  {k}: {', '.join(v)}" for k, v in sorted(reps.items(), key=lambda kv: -len(kv[1]))]))
    if not args.no_tools:
        tools(root)
    return 0


if __name__ == "__main__":
    sys.exit(main())
