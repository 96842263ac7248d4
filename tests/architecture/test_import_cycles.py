"""No import circle among the TUI's modules (``ctui/screens``).

A circle makes the import order matter (a module half-initialised when its partner reads it) and
hides which module owns what. Every import counts, including those inside functions (a lazy import
only moves the circle to run time); imports under ``if TYPE_CHECKING:`` are annotations and do not.
The graph is grimp's, the library import-linter (tests/architecture/test_architecture.py) builds its contracts on.
"""

from __future__ import annotations

import pytest

grimp = pytest.importorskip("grimp", reason="grimp comes with import-linter (the test extras)")

PACKAGE = "ctui.screens"


def import_cycles(graph, package: str) -> list[list[str]]:
    """The strongly connected groups of more than one module among ``package``'s modules (Tarjan's
    algorithm over the direct imports), each sorted; a module importing itself counts too."""
    mods = sorted(m for m in graph.modules if m.startswith(package + "."))
    edges = {m: sorted(i for i in graph.find_modules_directly_imported_by(m) if i.startswith(package + "."))
             for m in mods}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:  # iterative depth first search (no recursion limit on a long chain)
        work = [(v, iter(edges[v]))]
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        while work:
            node, it = work[-1]
            nxt = next(it, None)
            if nxt is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == node:
                            break
                    if len(comp) > 1 or node in edges[node]:
                        out.append(sorted(comp))
            elif nxt not in index:
                index[nxt] = low[nxt] = len(index)
                stack.append(nxt)
                on.add(nxt)
                work.append((nxt, iter(edges[nxt])))
            elif nxt in on:
                low[node] = min(low[node], index[nxt])

    for m in mods:
        if m not in index:
            visit(m)
    return sorted(out)


def _graph():
    return grimp.build_graph("ctui", include_external_packages=False, exclude_type_checking_imports=True)


def test_no_import_cycle_among_the_screens() -> None:
    graph = _graph()
    cycles = import_cycles(graph, PACKAGE)
    lines = []
    for comp in cycles:
        lines.append(f"circle of {len(comp)}: {', '.join(m.rsplit('.', 1)[-1] for m in comp)}")
        for a in comp:
            for b in sorted(graph.find_modules_directly_imported_by(a)):
                if b in comp:
                    at = [d["line_number"] for d in graph.get_import_details(importer=a, imported=b)]
                    lines.append(f"    {a} -> {b} (line {', '.join(map(str, at))})")
    assert not cycles, "import circles in ctui/screens:\n" + "\n".join(lines)


def test_the_cycle_finder_finds_a_circle() -> None:
    """The finder on a small graph with a known circle (a -> b -> c -> a) and a tail (c -> d)."""
    g = grimp.ImportGraph()
    for a, b in (("p.a", "p.b"), ("p.b", "p.c"), ("p.c", "p.a"), ("p.c", "p.d"), ("p.e", "p.e")):
        g.add_import(importer=a, imported=b)
    assert import_cycles(g, "p") == [["p.a", "p.b", "p.c"], ["p.e"]]
