"""Stage `report`: render every outputs/<task>/summary.json into one HTML page, plus the timing bars for dvc plots."""

import argparse
import os
from pathlib import Path

from cvpipe import io, report
from cvpipe.errors import CvpipeError, InputError


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--outputs", default="outputs", help="folder searched for <task>/summary.json")
    ap.add_argument("--out", default="outputs/report.html")
    ap.add_argument("--timings", default="outputs/plots/timings.json", help="per-method timings for dvc plots")
    args = ap.parse_args()
    root = Path()  # summaries name their pictures relative to the repository root, where dvc runs stages
    out = Path(args.out)
    try:
        summaries, sizes = load_summaries(Path(args.outputs), root)
        base = Path(os.path.relpath(out.resolve().parent, Path.cwd())).as_posix()
        page = report.build_html(summaries, base=base, sizes=sizes)
        rows = report.timing_rows(summaries)
    except CvpipeError as exc:
        raise SystemExit(f"cvpipe: error: {exc}") from exc
    with io.atomic_path(out) as tmp:
        tmp.write_text(page, encoding="utf-8")
    io.save_json(args.timings, rows)
    ran = ", ".join(s["task"] for s in summaries) or "none yet"
    print(f"report: {out} ({len(summaries)} of {len(report.TASKS)} tasks: {ran})")


if __name__ == "__main__":
    main()
