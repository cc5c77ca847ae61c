"""The DVC pipeline caches and reruns the way DVC users expect (on a fresh copy of this repository)."""

import re
import time

import pytest

from pipeline_copy import copy_repo, dvc

pytestmark = pytest.mark.slow


def ran(output: str) -> set[str]:
    """Names of the stages that `dvc repro` actually ran."""
    return set(re.findall(r"Running stage '([^']+)'", output))


@pytest.fixture(scope="module")
def reproduced(tmp_path_factory, repo_root):
    repo = copy_repo(repo_root, tmp_path_factory.mktemp("clone"))
    first = dvc(["repro"], repo)
    return repo, first.stdout


def test_fresh_clone_repro_runs_every_stage(reproduced):
    repo, out = reproduced
    assert {"samples", "homography_features", "homography_match", "report"} <= ran(out)
    assert (repo / "data/samples/homography/truth.json").is_file()
    assert (repo / "outputs/report.html").is_file() and (repo / "outputs/plots/timings.json").is_file()
    assert (repo / "outputs/homography/matches/dropped.json").is_file()


def test_dvc_plots_show_writes_its_page(reproduced, tmp_path):
    import json

    repo, _ = reproduced
    dvc(["plots", "show", "-o", str(tmp_path / "plots")], repo)
    assert (tmp_path / "plots" / "index.html").is_file()
    shown = json.loads(dvc(["plots", "show", "--json"], repo).stdout)
    assert "outputs/plots/timings.json" in shown["data"]  # every declared plot file was found and parsed
    assert "errors" not in shown, shown["errors"]


def test_second_repro_runs_nothing(reproduced):
    repo, _ = reproduced
    t0 = time.perf_counter()
    out = dvc(["repro"], repo).stdout
    elapsed = time.perf_counter() - t0
    assert ran(out) == set(), out
    print(f"no-op dvc repro: {elapsed:.2f} s")  # measured for BENCHMARKS.md, never asserted


def test_matching_param_change_reruns_matching_only(reproduced):
    repo, _ = reproduced
    params = repo / "params.yaml"
    text = params.read_text()
    changed = re.sub(r"(  match:\n    ratio: )0\.8", r"\g<1>0.7", text, count=1)
    assert changed != text, "the homography.match.ratio line was not found in params.yaml"
    params.write_text(changed)
    try:
        out = dvc(["repro"], repo).stdout
        stages = ran(out)
        assert "homography_match" in stages
        assert "homography_features" not in stages and "samples" not in stages
        assert "Stage 'homography_features' didn't change, skipping" in out
        diff = dvc(["params", "diff"], repo).stdout
        assert re.search(r"homography\.match\.ratio\s+0\.8\s+0\.7", diff), diff
    finally:
        params.write_text(text)
