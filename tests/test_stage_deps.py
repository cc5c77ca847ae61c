"""Every DVC stage depends on every repository module it imports, directly or not (an edit of the library can
never leave a stale result that `dvc repro` calls up to date), and no stage script imports another: what two stages
share lives in the library or in the shared runner."""

import ast

import pytest
from stage_deps import closure, missing_deps, stage_modules

from conftest import ROOT


def test_every_stage_lists_every_module_it_imports():
    assert missing_deps() == {}, "run `python tests/stage_deps.py` to see what to add to dvc.yaml"


def test_every_stage_runs_a_stage_module():
    assert set(stage_modules()) == set(__import__("yaml").safe_load((ROOT / "dvc.yaml").read_text())["stages"])


def test_closure_follows_imports_also_inside_functions():
    files = {f.relative_to(ROOT).as_posix() for f in closure("stages.hough_lines")}
    # hough_lines imports cvpipe.hough and the runner; the runner imports cvpipe.params, which imports cvpipe.errors
    assert {"stages/hough_lines.py", "stages/_runner.py", "cvpipe/hough/transform.py", "cvpipe/params/__init__.py",
            "cvpipe/params/base.py", "cvpipe/errors.py",
            "cvpipe/__init__.py", "stages/__init__.py"} <= files
    assert not any(f.startswith("tests/") for f in files)


#: the modules of the stages package a stage script may import: the package (it pins the CPU code paths) and the
#: shared runner; every other module there is a stage script
SHARED_STAGE_MODULES = {"stages", "stages._runner"}


def stage_imports(source: str) -> set[str]:
    """The modules of the stages package that ``source`` (a module directly inside ``stages/``) imports, other
    than :data:`SHARED_STAGE_MODULES`."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = ("stages" + (f".{node.module}" if node.module else "")) if node.level else (node.module or "")
            if base == "stages":  # `from stages import x`: x may be a module
                names.update(f"stages.{a.name}" for a in node.names)
            names.add(base)
    return {n for n in names if n.split(".")[0] == "stages"} - SHARED_STAGE_MODULES


def test_no_stage_imports_another_stage():
    found = {p.name: sorted(stage_imports(p.read_text(encoding="utf-8"))) for p in (ROOT / "stages").glob("*.py")}
    assert {name: mods for name, mods in found.items() if mods} == {}


@pytest.mark.parametrize("source, found", [
    ("from stages.logo_match import load_gallery", {"stages.logo_match"}),
    ("import stages.stereo_disparity", {"stages.stereo_disparity"}),
    ("from stages import _panorama as pr", {"stages._panorama"}),
    ("from . import logo_match", {"stages.logo_match"}),
    ("from .stereo_disparity import read_truth", {"stages.stereo_disparity"}),
    ("def f():\n    from stages.logo_match import x", {"stages.logo_match"}),
    ("from stages._runner import Stage, run\nfrom stages import _runner\nimport stages", set()),
    ("from cvpipe import stereo\nimport cvpipe.stages_like", set()),
])
def test_stage_imports_finds_every_form_of_import(source, found):
    assert stage_imports(source) == found
