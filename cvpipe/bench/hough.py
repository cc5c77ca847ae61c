"""``cvpipe bench hough --data DIR``: our Hough transform against ``cv2.HoughLines`` on the York Urban photos.

(a) Parity and speed at identical parameters: the share of OpenCV's lines that ours reproduces in the same
(rho, theta) cell, per image, and the time ratio ours / OpenCV measured in this process, interleaved, after warm-up
(median over images).
(b) Quality against the hand-labelled segments (stored 1-based, shifted to 0-based here): the recall of segments
that a detected line lies along (both end points within 2 px of it, angle within 1 degree), for both standard
transforms and both probabilistic ones (a segment must also be half covered by a detected segment).
"""

from __future__ import annotations

import argparse
import os
import time
import typing
from pathlib import Path

from ..errors import InputError
from ..params import HoughEdgesParams, HoughLinesParams

if typing.TYPE_CHECKING:  # annotations only: the modules are imported inside the functions that use them,
    # so that `cvpipe bench hough --help` imports neither numpy nor cv2
    import numpy as np


HELP = "our Hough lines vs cv2.HoughLines on York Urban: parity, speed ratio, ground-truth recall"
EXAMPLE = "cvpipe bench hough --data ../shared/data --json"

#: the probabilistic transforms' parameters (same for ours and OpenCV's)
PROB_THRESHOLD, PROB_MIN_LENGTH, PROB_MAX_GAP = 40, 25, 3

def add_arguments(parser: argparse.ArgumentParser) -> None:
    e, p = HoughEdgesParams(), HoughLinesParams()
    parser.add_argument("--data", default=os.environ.get("CVPIPE_DATA"),
                        help="data root holding yorkurban_lines/ (default: $CVPIPE_DATA)")
    parser.add_argument("--limit", type=int, default=0, help="use only the first N images (0 = all)")
    parser.add_argument("--repeats", type=int, default=5, help="timed calls per image and method (median)")
    parser.add_argument("--threshold", type=int, default=p.threshold, help="standard transform vote threshold")
    parser.add_argument("--canny", type=float, nargs=2, default=(e.canny_low, e.canny_high), metavar=("LOW", "HIGH"))
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


def _gt_segments(path: Path) -> np.ndarray:
    import numpy as np

    rows = [line.split() for line in path.read_text().splitlines() if line.strip() and not line.startswith("#")]
    seg = np.array([[float(v) for v in r[:4]] for r in rows], np.float64).reshape(-1, 4)
    return seg - 1.0  # MATLAB 1-based -> 0-based pixel coordinates


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def run(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np
    from tqdm import tqdm
    from .. import hough, io

    if not args.data:
        raise InputError("no data root: pass --data DIR or set CVPIPE_DATA")
    root = Path(args.data) / "yorkurban_lines"
    images = sorted((root / "images").glob("*.jpg")) if (root / "images").is_dir() else []
    if not images:
        raise InputError(f"{root}/images: no York Urban images found")
    if args.limit < 0 or args.repeats < 1:
        raise InputError(f"`--limit` must be >= 0 and `--repeats` >= 1, got {args.limit}, {args.repeats}")
    if args.limit:
        images = images[:args.limit]
    p, e = HoughLinesParams(), HoughEdgesParams()
    (rho, theta), thr = hough.hough_steps(p), args.threshold
    methods = {
        "ours": lambda ed: hough.hough_lines(ed, rho, theta, thr),
        "ours_serial": lambda ed: hough.hough_lines(ed, rho, theta, thr, parallel=False),
        "ours_parallel": lambda ed: hough.hough_lines(ed, rho, theta, thr, parallel=True),
        "opencv": lambda ed: hough.hough_lines_opencv(ed, rho, theta, thr),
    }
    rows = []
    hits = {k: [] for k in ("ours", "opencv", "ours_prob", "opencv_prob")}
    counts = {k: [] for k in hits}
    for f in tqdm(images, desc="bench hough", disable=None):
        gray = io.read_image(f, "gray")
        edges = hough.canny_edges(gray, args.canny[0], args.canny[1], aperture=e.aperture,
                                  l2_gradient=e.l2_gradient, blur_sigma=e.blur_sigma)
        ours, ref = methods["ours"](edges), methods["opencv"](edges)
        agree = hough.cell_agreement(ours, ref, rho, theta)
        for fn in methods.values():  # warm-up (caches, page faults) before timing
            fn(edges)
        times = {k: [] for k in methods}
        for _ in range(args.repeats):  # interleaved, so that load from other processes hits every method alike
            for k, fn in methods.items():
                times[k].append(_timed(lambda: fn(edges)))
        med = {k: float(np.median(v)) for k, v in times.items()}
        gt = _gt_segments(root / "gt_lines" / f"{f.stem}.txt")
        segs_ours = hough.hough_lines_probabilistic(edges, PROB_THRESHOLD, PROB_MIN_LENGTH, PROB_MAX_GAP, params=p,
                                                    rng=0)
        segs_cv = cv2.HoughLinesP(edges, rho, theta, PROB_THRESHOLD, minLineLength=PROB_MIN_LENGTH,
                                  maxLineGap=PROB_MAX_GAP)
        segs_cv = np.zeros((0, 4)) if segs_cv is None else segs_cv.reshape(-1, 4)
        for key, found, n in (("ours", hough.line_segment_matches(ours, gt), len(ours)),
                              ("opencv", hough.line_segment_matches(ref, gt), len(ref)),
                              ("ours_prob", hough.segment_segment_matches(segs_ours, gt), len(segs_ours)),
                              ("opencv_prob", hough.segment_segment_matches(segs_cv, gt), len(segs_cv))):
            hits[key].append(found)
            counts[key].append(n)
        rows.append({"image": f.stem, "edge_pixels": int(np.count_nonzero(edges)), **agree,
                     "identical": bool(ours.shape == ref.shape and np.array_equal(ours, ref)),
                     "seconds": med, "ratio": med["ours"] / med["opencv"],
                     "ratio_serial": med["ours_serial"] / med["opencv"],
                     "ratio_parallel": med["ours_parallel"] / med["opencv"]})

    parity = np.array([r["parity"] for r in rows])
    summary = {
        "images": len(rows), "rho": rho, "theta_deg": p.theta_deg, "threshold": thr, "canny": list(args.canny),
        "repeats": args.repeats,
        "parity_min": float(parity.min()), "parity_median": float(np.median(parity)),
        "images_at_least_99pct": int((parity >= 0.99).sum()),
        "images_identical": sum(r["identical"] for r in rows),
        "lines_per_image_median": float(np.median([r["ref_lines"] for r in rows])),
        "time_ratio_median": float(np.median([r["ratio"] for r in rows])),
        "time_ratio_serial_median": float(np.median([r["ratio_serial"] for r in rows])),
        "time_ratio_parallel_median": float(np.median([r["ratio_parallel"] for r in rows])),
        "ms_median": {k: 1e3 * float(np.median([r["seconds"][k] for r in rows])) for k in methods},
        "recall": {k: float(np.concatenate(v).mean()) for k, v in hits.items()},
        "gt_segments": int(sum(len(h) for h in hits["ours"])),
        "detections_per_image_median": {k: float(np.median(v)) for k, v in counts.items()},
        "probabilistic": {"threshold": PROB_THRESHOLD, "min_line_length": PROB_MIN_LENGTH,
                          "max_line_gap": PROB_MAX_GAP},
        "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }
    if args.json:
        print(io.dumps_json({"summary": summary, "per_image": rows}))
        return 0
    s = summary
    print(f"York Urban, {s['images']} images, Canny {s['canny']}, rho {rho}, theta {p.theta_deg} deg, "
          f"threshold {thr}, {s['repeats']} timed calls per image")
    print(f"parity (OpenCV lines reproduced in the same cell): min {s['parity_min']:.4f}, median "
          f"{s['parity_median']:.4f}; >= 99 % on {s['images_at_least_99pct']}/{s['images']} images; "
          f"identical output on {s['images_identical']}/{s['images']}")
    print(f"time ours/cv2 (median over images): {s['time_ratio_median']:.3f} (auto), serial "
          f"{s['time_ratio_serial_median']:.3f}, parallel {s['time_ratio_parallel_median']:.3f}; median ms "
          + ", ".join(f"{k} {v:.2f}" for k, v in s["ms_median"].items()))
    print(f"recall of {s['gt_segments']} GT segments (2 px, 1 deg): "
          + ", ".join(f"{k} {v:.3f}" for k, v in s["recall"].items()))
    print("detections per image (median): " + ", ".join(f"{k} {v:.0f}" for k, v in
                                                       s["detections_per_image_median"].items()))
    return 0
