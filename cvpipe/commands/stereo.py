"""``cvpipe stereo LEFT RIGHT --max-disp N [--method ...] -o OUT.npy [--json]``: disparity of a rectified pair."""

from __future__ import annotations

import argparse
import dataclasses

from typing import TYPE_CHECKING

from ..params import StereoBmParams, StereoSgbmParams, StereoSgmParams
from . import compile_note, step

if TYPE_CHECKING:
    import numpy as np

HELP = "disparity map of a rectified stereo pair (float32 .npy of the LEFT image, NaN = invalid)"
EXAMPLE = ("cvpipe stereo data/samples/stereo/left.png data/samples/stereo/right.png --max-disp 64 -o disp.npy "
           "--overlay disp.png --json")

#: ``--method`` (params.yaml's spelling, the keys of cvpipe.stereo.METHODS) -> the params dataclass whose defaults
#: the command uses; ``opencv-sgbm`` with a hyphen is accepted too
CLI_METHODS = {
    "sgm": StereoSgmParams,
    "opencv_sgbm": StereoSgbmParams,
    "opencv_bm": StereoBmParams,
}


def method_name(text: str) -> str:
    """A method name in params.yaml's spelling: ``opencv-sgbm`` and ``opencv_sgbm`` are the same method."""
    return text.strip().lower().replace("-", "_")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("left", help="left image of the rectified pair")
    parser.add_argument("right", help="right image (same size; both colour or both grayscale)")
    parser.add_argument("--max-disp", type=int, required=True,
                        help="number of disparities searched, 0 .. N-1 (like OpenCV's numDisparities)")
    parser.add_argument("--method", type=method_name, choices=tuple(CLI_METHODS), default="sgm",
                        help="our semi-global matching (default) or an OpenCV baseline (opencv-sgbm also accepted)")
    parser.add_argument("-o", "--out", required=True,
                        help="output .npy: (H, W) float32 disparity, NaN = invalid; or .png: the --overlay picture")
    parser.add_argument("--overlay", metavar="PNG", help="write the colour-mapped disparity with a colour bar (px)")
    parser.add_argument("--json", action="store_true", help='print {"valid_fraction", "out", "overlay"} on stdout')


def _read(path: str) -> np.ndarray:
    """Gray stays gray and colour becomes BGR, so that a gray/colour mix is refused by the library."""
    import numpy as np

    from .. import io
    from ..errors import InputError

    img = io.read_image(path, mode="unchanged")
    if img.dtype != np.uint8:
        raise InputError(f"{path}: expected an 8-bit image, got {img.dtype}")
    return img if img.ndim == 2 else io.to_bgr(img)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from .. import io, stereo
    from ..errors import InputError
    from ..overlays import disparity_colormap

    if not args.out.endswith((".npy", ".png")):
        raise InputError(f"`--out` must end in .npy (disparity array) or .png (picture), got {args.out}")
    pictures = [p for p in (args.overlay, args.out if args.out.endswith(".png") else None) if p]
    left, right = _read(args.left), _read(args.right)
    method, params_cls = args.method, CLI_METHODS[args.method]
    options = dataclasses.asdict(params_cls())
    if method == "sgm":
        compile_note("stereo", stereo)
    with step(f"disparity ({method})"):
        disp = stereo.compute_disparity(left, right, args.max_disp, method, **options)
    result = {"valid_fraction": float(np.isfinite(disp).mean())}
    if args.out.endswith(".npy"):
        with io.atomic_path(args.out) as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, disp.astype(np.float32), allow_pickle=False)
        result["out"] = args.out
    for picture in pictures:
        io.save_image(picture, disparity_colormap(disp, max_disp=args.max_disp - 1))
    if args.overlay:
        result["overlay"] = args.overlay
    if args.out.endswith(".png"):
        result["out"] = args.out
    if args.json:
        print(io.dumps_json(result))
    return 0
