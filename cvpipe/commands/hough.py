"""``cvpipe hough IMAGE``: straight lines of an image (our Hough transform or OpenCV's, same parameters)."""

from __future__ import annotations

import argparse
import math

from ..params import HoughEdgesParams, HoughLinesParams
from . import compile_note, note, step

HELP = "find straight lines (standard Hough transform, cv2.HoughLines conventions)"
EXAMPLE = "cvpipe hough data/samples/hough/synthetic_grid.png --threshold 100 --max-lines 10 --overlay lines.png"

#: ``--method`` choices, the keys of ``cvpipe.hough.IMPLEMENTATIONS`` (a test keeps the two equal)
METHODS = ("ours", "opencv")
#: lines printed by default: enough for any photo's main structure, few enough to read
DEFAULT_MAX_LINES = 50


def add_arguments(parser: argparse.ArgumentParser) -> None:
    e, p = HoughEdgesParams(), HoughLinesParams()
    parser.add_argument("image", help="input image (converted to grayscale)")
    parser.add_argument("--method", choices=METHODS, default=None,
                        help="our transform or cv2.HoughLines (default: ours)")
    parser.add_argument("--impl", choices=METHODS, default=None, help=argparse.SUPPRESS)  # deprecated spelling
    parser.add_argument("--rho", type=float, default=p.rho, help=f"distance resolution in pixels (default {p.rho})")
    parser.add_argument("--theta-deg", type=float, default=p.theta_deg,
                        help=f"angle resolution in degrees (default {p.theta_deg})")
    parser.add_argument("--threshold", type=int, default=p.threshold,
                        help=f"a line needs more than this many votes (default {p.threshold})")
    parser.add_argument("--canny", type=float, nargs=2, metavar=("LOW", "HIGH"), default=(e.canny_low, e.canny_high),
                        help=f"Canny hysteresis thresholds (default {e.canny_low:g} {e.canny_high:g})")
    parser.add_argument("--max-lines", type=int, default=DEFAULT_MAX_LINES, metavar="K",
                        help=f"report the K lines with most votes, 0 = all (default {DEFAULT_MAX_LINES})")
    parser.add_argument("--refine", action="store_true", help="sub-bin (rho, theta) for --method ours")
    parser.add_argument("--overlay", metavar="PNG", help="write the image with the reported lines drawn on it")
    parser.add_argument("--json", action="store_true",
                        help='print {"lines": [[rho, theta_rad, votes], ...] (cv2 convention), '
                             '"lines_deg": [{"rho_px", "theta_deg", "votes"}, ...], "total", "overlay"}')


def method_of(args: argparse.Namespace) -> str:
    """``--method``, or the deprecated ``--impl`` (with a note), default ``ours``."""
    if args.impl is not None:
        note("`--impl` is deprecated, use `--method`")
        if args.method is not None and args.method != args.impl:
            raise ValueError(f"`--impl {args.impl}` contradicts `--method {args.method}`; give only --method")
    return args.method or args.impl or "ours"


def run(args: argparse.Namespace) -> int:
    from .. import hough, io
    from ..errors import InputError

    method = method_of(args)
    if args.refine and method != "ours":
        raise InputError("`--refine` is only available with --method ours")
    if not (args.theta_deg > 0 and math.isfinite(args.theta_deg)):
        raise InputError(f"`--theta-deg` must be > 0, got {args.theta_deg}")
    if args.max_lines < 0:
        raise InputError(f"`--max-lines` must be >= 0 (0 = all), got {args.max_lines}")
    if method == "ours":
        # the serial or the parallel vote, whichever this run will use (hough_accumulator's own choice)
        from ..hough import _kernels, transform

        vote = _kernels._vote_parallel if transform._use_parallel(None) else _kernels._vote_serial
        compile_note("hough", (_kernels, [_kernels._edge_points, vote, _kernels._peaks]))
    e = HoughEdgesParams()
    with step("read"):
        gray = io.read_image(args.image, "gray")
    with step("edges"):
        edges = hough.canny_edges(gray, args.canny[0], args.canny[1], aperture=e.aperture, l2_gradient=e.l2_gradient,
                                  blur_sigma=e.blur_sigma)
    kwargs = {"refine": True} if args.refine else {}
    with step(f"lines ({method})"):
        lines = hough.get_impl(method)(edges, args.rho, math.radians(args.theta_deg), args.threshold, **kwargs)
    total = len(lines)
    if args.max_lines:
        lines = lines[: args.max_lines]
    result = {"lines": lines.tolist(), "total": total,
              "lines_deg": [{"rho_px": float(r), "theta_deg": round(math.degrees(t), 6), "votes": int(v)}
                            for r, t, v in lines]}
    if args.overlay:
        with step("overlay"):
            io.save_image(args.overlay, hough.draw_lines(io.read_image(args.image, "color"), lines, thickness=2))
        result["overlay"] = args.overlay
    if args.json:
        print(io.dumps_json(result))
    else:
        shown = f"{len(lines)} of {total}" if len(lines) < total else f"{total}"
        print(f"{shown} lines ({method}); rho [px], theta [deg], votes:")
        for d in result["lines_deg"]:
            print(f"{d['rho_px']:9.2f} {d['theta_deg']:8.3f} {d['votes']:6d}")
        if len(lines) < total:
            print(f"(--max-lines {args.max_lines}: {total - len(lines)} weaker lines not shown; --max-lines 0 for all)")
        if args.overlay:
            print(f"overlay: {args.overlay}")
    return 0
