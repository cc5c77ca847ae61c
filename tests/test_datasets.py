"""cvpipe.datasets: each finder's optional truth.json is read into its items, and a malformed record is refused with
one line naming the file and the record's field (``probes[1].verdict``)."""

import json

import numpy as np
import pytest

from cvpipe import datasets
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
])
def test_malformed_truth_names_file_and_field(tmp_path, finder, files, truth, message):
    d = _layout(tmp_path, files, truth)
    with pytest.raises(InputError, match=message):
        getattr(datasets, finder)(d)
