"""The report page: schema validation, escaping, relative links, task order, the stage and its dvc.yaml wiring."""

from __future__ import annotations

import copy
import html
import json
import re
import sys
from html.parser import HTMLParser

import pytest
import yaml

from cvpipe import io, report
from cvpipe.errors import InputError
from report_fixtures import NASTY, make_outputs, summary


class _Collect(HTMLParser):
    """Tags, attributes and text of a page, to check it without regular expressions on markup."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))

    def handle_data(self, data):
        self.text.append(data)


def parse(page: str) -> _Collect:
    p = _Collect()
    p.feed(page)
    p.close()
    return p


def good(task="hough"):
    return summary(task, [f"outputs/{task}/a.png"])


# ---- validation -------------------------------------------------------------------------------------------------

def test_a_valid_summary_passes_unchanged():
    s = good()
    assert report.validate_summary(copy.deepcopy(s), "x.json") == s


def _break(mutate):
    s = good()
    mutate(s)
    return s


BAD = [
    (lambda s: s.clear() or s.update({"a": 1}), r"missing key\(s\)"),
    (lambda s: s.update(extra=1), r"unknown key\(s\) \['extra'\]"),
    (lambda s: s.update(task="lines"), r"`task` must be one of \['logo', 'hough'"),
    (lambda s: s.update(title="  "), r"`title` must not be empty"),
    (lambda s: s.update(pictures={}), r"`pictures` must be a JSON array, got dict"),
    (lambda s: s.update(timings={}), r"unknown key\(s\) \['timings'\]"),  # timings are uncached, never here
    (lambda s: s.update(description=3), r"`description` must be a JSON string"),
    (lambda s: s["pictures"].append({"path": "x.png"}), r"`pictures\[1\]` must be an object with keys"),
    (lambda s: s["pictures"].append({"path": 3, "caption": "c"}), r"`pictures\[1\]` must have string"),
    (lambda s: s["pictures"].append({"path": "/tmp/x.png", "caption": ""}), r"`pictures\[1\]\.path` must be a path"),
    (lambda s: s["pictures"].append({"path": "outputs/../../x.png", "caption": ""}), r"relative to the repository"),
    (lambda s: s["pictures"].append({"path": "outputs\\x.png", "caption": ""}), r"relative to the repository"),
    (lambda s: s["pictures"].append({"path": "outputs/x.tiff", "caption": ""}), r"must be a PNG or JPEG file"),
    (lambda s: s["tables"].append([1]), r"`tables\[1\]` must be an object with keys"),
    (lambda s: s["tables"][0].update(title=1), r"`tables\[0\]\.title` must be a string"),
    (lambda s: s["tables"][0].update(columns=[]), r"`tables\[0\]\.columns` must be a non-empty array"),
    (lambda s: s["tables"][0].update(rows={}), r"`tables\[0\]\.rows` must be an array"),
    (lambda s: s["tables"][0]["rows"].append(["ours", 1]), r"`tables\[0\]\.rows\[2\]` has 2 cells, expected 4"),
    (lambda s: s["tables"][0]["rows"].append("ours"), r"`tables\[0\]\.rows\[2\]` has str cells, expected 4"),
    (lambda s: s["tables"][0]["rows"][1].__setitem__(2, [1]), r"`tables\[0\]\.rows\[1\]\[2\]` must be a string, n"),
]


@pytest.mark.parametrize("mutate, message", BAD)
def test_each_schema_violation_is_refused_naming_the_file(mutate, message):
    with pytest.raises(InputError, match=r"^outputs/hough/summary\.json: .*" + message):
        report.validate_summary(_break(mutate), "outputs/hough/summary.json")


def test_a_non_object_is_refused_naming_the_file():
    with pytest.raises(InputError, match=r"^s\.json: expected a JSON object \(the task summary\), got list"):
        report.validate_summary([], "s.json")


def test_two_summaries_of_one_task_are_refused():
    with pytest.raises(InputError, match="two summaries for task 'hough'"):
        report.build_html([good(), good()])


# ---- the page ---------------------------------------------------------------------------------------------------

def test_sections_follow_the_fixed_task_order_and_missing_tasks_are_listed_as_not_run():
    page = report.build_html([good("panorama"), good("logo"), good("stereo")])
    ids = [a["id"] for t, a in parse(page).tags if t == "section"]
    assert ids == ["task-logo", "task-stereo", "task-panorama"]
    toc = page[page.index("<nav"):page.index("</nav>")]
    for task in ("hough", "defect", "homography"):
        assert re.search(rf"{report.TASK_NAMES[task]} \u2014 <span class=\"notrun\">not run</span>", toc), task
    assert toc.count("not run") == 3 and "3 of 6 tasks have results" in page


def test_every_user_text_is_escaped():
    s = summary("defect", ["outputs/defect/a.png"], nasty=True)
    page = report.build_html([s])
    doc = parse(page)
    # the only elements are the page's own: no <script> or <b> smuggled in through a title, caption or cell
    assert {t for t, _ in doc.tags} <= {"html", "head", "meta", "title", "link", "style", "body", "main", "h1", "p",
                                        "nav", "h3", "ol", "li", "a", "span", "section", "h2", "div", "figure",
                                        "img", "figcaption", "table", "thead", "tr", "th", "tbody", "td", "footer",
                                        "code"}
    text = "".join(doc.text)
    assert text.count(NASTY) >= 4  # title (twice: contents and section), description, caption, table title
    alts = [a["alt"] for t, a in doc.tags if t == "img"]
    assert alts == [f"a.png {NASTY}"]  # the attribute survives quotes intact


def test_picture_links_are_relative_to_the_page_and_url_quoted():
    s = summary("hough", ["outputs/hough/lines #1.png", "data/samples/hough/grid.png"])
    doc = parse(report.build_html([s], base="outputs"))
    srcs = [a["src"] for t, a in doc.tags if t == "img"]
    assert srcs == ["hough/lines%20%231.png", "../data/samples/hough/grid.png"]
    hrefs = [a["href"] for t, a in doc.tags if t == "a" and not a["href"].startswith("#")]
    assert hrefs == srcs  # each picture links to its full-size file
    deeper = parse(report.build_html([s], base="outputs/site"))
    assert [a["src"] for t, a in deeper.tags if t == "img"][0] == "../hough/lines%20%231.png"


def test_known_sizes_become_img_attributes_and_wide_pictures_span_the_row():
    s = summary("panorama", ["outputs/panorama/ours.png", "outputs/panorama/input.jpg", "outputs/panorama/x.png"])
    sizes = {"outputs/panorama/ours.png": (1200, 400), "outputs/panorama/input.jpg": (640, 480)}
    doc = parse(report.build_html([s], sizes=sizes))
    imgs = [a for t, a in doc.tags if t == "img"]
    assert [(a.get("width"), a.get("height")) for a in imgs] == [("1200", "400"), ("640", "480"), (None, None)]
    figures = [a.get("class") for t, a in doc.tags if t == "figure"]
    assert figures == ["wide", None, None]  # 1200 / 400 = 3 >= WIDE_ASPECT; 640 / 480 is not; unknown stays


def test_page_loads_nothing_from_the_network():
    page = report.build_html([summary(t, [f"outputs/{t}/a.png"]) for t in report.TASKS])
    doc = parse(page)
    assert not [t for t, _ in doc.tags if t in ("script", "iframe", "object", "embed")]
    urls = [v for _, a in doc.tags for k, v in a.items() if k in ("src", "href")]
    assert urls and all(not re.match(r"^[a-z]+:", u) or u == "data:," for u in urls), urls
    assert "@import" not in page and "url(" not in page


def test_tables_format_numbers():
    page = report.build_html([good()])
    cells = re.findall(r"<td[^>]*>([^<]*)</td>", page)
    assert cells[:8] == ["ours", "0.1235", "0.98", "yes", "opencv", "12346", "\u2013", "no"]
    assert "Timings" not in page  # a cached page must not change with the machine's speed


@pytest.mark.parametrize("value, text", [(None, "\u2013"), (True, "yes"), (3, "3"), (0.0, "0"), (2.5e-5, "2.50e-05"),
                                         (float("inf"), "\u2013"), (123456.7, "123457"), ("x", "x")])
def test_format_cell(value, text):
    assert report.format_cell(value) == text


# three significant digits below a second, two decimals above; each unit's range starts where the previous ends
@pytest.mark.parametrize("seconds, text", [(0.0123, "12.3 ms"), (0.001, "1 ms"), (0.25, "250 ms"),
                                           (0.9994, "999 ms"), (2.5e-4, "250 \u00b5s"), (0.0, "0 \u00b5s"),
                                           (1.0, "1.00 s"), (2.5, "2.50 s"), (61.237, "61.24 s")])
def test_format_seconds(seconds, text):
    assert report.format_seconds(seconds) == text


def test_timing_rows_come_from_the_runner_timing_files_sorted_by_stage():
    files = [{"stage": "stereo_disparity@sgm", "seconds": {"total": 2.0, "pair": 1.5}},
             {"stage": "hough_lines@ours", "seconds": {"total": 0.5, "bad": float("nan")}}]
    rows = report.timing_rows(files)
    assert [(r["stage"], r["step"]) for r in rows] == [("hough_lines@ours", "total"), ("stereo_disparity@sgm", "pair"),
                                                       ("stereo_disparity@sgm", "total")]  # NaN left out
    assert rows[0] == {"stage": "hough_lines@ours", "step": "total", "label": "hough_lines@ours total",
                       "seconds": 0.5}


# ---- the stage --------------------------------------------------------------------------------------------------

def run_stage(monkeypatch, cwd, *args):
    """Run the report stage as `python -m stages.report` would, in ``cwd``; return its exit status."""
    import runpy

    monkeypatch.chdir(cwd)
    monkeypatch.setattr(sys, "argv", ["stages.report", "--outputs", "outputs", "--out", "outputs/report.html",
                                      "--timings", "outputs/plots/timings.json", *args])
    with pytest.raises(SystemExit) as exc:
        runpy.run_module("stages.report", run_name="__main__")
    return exc.value.code


def test_stage_renders_every_summary_and_the_timing_plot_data(tmp_path, monkeypatch):
    make_outputs(tmp_path, ("stereo", "hough"))
    timing = {"stage": "hough_lines@ours", "seconds": {"total": 0.25}}
    io.save_json(tmp_path / "outputs/timings/hough_lines@ours.json", timing)
    assert run_stage(monkeypatch, tmp_path) == 0
    page = (tmp_path / "outputs/report.html").read_text(encoding="utf-8")
    srcs = [a["src"] for t, a in parse(page).tags if t == "img"]
    sizes = [(a["width"], a["height"]) for t, a in parse(page).tags if t == "img"]
    assert sizes == [("320", "200"), ("160", "240")] * 2  # read from the files the fixture wrote
    assert len(srcs) == 4 and all((tmp_path / "outputs" / re.sub("%20", " ", re.sub("%23", "#", s))).is_file()
                                  for s in srcs)
    rows = io.load_json(tmp_path / "outputs/plots/timings.json")
    assert [r["label"] for r in rows if r["stage"] == "hough_lines@ours"] == ["hough_lines@ours total"]
    assert not list((tmp_path / "outputs").glob(".*tmp*"))  # the atomic writer left no temporary behind


def test_a_task_report_draws_its_pictures_within_the_picture_limit(tmp_path, monkeypatch, repo_root):
    """hough_report on an image whose two-panel overlay is over the picture limit (scaled down here, as a 9900 x
    9900 input's 196-megapixel overlay is over the real one): the overlay is drawn shrunk, its lines where the
    image's lines are, and the report stage reads it back."""
    import runpy

    import cv2
    import numpy as np

    monkeypatch.setattr(io, "PICTURE_MAX_PIXELS", 30_000)  # the 600 x 200 overlay is 120 000 pixels
    img = np.zeros((200, 300), np.uint8)
    img[100, :] = 255
    (tmp_path / "images").mkdir()
    cv2.imwrite(str(tmp_path / "images" / "big.png"), img)
    io.save_json(tmp_path / "edges" / "dropped.json", [])
    lines = {"impl": "x", "rho": 1.0, "theta": np.pi / 180, "threshold": 50, "refine": False,
             "images": [{"file": "big.png", "lines": [[100.0, np.pi / 2, 300]]}]}
    io.save_json(tmp_path / "ours.json", lines)
    io.save_json(tmp_path / "opencv.json", lines)
    (tmp_path / "params.yaml").write_text((repo_root / "params.yaml").read_text())
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", [
        "stages.hough_report", "--images", "images", "--edges", "edges", "--ours", "ours.json", "--opencv",
        "opencv.json", "--overlays", "outputs/hough/overlays", "--metrics", "metrics.json", "--summary",
        "outputs/hough/summary.json", "--plots", "plots"])
    with pytest.raises(SystemExit) as exc:
        runpy.run_module("stages.hough_report", run_name="__main__")
    assert exc.value.code == 0
    overlay = io.read_image(tmp_path / "outputs/hough/overlays/big.png")
    assert overlay.shape == (100, 300, 3)  # each panel shrunk by 0.5 to 150 x 100
    # the row y = 100 maps to (100 + 0.5) * 0.5 - 0.5 = 49.75: red (ours) on the left, green (OpenCV) on the right
    assert abs(int(overlay[:, 40, 2].argmax()) - 49.75) <= 1 and abs(int(overlay[:, 190, 1].argmax()) - 49.75) <= 1
    assert run_stage(monkeypatch, tmp_path) == 0
    page = (tmp_path / "outputs/report.html").read_text(encoding="utf-8")
    assert [(a["width"], a["height"]) for t, a in parse(page).tags if t == "img"] == [("300", "100")]


def test_stage_with_no_summaries_lists_every_task_as_not_run(tmp_path, monkeypatch):
    assert run_stage(monkeypatch, tmp_path) == 0
    page = (tmp_path / "outputs/report.html").read_text(encoding="utf-8")
    assert page.count("not run") == 6 and "<section" not in page
    # the only timing is the report stage's own, written after the rows were gathered
    assert io.load_json(tmp_path / "outputs/plots/timings.json") == []


def test_stage_names_the_file_whose_picture_is_missing(tmp_path, monkeypatch, capsys):
    make_outputs(tmp_path, ("hough",))
    (tmp_path / "outputs/hough/result.png").unlink()
    assert run_stage(monkeypatch, tmp_path) == 2
    assert re.search(r"report: error: outputs/hough/summary\.json: picture "
                                         r"'outputs/hough/result\.png' does not exist", capsys.readouterr().err)
    assert not (tmp_path / "outputs/report.html").exists()


def test_stage_names_the_summary_and_the_picture_that_is_not_an_image(tmp_path, monkeypatch, capsys):
    make_outputs(tmp_path, ("hough",))
    (tmp_path / "outputs/hough/result.png").write_bytes(b"not a png")
    assert run_stage(monkeypatch, tmp_path) == 2
    assert re.search(r"outputs/hough/summary\.json: picture outputs/hough/result\.png: not a "
                                         r"readable image", capsys.readouterr().err)


def test_stage_names_the_file_whose_task_is_in_the_wrong_folder(tmp_path, monkeypatch, capsys):
    make_outputs(tmp_path, ("hough",))
    (tmp_path / "outputs/hough").rename(tmp_path / "outputs/stereo")
    assert run_stage(monkeypatch, tmp_path) == 2
    assert re.search(r"outputs/stereo/summary\.json: `task` is 'hough' but the file is in the "
                                         r"folder of 'stereo'", capsys.readouterr().err)


def test_stage_names_the_file_that_breaks_the_schema(tmp_path, monkeypatch, capsys):
    make_outputs(tmp_path, ("hough",))
    path = tmp_path / "outputs/hough/summary.json"
    bad = json.loads(path.read_text())
    del bad["tables"]
    path.write_text(json.dumps(bad))
    assert run_stage(monkeypatch, tmp_path) == 2
    assert re.search(r"outputs/hough/summary\.json: missing key\(s\) \['tables'\]", capsys.readouterr().err)


# ---- dvc.yaml wiring --------------------------------------------------------------------------------------------

def test_report_stage_depends_on_the_summary_of_every_task_report_stage(repo_root):
    dvc = yaml.safe_load((repo_root / "dvc.yaml").read_text())
    stages = dvc["stages"]
    deps = set(stages["report"]["deps"])
    for task in report.TASKS:
        if f"{task}_report" in stages:  # a task that landed: one dep line makes the report rerun on its results
            assert f"outputs/{task}/summary.json" in deps, f"add `- outputs/{task}/summary.json` to report deps"
    assert "outputs/report.html" in stages["report"]["outs"]
    assert "outputs/plots/timings.json" not in stages["report"]["outs"]  # uncached: it changes with every run


def test_every_plot_file_is_written_by_a_stage(repo_root):
    dvc = yaml.safe_load((repo_root / "dvc.yaml").read_text())
    outs = []
    for st in dvc["stages"].values():
        # a matrix stage writes one file per item: expand ${item.<key>} for every value
        items = [{}]
        for key, values in (st.get("matrix") or {}).items():
            items = [{**it, key: v} for it in items for v in values]
        for o in st.get("outs", []) + st.get("plots", []) + st.get("metrics", []):
            name = next(iter(o)) if isinstance(o, dict) else o
            for it in items:
                expanded = name
                for key, v in it.items():
                    expanded = expanded.replace("${item.%s}" % key, str(v))
                outs.append(expanded)
    for entry in dvc["plots"]:
        path = next(iter(entry)) if isinstance(entry, dict) else entry
        cfg = entry[path] if isinstance(entry, dict) else {}
        files = [path] if not isinstance(cfg.get("y"), dict) else list(cfg["y"])
        for f in files:
            if f == "outputs/plots/timings.json":  # the report stage writes it, uncached (not a DVC output)
                continue
            assert any(f == o or f.startswith(o.rstrip("/") + "/") for o in outs), f"{f}: no stage writes it"


def test_progress_is_quiet_when_not_on_a_terminal(capsys):
    assert list(io.progress(range(5), "count")) == [0, 1, 2, 3, 4]
    assert capsys.readouterr().err == ""  # pytest captures stderr, which is then not a terminal


def test_escape_helper_round_trips():
    s = summary("logo", ["outputs/logo/a.png"], nasty=True)
    page = report.build_html([s])
    assert html.unescape(page).count(NASTY) >= 4 and NASTY not in page
