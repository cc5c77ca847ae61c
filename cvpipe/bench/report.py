"""``cvpipe bench report``: render BENCHMARKS.md from the benchmarks' JSON result files.

``make benchmarks`` writes each benchmark's result as JSON into one folder, one ``<name>.json`` per benchmark
(``benchmarks/`` by default; :mod:`cvpipe.bench.record` runs it and stamps it with the code it measured). This
command renders one section per benchmark of :data:`REPORTED`: the command that reproduces it, the machine (cpu
count and model), the load average it ran on, the library versions, the table of ours against each peer and its
plot (:mod:`cvpipe.bench.peers`; the plot is written as ``<dir>/<name>.svg``), then the result's figures as tables.
A benchmark whose JSON is absent gets one line saying so. Any other ``*.json`` in the folder is rendered too, after
the known ones. Tables are cut, with a line saying how many rows were left out, so that the whole file stays within
``--max-lines`` (a peer table keeps at least :data:`PEER_ROWS` rows). With ``--readme FILE`` the last column of
FILE's task table (between the :data:`README_START` and :data:`README_END` comments) is rewritten with each task's
headline.

The tables come from the JSON's shape, not from per-benchmark code, so a benchmark that gains a field shows it
without a change here: scalars (and dicts of scalars, one level deep) of the top level and of ``summary`` become a
"figure | value" table; a list of records (``rows``, ``sets``) or a dict of records (``methods``) becomes a table
with one row per record and one column per scalar field. :data:`REPORTED` only picks the order, leaves out the
per-item lists that a summary already condenses, and names the columns of the wide tables.
"""

from __future__ import annotations

import argparse
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError

HELP = "render BENCHMARKS.md from the benchmarks' JSON result files (benchmarks/<name>.json)"
EXAMPLE = "cvpipe bench report --dir benchmarks --out BENCHMARKS.md"

@dataclass(frozen=True)
class Reported:
    """How one benchmark's JSON is rendered.

    Attributes
    ----------
    title : str
        What the benchmark measures, one line.
    command : str
        The command that writes ``benchmarks/<name>.json`` (shown unless the JSON records its own ``command``).
    skip : tuple of str
        Top-level (or ``summary``) keys left out: per-item lists that the rendered summary condenses.
    columns : dict
        Table key -> the columns to show, in order (dotted paths into a record); other tables show every scalar
        field.
    writes_json : bool
        False for a benchmark that prints text only (its section is then always "not measured").
    """

    title: str
    command: str
    skip: tuple[str, ...] = ()
    columns: dict[str, tuple[str, ...]] | None = None
    writes_json: bool = True


#: benchmark name (the JSON file's stem) -> how it is rendered, in the order of BENCHMARKS.md
REPORTED: dict[str, Reported] = {
    "guard": Reported(
        "the speed guard: each from-scratch part against OpenCV in one process, against the committed limits",
        "python -m cvpipe.bench.record guard",
        columns={"rows": ("row", "value", "unit", "limit", "over", "items", "what", "accuracy")}),
    "hough": Reported(
        "our Hough transform vs cv2.HoughLines on York Urban: parity, time ratio, recall of the true segments",
        "python -m cvpipe.bench.record hough",
        skip=("per_image",)),
    "homography": Reported(
        "our homography estimator vs OpenCV RANSAC / MAGSAC: Oxford + CMP pairs and a synthetic outlier sweep",
        "python -m cvpipe.bench.record homography",
        skip=("real",),
        columns={"synthetic": ("outliers", "methods.ours.median_corner_error_px",
                               "methods.opencv_ransac.median_corner_error_px",
                               "methods.opencv_magsac.median_corner_error_px", "ratio_ours_magsac_wall",
                               "ratio_ours_magsac_cpu")}),
    "defect": Reported(
        "defect inspection on DeepPCB pairs warped by random homographies: ours vs a plain difference",
        "python -m cvpipe.bench.record defect",
        skip=("records",)),
    "logo": Reported(
        "logo recognition on the FlickrLogos-27 subset: precision, recall, accuracy, time per scene",
        "python -m cvpipe.bench.record logo"),
    "logo_loo": Reported(
        "logo recognition, leave-one-photo-out over the boxed training photos",
        "python -m cvpipe.bench.record logo_loo"),
    "stereo": Reported(
        "our semi-global matching vs OpenCV BM / SGBM on Middlebury + motorcycle",
        "python -m cvpipe.bench.record stereo",
        columns={"rows": ("pair", "method", "bad_1.0", "bad_2.0", "mean_error", "density", "seconds",
                          "time_ratio_to_sgbm", "cpu_ratio_to_sgbm")}),
    "stereo_rectify": Reported(
        "uncalibrated rectification on unrectified Middlebury draws: ours vs OpenCV's, vertical error",
        "python -m cvpipe.bench.record stereo_rectify",
        columns={"rows": ("pair", "seed", "vertical_median_px_ours", "vertical_median_px_opencv",
                          "vertical_p95_px_ours", "vertical_p95_px_opencv", "bad_2.0_rectified", "seconds_ours",
                          "seconds_opencv")}),
    "panorama": Reported(
        "our stitcher vs cv2.Stitcher on the Adobe and OpenStitching sets",
        "python -m cvpipe.bench.record panorama",
        columns={"sets": ("set", "images", "ours_ok", "opencv_status", "corner_error_median",
                          "direct_error_median", "ours_seconds", "opencv_seconds", "time_ratio", "command_ratio",
                          "command_cpu_ratio")}),
    "scale": Reported(
        "defect inspection fanned out over Dask: serial vs a LocalCluster vs an external cluster",
        "python -m cvpipe.bench.record scale",
        columns={"rows": ("mode", "probes", "probes_per_s", "speedup_vs_serial", "speedup_vs_local1",
                          "empty_task_median_ms", "peak_rss_mb", "identical_results", "errors")}),
    "pipeline": Reported(
        "a no-op `dvc repro` (DVC's own cache check) in an up-to-date repository",
        "cvpipe bench pipeline --repo . --repeat 3", writes_json=False),
}

#: keys that describe the run rather than the result: shown in the machine line, not in the tables
MACHINE_KEYS = ("cpus", "cpu_count", "cpu_model", "load_average", "load_average_1min", "command", "versions", "stamp",
                "wall_seconds")
#: the least rows a table of ours against the peers keeps when tables are cut (every method of a benchmark)
PEER_ROWS = 12
#: a record's label column: the first of these fields it has
LABELS = ("row", "set", "pair", "mode", "method", "image", "name")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--dir", default="benchmarks", help="folder of <name>.json result files (default: benchmarks)")
    parser.add_argument("--out", default="BENCHMARKS.md", help="file to write, `-` for stdout (default: BENCHMARKS.md)")
    parser.add_argument("--machine", help="the cpu model, for results whose JSON does not record one "
                                          "(`auto`: this machine's, from /proc/cpuinfo)")
    parser.add_argument("--max-lines", type=int, default=300, help="line budget of the whole file (default 300)")
    parser.add_argument("--readme", help="also rewrite the headline column of this README's task table "
                                         "(between its benchmark comments)")


# ----------------------------------------------------------------------------------------------- formatting


def fmt(value: Any) -> str:
    """A table cell: 4 significant digits, yes/no, ``-`` for null, lists joined, ``|`` escaped."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (list, tuple)):
        shown = ", ".join(fmt(v) for v in value[:8])
        return "none" if not value else shown if len(value) <= 8 else f"{shown}, ... ({len(value)} in all)"
    return str(value).replace("|", "\\|").replace("\n", " ")


def _scalar(value: Any) -> bool:
    return value is None or isinstance(value, (bool, int, float, str)) or (
        isinstance(value, list) and all(isinstance(v, (bool, int, float, str)) for v in value))


def _get(record: dict, path: str) -> Any:
    for part in path.split(".") if path not in record else [path]:
        if not isinstance(record, dict) or part not in record:
            return None
        record = record[part]
    return record


def _table(header: list[str], rows: list[list[Any]], max_rows: int, source: str) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows[:max_rows]]
    if len(rows) > max_rows:
        lines += ["", f"{len(rows) - max_rows} more rows in `{source}`."]
    return lines


def _is_records(value: Any) -> bool:
    """A non-empty dict of dicts or list of dicts: one table row per item."""
    items = value.values() if isinstance(value, dict) else value if isinstance(value, list) else ()
    return bool(items) and all(isinstance(v, dict) for v in items)


def _figures(key: str, value: Any) -> list[list[Any]]:
    """``key``'s scalar figures: a dict is flattened with dotted keys, a dict of only booleans is counted."""
    if _scalar(value):
        return [[key, value]]
    if not isinstance(value, dict) or _is_records(value):
        return []
    if value and all(isinstance(v, bool) for v in value.values()):
        return [[key, f"{sum(value.values())} of {len(value)}"]]
    return [row for k, v in value.items() for row in _figures(f"{key}.{k}", v)]


def _record_table(key: str, value: dict | list, columns: tuple[str, ...] | None, max_rows: int,
                  source: str) -> list[str]:
    """One row per record of ``value``, the dict's keys (if a dict) in the first column."""
    named = isinstance(value, dict)
    records = list(value.items()) if named else [(None, v) for v in value]
    if columns is None:
        seen: dict[str, None] = {}
        for _, r in records:
            for k, v in r.items():
                if isinstance(v, dict) and not _is_records(v) and all(_scalar(x) for x in v.values()):
                    seen.update({f"{k}.{s}": None for s in v})
                elif _scalar(v):
                    seen[k] = None
        label = next((k for k in LABELS if k in seen), None)
        columns = tuple(([label] if label else []) + [k for k in seen if k != label])
    header = ([key] if named else []) + list(columns)
    rows = [([name] if named else []) + [_get(r, c) for c in columns] for name, r in records]
    return ["", f"**{key}**", ""] + _table(header, rows, max_rows, source)


def render_result(data: Any, spec: Reported | None, max_rows: int, source: str) -> list[str]:
    """The tables of one benchmark's JSON (without its heading, command and machine line).

    Scalars of the top level and of ``summary`` (dicts flattened) make the "figure | value" table; every dict or
    list of records makes its own table. At most ``max_rows`` rows per table, then a line counting the rest.
    """
    if not isinstance(data, dict):
        data = {"result": data}
    skip = set(spec.skip if spec else ()) | set(MACHINE_KEYS)
    columns = (spec.columns if spec else None) or {}
    merged = dict(data)
    summary = data.get("summary")
    if isinstance(summary, dict) and not _is_records(summary):
        del merged["summary"]
        merged.update({f"summary.{k}" if k in merged else k: v for k, v in summary.items()})
    figures: list[list[Any]] = []
    tables: list[str] = []
    for key, value in merged.items():
        if key in skip:
            continue
        if _is_records(value):
            tables += _record_table(key, value, columns.get(key), max_rows, source)
        else:
            figures += _figures(key, value)
    return (_table(["figure", "value"], figures, max_rows, source) if figures else []) + tables


def _machine(data: Any, machine: str | None) -> str:
    data = data if isinstance(data, dict) else {}
    summary = data.get("summary") if isinstance(data.get("summary"), dict) else {}
    find = (lambda *keys: next((d[k] for k in keys for d in (data, summary) if d.get(k) is not None), None))
    cpus = find("cpus", "cpu_count")
    model = find("cpu_model") or machine
    load = find("load_average_1min", "load_average")
    parts = [f"{cpus} cpus" if cpus is not None else "cpu count not recorded",
             model if model else "cpu model not recorded"]
    if load is None:
        where = "load average not recorded"
    elif isinstance(load, list) and len(load) == 2:
        where = f"1-min load average {fmt(load[0])} before, {fmt(load[1])} after"
    elif isinstance(load, list):
        where = "load average (1, 5, 15 min) " + " / ".join(fmt(v) for v in load)
    else:
        where = f"1-min load average {fmt(load)}"
    versions = find("versions")
    if isinstance(versions, dict) and versions:
        where += "; " + ", ".join(f"{k} {v}" for k, v in sorted(versions.items()))
    text = f"Machine: {', '.join(parts)}; {where}."
    wall, stamp = find("wall_seconds"), find("stamp")
    if wall is not None:
        text += f" Wall time {fmt(wall)} s."
    if isinstance(stamp, dict) and stamp.get("digest"):
        text += (f" Code: cvpipe {stamp.get('cvpipe')}, sources sha256 {str(stamp['digest'])[:12]} "
                 f"({len(stamp.get('files', {}))} files).")
    return text


def cpu_model(cpuinfo: str = "/proc/cpuinfo") -> str | None:
    """This machine's cpu model name, from /proc/cpuinfo (None when it says none)."""
    try:
        text = Path(cpuinfo).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key.strip() in ("model name", "Model", "cpu model") and value.strip():
            return value.strip()
    return None


HEADER = ["# Benchmarks", "",
          "This file is generated by `cvpipe bench report` from the JSON results in `{dir}/`: do not edit it by",
          "hand. `make benchmarks` runs every benchmark on `$CVPIPE_DATA` and regenerates it (with the plots in",
          "`{dir}/` and the README's headline column). Each section is the current result of one benchmark: the",
          "command that gives its JSON, the machine, load and library versions it ran on, the code it measured (a",
          "digest of the cvpipe sources the run imported: a test fails when the code has changed since), ours",
          "against each peer, then all its figures. Rejected variants and their figures are in `docs/notes/`.", ""]


def render(results: dict[str, Any], machine: str | None = None, max_lines: int = 300,
           folder: str = "benchmarks") -> str:
    """BENCHMARKS.md from ``results``: benchmark name -> its parsed JSON, or None when the file is absent.

    Every table is cut to the largest number of rows that keeps the text within ``max_lines`` (but never below 3
    rows, so a folder of many benchmarks can exceed it).
    """
    names = [n for n in REPORTED if n in results] + sorted(n for n in results if n not in REPORTED)
    lines = _render_all(results, names, machine, None, folder)
    if len(lines) > max_lines:
        lo, hi = 3, len(lines)  # the line count grows with the cap: the largest cap that fits
        while lo < hi:
            mid = (lo + hi + 1) // 2
            if len(_render_all(results, names, machine, mid, folder)) <= max_lines:
                lo = mid
            else:
                hi = mid - 1
        lines = _render_all(results, names, machine, lo, folder)
    return "\n".join(lines) + "\n"


def _render_all(results: dict[str, Any], names: list[str], machine: str | None, cap: int | None,
                folder: str) -> list[str]:
    lines = [h.format(dir=folder) for h in HEADER]
    absent = []
    for name in names:
        spec, data = REPORTED.get(name), results[name]
        if data is None:
            absent.append(f"- `{name}`: `{spec.command}` prints text only, no JSON to report." if not spec.writes_json
                          else f"- `{name}`: no `{folder}/{name}.json`; write it with `{spec.command}`.")
            continue
        command = data.get("command") if isinstance(data, dict) else None
        if isinstance(command, list):
            command = " ".join(command)
        command = command or (spec.command if spec else "(not recorded in the JSON)")
        lines += [f"## {name}", ""]
        if spec:
            lines += [spec.title[0].upper() + spec.title[1:] + ".", ""]
        lines += [f"    {command}", "", _machine(data, machine), ""]
        lines += _peer_lines(name, data, folder, 10 ** 9 if cap is None else max(cap, PEER_ROWS))
        lines += render_result(data, spec, 10 ** 9 if cap is None else cap, f"{folder}/{name}.json") + [""]
    if absent:
        lines += ["## Not measured", ""] + absent + [""]
    while lines and lines[-1] == "":
        lines.pop()
    return lines


def _peer_lines(name: str, data: Any, folder: str, max_rows: int) -> list[str]:
    """The table of ours against each peer and the link to the plot, for a benchmark of :data:`peers.SECTIONS`."""
    from . import peers

    if name not in peers.SECTIONS or not isinstance(data, dict):
        return []
    table, plot = peers.SECTIONS[name]
    header, rows = table(data)
    lines = ["**ours against each peer**", ""] + _table(header, rows, max_rows, f"{folder}/{name}.json") + [""]
    if plot is not None and plot(data) is not None:
        lines += [f"![{name}]({folder}/{name}.svg)", ""]
    return lines


def render_plots(results: dict[str, Any]) -> dict[str, str]:
    """Benchmark name -> the SVG text of its plot, for each result that has one."""
    from . import peers

    out = {}
    for name, data in results.items():
        plot = peers.SECTIONS.get(name, (None, None))[1]
        svg = plot(data) if plot is not None and isinstance(data, dict) else None
        if svg is not None:
            out[name] = svg
    return out


#: the comments around the README's task table; the generator rewrites the table's last column between them
README_START = ("<!-- task table: the last column is generated by `cvpipe bench report --readme` from "
                "benchmarks/*.json -->")
README_END = "<!-- end of the task table -->"
#: the header of the generated column
README_COLUMN = "measured: ours vs the best peer ([BENCHMARKS.md](BENCHMARKS.md))"


def _cells(row: str) -> list[str]:
    import re

    return [c.strip() for c in re.split(r"(?<!\\)\|", row.strip())[1:-1]]


def rewrite_readme(text: str, results: dict[str, Any]) -> str:
    """``text`` with the headline column of its task table (between the markers) regenerated from ``results``.

    The table's other columns are kept as they are; a table without the column gets it appended. A row whose
    first cell is not a task of :data:`peers.HEADLINES` is kept unchanged.

    Raises
    ------
    InputError
        The markers are missing or hold no table.
    """
    from . import peers

    lines = text.split("\n")
    try:
        start = lines.index(README_START)
        end = lines.index(README_END, start)
    except ValueError:
        raise InputError(f"--readme: no task table between `{README_START}` and `{README_END}`") from None
    rows = [i for i in range(start + 1, end) if lines[i].lstrip().startswith("|")]
    if len(rows) < 2:
        raise InputError("--readme: the task table between the markers has no rows")
    header = _cells(lines[rows[0]])
    has_column = header[-1] == README_COLUMN
    width = len(header) if has_column else len(header) + 1
    for k, i in enumerate(rows):
        cells = _cells(lines[i])
        if not has_column:
            cells.append("")
        if k == 0:
            cells[-1] = README_COLUMN
        elif k == 1:
            cells = ["---"] * width
        elif cells[0] in peers.HEADLINES:
            cells[-1] = peers.headline(cells[0], results)
        lines[i] = "| " + " | ".join(cells) + " |" if k != 1 else "|" + "---|" * width
    return "\n".join(lines)


def load_results(folder: str | os.PathLike) -> dict[str, Any]:
    """Every benchmark of :data:`REPORTED` (None when its JSON is absent) and any other ``*.json`` in ``folder``.

    Raises
    ------
    InputError
        ``folder`` is missing or holds no ``*.json`` (a page of "not measured" lines would replace the real one).
    """
    from .. import io

    root = Path(folder)
    if not root.is_dir():
        raise InputError(f"--dir {root}: no such folder")
    found = sorted(root.glob("*.json"))
    if not found:
        raise InputError(f"--dir {root}: no benchmark results (*.json) in this folder")
    results: dict[str, Any] = {name: None for name in REPORTED}
    for path in found:
        results[path.stem] = io.load_json(path)
    return results


def run(args: argparse.Namespace) -> int:
    from .. import io

    if args.max_lines < 20:
        raise InputError(f"`--max-lines` must be >= 20, got {args.max_lines}")
    machine = cpu_model() if args.machine == "auto" else args.machine
    results = load_results(args.dir)
    readme = None
    if args.readme:  # checked before anything is written
        readme = rewrite_readme(io.read_text(args.readme, "--readme"), results)
    text = render(results, machine, args.max_lines, Path(args.dir).as_posix())
    if args.out == "-":
        print(text, end="")
    else:
        with io.atomic_path(io.check_output_path(args.out, "--out", (".md",))) as tmp:
            tmp.write_text(text, encoding="utf-8")
        for name, svg in render_plots(results).items():
            with io.atomic_path(Path(args.dir) / f"{name}.svg") as tmp:
                tmp.write_text(svg, encoding="utf-8")
    if readme is not None:
        with io.atomic_path(args.readme) as tmp:
            tmp.write_text(readme, encoding="utf-8")
    return 0
