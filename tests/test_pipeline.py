"""The DVC pipeline caches and reruns the way DVC users expect (on a fresh copy of this repository)."""

import re
import sys
import time

import pytest

from cvpipe.metrics import HEADLINE
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


def test_fresh_clone_run_leaves_git_status_clean(reproduced):
    """`make run` on a fresh clone must reproduce dvc.lock and the git-tracked metrics byte for byte."""
    import subprocess

    repo, _ = reproduced
    status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=repo, check=True,
                            capture_output=True, text=True).stdout
    assert status == "", f"the pipeline changed or left tracked/untracked files:\n{status}"


def test_forced_rerun_of_a_stage_leaves_the_stages_after_it_up_to_date(reproduced):
    repo, _ = reproduced
    out = dvc(["repro", "-f", "-s", "hough_edges"], repo).stdout
    assert ran(out) == {"hough_edges"}
    status = dvc(["status"], repo).stdout
    assert "hough_lines" not in status and "hough_report" not in status, status


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


def test_a_code_change_reruns_the_stages_that_run_that_code(reproduced):
    # every stage depends on each file it imports (tests/stage_deps.py): an edit of the Hough transform makes the
    # Hough stages that import it out of date, and no stage of another task
    repo, _ = reproduced
    source = repo / "cvpipe" / "hough" / "transform.py"
    text = source.read_text()
    source.write_text(text + "\n# an edit\n")
    try:
        status = dvc(["status"], repo).stdout
    finally:
        source.write_text(text)
    stale = set(re.findall(r"^(\S+):\s*$", status, re.M))
    assert {"hough_lines@ours", "hough_lines@opencv"} <= stale, status
    assert not {s for s in stale if s.split("_")[0] in ("homography", "defect", "logo", "stereo", "panorama")}, status
    assert dvc(["status"], repo).stdout.strip().endswith("Data and pipelines are up to date."), "restored"


def test_one_parameter_experiment_reads_in_120_columns(reproduced):
    # the README's `dvc exp show --only-changed --drop 'outputs/|data/|Created|State|Executor'` after a
    # one-parameter experiment: the changed parameter and the headline metrics it moved, none cut off (rich marks a
    # cut column with an ellipsis).
    # It runs before the own-images experiments of this module: --only-changed compares every experiment shown
    import subprocess

    from pipeline_copy import run_env

    repo, _ = reproduced
    try:
        dvc(["exp", "run", "-n", "threshold-140", "-S", "hough.lines.threshold=140"], repo)
        shown = subprocess.run([sys.executable, "-m", "dvc", "exp", "show", "--only-changed", "--drop",
                                "outputs/|data/|Created|State|Executor", "--no-pager"], cwd=repo, env={**run_env(), "COLUMNS": "120"},
                               capture_output=True, text=True, check=True).stdout
        lines = [ln for ln in shown.splitlines() if ln.strip()]
        assert max(len(ln) for ln in lines) <= 120 and "\u2026" not in shown, shown
        header = lines[1]
        for column in ("hough.lines.threshold", "hough.all.lines_ours", "hough.all.lines_opencv"):
            assert column in header, shown
        row = next(ln for ln in lines if "threshold-140" in ln)
        assert " 140 " in f"{row} ", shown
    finally:  # the workspace as before, for the tests after this one
        subprocess.run(["git", "checkout", "--", "params.yaml", "dvc.lock", "outputs"], cwd=repo, check=False)
        subprocess.run([sys.executable, "-m", "dvc", "checkout", "-q"], cwd=repo, env=run_env(), check=False)
        subprocess.run([sys.executable, "-m", "dvc", "exp", "remove", "threshold-140"], cwd=repo, env=run_env(),
                       check=False, capture_output=True)


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


# ---- own images: every task on a user-style folder without truth, through `dvc exp run -S <task>.data=...` ----

TASKS = ["hough", "homography", "defect", "logo", "stereo", "panorama"]


@pytest.mark.parametrize("task", TASKS)
def test_own_images_without_truth_through_dvc_exp_run(reproduced, task):
    import json
    import subprocess

    import own_data

    repo, _ = reproduced
    dest = f"data/mine/{task}"
    names = own_data.build(task, repo / "data/samples", repo / dest)
    assert not list((repo / dest).rglob("truth.json"))
    try:
        dvc(["exp", "run", "-n", f"mine-{task}", "-S", f"{task}.data={dest}"], repo)
        summary = json.loads((repo / f"outputs/{task}/summary.json").read_text())
        text = json.dumps(summary)
        for name in names:  # every item of the user's folder is reported (results table or pictures)
            assert name in text, f"{name} missing from the {task} summary"
        assert summary["pictures"], f"{task}: no pictures for the user's images"
        for pic in summary["pictures"]:
            assert (repo / pic["path"]).is_file(), pic
        assert "no ground truth" in text.lower(), f"{task}: the summary should say there is no ground truth"
        page = (repo / "outputs/report.html").read_text(encoding="utf-8")
        assert f'id="task-{task}"' in page and names[0] in page
        shown = json.loads(dvc(["exp", "show", "--json"], repo).stdout)
        exps = [e for rev in shown for e in (rev.get("experiments") or [])
                if any((r.get("name") == f"mine-{task}") for r in (e.get("revs") or []))]
        assert exps, f"experiment mine-{task} not in `dvc exp show --json`"
        data = exps[0]["revs"][0]["data"]
        metrics_text = json.dumps(data.get("metrics", {}))
        assert f'"{task}"' in metrics_text, f"{task}: the experiment has no metrics"
        # the headline only (without truth: counts and shares that need none); the per-item figures are details
        assert any(f'"{k}"' in metrics_text for k in HEADLINE[task]), metrics_text[:300]
        assert names[0] not in metrics_text, f"{task}: per-item figures belong in the details file, not the metrics"
    finally:
        subprocess.run(["git", "checkout", "--", "params.yaml", "dvc.lock"], cwd=repo, check=False)
        subprocess.run(["git", "checkout", "--", "outputs"], cwd=repo, check=False)

