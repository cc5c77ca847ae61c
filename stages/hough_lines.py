"""Stage `hough_lines@{ours,opencv}`: standard Hough lines of every edge map, with the median time per image."""

import argparse
import math
import time
from pathlib import Path

from tqdm import tqdm

from cvpipe import hough, io
from cvpipe.params import HoughLinesParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--edges", required=True, help="folder of edge maps (outputs/hough/edges)")
    ap.add_argument("--impl", required=True, choices=sorted(hough.IMPLEMENTATIONS))
    ap.add_argument("--out", required=True, help="JSON file: lines and seconds per image")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(HoughLinesParams, "hough.lines", args.params)
    fn = hough.get_impl(args.impl)
    kwargs = {"refine": p.refine} if args.impl == "ours" else {}
    theta = math.radians(p.theta_deg)
    images, first_call = [], None
    for f in tqdm(io.list_images(args.edges), desc=f"hough lines {args.impl}", disable=None):
        edges = io.read_image(f, "gray")
        t0 = time.perf_counter()
        lines = fn(edges, p.rho, theta, p.threshold, **kwargs)
        if first_call is None:  # ours: includes numba's compilation or its cache load
            first_call = time.perf_counter() - t0
        seconds = hough.median_seconds(lambda: fn(edges, p.rho, theta, p.threshold, **kwargs), p.repeats)
        images.append({"file": Path(f).name, "lines": lines.tolist(), "seconds": seconds})
    io.save_json(args.out, {"impl": args.impl, "rho": p.rho, "theta": theta, "threshold": p.threshold,
                            "refine": bool(kwargs.get("refine", False)), "first_call_seconds": first_call,
                            "images": images})


if __name__ == "__main__":
    main()
