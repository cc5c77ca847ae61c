"""The committed benchmark results are current and everything published from them agrees with them.

Every ``benchmarks/*.json`` carries a stamp of the cvpipe sources its run imported (``python -m
cvpipe.bench.record``); a result whose code has changed since fails here and is rerun with ``make benchmarks`` (or
``python -m cvpipe.bench.record NAME`` and ``cvpipe bench report``). BENCHMARKS.md, the plots and the README's headline
column must be exactly what ``cvpipe bench report`` makes from those files.
"""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from cvpipe.bench import peers, plots, record, report
from cvpipe.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
RESULTS = sorted((ROOT / "benchmarks").glob("*.json"))
REGENERATE = "rerun it: `python -m cvpipe.bench.record {name}` then `make` the report (see BENCHMARKS.md)"


@pytest.mark.parametrize("path", RESULTS, ids=[p.stem for p in RESULTS])
def test_committed_result_is_stamped_with_the_code_it_measures_now(path):
    data = json.loads(path.read_text())
    assert isinstance(data.get("stamp"), dict), f"{path.name} has no stamp: {REGENERATE.format(name=path.stem)}"
    changed = record.stale_files(data["stamp"], ROOT)
    assert changed == [], f"{path.name} is older than its code ({', '.join(changed)}): " + REGENERATE.format(
        name=path.stem)
    # the stamp covers the benchmark's own module and, through its imports, the task it measures
    assert f"cvpipe/bench/{record.RECORDED[path.stem].bench}.py" in data["stamp"]["files"]


def test_readme_headline_column_is_what_the_generator_makes_from_the_committed_results():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert report.rewrite_readme(text, report.load_results(ROOT / "benchmarks")) == text


def test_benchmarks_md_and_plots_are_what_the_generator_makes_from_the_committed_results():
    results = report.load_results(ROOT / "benchmarks")
    assert (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8") == report.render(results, report.cpu_model())
    for name, svg in report.render_plots(results).items():
        path = ROOT / "benchmarks" / f"{name}.svg"
        assert path.read_text(encoding="utf-8") == svg, f"{path.name} differs from its JSON's plot"
        assert len(svg) < 20_000  # small enough to commit and to show inline


# ---------------------------------------------------------------------------------------- the stamp itself


def test_stamp_names_a_changed_and_a_missing_file(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "b.pyx").write_text("cdef int y = 2\n")
    stamp = record.make_stamp(["a.py", "b.pyx"], tmp_path)
    assert record.stale_files(stamp, tmp_path) == []
    (tmp_path / "a.py").write_text("x = 2\n")
    (tmp_path / "b.pyx").unlink()
    assert record.stale_files(stamp, tmp_path) == ["a.py", "b.pyx (missing)"]
    assert record.stale_files({**stamp, "cvpipe": "0.0.0"}, tmp_path)[0].startswith("cvpipe version 0.0.0 -> ")


def test_python_code_is_stamped_without_its_docstrings_comments_and_layout(tmp_path):
    src = tmp_path / "m.py"
    src.write_text('"""Module."""\n\nX = 1  # one\n\n\ndef f(a):\n    """Doc."""\n    return a + X\n')
    digest = record.file_digest(src)
    src.write_text('"""Another text."""\n# a comment\nX = 1\ndef f(a):\n    return a + X\n')
    assert record.file_digest(src) == digest
    src.write_text('X = 1\ndef f(a):\n    return a - X\n')
    assert record.file_digest(src) != digest  # a change of code
    kernel = tmp_path / "k.pyx"
    kernel.write_text("cdef int x = 1\n")
    digest = record.file_digest(kernel)
    kernel.write_text("cdef int x = 1  # a comment\n")
    assert record.file_digest(kernel) != digest  # other sources by their bytes


def test_measured_files_are_the_imported_sources_with_compiled_modules_by_their_cython_source():
    import cvpipe.bench.hough  # noqa: F401
    import cvpipe.hough  # noqa: F401  - imports the compiled vote kernel

    files = record.measured_files()
    assert "cvpipe/hough/transform.py" in files and "cvpipe/bench/hough.py" in files
    assert "cvpipe/hough/_vote.pyx" in files  # the kernel's source, not the built library
    assert not any(f.endswith((".so", ".pyd")) for f in files)
    assert not {"cvpipe/bench/record.py", "cvpipe/bench/report.py"} & set(files)  # plumbing, not measured
    assert all((ROOT / f).is_file() for f in files)


def test_measured_files_leave_out_modules_outside_the_tree(tmp_path):
    other = type(sys)("cvpipe.elsewhere")
    other.__file__ = str(tmp_path / "elsewhere.py")
    assert record.measured_files({"cvpipe.elsewhere": other, "numpy": sys.modules.get("json")}) == []


# ------------------------------------------------------------------------------------ the README's column

TABLE = [report.README_START,
         "| task | question | methods compared |",
         "|---|---|---|",
         "| hough | which lines? | ours vs `cv2.HoughLines` |",
         "| extra | a row that is no task | kept |",
         report.README_END]


def _hough(images=102, identical=102):
    return {"summary": {"images": images, "images_identical": identical, "time_ratio_median": 0.25,
                        "recall": {"ours": 0.5, "opencv": 0.5}}}


def test_readme_column_is_added_then_rewritten_and_other_columns_are_kept():
    text = "intro\n" + "\n".join(TABLE) + "\nafter\n"
    once = report.rewrite_readme(text, {"hough": _hough()})
    rows = once.splitlines()
    assert rows[2].endswith(f"| {report.README_COLUMN} |") and rows[3] == "|---|---|---|---|"
    assert rows[4].startswith("| hough | which lines? | ours vs `cv2.HoughLines` | York Urban, 102 photos: ")
    assert "102/102" in rows[4] and "0.25x" in rows[4]
    assert rows[5] == "| extra | a row that is no task | kept |  |" and rows[0] == "intro" and rows[-1] == "after"
    assert report.rewrite_readme(once, {"hough": _hough()}) == once  # idempotent
    changed = report.rewrite_readme(once, {"hough": _hough(identical=101)})
    assert "101/102" in changed.splitlines()[4] and changed.splitlines()[:4] == rows[:4]
    absent = report.rewrite_readme(once, {"hough": None})
    assert absent.splitlines()[4].endswith(f"| {peers.NOT_MEASURED} |")


def test_readme_without_the_markers_is_refused():
    with pytest.raises(InputError, match="no task table between"):
        report.rewrite_readme("| task | question |\n|---|---|\n", {})
    with pytest.raises(InputError, match="has no rows"):
        report.rewrite_readme(f"{report.README_START}\n{report.README_END}\n", {})


def test_every_readme_task_has_a_headline_that_escapes_pipes():
    assert set(peers.HEADLINES) == {"logo", "hough", "defect", "homography", "stereo", "panorama"}
    data = {"methods": {"sift": {"accuracy": 0.8, "best_recall_at_precision_0.95": 0.5}},
            "protocol": {"test_scenes": 70}}
    text = peers.headline("logo", {"logo": data})
    assert "sift accuracy 0.8" in text and "70 test photos" in text
    assert "|" not in peers.headline("hough", {"hough": {"summary": {"images": "a|b", "time_ratio_median": 1.0}}}
                                     ).replace("\\|", "")


# --------------------------------------------------------------------------------- tables and plots

STEREO_ROWS = [("tsukuba", "sgm", 0.05, 0.2), ("tsukuba", "opencv_sgbm", 0.08, 0.4), ("venus", "sgm", 0.02, 0.3),
               ("venus", "opencv_sgbm", 0.01, 0.2)]
STEREO = {"rows": [{"pair": p, "method": m, "bad_2.0": b, "bad_1.0": b + 0.1, "mean_error": 1.0, "density": 1.0,
                    "seconds": s} for p, m, b, s in STEREO_ROWS]}


def test_stereo_table_and_headline_average_over_pairs_and_compare_total_time():
    header, rows = peers.stereo_table(STEREO)
    by = {r[0]: dict(zip(header, r)) for r in rows}
    assert by["ours (SGM, 8 paths)"]["mean bad-2.0"] == "3.5 %"  # (5 + 2) / 2
    assert by["cv2 SGBM, best mode per pair"]["mean bad-2.0"] == "4.5 %"
    assert by["ours (SGM, 8 paths)"]["time / SGBM"] == "0.83x"  # 0.5 s / 0.6 s
    text = peers.headline("stereo", {"stereo": STEREO})
    assert "lower or equal on 1/2" in text and "in 0.83x its time" in text


def test_plots_are_small_well_formed_svg_and_deterministic():
    svg = peers.stereo_plot(STEREO)
    root = ET.fromstring(svg)
    assert root.tag.endswith("svg") and len(svg) < 20_000
    assert svg == peers.stereo_plot(json.loads(json.dumps(STEREO)))
    # background, 2 pairs x 2 methods bars, 2 legend keys (BM is absent from these rows)
    assert sum(1 for e in root.iter() if e.tag.endswith("rect")) == 1 + 4 + 2
    line = plots.xy_chart({"a": [(0.1, 1.0), (1.0, 0.5), (float("nan"), 2.0)]}, "t", "x", "y", log_x=True)
    pts = [e for e in ET.fromstring(line).iter() if e.tag.endswith("circle")]
    assert len(pts) == 2  # the NaN point is left out


def test_panorama_shows_opencv_accuracy_only_where_the_result_measures_it():
    sets = [{"set": "goldengate", "images": 6, "ours_ok": True, "opencv_status": "OK", "opencv_seconds": 4.0,
             "presets": {"default": {"seconds": 2.0, "time_ratio": 0.5, "pair_error_median": 1.5},
                         "fast": {"seconds": 1.0, "time_ratio": 0.25, "pair_error_median": 3.0}}},
            {"set": "budapest", "images": 6, "ours_ok": True, "opencv_status": "ERR_NEED_MORE_IMGS",
             "opencv_seconds": 1.0, "presets": {"default": {"seconds": 3.0, "time_ratio": 3.0},
                                                "fast": {"seconds": 2.0, "time_ratio": 2.0}}}]
    data = {"sets": sets, "presets": ["default", "fast"]}
    header, rows = peers.panorama_table(data)
    col = header.index("cv2.Stitcher error (px)")
    assert [r[col] for r in rows] == ["-", "-"]
    assert rows[0][header.index("ours (fast) error (px)")] == "3" and rows[1][header.index("ours (default) s")] == "3"
    text = peers.headline("panorama", {"panorama": data})
    assert "ours stitched 2, `cv2.Stitcher` 1" in text and "1.5 px over 1 sets" in text and "OpenCV" not in text
    assert "in 1.00x its time" in text  # (2 + 3) s against (4 + 1) s, the default preset
    sets[0]["opencv_pair_error_median"] = 2.5
    assert "(OpenCV 2.5 px)" in peers.headline("panorama", {"panorama": data})
    svg = peers.panorama_plot(data)
    assert sum(1 for e in ET.fromstring(svg).iter() if e.tag.endswith("circle")) == 3  # 2 presets + OpenCV, 1 set


def test_logo_pr_curve_follows_the_threshold_from_high_to_low():
    curve = [{"threshold": t, "precision": p, "recall": r} for t, p, r in [(1.0, 1.0, 0.1), (3.0, 1.0, 0.0),
                                                                          (0.5, 0.8, 0.6)]]
    svg = peers.logo_plot({"methods": {"sift": {"curve": curve, "accuracy": 0.7}}})
    path = next(e for e in ET.fromstring(svg).iter() if e.tag.endswith("path") and e.get("stroke") == plots.COLOURS[0])
    xs = [float(p.split()[0]) for p in path.get("d")[1:].split("L")]
    assert xs == sorted(xs)  # recall 0.0, 0.1, 0.6
