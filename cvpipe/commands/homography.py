"""``cvpipe homography A B``: the homography mapping image A to image B from feature matches."""

from __future__ import annotations

import argparse

from ..params import FeaturesParams, HomographyEstimateParams, MatchParams
from . import (DETECTORS, add_feature_arguments, add_param_options, add_result_arguments,  # noqa: F401
               final_output, step)  # DETECTORS: the --detector choices (a test keeps them equal)

HELP = "estimate the homography mapping image A to image B (ours or OpenCV's RANSAC/MAGSAC)"
EXAMPLE = ("cvpipe homography data/samples/homography/0_astronaut_a.jpg data/samples/homography/0_astronaut_b.jpg "
           "--overlay outputs/examples/check.png --json")

#: ``--method`` choices: the keys of ``cvpipe.homography.METHODS`` (params.yaml's spelling; a test keeps them equal)
METHODS = ("ours", "opencv_ransac", "opencv_magsac")


def method_name(text: str) -> str:
    """A method name in params.yaml's spelling: ``opencv-ransac`` and ``opencv_ransac`` are the same method."""
    return text.strip().lower().replace("-", "_")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    f, m, e = FeaturesParams(), MatchParams(), HomographyEstimateParams()
    parser.add_argument("a", help="image A (the homography maps A's pixels to B's)")
    parser.add_argument("b", help="image B")
    parser.add_argument("--method", type=method_name, choices=METHODS, default="ours",
                        help="estimator (default: ours; opencv-ransac etc. with a hyphen are accepted too)")
    add_feature_arguments(parser, f.detector, f.max_features, m.ratio)
    add_param_options(parser, e, {"threshold": "inlier reprojection threshold in pixels of B",
                                  "confidence": "RANSAC confidence", "max_iters": "RANSAC iterations at most",
                                  "seed": "random seed"})
    add_result_arguments(parser, overlay="write B warped onto A as a checkerboard with A (straight edges across "
                                         "tiles = good H)", json='print {"H", "matches", "inliers", "overlay"} as JSON')


def run(args: argparse.Namespace) -> int:
    from .. import io
    from ..errors import EstimationError

    # every number was checked by its field when parsed (add_feature_arguments, add_param_options)
    estimate = HomographyEstimateParams(**{k: getattr(args, k) for k in HomographyEstimateParams.model_fields})
    io.check_distinct_outputs([("`--overlay`", args.overlay)], [("A", args.a), ("B", args.b)])
    from .. import homography

    with step("read"):
        a = io.read_image(args.a, "gray")
        b = io.read_image(args.b, "gray")
    with step(f"features ({args.detector}) and matches"):
        src, dst = homography.correspondences(a, b, args.detector, args.max_features, args.ratio)
    if len(src) < 4:
        raise EstimationError(
            f"only {len(src)} matches between {args.a} and {args.b} (need 4); "
            "try another --detector, more --max-features or a larger --ratio"
        )
    with step(f"estimate ({args.method})"):
        fit = homography.estimate_with(src, dst, estimate, args.method)
    result = {"H": fit.H, "matches": len(src), "inliers": fit.num_inliers}
    if args.overlay:
        from ..overlays import checkerboard_warp

        with step("overlay"):
            io.save_image(args.overlay, checkerboard_warp(io.read_image(args.a, "color"),
                                                          io.read_image(args.b, "color"), fit.H))
        result["overlay"] = args.overlay
    final_output()
    if args.json:
        print(io.dumps_json(result))
    else:
        print(f"matches {len(src)}, inliers {fit.num_inliers} ({args.method})")
        for row in fit.H:
            print(" ".join(f"{v: .9g}" for v in row))
        if args.overlay:
            print(f"overlay: {args.overlay}")
    return 0
