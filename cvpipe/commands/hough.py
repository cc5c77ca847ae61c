"""``cvpipe hough IMAGE``: straight lines of an image (our Hough transform or OpenCV's, same parameters)."""

from __future__ import annotations

import argparse
import math
import sys

from .. import hough, io
from ..compute import check_scheduler, map_items
from ..errors import CvpipeError, EstimationError, InputError
from ..params import HoughEdgesParams, HoughLinesParams

HELP = "find straight lines (standard Hough transform, cv2.HoughLines conventions)"
EXAMPLE = "cvpipe hough data/samples/hough/synthetic_grid.png --threshold 100 --json"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    e, p = HoughEdgesParams(), HoughLinesParams()
    parser.add_argument("image", nargs="+", help="input image(s) (converted to grayscale); with several, --json "
                                                 'prints a list of {"image", "lines"}')
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
    parser.add_argument("--scheduler", default="", metavar="ADDR",
                        help="run the images on Dask: 'local' or a scheduler address tcp://host:port "
                             "(default: in process)")


def _read_images(paths: list[str]):
    """``(gray image or None, read error)`` per path, lazily (the image travels with its task)."""
    for path in paths:
        try:
            yield io.read_image(path, "gray"), None
        except CvpipeError as exc:
            yield None, exc


def image_lines(item: tuple, shared: tuple):
    """The (N, 3) lines of one image (an item of :func:`cvpipe.compute.map_items`): ``item`` from
    :func:`_read_images`, ``shared`` = (HoughEdgesParams, canny (low, high), impl, rho, theta rad, threshold,
    keyword arguments)."""
    gray, error = item
    if error is not None:
        raise error
    e, canny, impl, rho, theta, threshold, kwargs = shared
    edges = hough.canny_edges(gray, canny[0], canny[1], aperture=e.aperture, l2_gradient=e.l2_gradient,
                              blur_sigma=e.blur_sigma)
    return hough.get_impl(impl)(edges, rho, theta, threshold, **kwargs)


def run(args: argparse.Namespace) -> int:
    if args.refine and args.impl != "ours":
        raise InputError("`--refine` is only available with --impl ours")
    if not (args.theta_deg > 0 and math.isfinite(args.theta_deg)):
        raise InputError(f"`--theta-deg` must be > 0, got {args.theta_deg}")
    kwargs = {"refine": True} if args.refine else {}
    shared = (HoughEdgesParams(), tuple(args.canny), args.impl, args.rho, math.radians(args.theta_deg),
              args.threshold, kwargs)
    results = list(map_items(image_lines, _read_images(args.image), shared=shared, total=len(args.image),
                             scheduler=check_scheduler(args.scheduler, "--scheduler"),
                             progress="hough" if len(args.image) > 1 else None))
    if len(args.image) == 1 and not results[0].ok:
        # one image: fail as before, with the exit status of its error's kind
        raise (EstimationError if results[0].error_type == "EstimationError" else InputError)(results[0].error)
    for path, res in zip(args.image, results):
        if not res.ok:
            print(f"cvpipe: error: {res.error}", file=sys.stderr)
    if len(args.image) > 1:
        if args.json:
            print(io.dumps_json([{"image": p, "lines": r.value.tolist()} if r.ok
                                 else {"image": p, "lines": None, "error": r.error}
                                 for p, r in zip(args.image, results)]))
        else:
            for path, res in zip(args.image, results):
                print(f"{path}: " + (f"{len(res.value)} lines ({args.impl})" if res.ok else "error"))
        return 2 if any(not r.ok for r in results) else 0
    lines = results[0].value
    if args.json:
        print(io.dumps_json({"lines": lines.tolist()}))
    else:
        print(f"{len(lines)} lines ({args.impl}); rho [px], theta [deg], votes:")
        for rho, theta, votes in lines:
            print(f"{rho:9.2f} {math.degrees(theta):8.3f} {int(votes):6d}")
    return 0
