"""The modules of the cvpipe library import each other without a cycle.

The graph is read from the source with ``ast``: every ``import`` and ``from ... import`` anywhere in a module (at
module level, inside functions, under ``if``), resolved to the most specific cvpipe module it names. An edge to a
package means its ``__init__``; the implicit import of a module's parent packages is not an edge (a submodule that
imports a sibling is not a cycle), but a submodule that imports a name from its own package's ``__init__``, which
imports that submodule, is. The compiled modules (``.pyx``) are modules of the graph too: their Python-level
imports are edges (read line by line, as ``ast`` cannot parse Cython); their ``cimport`` lines are not, as they are
resolved when the module is compiled.
"""

from __future__ import annotations

import ast
import re

from conftest import ROOT

PACKAGE = "cvpipe"


#: a Python-level import line of a Cython module: ``import a.b[ as c], ...`` or ``from x import a[ as b], ...``
_PYX_IMPORT = re.compile(r"^\s*(?:from\s+(?P<source>\.*[\w.]*)\s+import\s+(?P<names>[^#]+)"
                         r"|import\s+(?P<modules>[^#]+))")


def _modules() -> dict[str, object]:
    """Module name -> path of every module of the package, Python or compiled (a package is its ``__init__.py``)."""
    out = {}
    for path in sorted([*(ROOT / PACKAGE).rglob("*.py"), *(ROOT / PACKAGE).rglob("*.pyx")]):
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


def _imports(path) -> list[tuple[int, str, list[str]]]:
    """``(level, source, names)`` of every import of a module: ``import a.b`` is ``(0, "", ["a.b"])``,
    ``from ..x import y`` is ``(2, "x", ["y"])``."""
    text = path.read_text(encoding="utf-8")
    found = []
    if path.suffix == ".pyx":
        for line in text.splitlines():
            m = _PYX_IMPORT.match(line)
            if m is None:
                continue
            if m["modules"] is not None:
                found.append((0, "", [n.split()[0] for n in m["modules"].split(",") if n.strip()]))
            else:
                level = len(m["source"]) - len(m["source"].lstrip("."))
                names = m["names"].strip().strip("()").split(",")
                found.append((level, m["source"].lstrip("."), [n.split()[0] for n in names if n.strip()]))
        return found
    for node in ast.walk(ast.parse(text, str(path))):
        if isinstance(node, ast.Import):
            found.append((0, "", [a.name for a in node.names]))
        elif isinstance(node, ast.ImportFrom):
            found.append((node.level, node.module or "", [a.name for a in node.names]))
    return found


def import_graph() -> dict[str, set[str]]:
    """Module -> the cvpipe modules it imports (see the module docstring)."""
    modules = _modules()
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, path in modules.items():
        is_package = path.name == "__init__.py"
        for level, source, imported in _imports(path):
            if not level and not source:  # `import a.b`
                names = imported
            else:
                if level:
                    base = module.split(".") if is_package else module.split(".")[:-1]
                    base = base[: len(base) - (level - 1)]
                    source = ".".join(base + ([source] if source else []))
                # `from pkg import name`: the submodule pkg.name when it is one, else pkg itself
                names = [f"{source}.{name}" for name in imported]
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
    # the guard imports the algorithm modules inside its row functions only, and `from .. import _threads` names
    # a compiled module
    assert "cvpipe.hough" in graph["cvpipe.bench.guard"]
    assert "cvpipe._threads" in graph["cvpipe.bench.stereo"] and "cvpipe._linalg" in graph["cvpipe.linalg"]
    assert "cvpipe.interrupt" in graph["cvpipe._entry"] and "cvpipe.cli" in graph["cvpipe._entry"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None
