"""No two modules of the package import each other, directly or around a loop.

Function-level imports count: a cycle hidden inside a function still means
neither module can be read, or changed, without the other. The graph has one
node per module (a package's ``__init__`` is the node of the package's own
name); ``from . import name`` is an edge to the submodule ``name`` where one
exists, else to the package.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "invsss"


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(sources: dict[str, tuple[str, bool]]) -> dict[str, set[str]]:
    """``{module: modules it imports}`` from ``{module: (source, is_package)}``."""
    graph = {}
    for module, (source, is_package) in sources.items():
        package = module if is_package else module.rpartition(".")[0]
        edges = set()
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.Import):
                edges.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                edges.update(f"{target}.{a.name}" if f"{target}.{a.name}" in sources else target for a in node.names)
        graph[module] = {e for e in edges if e in sources and e != module}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def package_sources() -> dict[str, tuple[str, bool]]:
    return {module_name(p, PACKAGE): (p.read_text(), p.name == "__init__.py") for p in PACKAGE.rglob("*.py")}


def test_the_package_has_no_import_cycle():
    assert cycles(import_graph(package_sources())) == []


def test_a_planted_cycle_is_found_even_inside_a_function():
    sources = package_sources()
    # passes and pass_kernels imported each other this way before the taps moved out.
    sources["invsss.forward.taps"] = (sources["invsss.forward.taps"][0] + "\n\ndef f():\n    from . import passes\n",
                                      False)
    found = cycles(import_graph(sources))
    assert any({"invsss.forward.taps", "invsss.forward.passes"} <= set(c) for c in found)
