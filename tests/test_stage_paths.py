"""A user's folder name reaches a stage intact and never as shell text: ``dvc.yaml``'s commands name the parameter
(``--images-param hough.data``) and the stage reads its value from ``params.yaml``."""

import os
import re
import subprocess
import sys

import numpy as np
import pytest
import yaml

from cvpipe import io
from cvpipe.errors import InputError
from stages._runner import path_param

from conftest import ROOT

#: folder names that a shell would split, expand, run or choke on, and a non-ASCII one
NAMES = ["x;touch INJECTED;echo", "my pics", "photos (2024)", "toms'pics", 'say "cheese"', "$HOME`touch INJECTED`",
         "naïve café ✓", "-rf", "a\\b&&touch INJECTED|"]


def _stages() -> dict:
    return yaml.safe_load((ROOT / "dvc.yaml").read_text(encoding="utf-8"))["stages"]


def test_no_command_pastes_a_parameter_value():
    """Only the matrix items, literals of dvc.yaml itself, are templated into a ``cmd``."""
    for name, spec in _stages().items():
        templated = re.findall(r"\$\{([^}]+)\}", spec["cmd"])
        assert all(t.startswith("item.") for t in templated), f"{name}: {templated}"
        assert all(isinstance(v, (str, int)) for values in spec.get("matrix", {}).values() for v in values), name


def test_every_data_folder_is_passed_by_its_parameter_name():
    """Each stage that depends on a ``<task>.data`` folder is told that parameter's name in its ``cmd``."""
    for name, spec in _stages().items():
        for dep in spec.get("deps", []):
            m = re.fullmatch(r"\$\{(\w+\.data)\}/?", str(dep))
            if m:
                assert f"-param {m.group(1)} " in spec["cmd"] + " ", f"{name} does not read {m.group(1)} by name"


@pytest.fixture
def hough_stage(tmp_path):
    """A scratch working folder with the repository's params.yaml; ``run(folder)`` puts one image in ``folder``,
    points ``hough.data`` at it and runs the hough_edges ``cmd`` of dvc.yaml through ``sh -c`` as DVC does (its
    ``${...}`` templates filled with the parameters' values first, as DVC fills them)."""
    params = yaml.safe_load((ROOT / "params.yaml").read_text(encoding="utf-8"))

    def value(m: re.Match) -> str:
        node = params
        for part in m.group(1).split("."):
            node = node[part]
        return str(node)

    img = np.zeros((64, 64), np.uint8)
    img[20:44, 20:44] = 255  # a square: Canny finds its four edges

    def run(folder: str) -> subprocess.CompletedProcess:
        io.save_image(tmp_path / folder / "square.png", img)
        params["hough"]["data"] = folder
        (tmp_path / "params.yaml").write_text(yaml.safe_dump(params, allow_unicode=True), encoding="utf-8")
        env = {"PATH": f"{sys.executable.rsplit('/', 1)[0]}:/usr/bin:/bin", "PYTHONPATH": str(ROOT),
               "HOME": str(tmp_path)}
        cmd = re.sub(r"\$\{([^}]+)\}", value, _stages()["hough_edges"]["cmd"])
        return subprocess.run(["/bin/sh", "-c", cmd], cwd=tmp_path, env=env, capture_output=True, text=True)

    return tmp_path, run


@pytest.mark.parametrize("folder", NAMES)
def test_any_folder_name_reaches_the_stage_and_runs_nothing(hough_stage, folder):
    root, run = hough_stage
    proc = run(folder)
    assert proc.returncode == 0, proc.stderr
    assert (root / "outputs/hough/edges/square.png").is_file()
    assert not list(root.rglob("INJECTED")) and not (ROOT / "INJECTED").exists()


def test_a_data_parameter_that_is_not_a_path_is_one_line_naming_it(tmp_path):
    params = yaml.safe_load((ROOT / "params.yaml").read_text(encoding="utf-8"))
    params["hough"]["data"] = 123
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params), encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "stages.hough_edges", "--images-param", "hough.data", "--out", "o"],
                          cwd=tmp_path, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}, capture_output=True,
                          text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "hough_edges: error: `hough.data` must be a folder path (a non-empty string), got 123 (int) in params.yaml; "
        "a folder named like a number is given quoted: -S 'hough.data=\"123\"'"]
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("value, match", [(123, r"`t\.data` must be a folder path .* got 123 \(int\)"),
                                          ("", r"`t\.data` must be a folder path .* got ''"),
                                          (["a"], r"`t\.data` must be a folder path .* got \['a'\] \(list\)"),
                                          (None, r"`t\.data` must be a folder path .* got None")])
def test_path_param_refuses_a_value_that_is_not_a_path(tmp_path, value, match):
    (tmp_path / "p.yaml").write_text(yaml.safe_dump({"t": {"data": value}}))
    with pytest.raises(InputError, match=match):
        path_param(tmp_path / "p.yaml", "t.data")


def test_path_param_names_a_missing_parameter(tmp_path):
    (tmp_path / "p.yaml").write_text(yaml.safe_dump({"t": {"other": 1}}))
    with pytest.raises(InputError, match=r"parameter `t\.data` is missing"):
        path_param(tmp_path / "p.yaml", "t.data")


def test_every_data_folder_dependency_is_templated_into_a_path(tmp_path):
    """``dvc.yaml`` names each data folder as ``${<task>.data}/``: a value that YAML reads as a number
    (``-S panorama.data=123``) becomes the path ``123/`` (DVC's own templating fails with "'int' object has no
    attribute 'decode'" on a dependency that is a bare number), and an absolute path stays absolute."""
    for name, spec in _stages().items():
        for dep in spec.get("deps", []):
            assert not re.fullmatch(r"\$\{(\w+\.data)\}", str(dep)), f"{name}: {dep} is not templated into a path"
    repo = tmp_path / "repo"
    repo.mkdir()
    (repo / "dvc.yaml").write_text((ROOT / "dvc.yaml").read_text(encoding="utf-8"), encoding="utf-8")
    params = yaml.safe_load((ROOT / "params.yaml").read_text(encoding="utf-8"))
    params["panorama"]["data"] = 123
    params["hough"]["data"] = str(tmp_path / "absolute")  # outside the repository: DVC shows it as it is
    (repo / "params.yaml").write_text(yaml.safe_dump(params), encoding="utf-8")
    env = dict(os.environ, DVC_NO_ANALYTICS="1", PATH=f"{sys.executable.rsplit('/', 1)[0]}:{os.environ['PATH']}")
    subprocess.run([sys.executable, "-m", "dvc", "init", "--no-scm", "-q"], cwd=repo, env=env, check=True)
    proc = subprocess.run([sys.executable, "-m", "dvc", "status", "panorama_features", "hough_edges"], cwd=repo,
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    # both folders are missing: DVC lists them as deleted dependencies, under the paths the values name
    assert re.search(r"deleted:\s+123/?\n", proc.stdout), proc.stdout
    assert re.search(rf"deleted:\s+{re.escape(str(tmp_path))}/absolute/?\n", proc.stdout), proc.stdout


def test_path_param_returns_the_value_unchanged(tmp_path):
    (tmp_path / "p.yaml").write_text(yaml.safe_dump({"t": {"data": NAMES[0]}}))
    assert path_param(tmp_path / "p.yaml", "t.data") == NAMES[0]


def _stereo_depth(cwd, *argv) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stages.stereo_depth", "--rectified", "rect", "--out", "depth",
                           "--metrics", "m.json", *argv], cwd=cwd,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}, capture_output=True, text=True)


def test_stereo_depth_reads_the_method_folder_from_its_section(tmp_path):
    """``--disparities-root`` + ``stereo.depth.method`` from params.yaml: the method never passes through the shell."""
    params = yaml.safe_load((ROOT / "params.yaml").read_text(encoding="utf-8"))
    params["stereo"]["depth"]["method"] = "opencv_bm"
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params), encoding="utf-8")
    io.save_json(tmp_path / "rect/run.json", {"pairs": {"p": {}}})  # no calibration: disparity only
    io.save_json(tmp_path / "disp/opencv_bm/run.json", {"method": "opencv_bm", "pairs": {"p": {}}})
    proc = _stereo_depth(tmp_path, "--disparities-root", "disp")
    assert proc.returncode == 0, proc.stderr
    assert io.load_json(tmp_path / "depth/run.json")["method"] == "opencv_bm"


@pytest.mark.parametrize("argv", [[], ["--disparities", "a", "--disparities-root", "b"]])
def test_stereo_depth_needs_exactly_one_disparity_folder(tmp_path, argv):
    (tmp_path / "params.yaml").write_text((ROOT / "params.yaml").read_text(encoding="utf-8"), encoding="utf-8")
    proc = _stereo_depth(tmp_path, *argv)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "stereo_depth: error: give one of --disparities FOLDER or --disparities-root FOLDER"]
