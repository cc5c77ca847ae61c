"""``cvpipe homography A B``: the homography mapping image A to image B from feature matches."""

from __future__ import annotations

import argparse

from .. import io
from ..errors import EstimationError, InputError
from ..features import DETECTORS
from ..homography import METHODS, correspondences, estimate
from ..params import FeaturesParams, HomographyEstimateParams, MatchParams

HELP = "estimate the homography mapping image A to image B (ours or OpenCV's RANSAC/MAGSAC)"
EXAMPLE = "cvpipe homography data/samples/homography/0_astronaut_a.jpg data/samples/homography/0_astronaut_b.jpg --json"

#: CLI spelling -> registry name in cvpipe.homography.METHODS
CLI_METHODS = {name.replace("_", "-"): name for name in METHODS}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    f, m, e = FeaturesParams(), MatchParams(), HomographyEstimateParams()
    parser.add_argument("a", help="image A (the homography maps A's pixels to B's)")
    parser.add_argument("b", help="image B")
    parser.add_argument("--method", choices=sorted(CLI_METHODS), default="ours", help="estimator (default: ours)")
    parser.add_argument("--detector", choices=sorted(DETECTORS), default=f.detector,
                        help=f"keypoint detector (default: {f.detector})")
    parser.add_argument("--max-features", type=int, default=f.max_features, help=f"default: {f.max_features}")
    parser.add_argument("--ratio", type=float, default=m.ratio, help=f"Lowe's ratio test (default: {m.ratio})")
    parser.add_argument("--threshold", type=float, default=e.threshold,
                        help=f"inlier reprojection threshold in pixels of B (default: {e.threshold})")
    parser.add_argument("--confidence", type=float, default=e.confidence, help=f"default: {e.confidence}")
    parser.add_argument("--max-iters", type=int, default=e.max_iters, help=f"default: {e.max_iters}")
    parser.add_argument("--seed", type=int, default=e.seed, help=f"random seed (default: {e.seed})")
    parser.add_argument("--json", action="store_true", help='print {"H", "matches", "inliers"} as JSON')


def run(args: argparse.Namespace) -> int:
    if args.max_features < 1:
        raise InputError(f"`--max-features` must be >= 1, got {args.max_features}")
    if not 0.0 < args.ratio <= 1.0:
        raise InputError(f"`--ratio` must be in (0, 1], got {args.ratio}")
    a = io.read_image(args.a, "gray")
    b = io.read_image(args.b, "gray")
    src, dst = correspondences(a, b, args.detector, args.max_features, args.ratio)
    if len(src) < 4:
        raise EstimationError(
            f"only {len(src)} matches between {args.a} and {args.b} (need 4); "
            "try another --detector, more --max-features or a larger --ratio"
        )
    fit = estimate(CLI_METHODS[args.method], src, dst, threshold=args.threshold, confidence=args.confidence,
                   max_iters=args.max_iters, rng=args.seed)
    result = {"H": fit.H, "matches": len(src), "inliers": fit.num_inliers}
    if args.json:
        print(io.dumps_json(result))
    else:
        print(f"matches {len(src)}, inliers {fit.num_inliers} ({args.method})")
        for row in fit.H:
            print(" ".join(f"{v: .9g}" for v in row))
    return 0
