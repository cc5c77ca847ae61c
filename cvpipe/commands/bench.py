"""``cvpipe bench <task> --data DIR``: benchmarks on the real data sets."""

from __future__ import annotations

import argparse

HELP = "run a benchmark on a real data set (root from --data or $CVPIPE_DATA)"
EXAMPLE = "cvpipe bench hough --data ../shared/data"

#: benchmark name -> module under ``cvpipe.bench``
BENCHMARKS = {
    "logo": "logo",
    "hough": "hough",
    "defect": "defect",
    "homography": "homography",
    "stereo": "stereo",
    "panorama": "panorama",
    "pipeline": "pipeline",
    "scale": "scale",
    "guard": "guard",
    "report": "report",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..cli import add_subcommands

    # lazily: `cvpipe bench --help` reads each benchmark's HELP from its source, only the one run is imported
    add_subcommands(parser, "cvpipe.bench", BENCHMARKS, "benchmark")


def run(args: argparse.Namespace) -> int:  # pragma: no cover - dispatch happens through the sub-subparser
    return int(args._run(args) or 0)
