"""``cvpipe bench stereo --data DIR``: our semi-global matching against OpenCV's BM and SGBM.

Pairs: the five Middlebury pairs under ``DIR/middlebury_stereo`` (tsukuba, venus, cones, teddy, Adirondack; ground
truth scaled per set as its SOURCE.txt says, 0 = unknown) and scikit-image's Middlebury 2014 motorcycle pair (true
disparity bundled with scikit-image, inf = unknown). The disparity range of a pair is the smallest multiple of 16
above its largest true disparity, the same for every method.

Quality, over all pixels with known truth: bad-1.0 and bad-2.0 (estimate missing or off by more than 1 / 2 px),
mean absolute error over the pixels that have an estimate, and density (share of them with an estimate).
OpenCV SGBM is run in each of its four modes with block sizes 3, 5 and 7 (same range), and the configuration with
the lowest bad-2.0 on that pair is the baseline ("best of SGBM's modes"). Time: median over ``--repeats`` calls,
the methods interleaved in this process after a warm-up call, so that load from other processes hits them alike.
The first call of ours in the process is timed on its own.

With ``--rectify`` the benchmark is the rectification one instead (``cvpipe.bench.stereo_rectify``).
"""

from __future__ import annotations

import argparse
import os
import time
import typing
from pathlib import Path

from ..errors import InputError
from ..params import StereoBmParams, StereoSgmParams
from .stereo_pairs import MIDDLEBURY, disparity_range, load_pairs  # noqa: F401 - the pairs of both benchmarks

if typing.TYPE_CHECKING:  # annotations only: the modules are imported inside the functions that use them,
    # so that `cvpipe bench stereo --help` imports neither numpy nor cv2
    import numpy as np


HELP = "our semi-global matching vs OpenCV BM/SGBM on Middlebury + motorcycle: bad-1/bad-2, density, time"
EXAMPLE = "cvpipe bench stereo --data ../shared/data --json"

#: the OpenCV SGBM configurations searched for the best baseline per pair
SGBM_BLOCK_SIZES = (3, 5, 7)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", default=os.environ.get("CVPIPE_DATA"),
                        help="data root holding middlebury_stereo/ (default: $CVPIPE_DATA)")
    parser.add_argument("--repeats", type=int, default=5, help="timed calls per pair and method (median)")
    parser.add_argument("--rectify", action="store_true",
                        help="instead: unrectify each pair by a seeded random rotation/shift/scale of the right "
                             "view and compare our uncalibrated rectification with OpenCV's "
                             "(cvpipe.bench.stereo_rectify)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the unrectifying transforms (--rectify)")
    parser.add_argument("--seeds", type=int, default=1,
                        help="with --rectify: repeat the protocol with the unrectifying seeds SEED .. SEED+N-1")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


def _timed(fn) -> tuple[float, float]:
    """(wall seconds, CPU seconds of the whole process, all threads) of one call."""
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def _best_sgbm(left, right, max_disp, truth) -> tuple[dict, np.ndarray]:
    """The SGBM (mode, block size) with the lowest bad-2.0 on this pair, and its disparity."""
    from .. import stereo

    best = None
    for mode in stereo.SGBM_MODES:
        for bs in SGBM_BLOCK_SIZES:
            disp = stereo.disparity_opencv_sgbm(left, right, max_disp, mode=mode, block_size=bs)
            bad2 = stereo.evaluate(disp, truth, (2.0,))["bad_2.0"]
            if best is None or bad2 < best[0]:
                best = (bad2, {"mode": mode, "block_size": bs}, disp)
    return best[1], best[2]


def run(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np
    from tqdm import tqdm
    from .. import _threads, io, stereo

    if not args.data:
        raise InputError("no data root: pass --data DIR or set CVPIPE_DATA")
    if args.rectify:
        from .stereo_rectify import run_rectify

        return run_rectify(args, load_pairs(Path(args.data)))
    if args.repeats < 1:
        raise InputError(f"`--repeats` must be >= 1, got {args.repeats}")
    pairs = load_pairs(Path(args.data))
    probe = pairs["tsukuba"][0]
    first_call = _timed(lambda: stereo.disparity_sgm(probe, pairs["tsukuba"][1], 16))[0]

    sgm = StereoSgmParams().model_dump()
    bm = StereoBmParams().model_dump()
    rows, sgbm_choice = [], {}
    for name, (left, right, truth) in tqdm(pairs.items(), desc="bench stereo", disable=None):
        nd = disparity_range(truth)
        choice, _ = _best_sgbm(left, right, nd, truth)
        sgbm_choice[name] = choice
        methods = {
            "sgm": lambda: stereo.disparity_sgm(left, right, nd, **sgm),
            "sgm_4path": lambda: stereo.disparity_sgm(left, right, nd, **{**sgm, "paths": 4}),
            "sgm_fill": lambda: stereo.disparity_sgm(left, right, nd, **{**sgm, "fill": True}),
            "opencv_bm": lambda: stereo.disparity_opencv_bm(left, right, nd, **bm),
            "opencv_sgbm": lambda: stereo.disparity_opencv_sgbm(left, right, nd, **choice),
        }
        disps = {k: fn() for k, fn in methods.items()}  # also the warm-up call
        disps["opencv_sgbm_fill"] = stereo.fill_invalid(disps["opencv_sgbm"])
        times = {k: [] for k in methods}
        for _ in range(args.repeats):  # interleaved, so that load from other processes hits every method alike
            for k, fn in methods.items():
                times[k].append(_timed(fn))
        med = {k: float(np.median([t[0] for t in v])) for k, v in times.items()}
        cpu = {k: float(np.median([t[1] for t in v])) for k, v in times.items()}
        for k, disp in disps.items():
            t, c = med.get(k), cpu.get(k)
            rows.append({"pair": name, "method": k, "max_disp": nd, **stereo.evaluate(disp, truth),
                         "seconds": t, "time_ratio_to_sgbm": None if t is None else t / med["opencv_sgbm"],
                         "cpu_seconds": c, "cpu_ratio_to_sgbm": None if c is None else c / cpu["opencv_sgbm"]})

    def by(method, key):
        return {r["pair"]: r[key] for r in rows if r["method"] == method}

    sgm_b2, sgbm_b2 = by("sgm", "bad_2.0"), by("opencv_sgbm", "bad_2.0")
    fill_b2, sgbm_fill_b2 = by("sgm_fill", "bad_2.0"), by("opencv_sgbm_fill", "bad_2.0")
    ratios = list(by("sgm", "time_ratio_to_sgbm").values())
    summary = {
        "pairs": list(pairs), "repeats": args.repeats, "threads": {"openmp": _threads.max_threads(), "opencv":
                                                                   cv2.getNumThreads()},
        "sgbm_choice": sgbm_choice, "first_call_s": first_call,
        "sgm_bad2_not_worse_than_sgbm": {p: bool(sgm_b2[p] <= sgbm_b2[p]) for p in sgm_b2},
        "sgm_fill_bad2_not_worse_than_sgbm_fill": {p: bool(fill_b2[p] <= sgbm_fill_b2[p]) for p in fill_b2},
        "sgm_time_ratio_median": float(np.median(ratios)), "sgm_time_ratio_max": float(np.max(ratios)),
        "sgm_time_ratio_total": float(sum(by("sgm", "seconds").values()) / sum(by("opencv_sgbm", "seconds").values())),
        "sgm_4path_time_ratio_median": float(np.median(list(by("sgm_4path", "time_ratio_to_sgbm").values()))),
        "sgm_cpu_ratio_median": float(np.median(list(by("sgm", "cpu_ratio_to_sgbm").values()))),
        "load_average_1min": os.getloadavg()[0],
    }
    if args.json:
        print(io.dumps_json({"summary": summary, "rows": rows}))
        return 0
    print(f"{'pair':<11} {'method':<17} {'bad-1.0':>8} {'bad-2.0':>8} {'mean err':>9} {'density':>8} "
          f"{'time ms':>8} {'x SGBM':>7} {'cpu ms':>8} {'x SGBM':>7}")
    for r in rows:
        t = "" if r["seconds"] is None else f"{r['seconds'] * 1000:8.1f}"
        x = "" if r["time_ratio_to_sgbm"] is None else f"{r['time_ratio_to_sgbm']:7.2f}"
        c = "" if r["cpu_seconds"] is None else f"{r['cpu_seconds'] * 1000:8.1f}"
        cx = "" if r["cpu_ratio_to_sgbm"] is None else f"{r['cpu_ratio_to_sgbm']:7.2f}"
        print(f"{r['pair']:<11} {r['method']:<17} {100 * r['bad_1.0']:7.2f}% {100 * r['bad_2.0']:7.2f}% "
              f"{r['mean_error']:9.3f} {100 * r['density']:7.1f}% {t:>8} {x:>7} {c:>8} {cx:>7}")
    print("SGBM baseline per pair (lowest bad-2.0):",
          ", ".join(f"{p}: {c['mode']}/{c['block_size']}" for p, c in sgbm_choice.items()))
    print(f"sgm bad-2.0 <= SGBM on: {sum(summary['sgm_bad2_not_worse_than_sgbm'].values())}/{len(pairs)} pairs; "
          f"time ratio sgm / SGBM: median {summary['sgm_time_ratio_median']:.2f}, max "
          f"{summary['sgm_time_ratio_max']:.2f}, total {summary['sgm_time_ratio_total']:.2f} "
          f"(4 paths: median {summary['sgm_4path_time_ratio_median']:.2f}); "
          f"CPU time ratio median {summary['sgm_cpu_ratio_median']:.2f}; "
          f"load average {summary['load_average_1min']:.1f}")
    print(f"first call of ours in this process {first_call:.2f} s; threads: OpenMP {summary['threads']['openmp']}, "
          f"OpenCV {summary['threads']['opencv']}")
    return 0
