"""The architecture holds: import-linter contracts (pyproject.toml), no import cycles in the
engine, no module over 600 lines, no function over 100 lines (compiled kernels aside), no
string-named imports in the UI (see ARCHITECTURE.md)."""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "ctui"
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 100


def _py_files(base: Path = PKG) -> list[Path]:
    return sorted(p for p in base.rglob("*.py") if "__pycache__" not in p.parts)


def test_import_contracts_kept():
    exe = shutil.which("lint-imports")
    if exe is None:
        pytest.skip("lint-imports (import-linter) is not installed: pip install -e '.[test]'")
    r = subprocess.run([exe, "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    out = r.stdout + r.stderr
    kept = re.search(r"Contracts: (\d+) kept, (\d+) broken", out)
    assert kept is not None, out[-3000:]
    assert int(kept.group(1)) >= 6, out[-3000:]  # incl. "The UI talks to the engine through actions and core"
    assert r.returncode == 0 and kept.group(2) == "0", out[-3000:]


def test_contracts_cover_every_private_engine_module():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    forbidden = {m for c in cfg if "private" in c["name"] for m in c["forbidden_modules"]}
    private = {".".join(p.relative_to(ROOT).with_suffix("").parts) for p in _py_files(PKG / "engine")
               if p.name.startswith("_") and p.name != "__init__.py"}
    assert private <= forbidden, f"add to the private-modules contract: {sorted(private - forbidden)}"


def test_no_import_cycles_in_the_engine():
    grimp = pytest.importorskip("grimp", reason="grimp comes with import-linter")
    g = grimp.build_graph("ctui", cache_dir=None)
    mods = sorted(m for m in g.modules if m.startswith("ctui.engine."))
    adj = {m: [n for n in g.find_modules_directly_imported_by(m) if n.startswith("ctui.engine.")] for m in mods}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    cycles: list[list[str]] = []
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(mods) + 100))

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in adj.get(v, []):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for m in mods:
        if m not in index:
            visit(m)
    assert not cycles, f"import cycles: {cycles}"


def test_no_module_over_600_lines():
    big = {str(p.relative_to(ROOT)): n for p in _py_files() if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES}
    assert not big, f"modules over {MAX_MODULE_LINES} lines: {big}"


def _compiled(fn: ast.AST) -> bool:
    for d in getattr(fn, "decorator_list", []):
        name = ast.unparse(d)
        if "njit" in name or "numba" in name or name.startswith("jit"):
            return True
    return False


def test_no_function_over_100_lines():
    long = []
    for p in _py_files():
        tree = ast.parse(p.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not _compiled(node):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long.append(f"{p.relative_to(ROOT)}:{node.lineno} {node.name} ({n} lines)")
    assert not long, "functions over 100 lines: " + "; ".join(long)


def test_no_string_named_imports_in_the_ui():
    files = _py_files(PKG / "screens") + sorted(PKG.glob("*.py"))
    bad = []
    for p in files:
        for k, line in enumerate(p.read_text().splitlines(), 1):
            code = line.split("#", 1)[0]
            if "import_module" in code or "__import__(" in code or re.search(r"""\bengine\(\s*["']""", code):
                bad.append(f"{p.relative_to(ROOT)}:{k}: {line.strip()}")
    assert not bad, "string-named imports: " + "; ".join(bad)


def test_no_module_writes_another_objects_private_attributes():
    """``obj._name = ...`` (or setattr(obj, "_name", ...)) only on ``self``/``cls``: a screen,
    a worker or a helper module changes another object's state through its methods."""
    bad = []
    for p in _py_files():
        for node in ast.walk(ast.parse(p.read_text())):
            targets = node.targets if isinstance(node, ast.Assign) else \
                [node.target] if isinstance(node, (ast.AugAssign, ast.AnnAssign)) else []
            for t in targets:
                for e in ast.walk(t):
                    if (isinstance(e, ast.Attribute) and isinstance(e.ctx, ast.Store) and e.attr.startswith("_")
                            and not e.attr.startswith("__")
                            and not (isinstance(e.value, ast.Name) and e.value.id in ("self", "cls"))):
                        bad.append(f"{p.relative_to(ROOT)}:{e.lineno} {ast.unparse(e)}")
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "setattr"
                    and len(node.args) > 1 and isinstance(node.args[1], ast.Constant)
                    and str(node.args[1].value).startswith("_")):
                bad.append(f"{p.relative_to(ROOT)}:{node.lineno} {ast.unparse(node)}")
    assert not bad, "writes to another object's private attributes: " + "; ".join(bad)


def test_engine_imports_inside_functions_say_why():
    """An engine module imported inside a function (not at the top) is there for a reason the
    code states: a ``#`` comment on the import, or the function's docstring about the import
    (a heavy library such as numba or pydicom loaded on first use, a format's loader)."""
    bad = []
    for p in _py_files(PKG / "engine"):
        src = p.read_text().splitlines()
        for fn in ast.walk(ast.parse("\n".join(src))):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            doc = (ast.get_docstring(fn) or "").lower()
            for node in ast.walk(fn):
                if (isinstance(node, ast.ImportFrom) and (node.module or "").startswith("ctui.engine")
                        and not any("#" in src[i] for i in range(node.lineno - 1, node.end_lineno))
                        and "import" not in doc):
                    bad.append(f"{p.relative_to(ROOT)}:{node.lineno} {src[node.lineno - 1].strip()}")
    assert not bad, "imports inside functions without a reason (move them to the top, or say why): " + \
        "; ".join(sorted(set(bad)))


# Libraries a function may import without a comment: heavy or optional ones, loaded on first
# use so that `ctui --help` and the TUI's first paint do not wait for them (the reason, once).
HEAVY_LIBRARIES = ("scipy", "skimage", "cv2", "numba", "pydicom", "highdicom", "nibabel", "nrrd", "trimesh", "PIL",
                   "matplotlib", "moderngl", "mapbox_earcut", "fast_simplification", "dask", "distributed",
                   "psutil", "textual_image", "tifffile", "imageio", "meshio", "vtk", "pyvista", "SimpleITK",
                   "nnInteractive", "httpx")  # the last two: ctui[ai], the nninteractive method only
# Modules whose functions import for start-up time, with the reason (one for the whole module).
STARTUP_MODULES = {
    "ctui/cli.py": "`ctui --help` and the argument errors load no engine (numpy): a command imports its work",
    "ctui/commands/": "`ctui --help` imports every command's module: each `run` imports the engine it needs",
    "ctui/screens/app.py": "the first frame (the loading screen) is drawn before the workspace, dialogs and help load",
    "ctui/screens/loading.py": "the loading screen is the first frame: its dialogs load when first asked for",
}


def _import_blocks(src: list[str], fn) -> list[tuple[int, int, str]]:
    """(first line, last line, module) of each import inside ``fn``, the block being the run of
    import statements around it with no other line between."""
    imports = sorted((n.lineno, n.end_lineno, n.module if isinstance(n, ast.ImportFrom) else n.names[0].name)
                     for n in ast.walk(fn) if isinstance(n, ast.Import) or (isinstance(n, ast.ImportFrom) and not n.level))
    out = []
    for k, (a, b, mod) in enumerate(imports):
        lo, hi = a, b
        j = k
        while j > 0 and imports[j - 1][1] == lo - 1:
            j -= 1
            lo = imports[j][0]
        j = k
        while j + 1 < len(imports) and imports[j + 1][0] == hi + 1:
            j += 1
            hi = imports[j][1]
        out.append((lo, hi, mod or ""))
    return out


def test_imports_inside_functions_say_why():
    """Every import inside a function in ctui/ is there for start-up time or a heavy/optional
    library, and says so: a ``#`` comment on the import, on its block of imports or on the line
    above the block, or the function's docstring about the import; or it imports one of
    HEAVY_LIBRARIES; or its module is in STARTUP_MODULES. Any other import belongs at the top."""
    bad = []
    for p in _py_files():
        rel = str(p.relative_to(ROOT))
        if any(rel.startswith(m) for m in STARTUP_MODULES):
            continue
        src = p.read_text().splitlines()
        for fn in ast.walk(ast.parse("\n".join(src))):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            doc = (ast.get_docstring(fn) or "").lower()
            for lo, hi, mod in _import_blocks(src, fn):
                said = any("#" in src[i] for i in range(lo - 1, hi)) or src[lo - 2].strip().startswith("#") \
                    or "import" in doc
                if not said and mod.split(".")[0] not in HEAVY_LIBRARIES:
                    bad.append(f"{rel}:{lo} {mod}")
    assert not bad, "imports inside functions without a reason (move them to the top, or say why): " + \
        "; ".join(sorted(set(bad)))
