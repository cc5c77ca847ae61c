"""``cvpipe hough IMAGE...``: straight lines of images (our Hough transform or OpenCV's, same parameters)."""

from __future__ import annotations

import argparse
import math
import sys

from ..params import HoughEdgesParams, HoughLinesParams
from . import add_result_arguments, final_output, note, overlay_paths, param_type, progress, read_images, step

HELP = "find straight lines (standard Hough transform, cv2.HoughLines conventions)"
EXAMPLE = "cvpipe hough data/samples/hough/synthetic_grid.png --threshold 100 --max-lines 10 --overlay outputs/examples/lines.png"

#: ``--method`` choices, the keys of ``cvpipe.hough.IMPLEMENTATIONS`` (a test keeps the two equal)
METHODS = ("ours", "opencv")
#: lines printed by default: enough for any photo's main structure, few enough to read
DEFAULT_MAX_LINES = 50
#: ``--overlay`` with several images: ``<folder>/<image stem>_lines.png``
SUFFIX = "_lines"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    e, p = HoughEdgesParams(), HoughLinesParams()
    parser.add_argument("image", nargs="+", help="input image(s) (converted to grayscale); with several, --json "
                                                 'prints a list of records, each with its "image"')
    parser.add_argument("--method", choices=METHODS, default=None,
                        help="our transform or cv2.HoughLines (default: ours)")
    parser.add_argument("--impl", choices=METHODS, default=None, help=argparse.SUPPRESS)  # deprecated spelling
    lines = type(p)
    parser.add_argument("--rho", type=param_type(lines, "rho"), default=p.rho,
                        help=f"distance resolution in pixels (default {p.rho})")
    parser.add_argument("--theta-deg", type=param_type(lines, "theta_deg"), default=p.theta_deg,
                        help=f"angle resolution in degrees (default {p.theta_deg})")
    parser.add_argument("--threshold", type=param_type(lines, "threshold"), default=p.threshold,
                        help=f"a line needs more than this many votes (default {p.threshold})")
    # each value checked by its field (LOW's range applies to both: HIGH >= LOW >= 0)
    parser.add_argument("--canny", type=param_type(type(e), "canny_low"), nargs=2, metavar=("LOW", "HIGH"),
                        default=(e.canny_low, e.canny_high),
                        help=f"Canny hysteresis thresholds (default {e.canny_low:g} {e.canny_high:g})")
    parser.add_argument("--max-lines", type=int, default=DEFAULT_MAX_LINES, metavar="K",
                        help=f"report the K lines with most votes, 0 = all (default {DEFAULT_MAX_LINES})")
    parser.add_argument("--refine", action="store_true", help="sub-bin (rho, theta) for --method ours")
    add_result_arguments(parser, "write the image with the reported lines drawn on it", items="images", suffix=SUFFIX,
                         json='print {"lines": [[rho, theta_rad, votes], ...] (cv2 convention), '
                              '"lines_deg": [{"rho_px", "theta_deg", "votes"}, ...], "total", "overlay"}')


def method_of(args: argparse.Namespace) -> str:
    """``--method``, or the deprecated ``--impl`` (with a note), default ``ours``."""
    if args.impl is not None:
        note("`--impl` is deprecated, use `--method`")
        if args.method is not None and args.method != args.impl:
            raise ValueError(f"`--impl {args.impl}` contradicts `--method {args.method}`; give only --method")
    return args.method or args.impl or "ours"


def image_lines(item: tuple, shared: tuple):
    """The (N, 3) lines of one image, an item of :func:`cvpipe.compute.map_items` (runs on a worker).

    Parameters
    ----------
    item : tuple
        ``(gray image or None, read error or None)`` from :func:`cvpipe.commands.read_images`.
    shared : tuple
        ``(HoughEdgesParams, HoughLinesParams, method)``: the sections with the command's flags in them.

    Returns
    -------
    numpy.ndarray
        ``(rho, theta, votes)`` rows, most votes first (``cvpipe.hough`` conventions).
    """
    from .. import hough

    gray, error = item
    if error is not None:
        raise error
    edges_params, lines_params, method = shared
    return hough.detect_lines(hough.edges_of(gray, edges_params), lines_params, method)


def run(args: argparse.Namespace) -> int:
    from .. import hough, io
    from ..compute import check_scheduler, item_error, map_items, raise_unexpected
    from ..errors import InputError

    method = method_of(args)
    if args.refine and method != "ours":
        raise InputError("`--refine` is only available with --method ours")
    if args.max_lines < 0:
        raise InputError(f"`--max-lines` must be >= 0 (0 = all), got {args.max_lines}")
    low, high = args.canny
    if not low <= high:
        raise InputError(f"`--canny` must be LOW <= HIGH, got {low:g} {high:g}")
    scheduler = check_scheduler(args.scheduler, "--scheduler")
    # each flag was checked by its field when parsed (param_type), and the LOW <= HIGH limit above
    edges_params = HoughEdgesParams(canny_low=low, canny_high=high)
    lines_params = HoughLinesParams(rho=args.rho, theta_deg=args.theta_deg, threshold=args.threshold,
                                    refine=args.refine)
    shared = (edges_params, lines_params, method)
    pictures = overlay_paths(args.image, args.overlay, SUFFIX)
    io.check_distinct_outputs([("`--overlay`", p) for p in pictures],
                              [(f"IMAGE {k + 1}", path) for k, path in enumerate(args.image)])
    with step(f"lines ({method})"):
        images = read_images(args.image, "gray")
        results = list(progress(map_items(image_lines, images, shared=shared, scheduler=scheduler,
                                          total=len(args.image)), "hough", total=len(args.image)))
    records, errors = [], []
    for path, res, picture in zip(args.image, results, pictures):
        if not res.ok:
            raise_unexpected(res)  # a bug or an interrupt ends the command, as in a plain loop
            exc = item_error(res, file=path)
            errors.append(exc)
            msg = res.error if str(path) in res.error else f"{path}: {res.error}"
            records.append({"image": path, "lines": None, "error": msg})
            continue
        lines = res.value
        total = len(lines)
        if args.max_lines:
            lines = lines[: args.max_lines]
        result = {"image": path, "lines": lines.tolist(), "total": total,
                  "lines_deg": [{"rho_px": float(r), "theta_deg": round(math.degrees(t), 6), "votes": int(v)}
                                for r, t, v in lines]}
        if picture:
            with step("overlay"):
                io.save_image(picture, hough.draw_lines(io.read_image(path, "color"), lines, thickness=2))
            result["overlay"] = picture
        records.append(result)
    if len(args.image) == 1:
        if errors:  # one image: its failure is the one-line error, with the exit status of its kind
            raise type(errors[0])(records[0]["error"], file=errors[0].file)
        del records[0]["image"]  # the single-image record is unchanged: {"lines", "total", "lines_deg", "overlay"}
    final_output()
    for rec in records:
        if "error" in rec:
            print(f"cvpipe: error: {rec['error']}", file=sys.stderr)
    if args.json:
        print(io.dumps_json(records if len(args.image) > 1 else records[0]))
        return max((e.exit_code for e in errors), default=0)
    for path, rec in zip(args.image, records):
        if "error" in rec:
            print(f"{path}: error")
            continue
        lines, total = rec["lines"], rec["total"]
        shown = f"{len(lines)} of {total}" if len(lines) < total else f"{total}"
        head = f"{path}: " if len(args.image) > 1 else ""
        print(f"{head}{shown} lines ({method}); rho [px], theta [deg], votes:")
        for d in rec["lines_deg"]:
            print(f"{d['rho_px']:9.2f} {d['theta_deg']:8.3f} {d['votes']:6d}")
        if len(lines) < total:
            print(f"(--max-lines {args.max_lines}: {total - len(lines)} weaker lines not shown; --max-lines 0 for all)")
        if "overlay" in rec:
            print(f"overlay: {rec['overlay']}")
    return max((e.exit_code for e in errors), default=0)
