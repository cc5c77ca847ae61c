"""The modules of the cvpipe library import each other without a cycle.

The graph is read from the source with ``ast``: every ``import`` and ``from ... import`` anywhere in a module (at
module level, inside functions, under ``if``), resolved to the most specific cvpipe module it names. An edge to a
package means its ``__init__``; the implicit import of a module's parent packages is not an edge (a submodule that
imports a sibling is not a cycle), but a submodule that imports a name from its own package's ``__init__``, which
imports that submodule, is.
"""

from __future__ import annotations

import ast

from conftest import ROOT

PACKAGE = "cvpipe"


def _modules() -> dict[str, object]:
    """Module name -> path of every module of the package (a package is its ``__init__.py``)."""
    out = {}
    for path in sorted((ROOT / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _target(name: str, modules) -> str | None:
    """The most specific module of ``modules`` that the dotted ``name`` is or lies in (None outside the package)."""
    parts = name.split(".")
    while parts:
        candidate = ".".join(parts)
        if candidate in modules:
            return candidate
        parts.pop()
    return None


def import_graph() -> dict[str, set[str]]:
    """Module -> the cvpipe modules it imports (see the module docstring)."""
    modules = _modules()
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, path in modules.items():
        is_package = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = module.split(".") if is_package else module.split(".")[:-1]
                    base = base[: len(base) - (node.level - 1)]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                # `from pkg import name`: the submodule pkg.name when it is one, else pkg itself
                names = [f"{source}.{a.name}" for a in node.names]
            for name in names:
                target = _target(name, modules)
                if target is not None and target != module:
                    graph[module].add(target)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as ``[a, b, ..., a]``, or None when it is a DAG."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state:
            found = visit(start)
            if found:
                return found
    return None


def test_the_library_imports_form_a_dag():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_the_graph_has_the_imports_inside_functions_and_a_cycle_is_named():
    graph = import_graph()
    # cvpipe.hough.transform imports its numba kernels inside a function only
    assert "cvpipe.hough._kernels" in graph["cvpipe.hough.transform"]
    assert "cvpipe.interrupt" in graph["cvpipe._entry"] and "cvpipe.cli" in graph["cvpipe._entry"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None
