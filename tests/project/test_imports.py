"""No import circles inside the package.

The graph counts every `import` of a vtsbench module, at module level and inside functions
(a lazy import is still a dependency: it only moves the failure to run time), and leaves out
imports under `if TYPE_CHECKING:`, which exist for annotations only and never run.
"""

from __future__ import annotations

from pathlib import Path

import vtsbench
from tests.fixtures.import_graph import import_graph

ROOT = Path(vtsbench.__file__).parent


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    comp.append(m)
                    if m == node:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def test_package_has_no_import_circles() -> None:
    graph = import_graph(ROOT)
    assert len(graph) > 50 and sum(map(len, graph.values())) > 100  # the parse found the edges
    found = cycles(graph)
    assert not found, "import circles: " + "; ".join(
        " <-> ".join(c) + " (" + ", ".join(f"{a}->{b}" for a in c for b in sorted(graph[a])
                                           if b in c) + ")" for c in found)


def test_known_edges_are_seen() -> None:
    """The parse sees relative, function-level and parent-package imports."""
    graph = import_graph(ROOT)
    assert "vtsbench.dataset.read.arrays" in graph["vtsbench.dataset.read.hf"]  # in a function
    assert "vtsbench.dataset.read.store" in graph["vtsbench.dataset.read.loader"]  # `from . import`
    assert "vtsbench.dataset.build.plan" not in graph["vtsbench.dataset.build.card"]  # types only


def test_a_circle_is_reported(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .sub import b\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from ..c import x\n")
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nimport pkg.a\n"
                              "if TYPE_CHECKING:\n    from . import d\n")
    (pkg / "d.py").write_text("from .c import y\n")
    graph = import_graph(pkg)
    assert cycles(graph) == [["pkg.a", "pkg.c", "pkg.sub.b"]]
    (pkg / "c.py").write_text("x = 1\n")
    assert cycles(import_graph(pkg)) == []
