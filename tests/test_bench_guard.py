"""`cvpipe bench guard`'s decision: every row is compared with its committed limit, and a row over it (or without
one) fails the run with its name. The measurements themselves are the guard's job, never asserted here; how a row
reads a command's own step line (the stitch start-up) is."""

from __future__ import annotations

import argparse
import json
import re
import sys

import pytest

from cvpipe.bench import guard
from cvpipe.errors import InputError


def _args(tmp_path, limits: str, **kw) -> argparse.Namespace:
    (tmp_path / "samples" / "hough").mkdir(parents=True, exist_ok=True)
    path = tmp_path / "limits.txt"
    path.write_text(limits)
    base = dict(samples=str(tmp_path / "samples"), data=None, repeats=1, rows=["a"], limits=str(path),
                out=str(tmp_path / "out.json"), json=False)
    return argparse.Namespace(**{**base, **kw})


@pytest.fixture
def fake_group(monkeypatch):
    """A group "a" whose rows have the values the test sets (no timing involved)."""
    values = {}

    def rows(ctx):
        return [guard.Row(name, v, "x", "what", "accuracy", 1) for name, v in values.items()]

    monkeypatch.setitem(guard.GROUPS, "a", rows)
    return values


def test_committed_limits_file_names_each_row_once_with_a_reason():
    limits = guard.read_limits(guard.LIMITS_FILE)
    assert limits and all(v > 0 and why for v, why in limits.values())
    text = [line.split()[0] for line in guard.LIMITS_FILE.read_text().splitlines()
            if line.strip() and not line.startswith("#")]
    assert len(text) == len(set(text)), "a row has two limit lines"


def test_rows_within_their_limits_pass(tmp_path, fake_group, capsys):
    fake_group.update({"fast": 0.4, "exact": 1.0})
    assert guard.run(_args(tmp_path, "fast 0.5 why\nexact 1.0 why\n")) == 0
    out = json.loads((tmp_path / "out.json").read_text())
    assert out["over"] == [] and {r["row"]: r["limit"] for r in out["rows"]} == {"fast": 0.5, "exact": 1.0}


def test_a_row_over_its_limit_fails_naming_it(tmp_path, fake_group, capsys):
    fake_group.update({"fast": 0.4, "slow": 2.01})
    assert guard.run(_args(tmp_path, "fast 0.5 why\nslow 2.0 why\n")) == 1
    err = capsys.readouterr().err
    assert "over the limit: slow" in err and "fast" not in err


def test_a_row_without_a_limit_fails(tmp_path, fake_group, capsys):
    fake_group.update({"new_row": 0.1})
    assert guard.run(_args(tmp_path, "other 1.0 why\n")) == 1
    assert "without a limit" in capsys.readouterr().err and "new_row" in json.loads(
        (tmp_path / "out.json").read_text())["no_limit"]


def test_a_nan_row_is_over_its_limit(tmp_path, fake_group):
    fake_group.update({"broken": float("nan")})
    assert guard.run(_args(tmp_path, "broken 1.0 why\n")) == 1


@pytest.mark.parametrize("text", ["row\n", "row fast why\n"])
def test_malformed_limit_lines_name_the_file_and_line(tmp_path, text):
    path = tmp_path / "limits.txt"
    path.write_text("# comment\n" + text)
    with pytest.raises(InputError, match=r"limits.txt:2: expected `row limit why`"):
        guard.read_limits(path)


def test_bad_arguments_are_refused(tmp_path, fake_group):
    with pytest.raises(InputError, match="--repeats"):
        guard.run(_args(tmp_path, "a 1 why\n", repeats=0))
    with pytest.raises(InputError, match="--rows: unknown nope"):
        guard.run(_args(tmp_path, "a 1 why\n", rows=["nope"]))
    with pytest.raises(InputError, match="no bundled samples"):
        guard.run(_args(tmp_path, "a 1 why\n", samples=str(tmp_path / "missing")))


def test_the_stitch_step_line_is_the_one_the_commands_log(capsys):
    from cvpipe.commands import configure_output, step

    configure_output(verbose=1)
    try:
        with step("stitch 3 images"):
            pass
    finally:
        configure_output()
    lines = capsys.readouterr().err.splitlines()
    assert any(guard._STITCH_STEP.match(line) for line in lines), lines


def test_time_before_a_step_is_read_from_its_line_and_a_missing_line_fails():
    say = "import sys; print('cvpipe: stitch 2 images: 0.000 s', file=sys.stderr)"
    assert 0 < guard._before_step([sys.executable, "-c", say], guard._STITCH_STEP, 1) < 60
    with pytest.raises(InputError, match="no line of the step"):
        guard._before_step([sys.executable, "-c", "pass"], guard._STITCH_STEP, 1)
    with pytest.raises(InputError, match="exit 3"):
        guard._before_step([sys.executable, "-c", say + "; sys.exit(3)"], guard._STITCH_STEP, 1)


@pytest.mark.parametrize("source", ["/dev/zero", "folder", "large", "binary"])
def test_the_limits_file_is_a_small_regular_text_file(tmp_path, source):
    """A limits file is read with a size cap: `/dev/zero` is refused at once (it was read for 41 s, up to 6.8 GB)."""
    path = {"/dev/zero": "/dev/zero", "folder": str(tmp_path)}.get(source, str(tmp_path / "limits.txt"))
    if source == "large":
        (tmp_path / "limits.txt").write_text("row 1.0 why\n" * 200_000)  # 2.4 MB
    elif source == "binary":
        (tmp_path / "limits.txt").write_bytes(b"row 1.0 why\n\0\xff")
    expected = {"/dev/zero": "not a regular file", "folder": "is a folder", "large": "larger than the limit of",
                "binary": "NUL bytes"}[source]
    with pytest.raises(InputError, match=r"^" + re.escape(path) + ": .*" + expected):
        guard.read_limits(path)


def test_limits_and_output_are_checked_before_any_row_runs(tmp_path, capsys, monkeypatch):
    """A bad --limits or an --out that cannot be written is refused before the measuring starts."""
    from cvpipe import cli

    monkeypatch.setitem(guard.GROUPS, "a", lambda ctx: pytest.fail("a row ran before the arguments were checked"))
    (tmp_path / "samples" / "hough").mkdir(parents=True)
    limits = tmp_path / "limits.txt"
    limits.write_text("a 1.0 why\n")
    folder = tmp_path / "out"
    folder.mkdir()
    base = ["bench", "guard", "--samples", str(tmp_path / "samples"), "--rows", "a"]
    for extra, expected in ((["--limits", "/dev/zero"], "/dev/zero: "),
                            (["--limits", str(limits), "--out", str(folder)], f"{folder}: --out is a folder")):
        assert cli.main([*base, *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"cvpipe: error: {expected}"), err
    assert list(folder.iterdir()) == []
