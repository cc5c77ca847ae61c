"""``cvpipe stereo LEFT RIGHT --max-disp N [--method ...] -o OUT.npy [--json]``: disparity of a rectified pair."""

from __future__ import annotations

import argparse
import dataclasses

import cv2
import numpy as np

from .. import io, stereo
from ..params import StereoBmParams, StereoSgbmParams, StereoSgmParams

HELP = "disparity map of a rectified stereo pair (float32 .npy of the LEFT image, NaN = invalid)"
EXAMPLE = "cvpipe stereo data/samples/stereo/left.png data/samples/stereo/right.png --max-disp 64 -o disp.npy --json"

#: command-line method name -> (cvpipe.stereo.METHODS key, params dataclass whose defaults the command uses)
CLI_METHODS = {
    "sgm": ("sgm", StereoSgmParams),
    "opencv-sgbm": ("opencv_sgbm", StereoSgbmParams),
    "opencv-bm": ("opencv_bm", StereoBmParams),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("left", help="left image of the rectified pair")
    parser.add_argument("right", help="right image (same size; both colour or both grayscale)")
    parser.add_argument("--max-disp", type=int, required=True,
                        help="number of disparities searched, 0 .. N-1 (like OpenCV's numDisparities)")
    parser.add_argument("--method", choices=sorted(CLI_METHODS), default="sgm",
                        help="our semi-global matching (default) or an OpenCV baseline")
    parser.add_argument("-o", "--out", required=True, help="output .npy: (H, W) float32 disparity, NaN = invalid")
    parser.add_argument("--json", action="store_true", help='print {"valid_fraction": ...} on stdout')


def _read(path: str) -> np.ndarray:
    """Gray stays gray and colour becomes BGR, so that a gray/colour mix is refused by the library.

    16-bit (and float) images are scaled to 8 bits as :func:`cvpipe.io.read_image` does for the other commands.
    """
    img = io.read_image(path, mode="unchanged")
    if img.dtype != np.uint8:
        img = cv2.convertScaleAbs(img, alpha=255.0 / float(np.iinfo(img.dtype).max)) if img.dtype.kind in "ui" \
            else cv2.convertScaleAbs(np.nan_to_num(img), alpha=255.0)
    return img if img.ndim == 2 else io.to_bgr(img)


def run(args: argparse.Namespace) -> int:
    io.check_output_path(args.out, "`--out`", (".npy",))
    left, right = _read(args.left), _read(args.right)
    method, params_cls = CLI_METHODS[args.method]
    options = dataclasses.asdict(params_cls())
    disp = stereo.compute_disparity(left, right, args.max_disp, method, **options)
    with io.atomic_path(args.out) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, disp.astype(np.float32), allow_pickle=False)
    if args.json:
        print(io.dumps_json({"valid_fraction": float(np.isfinite(disp).mean())}))
    return 0
