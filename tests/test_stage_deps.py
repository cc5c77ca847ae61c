"""Every DVC stage depends on every repository module it imports, directly or not (an edit of the library can
never leave a stale result that `dvc repro` calls up to date)."""

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
