"""`cvpipe init` and `cvpipe stage`: a user's pipeline is this repository's with the stages run from the package,
no dependency on source files, the parameters at their model defaults, and running init again never changes what
the user set. The whole flow from an installed wheel (dvc repro, a queued sweep, push/pull) is in
test_own_repository.py (slow tier)."""

from __future__ import annotations

import subprocess
import sys

import pytest
import yaml

from conftest import ROOT
from cvpipe import __version__, cli
from cvpipe import init as pipeline
from cvpipe.errors import InputError
from cvpipe.params import SECTIONS, from_mapping
from stages import _runner


@pytest.fixture(scope="module")
def template():
    return yaml.safe_load((ROOT / "dvc.yaml").read_text(encoding="utf-8"))


def test_user_stage_runs_the_packaged_stage_and_depends_on_no_source_file(template):
    st = pipeline.user_stage(template["stages"]["hough_report"])
    assert st["cmd"].startswith("cvpipe stage hough_report ") and "python -m" not in st["cmd"]
    assert not [d for d in st["deps"] if d.startswith(("cvpipe/", "stages/"))]
    # what is not code is kept as it was: the data folder and the earlier stages' outputs
    kept = [d for d in template["stages"]["hough_report"]["deps"] if not d.startswith(("cvpipe/", "stages/"))]
    assert st["deps"] == kept and "${hough.data}/" in kept and "outputs/hough/edges" in kept
    assert st["params"][0] == pipeline.VERSION_SECTION and st["params"][1:] == ["hough.report"]
    assert st["outs"] == template["stages"]["hough_report"]["outs"]


def test_user_pipeline_has_the_chosen_tasks_only(template):
    dvc = pipeline.user_pipeline(template, ("hough", "panorama"), samples=False)
    names = set(dvc["stages"])
    assert names == {n for n in template["stages"] if n.startswith(("hough_", "panorama_"))} | {"report"}
    assert all("python -m stages." not in str(st["cmd"]) for st in dvc["stages"].values())
    assert all(pipeline.VERSION_SECTION in st["params"] for st in dvc["stages"].values())
    # the report depends on the chosen tasks' summaries only
    assert sorted(dvc["stages"]["report"]["deps"]) == ["outputs/hough/summary.json", "outputs/panorama/summary.json"]
    ids = [next(iter(p)) if isinstance(p, dict) else p for p in dvc["plots"]]
    assert "panorama_corner_error" in ids and "logo_precision_recall" not in ids
    with_samples = pipeline.user_pipeline(template, ("hough",), samples=True)
    assert "samples" in with_samples["stages"]


def test_every_stage_of_the_pipeline_ships_with_the_package(template):
    from cvpipe.commands.stage import stage_names

    run = {str(st["cmd"]).split()[2].removeprefix("stages.") for st in template["stages"].values()}
    assert run <= set(stage_names())
    assert "_runner" not in stage_names()


def test_default_params_are_the_models_defaults():
    params = pipeline.default_params()
    for section, cls in SECTIONS.items():
        node = params
        for part in section.split("."):
            node = node[part]
        assert from_mapping(cls, node, section) == cls()
    assert {t: params[t]["data"] for t in pipeline.TASKS} == {t: f"data/samples/{t}" for t in pipeline.TASKS}


def test_repository_params_yaml_has_every_section_and_valid_values():
    """The structure of this repository's params.yaml, not its values: they are the user's after `dvc exp apply`."""
    from cvpipe.params import read_params_file

    have, want = read_params_file(ROOT / "params.yaml"), pipeline.default_params()

    def keys(node, prefix=""):
        return {f"{prefix}{k}" for k, v in node.items()} | {
            s for k, v in node.items() if isinstance(v, dict) for s in keys(v, f"{prefix}{k}.")}

    assert keys(have) == keys(want)
    for section, cls in SECTIONS.items():
        node = have
        for part in section.split("."):
            node = node[part]
        from_mapping(cls, node, section)  # raises on an invalid value


def test_user_params_keep_the_chosen_tasks_and_record_the_version():
    params = pipeline.user_params(pipeline.default_params(), ("panorama",), {"panorama": "data/trip"}, "9.9")
    assert set(params) == {"panorama", "compute", pipeline.VERSION_SECTION}
    assert params["panorama"]["data"] == "data/trip" and params[pipeline.VERSION_SECTION] == {"version": "9.9"}
    on_samples = pipeline.user_params(pipeline.default_params(), ("hough",), {}, "9.9")
    assert "samples" in on_samples and pipeline.needs_samples(on_samples, ("hough",))


@pytest.mark.parametrize("pairs, message", [
    (["panorama"], "expected TASK=FOLDER"),
    (["pano=data/x"], "unknown task `pano`"),
    (["hough=a", "hough=b"], "given twice"),
    (["hough="], "expected TASK=FOLDER"),
])
def test_parse_data_refuses_bad_pairs(pairs, message):
    with pytest.raises(ValueError, match=message):
        pipeline.parse_data(pairs)


def test_parse_tasks_orders_and_refuses_unknown():
    assert pipeline.parse_tasks("stereo,hough") == ("hough", "stereo")
    assert pipeline.parse_tasks(None) == pipeline.TASKS
    with pytest.raises(ValueError, match="unknown task"):
        pipeline.parse_tasks("hough,lines")


def test_merge_missing_adds_keys_and_never_changes_a_value():
    have = {"hough": {"lines": {"threshold": 120}}, "mine": 1}
    added = pipeline.merge_missing(have, {"hough": {"lines": {"threshold": 150, "rho": 1.0}}, "stereo": {"a": 1}})
    assert have == {"hough": {"lines": {"threshold": 120, "rho": 1.0}}, "mine": 1, "stereo": {"a": 1}}
    assert sorted(added) == ["hough.lines.rho", "stereo"]


def _init(tmp_path, *args):
    return cli.main(["init", str(tmp_path / "repo"), *args])


def _need_git_and_dvc():
    import shutil

    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    pytest.importorskip("dvc")


def test_init_writes_a_pipeline_and_running_it_again_keeps_the_users_edits(tmp_path, capsys):
    _need_git_and_dvc()
    repo = tmp_path / "repo"
    (repo / "data" / "lines").mkdir(parents=True)
    assert _init(tmp_path, "--tasks", "hough", "--data", "hough=data/lines") == 0
    assert (repo / ".git").is_dir() and (repo / ".dvc").is_dir()
    dvc = yaml.safe_load((repo / "dvc.yaml").read_text())
    params = yaml.safe_load((repo / "params.yaml").read_text())
    assert set(dvc["stages"]) == {"hough_data", "hough_edges", "hough_lines", "hough_report", "report"}
    assert params["hough"]["data"] == "data/lines" and params["cvpipe"]["version"] == __version__
    ignore = (repo / ".gitignore").read_text().splitlines()
    assert set(pipeline.GITIGNORE_LINES) <= set(ignore)
    out = capsys.readouterr().out
    assert "dvc add data/lines" in out and "dvc repro" in out

    # the user's edits: a parameter and a comment
    text = (repo / "params.yaml").read_text().replace("threshold: 150", "threshold: 120  # mine")
    (repo / "params.yaml").write_text(text)
    assert _init(tmp_path, "--tasks", "hough", "--data", "hough=data/lines") == 0
    assert "up to date" in capsys.readouterr().out
    assert (repo / "params.yaml").read_text() == text
    assert (repo / ".gitignore").read_text().splitlines() == ignore  # no line twice

    # a second task is added; what was there stays as it was
    assert _init(tmp_path, "--tasks", "hough,stereo") == 0
    out = capsys.readouterr().out
    assert "stages.stereo_disparity" in out
    params = yaml.safe_load((repo / "params.yaml").read_text())
    assert params["hough"]["lines"]["threshold"] == 120 and params["stereo"]["data"] == "data/samples/stereo"
    assert "threshold: 120  # mine" in (repo / "params.yaml").read_text()
    dvc = yaml.safe_load((repo / "dvc.yaml").read_text())
    assert {"hough_edges", "stereo_disparity", "samples"} <= set(dvc["stages"])


def test_init_refuses_a_data_folder_that_contradicts_the_users(tmp_path, capsys):
    _need_git_and_dvc()
    repo = tmp_path / "repo"
    for d in ("a", "b"):
        (repo / "data" / d).mkdir(parents=True)
    assert _init(tmp_path, "--tasks", "hough", "--data", "hough=data/a") == 0
    before = (repo / "params.yaml").read_text()
    capsys.readouterr()
    assert _init(tmp_path, "--tasks", "hough", "--data", "hough=data/b") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "params.yaml" in err and "hough.data" in err and "'data/a'" in err
    assert (repo / "params.yaml").read_text() == before


@pytest.mark.parametrize("args, message", [
    (["--data", "hough=data/none"], "no such folder"),
    (["--data", "hough=/"], "must be inside the repository"),
    (["--tasks", "hough", "--data", "stereo=data"], "not in --tasks"),
])
def test_init_refuses_bad_data_folders(tmp_path, capsys, args, message):
    _need_git_and_dvc()
    (tmp_path / "repo" / "data").mkdir(parents=True)
    assert _init(tmp_path, *args) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "repo" / "dvc.yaml").exists()


def test_upgrade_records_the_installed_version(tmp_path, capsys):
    _need_git_and_dvc()
    assert _init(tmp_path, "--tasks", "hough") == 0
    path = tmp_path / "repo" / "params.yaml"
    path.write_text(path.read_text().replace(f"version: {__version__}", "version: 0.0.1"))
    with pytest.raises(InputError, match=r"`cvpipe.version` is 0.0.1 but cvpipe .* installed"):
        _runner.check_version(path)
    assert _init(tmp_path, "--tasks", "hough") == 0
    assert "cvpipe init --upgrade" in capsys.readouterr().err  # the note; the value is the user's until then
    assert _init(tmp_path, "--tasks", "hough", "--upgrade") == 0
    assert yaml.safe_load(path.read_text())["cvpipe"]["version"] == __version__
    _runner.check_version(path)  # passes now


def test_this_repository_records_no_version_so_stages_check_nothing():
    assert "cvpipe" not in yaml.safe_load((ROOT / "params.yaml").read_text())
    _runner.check_version(ROOT / "params.yaml")


def test_a_data_folder_missing_from_an_experiment_copy_says_how_to_track_it(tmp_path):
    copy = tmp_path / ".dvc" / "tmp" / "exps" / "tmpabc"
    copy.mkdir(parents=True)
    with pytest.raises(InputError) as info:
        _runner.check_data_folder("data/mine/trip", "panorama.data", cwd=copy)
    message = str(info.value)
    assert "\n" not in message and "dvc add data/mine/trip" in message and "--copy-paths" in message
    with pytest.raises(InputError, match=r"`panorama.data`: no such folder: data/mine/trip$"):
        _runner.check_data_folder("data/mine/trip", "panorama.data", cwd=tmp_path)


def test_cvpipe_stage_runs_a_packaged_stage_like_python_dash_m(tmp_path):
    import numpy as np
    import cv2

    (tmp_path / "img").mkdir()
    img = np.zeros((64, 64), np.uint8)
    cv2.line(img, (5, 10), (60, 50), 255, 2)
    cv2.imwrite(str(tmp_path / "img" / "a.png"), img)
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(pipeline.default_params()))
    outs = []
    for cmd in ([sys.executable, "-m", "cvpipe", "stage", "hough_edges"], [sys.executable, "-m", "stages.hough_edges"]):
        out = tmp_path / f"edges{len(outs)}"
        proc = subprocess.run([*cmd, "--images", "img", "--out", str(out)], cwd=tmp_path, capture_output=True,
                              text=True, env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
        assert proc.returncode == 0, proc.stderr
        outs.append(cv2.imread(str(out / "a.png"), cv2.IMREAD_UNCHANGED))
    assert outs[0] is not None and np.array_equal(outs[0], outs[1]) and outs[0].max() == 255


def test_cvpipe_stage_refuses_an_unknown_stage(capsys):
    assert cli.main(["stage", "hough_edge"]) == 2
    err = capsys.readouterr().err
    assert "unknown stage `hough_edge`" in err and "hough_edges" in err


def test_task_data_knows_how_a_copy_of_the_repository_gets_the_folder(tmp_path, monkeypatch):
    from stages.task_data import tracked_by

    monkeypatch.chdir(tmp_path)
    subprocess.run(["git", "init", "-q"], check=True)
    for d in ("data/mine/a", "data/mine/b", "data/git", "data/samples/hough"):
        (tmp_path / d).mkdir(parents=True)
        (tmp_path / d / "x.png").write_bytes(b"x")
    assert tracked_by("data/mine/a") is None
    (tmp_path / "data" / "mine.dvc").write_text("outs:\n- path: mine\n")  # `dvc add data/mine` covers a and b
    assert tracked_by("data/mine/a") == "dvc" and tracked_by("data/mine/b") == "dvc"
    subprocess.run(["git", "add", "data/git/x.png"], check=True)
    assert tracked_by("data/git") == "git"
    assert tracked_by("data/samples/hough") is None
    (tmp_path / "dvc.yaml").write_text("stages:\n  samples:\n    cmd: x\n    outs:\n      - data/samples\n")
    assert tracked_by("data/samples/hough") == "dvc"  # a stage's output: restored from DVC's cache
