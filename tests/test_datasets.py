"""cvpipe.datasets: each finder's optional truth.json is read into its items, and a malformed record is refused with
one line naming the file and the record's field (``probes[1].verdict``)."""

import json
import os
import re

import numpy as np
import pytest

from cvpipe import datasets, io
from cvpipe.errors import InputError

PNG = bytes.fromhex("89504e470d0a1a0a")  # the finders list files by suffix and never decode them


def _layout(root, files, truth):
    for name in files:
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(PNG)
    (root / "truth.json").write_text(json.dumps(truth))
    return root


def test_truth_is_attached_by_file_name(tmp_path):
    d = _layout(tmp_path / "defect", ["reference.png", "probes/p1.png", "probes/p2.png"],
                {"probes": [{"file": "probes/p1.png", "verdict": "faulty", "boxes": [[1, 2, 3, 4]]}]})
    inputs, _ = datasets.find_defect(d)
    p1, p2 = inputs.probes
    assert (p1.verdict, p1.boxes.tolist(), p1.H) == ("faulty", [[1.0, 2.0, 3.0, 4.0]], None)
    assert p2.verdict is None  # not listed: no truth

    d = _layout(tmp_path / "logo", ["gallery/acme.png", "scenes/s1.png", "scenes/s2.png"],
                {"scenes": [{"file": "s1.png", "brand": "acme", "quad": [[0, 0], [9, 0], [9, 9], [0, 9]]}]})
    inputs, _ = datasets.find_logo(d)
    s1, s2 = inputs.scenes
    assert s1.brand == "acme" and s1.labelled and s1.quad.shape == (4, 2) and not s2.labelled

    d = _layout(tmp_path / "hough", ["a.png", "b.png"], {"images": [{"file": "a.png", "lines": [[5.0, 0.5]]}]})
    items, _ = datasets.find_hough(d)
    assert items[0].truth_lines.tolist() == [[5.0, 0.5]] and items[1].truth_lines is None

    d = _layout(tmp_path / "homography", ["x_a.png", "x_b.png", "y_a.png", "y_b.png"],
                {"pairs": [{"name": "x", "H": np.eye(3).tolist()}]})
    pairs, _ = datasets.find_homography(d)
    assert np.array_equal(pairs[0].H, np.eye(3)) and pairs[1].H is None


@pytest.mark.parametrize("finder, files, truth, message", [
    ("find_defect", ["reference.png", "probes/p1.png"], {"probes": [{"file": "p1.png", "verdict": "ok"}]},
     r"truth\.json: field `probes\[0\]\.verdict` must be 'faulty' or 'perfect', got 'ok'$"),
    ("find_defect", ["reference.png", "probes/p1.png"], {"probes": [{"verdict": "faulty"}]},
     r"truth\.json: field `probes\[0\]\.file` is missing$"),
    ("find_logo", ["gallery/acme.png", "scenes/s1.png"], {"scenes": [{"file": "s1.png", "brand": "zed"}]},
     r"truth\.json: field `scenes\[0\]\.brand` is 'zed', which is not a gallery brand$"),
    ("find_hough", ["a.png"], {"images": [{"lines": []}]}, r"truth\.json: field `images\[0\]\.file` is missing$"),
    ("find_homography", ["x_a.png", "x_b.png"], {"pairs": [{"name": "x", "H": [[1, 0], [0, 1]]}]},
     r"truth\.json: field `pairs\[0\]\.H` must be finite numbers of shape \(3, 3\), got shape \(2, 2\)$"),
    ("find_panorama", ["s/a.png", "s/b.png"], {"sets": [{"name": "s", "images": ["a.png"], "H": []}]},
     r"truth\.json: fields `sets\[0\]\.images` and `sets\[0\]\.H` must be lists of equal length$"),
    ("find_hough", ["a.png"], {"images": {"file": "a.png"}}, r"truth\.json: field `images` must be a list of records$"),
    ("find_hough", ["a.png"], {"images": [3]}, r"truth\.json: field `images\[0\]` must be an object$"),
    # wrong types: each refused naming the field, never a TypeError from inside the finder
    ("find_logo", ["gallery/acme.png", "scenes/s1.png"], {"scenes": [{"file": "s1.png", "brand": ["acme"]}]},
     r"truth\.json: field `scenes\[0\]\.brand` must be a non-empty string or null, got \['acme'\]$"),
    ("find_logo", ["gallery/acme.png", "scenes/s1.png"], {"scenes": [{"file": "s1.png", "brand": {"n": "acme"}}]},
     r"truth\.json: field `scenes\[0\]\.brand` must be a non-empty string or null, got \{'n': 'acme'\}$"),
    ("find_logo", ["gallery/acme.png", "scenes/s1.png"],
     {"scenes": [{"file": "s1.png", "brand": "acme", "quad": [[0, 0], [9, 0], [9, "9"], [0, 9]]}]},
     r"truth\.json: field `scenes\[0\]\.quad` must be finite numbers of shape \(4, 2\), got '9' at \[2\]\[1\]$"),
    ("find_logo", ["gallery/acme.png", "scenes/s1.png"], {"scenes": [{"file": ["s1.png"], "brand": None}]},
     r"truth\.json: field `scenes\[0\]\.file` must be a non-empty string, got \['s1\.png'\]$"),
    ("find_hough", ["a.png"], {"images": [{"file": "a.png", "lines": [{"a": 1}, 1]}]},
     r"truth\.json: field `images\[0\]\.lines` must be finite numbers of shape \(N, 2\), got \{'a': 1\} at \[0\]$"),
    ("find_hough", ["a.png"], {"images": [{"file": "a.png", "lines": [[5.0, True]]}]},
     r"truth\.json: field `images\[0\]\.lines` must be finite numbers of shape \(N, 2\), got True at \[0\]\[1\]$"),
    ("find_hough", ["a.png"], {"images": [{"file": "a.png", "lines": [[5.0, 0.5], [1.0]]}]},
     r"truth\.json: field `images\[0\]\.lines` must be finite numbers of shape \(N, 2\), got lists of unequal "
     r"length$"),
    ("find_hough", ["a.png"], {"images": [{"file": "a.png", "lines": [[5.0, 0.5], [1.0, float("nan")]]}]},
     r"truth\.json: field `images\[0\]\.lines` must be finite numbers of shape \(N, 2\), got NaN or infinity at "
     r"\[1\]\[1\]$"),
    ("find_hough", ["a.png"], {"images": [{"file": "a.png", "lines": [[float("inf"), 0.5]]}]},
     r"truth\.json: field `images\[0\]\.lines` must be finite numbers of shape \(N, 2\), got NaN or infinity at "
     r"\[0\]\[0\]$"),
    ("find_hough", ["a.png"], {"images": [{"file": "a.png", "lines": [[10 ** 400, 0.5]]}]},
     r"truth\.json: field `images\[0\]\.lines` must be finite numbers of shape \(N, 2\), got a number too large "
     r"for a float$"),
    ("find_defect", ["reference.png", "probes/p1.png"],
     {"probes": [{"file": "p1.png", "verdict": "faulty", "boxes": [[1, 2, 3]]}]},
     r"truth\.json: field `probes\[0\]\.boxes` must be finite numbers of shape \(N, 4\), got shape \(1, 3\)$"),
    ("find_defect", ["reference.png", "probes/p1.png"],
     {"probes": [{"file": "p1.png", "verdict": "faulty", "boxes": [1, 2, 3]}]},
     r"truth\.json: field `probes\[0\]\.boxes` must be finite numbers of shape \(N, 4\), got shape \(3,\)$"),
    ("find_defect", ["reference.png", "probes/p1.png"],
     {"probes": [{"file": "p1.png", "verdict": "faulty", "boxes": [[1, 2, float("-inf"), 4]]}]},
     r"truth\.json: field `probes\[0\]\.boxes` must be finite numbers of shape \(N, 4\), got NaN or infinity at "
     r"\[0\]\[2\]$"),
    ("find_defect", ["reference.png", "probes/p1.png"], {"probes": [{"file": "p1.png", "verdict": ["faulty"]}]},
     r"truth\.json: field `probes\[0\]\.verdict` must be 'faulty' or 'perfect', got \['faulty'\]$"),
    ("find_homography", ["x_a.png", "x_b.png"], {"pairs": [{"name": {"x": 1}, "H": np.eye(3).tolist()}]},
     r"truth\.json: field `pairs\[0\]\.name` must be a non-empty string, got \{'x': 1\}$"),
    ("find_homography", ["x_a.png", "x_b.png"], {"pairs": [{"name": "x", "H": [[1, 0, 0], [0, 1, 0], [0, 0, None]]}]},
     r"truth\.json: field `pairs\[0\]\.H` must be finite numbers of shape \(3, 3\), got None at \[2\]\[2\]$"),
    ("find_panorama", ["s/a.png", "s/b.png"], {"sets": [{"name": "s", "images": [1], "H": [np.eye(3).tolist()]}]},
     r"truth\.json: field `sets\[0\]\.images\[0\]` must be a non-empty string, got 1$"),
    ("find_panorama", ["s/a.png", "s/b.png"], {"sets": [{"name": "s", "images": ["a.png"], "H": [[[1, 0, 0]]]}]},
     r"truth\.json: field `sets\[0\]\.H\[0\]` must be finite numbers of shape \(3, 3\), got shape \(1, 3\)$"),
    ("find_hough", ["a.png"], [{"file": "a.png"}], r"truth\.json: expected a JSON object, got \[\{'file': 'a\.png'\}\]$"),
    ("find_stereo", ["left.png", "right.png"], ["max_disp", 64], r"truth\.json: expected a JSON object, got "
     r"\['max_disp', 64\]$"),
])
def test_malformed_truth_names_file_and_field(tmp_path, finder, files, truth, message):
    d = _layout(tmp_path, files, truth)
    with pytest.raises(InputError, match=message):
        getattr(datasets, finder)(d)


def test_a_truth_file_is_read_with_a_size_limit(tmp_path, monkeypatch):
    d = _layout(tmp_path, ["a.png"], {"images": [{"file": "a.png", "lines": [[5.0, 0.5]] * 20}]})
    monkeypatch.setattr(datasets, "TRUTH_MAX_BYTES", 100)
    with pytest.raises(InputError, match=r"truth\.json: the truth JSON file is larger than the limit of 100 bytes$"):
        datasets.find_hough(d)


@pytest.mark.parametrize("text, message", [
    ('{"images": [{"file": "a.png", "lines": [[1e999, 0.5]]}]}',  # JSON's way to write an overflow: inf
     r"truth\.json: field `images\[0\]\.lines` must be finite numbers of shape \(N, 2\), got NaN or infinity"),
    ('{"images": [{"file": "a.png", "lines": [[NaN, 0.5]]}]}',
     r"truth\.json: field `images\[0\]\.lines` must be finite numbers of shape \(N, 2\), got NaN or infinity"),
    ('{"images": ' + "[" * 100_000 + "]" * 100_000 + "}",
     r"truth\.json: not a usable truth JSON file \(lists or objects nested too deeply\)$"),
])
def test_truth_text_that_parses_to_no_usable_number_is_refused(tmp_path, text, message):
    (tmp_path / "a.png").write_bytes(PNG)
    (tmp_path / "truth.json").write_text(text)
    with pytest.raises(InputError, match=message):
        datasets.find_hough(tmp_path)


def test_empty_lists_and_nulls_are_no_truth_lines_or_boxes(tmp_path):
    d = _layout(tmp_path / "hough", ["a.png", "b.png"],
                {"images": [{"file": "a.png", "lines": []}, {"file": "b.png", "lines": None}]})
    items, _ = datasets.find_hough(d)
    assert [it.truth_lines.shape for it in items] == [(0, 2), (0, 2)]
    d = _layout(tmp_path / "defect", ["reference.png", "probes/p1.png", "probes/p2.png"],
                {"probes": [{"file": "p1.png", "verdict": "perfect", "boxes": [], "H": None},
                            {"file": "p2.png", "verdict": "perfect"}]})
    inputs, _ = datasets.find_defect(d)
    assert [(p.boxes.shape, p.H) for p in inputs.probes] == [((0, 4), None), ((0, 4), None)]


def _stereo_truth(tmp_path, how):
    path = tmp_path / "truth.npz"
    if how == "cut off":
        io.save_npz(path, disparity=np.ones((30, 40), np.float32))
        path.write_bytes(path.read_bytes()[:-40])
    elif how == "wrong keys":
        io.save_npz(path, disp=np.ones((30, 40), np.float32))
    elif how == "strings":
        io.save_npz(path, disparity=np.full((30, 40), "x"))
    elif how == "wrong shape":
        io.save_npz(path, disparity=np.ones((40, 30), np.float32))
    return path


@pytest.mark.parametrize("how, message", [
    ("cut off", r"truth\.npz: not a readable \.npz archive \(.*\); expected an \.npz holding `disparity`$"),
    ("wrong keys", r"truth\.npz: missing array\(s\) `disparity`; expected an \.npz holding `disparity`$"),
    ("strings", r"truth\.npz: array `disparity` must hold numbers \(pixels, NaN = unknown\), got dtype <U1$"),
    ("wrong shape", r"truth\.npz: array `disparity` has shape \(40, 30\), the left image is \(30, 40\)$"),
])
def test_a_damaged_stereo_truth_npz_names_the_file_and_the_array(tmp_path, how, message):
    with pytest.raises(InputError, match=message):
        datasets.read_stereo_truth(_stereo_truth(tmp_path, how), (30, 40))


# --------------------------------------------------------------------------------------- names that are not UTF-8


def _make_non_utf8(folder) -> None:
    """Create ``folder/caf\\xe9.png`` (Latin-1 bytes), skipping the test where the file system refuses the name."""
    os.makedirs(folder, exist_ok=True)
    try:
        os.close(os.open(os.path.join(os.fsencode(folder), b"caf\xe9.png"), os.O_WRONLY | os.O_CREAT, 0o644))
    except (OSError, ValueError):
        pytest.skip("this file system refuses names that are not UTF-8")


@pytest.mark.parametrize("finder, where", [
    ("hough", ""), ("homography", "pair"), ("defect", "probes"), ("logo", "scenes"), ("logo", "gallery/brand"),
    ("stereo", "pair"), ("panorama", "set"),
])
def test_a_name_that_is_not_utf8_is_refused_naming_the_folder_and_the_name(tmp_path, finder, where):
    folder = tmp_path / where
    _make_non_utf8(folder)
    # DVC cannot hash a data folder holding such a name; refused before anything runs, with the name's bytes shown
    message = rf"^{re.escape(str(folder))}: the name {re.escape(repr(b'caf' + bytes([0xE9]) + b'.png'))} is not UTF-8"
    with pytest.raises(InputError, match=message + r"; rename it \(names in a data folder must be UTF-8\)$"):
        getattr(datasets, f"find_{finder}")(tmp_path)


def test_the_features_stage_refuses_a_name_that_is_not_utf8(tmp_path):
    from stages.features import images_under

    _make_non_utf8(tmp_path / "gallery")
    with pytest.raises(InputError, match=rf"^{re.escape(str(tmp_path / 'gallery'))}: the name b'caf\\xe9\.png' is "
                                         "not UTF-8"):
        images_under(tmp_path)
