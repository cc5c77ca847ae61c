"""``cvpipe hough IMAGE``: straight lines of an image (our Hough transform or OpenCV's, same parameters)."""

from __future__ import annotations

import argparse
import math

from .. import hough, io
from ..errors import InputError
from ..params import HoughEdgesParams, HoughLinesParams

HELP = "find straight lines (standard Hough transform, cv2.HoughLines conventions)"
EXAMPLE = "cvpipe hough data/samples/hough/synthetic_grid.png --threshold 100 --json"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    e, p = HoughEdgesParams(), HoughLinesParams()
    parser.add_argument("image", help="input image (converted to grayscale)")
    parser.add_argument("--impl", choices=sorted(hough.IMPLEMENTATIONS), default="ours",
                        help="our transform or cv2.HoughLines (default: ours)")
    parser.add_argument("--rho", type=float, default=p.rho, help=f"distance resolution in pixels (default {p.rho})")
    parser.add_argument("--theta-deg", type=float, default=p.theta_deg,
                        help=f"angle resolution in degrees (default {p.theta_deg})")
    parser.add_argument("--threshold", type=int, default=p.threshold,
                        help=f"a line needs more than this many votes (default {p.threshold})")
    parser.add_argument("--canny", type=float, nargs=2, metavar=("LOW", "HIGH"), default=(e.canny_low, e.canny_high),
                        help=f"Canny hysteresis thresholds (default {e.canny_low:g} {e.canny_high:g})")
    parser.add_argument("--refine", action="store_true", help="sub-bin (rho, theta) for --impl ours")
    parser.add_argument("--json", action="store_true", help='print {"lines": [[rho, theta, votes], ...]}')


def run(args: argparse.Namespace) -> int:
    if args.refine and args.impl != "ours":
        raise InputError("`--refine` is only available with --impl ours")
    e = HoughEdgesParams()
    gray = io.read_image(args.image, "gray")
    edges = hough.canny_edges(gray, args.canny[0], args.canny[1], aperture=e.aperture, l2_gradient=e.l2_gradient,
                              blur_sigma=e.blur_sigma)
    if not (args.theta_deg > 0 and math.isfinite(args.theta_deg)):
        raise InputError(f"`--theta-deg` must be > 0, got {args.theta_deg}")
    kwargs = {"refine": True} if args.refine else {}
    lines = hough.get_impl(args.impl)(edges, args.rho, math.radians(args.theta_deg), args.threshold, **kwargs)
    if args.json:
        print(io.dumps_json({"lines": lines.tolist()}))
    else:
        print(f"{len(lines)} lines ({args.impl}); rho [px], theta [deg], votes:")
        for rho, theta, votes in lines:
            print(f"{rho:9.2f} {math.degrees(theta):8.3f} {int(votes):6d}")
    return 0
