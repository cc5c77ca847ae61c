"""The report page: every task's summary (pictures, comparison tables, timings) rendered into one static HTML page.

Pure: summaries (dicts, as each ``<task>_report`` stage writes them to ``outputs/<task>/summary.json``) in, HTML text
out. The page links its pictures by relative paths, carries its CSS inline and loads nothing else (no scripts, no
fonts, no network), so it opens from a file manager or ``file://`` on a machine without network.

Summary schema (one per task)::

    {"task": "<task>", "title": "one line", "description": "two or three sentences",
     "pictures": [{"path": "outputs/<task>/....png", "caption": "..."}],        # repo-relative paths
     "tables": [{"title": "...", "columns": ["method", ...], "rows": [["ours", 0.12, ...], ...]}]}

Summaries are cached stage outputs, so they hold no timings (a rerun must reproduce them byte for byte); the stage
runner writes timings to the uncached ``outputs/timings/``, which :func:`timing_rows` turns into the ``dvc plots``
rows.
"""

from __future__ import annotations

import html
import math
import posixpath
from typing import Any, Iterable, Mapping, Sequence
from urllib.parse import quote

from .errors import InputError

#: the tasks, in the order of the page
TASKS = ("logo", "hough", "defect", "homography", "stereo", "panorama")
#: heading of a task whose summary has not been written yet
TASK_NAMES = {
    "logo": "Logo detection",
    "hough": "Hough lines",
    "defect": "Defect inspection",
    "homography": "Homography estimation",
    "stereo": "Stereo disparity",
    "panorama": "Panorama stitching",
}
#: keys of a summary, each with the type it must have
SUMMARY_KEYS = {"task": str, "title": str, "description": str, "pictures": list, "tables": list}
#: picture formats every browser shows
PICTURE_SUFFIXES = (".png", ".jpg", ".jpeg")
_CELL_TYPES = (str, int, float, bool, type(None))
#: width / height from which a picture gets a whole row of the grid
WIDE_ASPECT = 2.0

CSS = """
:root { --fg: #1d232b; --muted: #5b6570; --line: #d9dee4; --accent: #1f6feb; --bg: #ffffff; --soft: #f4f6f8; }
* { box-sizing: border-box; }
body { margin: 0; background: var(--bg); color: var(--fg);
       font: 15px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif; }
main { max-width: 1200px; margin: 0 auto; padding: 1.5rem 1rem 4rem; }
h1 { font-size: 1.7rem; margin: 0 0 .3rem; }
h2 { font-size: 1.35rem; margin: 2.5rem 0 .3rem; padding-top: .6rem; border-top: 2px solid var(--line); }
h3 { font-size: 1.05rem; margin: 1.4rem 0 .4rem; }
p.lead, p.title { color: var(--muted); margin: 0 0 .6rem; }
a { color: var(--accent); }
nav ol { padding-left: 1.4rem; margin: .4rem 0; }
nav li { margin: .15rem 0; }
.notrun { color: var(--muted); font-style: italic; }
.grid { display: grid; grid-template-columns: repeat(auto-fill, minmax(260px, 1fr)); gap: 1rem; margin: .8rem 0;
        align-items: start; }
figure.wide { grid-column: 1 / -1; }
figure { margin: 0; background: var(--soft); border: 1px solid var(--line); border-radius: 6px; padding: .5rem; }
figure img { display: block; width: 100%; height: auto; max-height: 75vh; object-fit: contain;
             border-radius: 3px; background: #fff; }
figcaption { font-size: .85rem; color: var(--muted); margin-top: .35rem; }
.tablewrap { overflow-x: auto; }
table { border-collapse: collapse; margin: .3rem 0 1rem; font-size: .9rem; }
th, td { border-bottom: 1px solid var(--line); padding: .3rem .7rem; text-align: left; vertical-align: top; }
th { background: var(--soft); font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.bar { display: inline-block; height: .7rem; background: var(--accent); border-radius: 2px; vertical-align: middle; }
td.barcell { width: 40%; min-width: 8rem; }
footer { margin-top: 3rem; color: var(--muted); font-size: .85rem; }
@media (max-width: 600px) { body { font-size: 14px; } .grid { grid-template-columns: 1fr; } }
"""


def _fail(source: str, where: str, what: str) -> InputError:
    return InputError(f"{source}: `{where}` {what}")


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def validate_summary(obj: Any, source: str = "summary") -> dict:
    """Check one task summary against the schema of the module docstring.

    Parameters
    ----------
    obj : object
        The parsed JSON.
    source : str
        Where it came from (the file name); every message starts with it.

    Returns
    -------
    dict
        ``obj`` itself, now known to follow the schema.

    Raises
    ------
    InputError
        A missing, unknown or mistyped key, an unknown task, a picture path that is absolute, leaves the repository
        or is not PNG/JPEG, a table row whose length differs from the columns, or a negative or non-finite timing.
    """
    if not isinstance(obj, dict):
        raise InputError(f"{source}: expected a JSON object (the task summary), got {type(obj).__name__}")
    missing = [k for k in SUMMARY_KEYS if k not in obj]
    if missing:
        raise InputError(f"{source}: missing key(s) {missing}; a summary has {list(SUMMARY_KEYS)}")
    unknown = sorted(set(obj) - set(SUMMARY_KEYS))
    if unknown:
        raise InputError(f"{source}: unknown key(s) {unknown}; a summary has {list(SUMMARY_KEYS)}")
    for key, typ in SUMMARY_KEYS.items():
        if not isinstance(obj[key], typ):
            raise _fail(source, key, f"must be a JSON {_json_type(typ)}, got {type(obj[key]).__name__}")
    if obj["task"] not in TASKS:
        raise _fail(source, "task", f"must be one of {list(TASKS)}, got {obj['task']!r}")
    if not obj["title"].strip():
        raise _fail(source, "title", "must not be empty")
    for i, pic in enumerate(obj["pictures"]):
        _check_picture(pic, source, f"pictures[{i}]")
    for i, table in enumerate(obj["tables"]):
        _check_table(table, source, f"tables[{i}]")
    return obj


def _json_type(typ: type) -> str:
    return {str: "string", list: "array", dict: "object"}[typ]


def _check_picture(pic: Any, source: str, where: str) -> None:
    if not isinstance(pic, dict) or set(pic) != {"path", "caption"}:
        raise _fail(source, where, f'must be an object with keys "path" and "caption", got {pic!r}')
    path, caption = pic["path"], pic["caption"]
    if not isinstance(path, str) or not isinstance(caption, str):
        raise _fail(source, where, "must have string `path` and `caption`")
    norm = posixpath.normpath(path)
    if "\\" in path or posixpath.isabs(path) or norm == ".." or norm.startswith("../"):
        raise _fail(source, f"{where}.path", f"must be a path relative to the repository root, got {path!r}")
    if posixpath.splitext(path)[1].lower() not in PICTURE_SUFFIXES:
        raise _fail(source, f"{where}.path", f"must be a PNG or JPEG file, got {path!r}")


def _check_table(table: Any, source: str, where: str) -> None:
    if not isinstance(table, dict) or set(table) != {"title", "columns", "rows"}:
        raise _fail(source, where, f'must be an object with keys "title", "columns" and "rows", got {table!r}')
    if not isinstance(table["title"], str):
        raise _fail(source, f"{where}.title", "must be a string")
    cols = table["columns"]
    if not isinstance(cols, list) or not cols or not all(isinstance(c, str) for c in cols):
        raise _fail(source, f"{where}.columns", f"must be a non-empty array of strings, got {cols!r}")
    if not isinstance(table["rows"], list):
        raise _fail(source, f"{where}.rows", "must be an array of rows")
    for r, row in enumerate(table["rows"]):
        if not isinstance(row, list) or len(row) != len(cols):
            n = len(row) if isinstance(row, list) else type(row).__name__
            raise _fail(source, f"{where}.rows[{r}]", f"has {n} cells, expected {len(cols)} (one per column)")
        for c, cell in enumerate(row):
            if not isinstance(cell, _CELL_TYPES):
                raise _fail(source, f"{where}.rows[{r}][{c}]", f"must be a string, number, boolean or null, "
                                                               f"got {type(cell).__name__}")


def picture_href(path: str, base: str = "outputs") -> str:
    """URL of a repo-relative picture ``path`` as seen from a page in the repo-relative folder ``base``.

    >>> picture_href("outputs/hough/lines #1.png")
    'hough/lines%20%231.png'
    >>> picture_href("data/samples/hough/grid.png")
    '../data/samples/hough/grid.png'
    """
    return quote(posixpath.relpath(posixpath.normpath(path), posixpath.normpath(base or ".")), safe="/")


def format_cell(value: Any) -> str:
    """Text of one table cell: numbers to 4 significant digits, null as a dash, booleans as yes/no."""
    if value is None:
        return "\u2013"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "\u2013"
        if value == 0:
            return "0"
        if abs(value) >= 1e4:
            return f"{value:.0f}"
        if abs(value) >= 1e-3:
            return f"{value:.4g}"
        return f"{value:.2e}"
    return str(value)


def format_seconds(seconds: float) -> str:
    """``0.0123`` -> ``12.3 ms``, ``2.5`` -> ``2.50 s``."""
    if seconds < 1e-3:
        return f"{seconds * 1e6:.0f} \u00b5s"
    if seconds < 1:
        return f"{seconds * 1e3:.3g} ms"
    return f"{seconds:.2f} s"


def timing_rows(timings: Iterable[Mapping[str, Any]]) -> list[dict]:
    """One row per stage and timed step: the data of the ``dvc plots`` timing bars.

    Parameters
    ----------
    timings : iterable of dict
        The stage runner's timing files, ``{"stage": "hough_lines@ours", "seconds": {"total": 1.2, ...}}``.

    Returns
    -------
    list of dict
        ``{"stage", "step", "label": "<stage> <step>", "seconds"}``, sorted by stage and step.
    """
    rows = []
    for t in sorted(timings, key=lambda t: str(t.get("stage"))):
        for step, seconds in sorted((t.get("seconds") or {}).items()):
            if _is_number(seconds) and math.isfinite(seconds):
                rows.append({"stage": str(t["stage"]), "step": step, "label": f"{t['stage']} {step}",
                             "seconds": float(seconds)})
    return rows


def _ordered(summaries: Iterable[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    by_task: dict[str, Mapping[str, Any]] = {}
    for s in summaries:
        if s["task"] in by_task:
            raise InputError(f"two summaries for task {s['task']!r}; expected one per task")
        by_task[s["task"]] = s
    return [by_task[t] for t in TASKS if t in by_task]


def _e(text: Any) -> str:
    return html.escape(str(text), quote=True)


def _table(title: str, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    out = [f"<h3>{_e(title)}</h3>" if title else "", '<div class="tablewrap"><table>', "<thead><tr>"]
    out += [f'<th scope="col">{_e(c)}</th>' for c in columns]
    out.append("</tr></thead><tbody>")
    for row in rows:
        cells = "".join(
            f'<td class="num">{_e(format_cell(v))}</td>' if _is_number(v) else f"<td>{_e(format_cell(v))}</td>"
            for v in row
        )
        out.append(f"<tr>{cells}</tr>")
    out.append("</tbody></table></div>")
    return out


def _section(s: Mapping[str, Any], base: str, sizes: Mapping[str, tuple[int, int]]) -> list[str]:
    task = s["task"]
    out = [f'<section id="task-{_e(task)}">', f"<h2>{_e(TASK_NAMES[task])}</h2>",
           f'<p class="title">{_e(s["title"])}</p>', f"<p>{_e(s['description'])}</p>"]
    if s["pictures"]:
        out.append('<div class="grid">')
        for pic in s["pictures"]:
            href = _e(picture_href(pic["path"], base))
            cap = _e(pic["caption"])
            size, wide = "", ""
            if pic["path"] in sizes:
                w, h = sizes[pic["path"]]
                size = f' width="{int(w)}" height="{int(h)}"'  # the browser reserves the space before decoding
                wide = ' class="wide"' if w >= WIDE_ASPECT * h else ""
            out.append(f'<figure{wide}><a href="{href}"><img src="{href}"{size} alt="{cap}"></a>'
                       f"<figcaption>{cap}</figcaption></figure>")
        out.append("</div>")
    for table in s["tables"]:
        out += _table(table["title"], table["columns"], table["rows"])
    out.append("</section>")
    return out


def build_html(
    summaries: Iterable[Mapping[str, Any]],
    base: str = "outputs",
    sizes: Mapping[str, tuple[int, int]] | None = None,
) -> str:
    """The report page of the given task summaries.

    Parameters
    ----------
    summaries : iterable of mapping
        Task summaries that passed :func:`validate_summary`, at most one per task, in any order.
    base : str
        Repo-relative folder the page is written to; picture links are made relative to it.
    sizes : mapping, optional
        Picture path -> (width, height) in pixels. Known sizes become the <img> width/height attributes, and a
        picture at least :data:`WIDE_ASPECT` times wider than high (a panorama) spans the whole row.

    Returns
    -------
    str
        A complete HTML5 document: a table of contents (tasks without a summary are listed as "not run"), then one
        section per task in the order of :data:`TASKS` with its description, pictures, tables and timings.

    Raises
    ------
    InputError
        Two summaries for the same task.
    """
    present = {s["task"]: s for s in _ordered(summaries)}
    toc = []
    for task in TASKS:
        if task in present:
            toc.append(f'<li><a href="#task-{task}">{_e(TASK_NAMES[task])}</a> \u2014 {_e(present[task]["title"])}'
                       "</li>")
        else:
            toc.append(f'<li>{_e(TASK_NAMES[task])} \u2014 <span class="notrun">not run</span></li>')
    body = [
        "<main>",
        "<h1>cvpipe report</h1>",
        f'<p class="lead">{len(present)} of {len(TASKS)} tasks have results. Every picture links to its full-size '
        "file; tables compare the methods on the same inputs.</p>",
        '<nav aria-label="contents"><h3>Contents</h3><ol>', *toc, "</ol></nav>",
    ]
    for task in TASKS:
        if task in present:
            body += _section(present[task], base, sizes or {})
    body += ["<footer>Written by the <code>report</code> stage (<code>dvc repro report</code>) from "
             "<code>outputs/&lt;task&gt;/summary.json</code>; curves and bars: <code>dvc plots show</code>. These "
             "pictures next to an experiment's: <code>dvc plots diff main &lt;experiment&gt;</code> (an offline "
             "page, one column per revision).</footer>",
             "</main>"]
    head = ['<!DOCTYPE html>', '<html lang="en">', "<head>", '<meta charset="utf-8">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            "<title>cvpipe report</title>",
            '<link rel="icon" href="data:,">',  # no favicon request (it would 404 on file://)
            f"<style>{CSS}</style>", "</head>", "<body>"]
    return "\n".join(head + [line for line in body if line] + ["</body>", "</html>"]) + "\n"
