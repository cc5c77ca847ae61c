"""cvpipe.hough: known lines are recovered, results equal cv2.HoughLines exactly, bad input is refused by name."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from cvpipe import cli, hough
from cvpipe.errors import InputError
from cvpipe.params import HoughEdgesParams, HoughLinesParams, HoughReportParams, from_mapping


def draw_line(shape, rho, theta, step=0.25):
    """Edge map (uint8) with the 1-px digital line x cos(theta) + y sin(theta) = rho sampled densely."""
    img = np.zeros(shape, np.uint8)
    c, s = math.cos(theta), math.sin(theta)
    reach = shape[0] + shape[1]
    for t in np.arange(-reach, reach, step):
        x, y = int(round(rho * c - t * s)), int(round(rho * s + t * c))
        if 0 <= x < shape[1] and 0 <= y < shape[0]:
            img[y, x] = 255
    return img


def opencv_lines(edges, rho, theta, threshold, **kw):
    out = cv2.HoughLinesWithAccumulator(edges, rho, theta, threshold, **kw)
    return np.zeros((0, 3)) if out is None else out.reshape(-1, 3).astype(np.float64)


# ------------------------------------------------------------------------------------------------ known lines

KNOWN = [
    (60.0, 0.0),                   # vertical line x = 60
    (45.0, math.pi / 2),           # horizontal line y = 45
    (-40.0, math.radians(135)),    # negative rho: x cos 135 + y sin 135 = -40
    (150.0, math.radians(30)),
    (20.0, math.radians(100)),     # 100 degrees, crosses x = 0 at y ~ 20
]


@pytest.mark.parametrize("rho, theta", KNOWN)
def test_single_known_line_is_the_strongest(rho, theta):
    edges = draw_line((200, 260), rho, theta)
    lines = hough.hough_lines(edges, 1.0, math.pi / 180, 40)
    assert len(lines) >= 1
    best = lines[0]
    # the true line lies on whole-degree, whole-pixel cell centres, so the strongest cell is that cell exactly
    assert best[0] == pytest.approx(rho, abs=1e-4)
    assert best[1] == pytest.approx(theta, abs=1e-6)
    pixels = np.count_nonzero(edges)
    if theta in (0.0, math.pi / 2):
        assert best[2] == pixels  # an axis-aligned line: every pixel is exactly on it and votes for its cell
    else:
        # pixels of an oblique digital line sit up to ~0.7 px off the true line; most of them still round into it
        assert best[2] >= 0.7 * pixels


def test_several_lines_at_once_are_all_found():
    edges = np.zeros((240, 320), np.uint8)
    for rho, theta in KNOWN:
        edges |= draw_line(edges.shape, rho, theta)
    lines = hough.hough_lines(edges, 1.0, math.pi / 180, 60)
    found = hough.truth_matches(lines[:len(KNOWN) + 2], np.array(KNOWN), rho_tol=1.0, theta_tol=math.radians(1.0))
    # the strongest few cells hold every drawn line (1 px / 1 degree: one cell of the accumulator)
    assert found.all(), lines[:8]


def test_refinement_is_sub_bin_on_off_grid_lines():
    rng = np.random.default_rng(7)
    cell_err, fine_err = [], []
    for _ in range(8):
        theta, rho = rng.uniform(0.2, 2.9), rng.uniform(20, 120)
        edges = draw_line((200, 260), rho, theta)
        for refine, errs in ((False, cell_err), (True, fine_err)):
            r, t, _ = hough.hough_lines(edges, 1.0, math.pi / 180, 40, refine=refine)[0]
            errs.append((abs(r - rho), abs(math.degrees(t - theta))))
    cell_err, fine_err = np.array(cell_err), np.array(fine_err)
    # a cell is 1 px x 1 degree. A digital line of length L only pins its angle down to about 1 px / L (a line
    # 0.2 degrees off a diagonal or an axis steps once over 200 px), so the bound is a quarter degree and half a
    # pixel at the origin; on average the fit must be several times better than the cell centre
    assert fine_err[:, 0].max() < 0.5 and fine_err[:, 1].max() < 0.25, fine_err
    assert np.all(fine_err.mean(axis=0) < cell_err.mean(axis=0) / 3), (fine_err.mean(0), cell_err.mean(0))


def test_refined_theta_stays_in_range_near_vertical():
    # a line slightly past vertical on the other side (theta just under pi) must come back as theta in [0, pi)
    edges = draw_line((200, 260), -100.0, math.pi - 0.004)
    lines = hough.hough_lines(edges, 1.0, math.pi / 180, 40, refine=True)
    assert np.all((lines[:, 1] >= 0) & (lines[:, 1] < math.pi))
    # the cell found is (100, 0): the fit must come back to the true side of the wrap, within the 1 px / L limit
    assert hough.truth_matches(lines[:1], [[-100.0, math.pi - 0.004]], 0.5, math.radians(0.25)).all()


def test_no_edges_gives_no_lines():
    empty = np.zeros((50, 70), np.uint8)
    lines = hough.hough_lines(empty, 1.0, math.pi / 180, 1)
    assert lines.shape == (0, 3)
    assert hough.hough_lines(empty, 1.0, math.pi / 180, 1, refine=True).shape == (0, 3)
    assert hough.hough_lines_opencv(empty, 1.0, math.pi / 180, 1).shape == (0, 3)
    assert hough.hough_lines_probabilistic(empty, threshold=1, rng=0).shape == (0, 4)


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (3, 5), (8, 8), (7, 9), (241, 317)])
@pytest.mark.parametrize("density", [0.0, 0.03, 0.5, 1.0])
def test_edge_points_are_the_nonzero_pixels_in_row_major_order(shape, density):
    # the scan reads eight pixels at a time: sizes that are and are not multiples of 8 (a tail of 0-7 pixels),
    # empty, sparse, dense and full maps, any nonzero value
    from cvpipe.hough import _vote

    rng = np.random.default_rng(shape[0] * 1000 + shape[1])
    edges = ((rng.random(shape) < density) * rng.integers(1, 256, shape)).astype(np.uint8)
    xs, ys = _vote.edge_points(edges)
    rows, cols = np.nonzero(edges)
    assert xs.dtype == ys.dtype == np.float32
    np.testing.assert_array_equal(xs, cols)
    np.testing.assert_array_equal(ys, rows)


# ------------------------------------------------------------------------------------------------ OpenCV parity


def random_edges(rng, shape, density, lines=4):
    """Random speckle plus a few drawn lines, so there are both strong peaks and many near-ties."""
    edges = ((rng.random(shape) < density) * 255).astype(np.uint8)
    for _ in range(lines):
        p, q = rng.integers(0, shape[1], 2), rng.integers(0, shape[0], 2)
        cv2.line(edges, (int(p[0]), int(q[0])), (int(p[1]), int(q[1])), 255, 1)
    return edges


PARITY_CASES = [
    # (shape, density, rho, theta, threshold, extra cv2 arguments)
    ((120, 160), 0.02, 1.0, math.pi / 180, 8, {}),
    ((97, 131), 0.05, 1.0, math.pi / 180, 12, {}),         # odd sizes
    ((100, 100), 0.03, 0.5, math.pi / 360, 6, {}),         # fine bins; numrho even
    ((90, 150), 0.03, 2.0, math.pi / 90, 15, {}),
    ((80, 120), 0.04, 1.5, math.radians(0.7), 8, {}),      # steps that do not divide pi
    ((64, 64), 0.1, 3.0, math.radians(5), 20, {}),
    ((120, 160), 0.02, 1.0, math.pi / 180, 5, {"min_theta": 0.3, "max_theta": 2.0}),
    ((120, 160), 0.02, 1.0, math.pi / 180, 5, {"min_theta": 0.0, "max_theta": math.pi / 2}),
]


@pytest.mark.parametrize("shape, density, rho, theta, threshold, extra", PARITY_CASES)
@pytest.mark.parametrize("parallel", [False, True])
def test_exact_parity_with_cv2_houghlines(shape, density, rho, theta, threshold, extra, parallel):
    rng = np.random.default_rng(hash((shape, rho, threshold)) % 2**32)
    for _ in range(3):
        edges = random_edges(rng, shape, density)
        ours = hough.hough_lines(edges, rho, theta, threshold, parallel=parallel, **extra)
        ref = opencv_lines(edges, rho, theta, threshold, **extra)
        assert len(ref) > 0, "the case should produce lines"
        # same cells, same votes, same order (ties broken like OpenCV's comparator), bit-identical float32 values
        np.testing.assert_array_equal(ours, ref)


def test_parity_on_canny_edges_of_a_photo(textured_image):
    edges = cv2.Canny(textured_image, 50, 150)
    for threshold in (60, 120):
        np.testing.assert_array_equal(hough.hough_lines(edges, 1.0, math.pi / 180, threshold),
                                      opencv_lines(edges, 1.0, math.pi / 180, threshold))


def test_bool_edges_equal_uint8_edges():
    rng = np.random.default_rng(3)
    edges = random_edges(rng, (60, 80), 0.05)
    np.testing.assert_array_equal(hough.hough_lines(edges > 0, 1.0, math.pi / 180, 6),
                                  hough.hough_lines(edges, 1.0, math.pi / 180, 6))


def test_max_lines_keeps_the_strongest():
    rng = np.random.default_rng(4)
    edges = random_edges(rng, (80, 100), 0.05)
    full = hough.hough_lines(edges, 1.0, math.pi / 180, 6)
    assert len(full) > 5
    np.testing.assert_array_equal(hough.hough_lines(edges, 1.0, math.pi / 180, 6, max_lines=5), full[:5])


def test_york_urban_parity(data_root):
    files = sorted((data_root / "yorkurban_lines" / "images").glob("*.jpg"))[:3]
    if not files:
        pytest.skip("York Urban images not found")
    for f in files:
        edges = cv2.Canny(cv2.imread(str(f), cv2.IMREAD_GRAYSCALE), 50, 150)
        np.testing.assert_array_equal(hough.hough_lines(edges, 1.0, math.pi / 180, 150),
                                      opencv_lines(edges, 1.0, math.pi / 180, 150))


# ------------------------------------------------------------------------------------------------ probabilistic


def test_probabilistic_recovers_drawn_segments():
    edges = np.zeros((200, 300), np.uint8)
    truth = np.array([[20, 30, 260, 30], [50, 10, 50, 180], [100, 60, 250, 190]])
    for x1, y1, x2, y2 in truth:
        cv2.line(edges, (int(x1), int(y1)), (int(x2), int(y2)), 255, 1)
    segs = hough.hough_lines_probabilistic(edges, 30, 40, 3, params=HoughLinesParams(rho=1.0, theta_deg=1.0), rng=0)
    # each drawn segment is covered (>= 90 %) by a detected one on its line; end points of a digital line are
    # exact up to a pixel, so 1.5 px and 1 degree
    found = hough.segment_segment_matches(segs, truth, dist_px=1.5, angle_deg=1.0, min_overlap=0.9)
    assert found.all(), segs
    # nothing else: an edge map with only these lines gives at most one segment per line
    assert len(segs) == len(truth), segs


def test_probabilistic_is_reproducible_and_respects_min_length():
    rng = np.random.default_rng(5)
    edges = random_edges(rng, (120, 160), 0.01, lines=6)
    a = hough.hough_lines_probabilistic(edges, threshold=20, min_line_length=25, max_line_gap=2, rng=11)
    b = hough.hough_lines_probabilistic(edges, threshold=20, min_line_length=25, max_line_gap=2, rng=11)
    np.testing.assert_array_equal(a, b)
    assert len(a) > 0
    extent = np.maximum(np.abs(a[:, 2] - a[:, 0]), np.abs(a[:, 3] - a[:, 1]))
    assert extent.min() >= 25
    capped = hough.hough_lines_probabilistic(edges, threshold=20, min_line_length=25, max_line_gap=2, rng=11,
                                             max_lines=2)
    np.testing.assert_array_equal(capped, a[:2])  # the same visiting order, stopped after two segments


@pytest.mark.parametrize("shape, rho", [((10, 10), 100.0), ((1, 10), 16.0), ((3, 40), 60.0)])
def test_probabilistic_with_a_rho_coarser_than_the_image(shape, rho):
    # numrho = round((2 (h + w) + 1) / rho) is 0 or 1 here, and corner pixels fall in bins beside that range: the
    # accumulator grows to hold them, and the segments stay inside the image
    edges = np.full(shape, 255, np.uint8)
    segs = hough.hough_lines_probabilistic(edges, threshold=1, min_line_length=0, max_line_gap=0,
                                           params=HoughLinesParams(rho=rho, theta_deg=1.0), rng=0)
    assert segs.dtype == np.int32 and segs.shape[1] == 4 and len(segs) >= 1
    assert ((segs[:, 0::2] >= 0) & (segs[:, 0::2] < shape[1]) & (segs[:, 1::2] >= 0) & (segs[:, 1::2] < shape[0])).all()


# ------------------------------------------------------------------------------------------------ metrics


def test_line_segment_matches_tolerances():
    seg = np.array([[10.0, 50.0, 110.0, 50.0]])          # horizontal segment y = 50
    on = [[50.0, math.pi / 2, 1]]
    assert hough.line_segment_matches(on, seg).all()
    assert hough.line_segment_matches([[51.9, math.pi / 2]], seg).all()
    assert not hough.line_segment_matches([[52.1, math.pi / 2]], seg).any()   # 2.1 px off
    # tilted by 0.9 degrees about the segment's midpoint: angle ok, ends move 0.79 px
    t = math.pi / 2 + math.radians(0.9)
    rho = 60 * math.cos(t) + 50 * math.sin(t)
    assert hough.line_segment_matches([[rho, t]], seg).all()
    t = math.pi / 2 + math.radians(1.1)
    rho = 60 * math.cos(t) + 50 * math.sin(t)
    assert not hough.line_segment_matches([[rho, t]], seg).any()
    assert hough.line_segment_matches(np.zeros((0, 3)), seg).shape == (1,)


def test_segment_segment_matches_needs_overlap():
    gt = np.array([[0.0, 0.0, 100.0, 0.0]])
    assert hough.segment_segment_matches([[10, 1, 80, 1]], gt).all()
    assert not hough.segment_segment_matches([[10, 1, 40, 1]], gt).any()      # covers 30 % < 50 %
    assert not hough.segment_segment_matches([[200, 0, 300, 0]], gt).any()    # same line, elsewhere


def test_truth_matches_handles_the_theta_wrap():
    truth = [[-50.0, math.pi - 0.005]]
    # the same line expressed with theta near 0 and rho of the other sign
    assert hough.truth_matches([[50.0, 0.005 - 0.01 + 0.005]], truth, 1.0, math.radians(1)).all()
    assert not hough.truth_matches([[50.0, 0.5]], truth, 1.0, math.radians(1)).any()


def test_cell_agreement_counts():
    ref = np.array([[10.0, 0.0, 50], [20.0, math.radians(3), 40], [-5.0, math.radians(90), 30]])
    ours = np.array([[10.0, 0.0, 50], [-5.0, math.radians(90), 29]])
    a = hough.cell_agreement(ours, ref)
    assert (a["reproduced"], a["ref_lines"], a["our_lines"], a["same_votes"]) == (2, 3, 2, 1)
    assert a["parity"] == pytest.approx(2 / 3) and not a["same_order"]
    assert hough.cell_agreement(np.zeros((0, 3)), np.zeros((0, 3)))["parity"] == 1.0


def test_compare_runs_summary():
    lines = [[10.0, 0.0, 50.0]]
    ours = {"rho": 1.0, "theta": math.pi / 180, "images": [{"file": "a.png", "lines": lines}]}
    ref = {"rho": 1.0, "theta": math.pi / 180, "images": [{"file": "a.png", "lines": lines}]}
    truth = {"a": [[10.0, 0.0], [80.0, 1.0]]}
    m = hough.compare_runs(ours, ref, truth)
    assert m["parity_min"] == 1.0 and m["identical_images"] == 1 and m["truth_images"] == 1
    assert m["recall_ours"] == m["recall_opencv"] == 0.5
    with pytest.raises(InputError, match="not in the opencv run"):
        hough.compare_runs(ours, {**ref, "images": []})


def test_compare_runs_counts_the_lines_of_both_over_all_images():
    # a threshold experiment moves these (the headline metrics of `dvc exp show`), even where parity stays 1.0
    two = [[10.0, 0.0, 50.0], [40.0, 0.5, 45.0]]
    ours = {"rho": 1.0, "theta": math.pi / 180,
            "images": [{"file": "a.png", "lines": two}, {"file": "b.png", "lines": two[:1]}]}
    ref = {"rho": 1.0, "theta": math.pi / 180,
           "images": [{"file": "a.png", "lines": two[:1]}, {"file": "b.png", "lines": two[:1]}]}
    m = hough.compare_runs(ours, ref)
    assert (m["lines_ours"], m["lines_opencv"]) == (3, 2)


def test_compare_runs_takes_the_report_section_in_degrees():
    # a line 2 degrees off the truth: found within theta_tol_deg = 2.5, missed at 1.5 (so the degrees are converted,
    # not read as radians, which would accept it at either); rho is exact, so rho_tol does not decide
    lines = [[10.0, math.radians(2.0), 50.0]]
    run = {"rho": 1.0, "theta": math.pi / 180, "images": [{"file": "a.png", "lines": lines}]}
    truth = {"a": [[10.0, 0.0]]}
    loose = hough.compare_runs(run, run, truth, HoughReportParams(theta_tol_deg=2.5))
    strict = hough.compare_runs(run, run, truth, HoughReportParams(theta_tol_deg=1.5))
    assert loose["recall_ours"] == 1.0 and strict["recall_ours"] == 0.0


@pytest.mark.parametrize("method", ["ours", "opencv"])
def test_detect_lines_takes_the_lines_section_in_degrees(method):
    rng = np.random.default_rng(3)
    edges = random_edges(rng, (90, 120), 0.01, lines=5)
    p = HoughLinesParams(rho=0.5, theta_deg=0.5, threshold=30)
    # the section's half-degree step is pi / 360 radians for both implementations: OpenCV's own lines, exactly
    np.testing.assert_array_equal(hough.detect_lines(edges, p, method), opencv_lines(edges, 0.5, math.pi / 360, 30))
    assert hough.hough_steps(p) == (0.5, math.radians(0.5))


def test_detect_lines_refines_ours_only():
    rng = np.random.default_rng(4)
    edges = random_edges(rng, (90, 120), 0.01, lines=5)
    p = HoughLinesParams(threshold=30, refine=True)
    np.testing.assert_array_equal(hough.detect_lines(edges, p, "ours"),
                                  hough.hough_lines(edges, 1.0, math.pi / 180, 30, refine=True))
    # OpenCV has no refinement: the flag is ignored there, as in the hough_lines@opencv stage
    np.testing.assert_array_equal(hough.detect_lines(edges, p, "opencv"), opencv_lines(edges, 1.0, math.pi / 180, 30))
    with pytest.raises(InputError, match=r"`params` must be a HoughLinesParams"):
        hough.detect_lines(edges, {"threshold": 30})


def test_report_summary_is_valid_for_the_report_page():
    from cvpipe.report import validate_summary

    lines = [[10.0, 0.0, 50.0], [20.0, 1.0, 40.0]]
    ours = {"rho": 1.0, "theta": math.pi / 180, "threshold": 30, "images": [{"file": "a.png", "lines": lines}]}
    ref = dict(ours)
    metrics = hough.compare_runs(ours, ref, {"a": [[10.0, 0.0]]})
    summary = hough.report_summary(metrics, ours, ref, [{"path": "outputs/hough/overlays/a.png", "caption": "a"}],
                                   [{"item": "b.jpg", "reason": "not a readable image"}])
    validate_summary(summary, "hough summary")
    assert summary["tables"][0]["rows"][0][:4] == ["ours", 2, 1.0, 1.0]
    assert summary["tables"][-1]["rows"] == [["b.jpg", "not a readable image"]]  # nothing dropped silently
    assert hough.quality_plot(metrics) == [{"image": "a", "method": "ours", "lines": 2, "true_found": 1},
                                           {"image": "a", "method": "opencv", "lines": 2, "true_found": 1}]
    flat = hough.metrics_of(metrics)["hough"]
    assert flat["all"]["recall_ours"] == 1.0 and flat["a"]["identical"] == 1


def test_report_summary_without_truth_says_so():
    lines = [[10.0, 0.0, 50.0]]
    run = {"rho": 1.0, "theta": math.pi / 180, "threshold": 30, "images": [{"file": "a.png", "lines": lines}]}
    metrics = hough.compare_runs(run, run, None)
    assert "recall_ours" not in metrics and metrics["truth_images"] == 0
    summary = hough.report_summary(metrics, run, run, [], [])
    assert "no ground truth" in summary["description"]
    assert summary["tables"][0]["rows"][0][3] == "no ground truth"


def test_draw_lines_marks_the_line():
    img = np.zeros((40, 60), np.uint8)
    out = hough.draw_lines(img, [[20.0, 0.0, 9]], (0, 0, 255))
    assert out.shape == (40, 60, 3) and out[:, 20, 2].min() > 0 and out[:, 40].max() == 0
    seg = hough.draw_segments(img, [[5, 5, 30, 5]])
    assert seg[5, 10, 1] > 0 and seg[20].max() == 0


# ------------------------------------------------------------------------------------------------ validation


@pytest.mark.parametrize("edges, message", [
    (np.zeros((4, 5, 3), np.uint8), r"`edges` must be a 2-D \(H, W\) image"),
    (np.zeros((0, 5), np.uint8), r"`edges` must not be empty"),
    (np.zeros((4, 5), np.float32), r"`edges` must be uint8 or bool"),
    ([[0, 1], [1, 0]], r"`edges` must be a numpy array"),
])
def test_bad_edges(edges, message):
    with pytest.raises(InputError, match=message):
        hough.hough_lines(edges)
    with pytest.raises(InputError, match=message):
        hough.hough_lines_probabilistic(edges)


@pytest.mark.parametrize("kwargs, message", [
    ({"rho": 0.0}, r"`rho` must be > 0, got 0.0"),
    ({"rho": -1.0}, r"`rho` must be > 0"),
    ({"rho": float("nan")}, r"`rho` must be > 0"),
    ({"rho": "1"}, r"`rho` must be a number"),
    ({"theta": 0.0}, r"`theta` must be > 0"),
    ({"theta": 4.0}, r"`theta` must be in \(0, pi\]"),
    ({"threshold": 0}, r"`threshold` must be an integer >= 1, got 0"),
    ({"threshold": -3}, r"`threshold` must be an integer >= 1"),
    ({"threshold": 2.5}, r"`threshold` must be an integer"),
    ({"min_theta": 1.0, "max_theta": 0.5}, r"need 0 <= `min_theta` <= `max_theta` <= pi"),
    ({"max_theta": 4.0}, r"need 0 <= `min_theta` <= `max_theta` <= pi"),
    ({"min_theta": float("inf")}, r"`min_theta` must be a finite number"),
    ({"max_lines": 0}, r"`max_lines` must be an integer >= 1"),
])
def test_bad_parameters(kwargs, message):
    edges = np.zeros((10, 10), np.uint8)
    with pytest.raises(InputError, match=message):
        hough.hough_lines(edges, **kwargs)


@pytest.mark.parametrize("kwargs, message", [
    ({"min_line_length": -1}, r"`min_line_length` must be a number >= 0"),
    ({"max_line_gap": float("nan")}, r"`max_line_gap` must be a number >= 0"),
    ({"threshold": 0}, r"`threshold` must be an integer >= 1"),
    ({"max_lines": 0}, r"`max_lines` must be an integer >= 1"),
    ({"params": {"rho": 0.5}}, r"`params` must be a HoughLinesParams \(the hough.lines section\), got dict"),
])
def test_bad_probabilistic_parameters(kwargs, message):
    with pytest.raises(InputError, match=message):
        hough.hough_lines_probabilistic(np.zeros((10, 10), np.uint8), **kwargs)


def test_bad_opencv_wrapper_and_registry():
    with pytest.raises(InputError, match=r"`threshold` must be an integer >= 1"):
        hough.hough_lines_opencv(np.zeros((10, 10), np.uint8), threshold=0)
    with pytest.raises(InputError, match=r"`impl` must be one of \['opencv', 'ours'\], got 'fast'"):
        hough.get_impl("fast")
    with pytest.raises(InputError, match=r"`lines` must have shape \(N, 2\) or \(N, 3\)"):
        hough.cell_agreement(np.zeros((3, 1)), np.zeros((0, 3)))


@pytest.mark.parametrize("kwargs, message", [
    ({"low": 100, "high": 50}, r"need 0 <= `low` <= `high`"),
    ({"aperture": 4}, r"`aperture` must be one of \[3, 5, 7\]"),
    ({"blur_sigma": -1}, r"`blur_sigma` must be >= 0"),
])
def test_bad_canny_parameters(kwargs, message):
    with pytest.raises(InputError, match=message):
        hough.canny_edges(np.zeros((10, 10), np.uint8), **kwargs)


def test_canny_edges_input_and_blur():
    with pytest.raises(InputError, match=r"`gray` must be a non-empty 2-D uint8 image"):
        hough.canny_edges(np.zeros((10, 10, 3), np.uint8))
    img = np.zeros((40, 40), np.uint8)
    img[:, 20:] = 200
    edges = hough.canny_edges(img, blur_sigma=1.0)
    # a vertical step edge gives edge pixels only in the columns next to the step
    assert set(np.nonzero(edges)[1]) <= {19, 20, 21} and edges.any()


@pytest.mark.parametrize("cls, mapping, message", [
    (HoughEdgesParams, {"canny_low": 200.0}, r"`hough\.x\.canny_high` must be in \[200.0"),
    (HoughEdgesParams, {"aperture": 4}, r"`hough\.x\.aperture` must be one of \[3, 5, 7\]"),
    (HoughEdgesParams, {"blur_sigma": -1.0}, r"`hough\.x\.blur_sigma` must be in \[0.0"),
    (HoughLinesParams, {"rho": 0.0}, r"`hough\.x\.rho` must be in \(0.0"),
    (HoughLinesParams, {"theta_deg": 0.0}, r"`hough\.x\.theta_deg` must be in \(0.0"),
    (HoughLinesParams, {"threshold": 0}, r"`hough\.x\.threshold` must be in \[1"),
    (HoughLinesParams, {"repeats": 0}, r"`hough\.x\.repeats` must be in \[1, 100\]"),
    (HoughReportParams, {"rho_tol": 0.0}, r"`hough\.x\.rho_tol` must be in \(0.0"),
    (HoughReportParams, {"theta_tol_deg": 95.0}, r"`hough\.x\.theta_tol_deg` must be in \(0.0, 90.0\]"),
])
def test_params_validation(cls, mapping, message):
    with pytest.raises(InputError, match=message):
        from_mapping(cls, mapping, "hough.x")


# ------------------------------------------------------------------------------------------------ CLI


@pytest.fixture()
def line_photo(tmp_path):
    img = np.full((120, 160), 30, np.uint8)
    cv2.line(img, (40, 0), (40, 119), 220, 2)
    cv2.line(img, (0, 90), (159, 90), 220, 2)
    path = tmp_path / "lines.png"
    cv2.imwrite(str(path), img)
    return path, img


@pytest.mark.parametrize("impl", ["ours", "opencv"])
def test_cli_json_matches_the_library(line_photo, capsys, impl):
    path, img = line_photo
    assert cli.main(["hough", str(path), "--method", impl, "--threshold", "60", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    edges = cv2.Canny(img, 50, 150)
    np.testing.assert_array_equal(np.array(out["lines"]).reshape(-1, 3),
                                  opencv_lines(edges, 1.0, math.pi / 180, 60))
    # both painted lines are there: x = 40 (theta 0) and y = 90 (theta pi/2); a 2-px line has edges on both sides
    assert hough.truth_matches(out["lines"], [[40.0, 0.0], [90.0, math.pi / 2]], 2.0, math.radians(1)).all()


def test_cli_text_output_and_refine(line_photo, capsys):
    path, img = line_photo
    argv = ["hough", str(path), "--threshold", "60", "--refine", "--theta-deg", "0.5", "--rho", "0.5",
            "--max-lines", "0"]
    edges = cv2.Canny(img, 50, 150)  # the command's default edges (Canny 50 150), as in the test above
    refined = hough.hough_lines(edges, 0.5, math.radians(0.5), 60, refine=True)
    # refinement moves these lines off their bin centres: a command that ignored --refine would print others
    assert not np.array_equal(refined, hough.hough_lines(edges, 0.5, math.radians(0.5), 60))
    assert cli.main([*argv, "--json"]) == 0
    np.testing.assert_array_equal(np.array(json.loads(capsys.readouterr().out)["lines"]), refined)
    assert cli.main(argv) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"{len(refined)} lines (ours); rho [px], theta [deg], votes:"
    printed = np.array([[float(v) for v in row.split()] for row in out[1:]])
    # the text shows the same lines to its printed digits: half of 0.01 px for rho, half of 0.001 degrees for theta
    # (plus the rounding to 6 decimals of the JSON's theta_deg before it is printed)
    np.testing.assert_allclose(printed[:, 0], refined[:, 0], rtol=0, atol=0.005 + 1e-9)
    np.testing.assert_allclose(printed[:, 1], np.degrees(refined[:, 1]), rtol=0, atol=0.0005 + 1e-6)
    np.testing.assert_array_equal(printed[:, 2], refined[:, 2])


@pytest.mark.parametrize("argv, message", [
    (["--threshold", "0"], "`--threshold` must be in [1, 2147483647], got 0"),
    (["--rho", "-1"], "`--rho` must be in (0.0, 100.0], got -1.0"),
    (["--theta-deg", "0"], "`--theta-deg` must be in (0.0, 180.0], got 0.0"),
    (["--method", "opencv", "--refine"], "`--refine` is only available with --method ours"),
    (["--canny", "200", "100"], "`--canny` must be LOW <= HIGH, got 200 100"),
])
def test_cli_bad_arguments_exit_2(line_photo, capsys, argv, message):
    path, _ = line_photo
    assert cli.main(["hough", str(path), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("cvpipe: error:") and message in err[0]


def test_cli_missing_file_exits_2(tmp_path, capsys):
    assert cli.main(["hough", str(tmp_path / "none.png")]) == 2
    assert "no such file" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------ benchmark


def test_bench_without_york_data_exits_2(tmp_path, capsys):
    assert cli.main(["bench", "hough", "--data", str(tmp_path)]) == 2
    assert "no York Urban images found" in capsys.readouterr().err


def test_bench_on_two_york_images(data_root, capsys):
    if not (data_root / "yorkurban_lines" / "images").is_dir():
        pytest.skip("York Urban images not found")
    assert cli.main(["bench", "hough", "--data", str(data_root), "--limit", "2", "--repeats", "1",
                     "--json"]) == 0
    s = json.loads(capsys.readouterr().out)["summary"]
    # identical parameters give identical lines (the parity target is >= 99 % on every image)
    assert s["images"] == 2 and s["parity_min"] == 1.0 and s["images_identical"] == 2
    # the same lines find the same ground-truth segments
    assert s["recall"]["ours"] == s["recall"]["opencv"]
    assert s["gt_segments"] > 0 and 0.0 < s["recall"]["ours"] <= 1.0


# ------------------------------------------------------------------------------------------------ start-up


def test_no_transform_imports_numba():
    """The transforms run on compiled kernels: neither OpenCV's baseline nor ours imports numba."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    code = ("import sys, numpy as np\nfrom cvpipe import hough\ne = np.zeros((50, 60), np.uint8); e[20] = 255\n"
            "assert len(hough.hough_lines_opencv(e, 1.0, np.pi / 180, 30)) >= 1\n"
            "assert len(hough.hough_lines(e, 1.0, np.pi / 180, 30, refine=True, parallel=True)) >= 1\n"
            "assert len(hough.hough_lines_probabilistic(e, threshold=10, rng=0)) >= 1\n"
            "print('numba' in sys.modules)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=root)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "False"


# ------------------------------------------------------------------------------------------------ docstrings


@pytest.mark.parametrize("name", ["transform", "probabilistic", "edges", "evaluate", "report"])
def test_docstring_examples_run(name):
    """Every public entry point of cvpipe.hough documents an Examples section, and the examples give what they say."""
    import doctest
    import importlib

    module = importlib.import_module(f"cvpipe.hough.{name}")
    public = [getattr(module, n) for n in module.__all__ if callable(getattr(module, n))
              and not isinstance(getattr(module, n), type)]
    missing = [f.__name__ for f in public if "Examples\n" not in (f.__doc__ or "")]
    assert not missing, f"public functions of {module.__name__} without an Examples section: {missing}"
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0 and result.attempted >= 2 * len(public)
