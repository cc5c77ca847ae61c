"""Rules of the layout, read from the source with ``ast``: no module uses a private name of a dependency, and no
stage script imports another stage (what two stages share lives in the library, or in the stage runner)."""

from __future__ import annotations

import ast

import pytest

from conftest import ROOT

#: the dependencies whose internals break on their next release (OpenCV's, Dask's, DVC's)
DEPENDENCIES = ("cv2", "dask", "distributed", "dvc")


def _sources() -> list:
    return sorted((ROOT / "cvpipe").rglob("*.py")) + sorted((ROOT / "stages").glob("*.py"))


def _private(part: str) -> bool:
    return part.startswith("_") and not (part.startswith("__") and part.endswith("__"))


def private_uses(tree: ast.AST) -> list[str]:
    """Every import of a private module or name of :data:`DEPENDENCIES`, and every ``alias._name`` attribute of a
    name bound to one of them, as source text."""
    found, aliases = [], set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                parts = a.name.split(".")
                if parts[0] in DEPENDENCIES:
                    aliases.add(a.asname or parts[0])
                    if any(_private(p) for p in parts[1:]):
                        found.append(f"import {a.name}")
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            parts = node.module.split(".")
            if parts[0] in DEPENDENCIES:
                if any(_private(p) for p in parts[1:]):
                    found.append(f"from {node.module} import ...")
                for a in node.names:
                    if _private(a.name):
                        found.append(f"from {node.module} import {a.name}")
                    elif "." not in node.module and a.name not in ("*",):
                        aliases.add(a.asname or a.name)  # a submodule (``from dask import core``) or a public name
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and _private(node.attr) and isinstance(node.value, ast.Name)
                and node.value.id in aliases):
            found.append(f"{node.value.id}.{node.attr}")
    return found


def test_the_detector_finds_each_kind_of_private_use():
    code = ("import dask.core._x\nfrom dvc import _helperlib\nfrom distributed._compat import y\nimport cv2 as cv\n"
            "cv._native()\nfrom dask import delayed\ndelayed.__doc__\nimport numpy as np\nnp._core\n")
    assert private_uses(ast.parse(code)) == ["import dask.core._x", "from dvc import _helperlib",
                                             "from distributed._compat import ...", "cv._native"]


@pytest.mark.parametrize("path", _sources(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_no_private_name_of_a_dependency(path):
    assert private_uses(ast.parse(path.read_text(encoding="utf-8"))) == []


def stage_imports(tree: ast.AST) -> set[str]:
    """The ``stages.*`` modules (other than the runner) that a stage script imports."""
    out = set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level > 0:  # ``from . import x`` / ``from .x import y`` inside the stages package
                base = "stages" + ("." + node.module if node.module else "")
                names = [base] if node.module else [f"stages.{a.name}" for a in node.names]
            elif node.module:
                names = [node.module] + ([f"stages.{a.name}" for a in node.names] if node.module == "stages" else [])
        out |= {n for n in names if n.startswith("stages.") and n not in ("stages._runner",)}
    return out


def test_the_stage_detector_sees_absolute_and_relative_imports():
    code = ("from stages._runner import run\nfrom stages.logo_match import x\nfrom . import hough_edges\n"
            "import stages.y\n")
    assert stage_imports(ast.parse(code)) == {"stages.logo_match", "stages.hough_edges", "stages.y"}


@pytest.mark.parametrize("path", sorted((ROOT / "stages").glob("*.py")), ids=lambda p: p.name)
def test_no_stage_imports_another_stage(path):
    assert stage_imports(ast.parse(path.read_text(encoding="utf-8"))) == set()
