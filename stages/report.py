"""Stage `report`: render every outputs/<task>/summary.json into one HTML page (outputs/report.html), and gather the
stage runner's uncached timing files into the rows of the `dvc plots` timing bars (outputs/plots/timings.json,
not a DVC output: it changes with every run)."""

import os
from pathlib import Path

from cvpipe import io, report
from cvpipe.errors import InputError
from ._runner import TIMINGS_DIR, Stage, run


def load_summaries(outputs: Path, root: Path) -> tuple[list[dict], dict[str, tuple[int, int]]]:
    """Every ``<outputs>/*/summary.json``, validated, and the (width, height) of every picture they name."""
    summaries, sizes = [], {}
    for f in sorted(outputs.glob("*/summary.json")):
        s = report.validate_summary(io.load_json(f), str(f))
        if s["task"] != f.parent.name:
            raise InputError(f"{f}: `task` is {s['task']!r} but the file is in the folder of {f.parent.name!r}")
        for pic in s["pictures"]:
            if not (root / pic["path"]).is_file():
                raise InputError(f"{f}: picture {pic['path']!r} does not exist (relative to the repository root)")
            try:
                h, w = io.read_image(root / pic["path"], "unchanged").shape[:2]
            except InputError as exc:
                raise InputError(f"{f}: picture {exc}") from exc
            sizes[pic["path"]] = (w, h)
        summaries.append(s)
    return summaries, sizes


def report_page(st: Stage) -> None:
    root = Path()  # summaries name their pictures relative to the repository root, where dvc runs stages
    out = Path(st.args.out)
    summaries, sizes = load_summaries(Path(st.args.outputs), root)
    base = Path(os.path.relpath(out.resolve().parent, Path.cwd())).as_posix()
    page = report.build_html(summaries, base=base, sizes=sizes)
    with io.atomic_path(out) as tmp:
        tmp.write_text(page, encoding="utf-8")
    timings = []
    for f in sorted(TIMINGS_DIR.glob("*.json")):
        try:
            timings.append(io.load_json(f))
        except InputError as exc:
            st.drop(f.name, str(exc))
    io.save_json(st.args.timings, report.timing_rows(timings))
    ran = ", ".join(s["task"] for s in summaries) or "none yet"
    st.made(f"{out} ({len(summaries)} of {len(report.TASKS)} tasks: {ran})")


if __name__ == "__main__":
    run(report_page, name="report",
        args={"outputs": "folder searched for <task>/summary.json", "out": "the HTML page",
              "timings": "rows for the dvc plots timing bars (uncached)"})
