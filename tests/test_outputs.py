"""Outputs never collide and are written all or none: every command refuses, before any work, two outputs that name
one file and an output that names an input (exit 2, one line), and a command that writes several files leaves the
older files untouched when a later step fails."""

from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

from cvpipe import cli, io
from cvpipe.errors import InputError

from sweep_inputs import texture


@pytest.fixture
def pair(tmp_path):
    """A rectified 64x96 pair (the right view 4 px to the left: disparity 4) and a Middlebury calib.txt for it."""
    left = texture(64, 96, seed=5)
    io.save_image(tmp_path / "L.png", left)
    io.save_image(tmp_path / "R.png", np.roll(left, -4, axis=1))
    (tmp_path / "calib.txt").write_text("cam0=[100 0 48; 0 100 32; 0 0 1]\ncam1=[100 0 48; 0 100 32; 0 0 1]\n"
                                        "doffs=0\nbaseline=50\nwidth=96\nheight=64\nndisp=16\n")
    return tmp_path


def _run(capsys, argv):
    code = cli.main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def _refused(capsys, argv, match):
    """``argv`` is exit 2 with one error line matching ``match`` and the JSON error record; returns that line."""
    code, out, err = _run(capsys, [*argv, "--json"])
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("cvpipe: error: "), err
    assert re.search(match, lines[0]), lines[0]
    doc = json.loads(out)
    assert doc["exit"] == 2 and doc["file"]
    return lines[0]


def _tree(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


STEREO = ["stereo", "{d}/L.png", "{d}/R.png", "--max-disp", "16", "--method", "opencv-bm"]


@pytest.mark.parametrize("extra, match", [
    (["-o", "{d}/d.npy", "--depth", "{d}/d.npy", "--calib", "{d}/calib.txt"],
     r"`-o` and `--depth` name the same file .*d\.npy"),
    (["-o", "{d}/d.npy", "--depth", "{d}/z.png", "--overlay", "{d}/z.png", "--calib", "{d}/calib.txt"],
     r"`--depth` and `--overlay` name the same file .*z\.png"),
    (["-o", "{d}/L.png"], r"`-o` .*L\.png is the input LEFT"),
    (["-o", "{d}/d.png", "--overlay", "{d}/R.png"], r"`--overlay` .*R\.png is the input RIGHT"),
    (["-o", "{d}/d.npy", "--ply", "{d}/rig.ply", "--calib", "{d}/rig.ply"], r"`--ply` .*rig\.ply is the input `--calib`"),
    (["-o", "{d}/sub/../d.npy", "--depth", "{d}/d.npy", "--calib", "{d}/calib.txt"], r"name the same file"),
])
def test_stereo_outputs_that_collide_are_refused_before_any_work(pair, capsys, extra, match):
    before = _tree(pair)
    (pair / "sub").mkdir()
    _refused(capsys, [a.format(d=pair) for a in STEREO + extra], match)
    assert _tree(pair) == before  # nothing written, no input replaced


def test_a_symbolic_link_to_another_output_is_the_same_file(pair, capsys):
    (pair / "link.npy").symlink_to(pair / "d.npy")
    _refused(capsys, [a.format(d=pair) for a in STEREO] + ["-o", str(pair / "d.npy"), "--depth",
                                                           str(pair / "link.npy"), "--calib", str(pair / "calib.txt")],
             r"name the same file")


def test_stitch_output_that_is_an_input_is_refused(pair, capsys):
    before = _tree(pair)
    _refused(capsys, ["stitch", str(pair / "L.png"), str(pair / "R.png"), "-o", str(pair / "L.png")],
             r"`-o` .*L\.png is the input IMAGE 1")
    _refused(capsys, ["stitch", str(pair / "L.png"), str(pair / "R.png"), "-o", str(pair / "p.png"), "--overlay",
                      str(pair / "p.png")], r"`-o` and `--overlay` name the same file")
    assert _tree(pair) == before


def test_homography_overlay_that_is_an_input_is_refused(pair, capsys):
    before = _tree(pair)
    _refused(capsys, ["homography", str(pair / "L.png"), str(pair / "R.png"), "--overlay", str(pair / "R.png")],
             r"`--overlay` .*R\.png is the input B")
    assert _tree(pair) == before


def test_batch_commands_refuse_a_picture_that_is_an_input(pair, capsys):
    before = _tree(pair)
    _refused(capsys, ["hough", str(pair / "L.png"), "--overlay", str(pair / "L.png")],
             r"`--overlay` .*L\.png is the input IMAGE 1")
    _refused(capsys, ["inspect", str(pair / "L.png"), str(pair / "R.png"), "--overlay", str(pair / "L.png")],
             r"`--overlay` .*L\.png is the input REFERENCE")
    _refused(capsys, ["logo", str(pair / "R.png"), "--gallery", str(pair), "--overlay", str(pair / "R.png")],
             r"`--overlay` .*R\.png is the input SCENE 1")
    assert _tree(pair) == before


def test_stereo_writes_all_its_files_or_none(pair, capsys, monkeypatch):
    """A failure after the disparity was computed (here: the depth step) leaves the older -o and --depth files
    untouched and no temporary behind; the same run without the failure replaces both."""
    from cvpipe.stereo import depth

    (pair / "d.npy").write_bytes(b"old disparity")
    (pair / "z.npy").write_bytes(b"old depth")
    argv = [a.format(d=pair) for a in STEREO] + ["-o", str(pair / "d.npy"), "--depth", str(pair / "z.npy"),
                                                 "--calib", str(pair / "calib.txt")]

    def refuse(*args, **kwargs):
        raise InputError("depth refused")

    with monkeypatch.context() as m:
        m.setattr(depth, "depth_from_disparity", refuse)
        code, _, err = _run(capsys, argv)
    assert code == 2 and "depth refused" in err
    assert (pair / "d.npy").read_bytes() == b"old disparity" and (pair / "z.npy").read_bytes() == b"old depth"
    assert not [p for p in os.listdir(pair) if io.TMP_MARKER in p]
    code, _, err = _run(capsys, argv)
    assert code == 0, err
    assert np.load(pair / "d.npy").shape == (64, 96) and np.load(pair / "z.npy").shape == (64, 96)


def test_all_or_none_renames_every_file_only_on_success(tmp_path):
    (tmp_path / "a.txt").write_text("old a")
    with pytest.raises(RuntimeError, match="late failure"):
        with io.all_or_none() as outs:
            outs.path(tmp_path / "a.txt").write_text("new a")
            io.save_json(outs.path(tmp_path / "b.json"), {"new": True})
            raise RuntimeError("late failure")
    assert sorted(os.listdir(tmp_path)) == ["a.txt"] and (tmp_path / "a.txt").read_text() == "old a"
    with io.all_or_none() as outs:
        outs.path(tmp_path / "a.txt").write_text("new a")
        io.save_json(outs.path(tmp_path / "b.json"), {"new": True})
        assert sorted(os.listdir(tmp_path))[-1] == "a.txt"  # nothing renamed before the block ends
    assert sorted(os.listdir(tmp_path)) == ["a.txt", "b.json"] and (tmp_path / "a.txt").read_text() == "new a"
    assert io.load_json(tmp_path / "b.json") == {"new": True}


def test_check_distinct_outputs_names_both_culprits(tmp_path):
    with pytest.raises(InputError, match=r"^`-o` and `--depth` name the same file .*x\.npy; give each output its own"):
        io.check_distinct_outputs([("`-o`", tmp_path / "x.npy"), ("`--depth`", tmp_path / "." / "x.npy")])
    with pytest.raises(InputError, match=r"^`-o` .*in\.png is the input LEFT; writing it would replace the input"):
        io.check_distinct_outputs([("`-o`", tmp_path / "in.png")], [("LEFT", tmp_path / "in.png")])
    io.check_distinct_outputs([("`-o`", tmp_path / "a.npy"), ("`--depth`", None), ("`--ply`", tmp_path / "b.ply")],
                              [("LEFT", tmp_path / "in.png"), ("`--calib`", None)])
