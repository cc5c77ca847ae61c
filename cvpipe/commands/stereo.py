"""``cvpipe stereo LEFT RIGHT --max-disp N|auto [--method ...] [--rectify] [--calib FILE] -o OUT.npy|OUT.png
[--depth Z.npy|Z.png] [--ply P.ply] [--json]``: disparity of a pair (rectified first with ``--rectify``), and with a
calibration its depth and coloured point cloud."""

from __future__ import annotations

import argparse
import os
import sys
from typing import TYPE_CHECKING

from ..params import StereoBmParams, StereoRectifyParams, StereoSgbmParams, StereoSgmParams
from . import final_output, note, param_type, step

if TYPE_CHECKING:
    import numpy as np

    from ..stereo import calibration

HELP = ("disparity map of a stereo pair (float32 .npy of the LEFT image, NaN = invalid), rectified first with "
        "--rectify; depth and a point cloud with --calib")
EXAMPLE = ("cvpipe stereo data/samples/stereo/motorcycle/left.png data/samples/stereo/motorcycle/right.png "
           "--max-disp 64 -o outputs/examples/disp.npy "
           "--overlay outputs/examples/disp.png --json")

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
    parser.add_argument("left", help="left image of the pair (rectified, or use --rectify)")
    parser.add_argument("right", help="right image (same size; both colour or both grayscale)")
    parser.add_argument("--max-disp", type=_max_disp_arg, required=True,
                        help="number of disparities searched, 0 .. N-1 (like OpenCV's numDisparities), or `auto`: "
                             "estimated from the (rectified) feature matches")
    parser.add_argument("--method", type=method_name, choices=tuple(CLI_METHODS), default="sgm",
                        help="our semi-global matching (default) or an OpenCV baseline (opencv-sgbm also accepted)")
    parser.add_argument("-o", "--out", required=True,
                        help="output .npy: (H, W) float32 disparity, NaN = invalid; or .png: a colour-mapped picture")
    parser.add_argument("--rectify", action="store_true",
                        help="rectify first: from --calib when it holds the rig's pose (OpenCV YAML), else from "
                             "feature matches (fundamental matrix); the outputs are in the rectified LEFT frame")
    parser.add_argument("--calib", help="calibration: Middlebury calib.txt or OpenCV stereo YAML (K1 D1 K2 D2 R T)")
    parser.add_argument("--depth", help="depth output (needs --calib): .npy float32 in the baseline's unit, "
                                        "NaN = invalid; or .png picture")
    parser.add_argument("--ply", help="coloured point cloud of the valid pixels, binary PLY (needs --calib)")
    parser.add_argument("--overlay", metavar="PNG", help="write the colour-mapped disparity with a colour bar (px)")
    parser.add_argument("--seed", type=param_type(StereoRectifyParams, "seed"), default=StereoRectifyParams().seed,
                        help="seed of the RANSAC sampling (--rectify)")
    parser.add_argument("--json", action="store_true",
                        help='print {"valid_fraction", "max_disp", "disparity_only", ...; with --rectify "H_left", '
                             '"H_right", "vertical_error_median_px", "vertical_error_p95_px"} on stdout')


def _read(path: str) -> np.ndarray:
    """Gray stays gray and colour becomes BGR, so that a gray/colour mix is refused by the library.

    16-bit (and float) images are scaled to 8 bits as :func:`cvpipe.io.read_image` does for the other commands.
    """
    import cv2
    import numpy as np

    from .. import io

    img = io.read_image(path, mode="unchanged")
    if img.dtype != np.uint8:
        img = cv2.convertScaleAbs(img, alpha=255.0 / float(np.iinfo(img.dtype).max)) if img.dtype.kind in "ui" \
            else cv2.convertScaleAbs(np.nan_to_num(img), alpha=255.0)
    return img if img.ndim == 2 else io.to_bgr(img)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from .. import io, stereo
    from ..errors import InputError
    from ..stereo import depth as depth_mod

    for flag, path, kinds in (("`-o`", args.out, (".npy", ".png")), ("`--depth`", args.depth, (".npy", ".png")),
                              ("`--ply`", args.ply, (".ply",)), ("`--overlay`", args.overlay, (".png",))):
        if path is not None:
            io.check_output_path(path, flag, kinds)
    io.check_distinct_outputs([("`-o`", args.out), ("`--depth`", args.depth), ("`--ply`", args.ply),
                               ("`--overlay`", args.overlay)],
                              [("LEFT", args.left), ("RIGHT", args.right), ("`--calib`", args.calib)])
    left, right = _read(args.left), _read(args.right)
    calib = _read_calib(args.calib) if args.calib else None
    if calib is None and (args.depth or args.ply):
        raise InputError("`--depth` and `--ply` need `--calib FILE` (focal length and baseline)")
    info, geometry, left, right, auto_disp = _prepare(args, left, right, calib)
    max_disp = auto_disp if args.max_disp == "auto" else args.max_disp
    method, params_cls = args.method, CLI_METHODS[args.method]
    with step(f"disparity ({method})"):
        disp = stereo.disparity_with(left, right, max_disp, params_cls(), method)
    z = None
    if geometry is not None:  # before anything is written: a calibration that gives no depth writes nothing
        try:
            z = depth_mod.depth_from_disparity(disp, geometry.focal, geometry.baseline, geometry.doffs)
        except InputError as exc:
            raise InputError(f"{args.calib}: {exc}", file=args.calib) from None
    final_output()
    # every file or none: a failure of a later one (a full disk) leaves all the older files untouched
    with io.all_or_none() as outs:
        _save_map(outs.path(args.out), disp.astype(np.float32), 0.0, float(max_disp), "px", "disparity")
        out = {"valid_fraction": float(np.isfinite(disp).mean()), "max_disp": int(max_disp), "out": args.out,
               **info}
        if args.overlay:
            _save_map(outs.path(args.overlay), disp.astype(np.float32), 0.0, float(max_disp), "px", "disparity")
            out["overlay"] = args.overlay
        if z is not None:
            out.update({"depth_unit": geometry.unit, "focal_px": geometry.focal, "baseline": geometry.baseline,
                        "doffs_px": geometry.doffs, "depth_exact": geometry.exact})
            if args.depth:
                _save_map(outs.path(args.depth), z, None, None, geometry.unit, "depth")
            if args.ply:
                xyz, rgb = depth_mod.point_cloud(z, left, geometry.focal, geometry.cx, geometry.cy)
                data = depth_mod.ply_bytes(xyz, rgb,
                                           comment=f"units {geometry.unit}; camera frame x right y down z fwd")
                outs.path(args.ply).write_bytes(data)
                out["points"] = int(len(xyz))
    if "note" in out:  # after the work, so that a failure stays a single line on stderr
        note(f"note: {out['note']}")
    if args.json:
        print(io.dumps_json(out))
    return 0


def _max_disp_arg(text: str):
    if text == "auto":
        return "auto"
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1 or `auto`, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1 or `auto`, got {text!r}")
    return v


def _read_calib(path: str) -> calibration.Calibration:
    from .. import io
    from ..errors import InputError
    from ..stereo import calibration

    try:
        return calibration.parse_calibration(io.read_text(path, "calibration"), path)
    except InputError as exc:
        exc.file = exc.file or path
        raise


def _prepare(args, left, right, calib):
    """Rectify when asked; returns (JSON fields, depth geometry or None, left, right, auto max_disp)."""
    from .. import io
    from ..stereo import rectify
    from ..errors import InputError

    if left.shape[:2] != right.shape[:2]:
        raise InputError(f"{args.right}: size {right.shape[1]}x{right.shape[0]} differs from the left image's "
                         f"{left.shape[1]}x{left.shape[0]}")
    h, w = left.shape[:2]
    if calib is not None:
        calib.check_size((w, h))
        if not args.rectify:
            rectify.rectified_depth_geometry(calib)  # refuses an unrectified rig before the matching work
    info: dict = {"disparity_only": calib is None}
    if calib is None:
        info["note"] = "no calibration (--calib): only disparity is produced, no depth"
    need_matches = args.rectify or args.max_disp == "auto"
    p1 = p2 = None
    if need_matches:
        from ..homography import correspondences

        p1, p2 = correspondences(io.to_gray(left), io.to_gray(right))
        info["matches"] = int(len(p1))
    if not args.rectify:
        geometry = None if calib is None else rectify.rectified_depth_geometry(calib)
        auto = rectify.max_disp_from_matches(p1, p2) if args.max_disp == "auto" else None
        return info, geometry, left, right, auto
    if calib is not None and not calib.rectified:
        rect = rectify.rectify_calibrated(calib, (w, h), p1, p2)
        info["rectification"] = "calibrated"
    else:
        rect = rectify.rectify_uncalibrated(p1, p2, (w, h), calibration=calib, rng=args.seed)
        info.update({"rectification": "uncalibrated", "inliers": rect.fit.num_inliers})
    info.update({"H_left": rect.H_left, "H_right": rect.H_right, "shift_px": rect.shift,
                 "disparity_range_px": list(rect.disparity_range),
                 "vertical_error_median_px": rect.vertical_error_median,
                 "vertical_error_p95_px": rect.vertical_error_p95})
    left, right = rectify.warp_pair(left, right, rect)
    return info, rect.depth, left, right, rect.max_disp


def _save_map(path: str | os.PathLike, values: np.ndarray, lo, hi, unit: str, label: str) -> None:
    """.npy: the float32 array; .png: the colour-mapped picture with its colour bar."""
    import numpy as np

    from .. import io
    from ..stereo import depth as depth_mod

    if str(path).lower().endswith(".png"):
        io.save_image(path, depth_mod.colorize(values, lo, hi, unit=unit, label=label))
        return
    with io.atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, values.astype(np.float32), allow_pickle=False)
