"""The package's import graph has no cycles, between modules or between subpackages.

Every ``import`` / ``from ... import`` statement counts, those inside functions included: a
function-level import hides a cycle from the interpreter, not from the layering. A
subpackage (``crowdstudy.body``, ``crowdstudy.render`` ...) is one node of the coarse graph;
a top-level module (``crowdstudy.scene``, ``crowdstudy.tables`` ...) is its own node.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "crowdstudy"


def _modules() -> dict[str, Path]:
    mods = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


def import_graph() -> dict[str, set[str]]:
    """{module: modules of the package it imports}, every import statement counted."""
    mods = _modules()

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
                    base = base[: len(base) - (node.level - 1)]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                targets = [f"{source}.{a.name}" if f"{source}.{a.name}" in mods else source for a in node.names]
            for t in targets:
                r = resolve(t)
                if r and r != mod:
                    graph[mod].add(r)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def _subpackage(mod: str) -> str:
    parts = mod.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 and (PACKAGE / parts[1]).is_dir() else mod


def _describe(cycles, graph) -> str:
    lines = []
    for comp in cycles:
        lines.append(" <-> ".join(comp))
        lines += [f"    {a} -> {b}" for a in comp for b in sorted(graph[a]) if b in comp]
    return "\n".join(lines)


def test_no_import_cycle_between_modules():
    graph = import_graph()
    cycles = _cycles(graph)
    assert not cycles, "import cycles between modules:\n" + _describe(cycles, graph)


def test_no_import_cycle_between_subpackages():
    graph = import_graph()
    coarse: dict[str, set[str]] = {}
    for a, targets in graph.items():
        coarse.setdefault(_subpackage(a), set()).update(_subpackage(b) for b in targets)
    for a in coarse:
        coarse[a].discard(a)
    for targets in list(coarse.values()):
        for b in targets:
            coarse.setdefault(b, set())
    cycles = _cycles(coarse)
    assert not cycles, "import cycles between subpackages:\n" + _describe(cycles, coarse)


def test_the_check_sees_imports_inside_functions():
    graph = {"a": {"b"}, "b": {"a"}, "c": {"a"}}
    assert _cycles(graph) == [["a", "b"]]
    assert "crowdstudy.cli" in import_graph()["crowdstudy.__main__"]
