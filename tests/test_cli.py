"""The `cvpipe` command: version, help with examples, error format and exit status."""

import argparse
import subprocess
import sys

import pytest

from cvpipe import __version__, cli


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"cvpipe {__version__}"


def test_every_subcommand_has_help_with_example(capsys):
    names = list(cli.LazyCommands(argparse.ArgumentParser(), "cvpipe.commands", cli.COMMANDS, "command").parsers)
    assert "bench" in names and set(names) == set(cli.COMMANDS)  # every listed module exists
    for name in names:
        with pytest.raises(SystemExit):
            cli.main([name, "--help"])
        text = capsys.readouterr().out
        assert "example:" in text and f"cvpipe {name}" in text


def test_unknown_command_exits_2():
    proc = subprocess.run([sys.executable, "-m", "cvpipe.cli", "frobnicate"], capture_output=True, text=True)
    assert proc.returncode == 2 and "cvpipe: error:" in proc.stderr


def test_bench_pipeline_rejects_a_folder_without_dvc_yaml(tmp_path, capsys):
    assert cli.main(["bench", "pipeline", "--repo", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("cvpipe: error:") and "no dvc.yaml" in err[0]


def test_top_level_help_shows_an_example(capsys):
    with pytest.raises(SystemExit):
        cli.main(["--help"])
    out = capsys.readouterr().out
    assert "example:\n  cvpipe " in out


def test_every_benchmark_has_one_line_help_with_example(capsys):
    from cvpipe.commands import bench

    modules = cli._load("cvpipe.bench", bench.BENCHMARKS)
    assert "pipeline" in modules
    for name, module in modules.items():
        assert "\n" not in module.HELP and "\n" not in module.EXAMPLE, name
        assert module.EXAMPLE.startswith(f"cvpipe bench {name}"), module.EXAMPLE
        with pytest.raises(SystemExit):
            cli.main(["bench", name, "--help"])
        assert f"example:\n  {module.EXAMPLE}" in capsys.readouterr().out
