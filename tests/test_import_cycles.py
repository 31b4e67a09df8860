"""No import cycle inside a package: a module's imports point down its layers.

The import graph is read from the source with ``ast`` (module-level and function-level
imports alike, since a deferred import still ties two modules' designs), so the check is
exact for the project's own relative and absolute imports and needs nothing imported.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ["skysim", "sensor", "experiments"]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _graph(package: str) -> dict[str, set[str]]:
    files = {_module_name(p): p for p in (ROOT / package).rglob("*.py")
             if "data" not in p.relative_to(ROOT).parts}
    graph = {m: set() for m in files}
    for mod, path in files.items():
        is_pkg = path.name == "__init__.py"
        base = mod.split(".") if is_pkg else mod.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    stem = base[:len(base) - node.level + 1]
                    prefix = ".".join(stem + ([node.module] if node.module else []))
                else:
                    prefix = node.module or ""
                targets = [prefix] + [f"{prefix}.{a.name}" for a in node.names]
            for t in targets:
                while t and t not in files:   # the deepest module of the dotted name
                    t = t.rpartition(".")[0]
                if t and t != mod and not mod.startswith(t + "."):  # a package's own parents
                    graph[mod].add(t)
    return graph


def _cycle(graph):
    """One cycle of the graph as a list of modules, or None (depth-first search)."""
    state, stack = {}, []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                return stack[stack.index(n):] + [n]
            if n not in state:
                found = visit(n)
                if found:
                    return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state:
            found = visit(m)
            if found:
                return found
    return None


KNOWN = set()
"""Import edges that still close a cycle, each with what removes it; no other may."""


@pytest.mark.parametrize("package", PACKAGES + ["calibration"])
def test_no_import_cycle(package):
    graph = _graph(package)
    for a, b in KNOWN:
        graph.get(a, set()).discard(b)
    cycle = _cycle(graph)
    assert cycle is None, " -> ".join(cycle)


def test_known_cycles_still_exist():
    """Each listed edge still closes a cycle: one that no longer does leaves the list."""
    graph = _graph("calibration")
    for a, b in KNOWN:
        assert b in graph[a], (a, b)
        g = {m: set(e) for m, e in graph.items()}
        g[a] = {b}
        assert _cycle(g) is not None, (a, b)


def test_a_planted_cycle_is_found():
    """The checker itself: a two-module cycle and a clean chain."""
    assert _cycle({"a": {"b"}, "b": {"a"}}) in (["a", "b", "a"], ["b", "a", "b"])
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
