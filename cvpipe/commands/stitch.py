"""``cvpipe stitch IMAGE... -o PANO.png``: one seamless, cropped panorama from overlapping photos in any order."""

from __future__ import annotations

import argparse
import typing
from pathlib import Path

from ..params import (PanoramaBlendParams, PanoramaFeaturesParams, PanoramaHomographiesParams, PanoramaMatchParams,
                      PanoramaWarpParams, replace)
from . import (DETECTORS, add_feature_arguments, add_param_options, add_result_arguments,  # noqa: F401
               final_output, log, progress, step, with_flags)

HELP = "stitch overlapping photos (any order) into one seamless, cropped panorama"
EXAMPLE = "cvpipe stitch data/samples/panorama/coffee/*.jpg -o outputs/examples/pano.png --projection plane --json"

_F, _M, _W, _B = PanoramaFeaturesParams(), PanoramaMatchParams(), PanoramaWarpParams(), PanoramaBlendParams()
_H = PanoramaHomographiesParams()
#: ``--projection`` choices, from the params model: ``cvpipe.panorama.warp.PROJECTIONS`` (a test keeps them equal;
#: DETECTORS likewise)
PROJECTIONS = typing.get_args(PanoramaWarpParams.model_fields["projection"].annotation)
#: parameters that the panorama's hints name, spelt as flags in this command's messages
_HINTED = ("min_inliers", "min_confidence", "max_features", "work_megapix", "refine")


#: ``--preset`` choices and default: cvpipe.panorama.presets' (spelt here so that ``--help`` imports no cv2; a test
#: keeps them equal)
PRESET_CHOICES, DEFAULT_PRESET = ("default", "fast"), "default"
#: flags whose default comes from the preset (None on the command line: not given)
_PRESET_FLAGS = {"detector": ("features", "detector"), "max_features": ("features", "max_features"),
                 "pair_refine": ("matching", "pair_refine")}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("images", nargs="+", metavar="IMAGE", help="two or more overlapping photos, any order")
    parser.add_argument("-o", "--out", required=True, metavar="PANO.png", help="where to write the panorama")
    parser.add_argument("--preset", choices=PRESET_CHOICES, default=DEFAULT_PRESET,
                        help="'default': SIFT features, the lowest pairwise error and the most pairs found, about "
                             "0.3-1.4x cv2.Stitcher's time (SIFT is half of it on large photos); use it when the "
                             "photos overlap little or the panorama is the end product. 'fast': ORB features with "
                             "each pair refitted to Lucas-Kanade tracks, about 0.2-0.7x cv2.Stitcher's time and a "
                             "lower ground-truth error than cv2.Stitcher on every set we measured; use it for "
                             "previews, many photos or many sets. --detector, --max-features and --pair-refine given "
                             "with a preset win over it (default %(default)s)")
    add_param_options(parser, _W, {"projection": "panorama surface"})
    add_param_options(parser, _B, {"blender": "blending",
                                   "gain_compensation": "exposure compensation between the photos: one gain per "
                                                        "photo, per colour channel, per block of --gain-block px, "
                                                        "or both (OpenCV's compensators)",
                                   "gain_block": "block size in pixels of the block compensators"})
    add_feature_arguments(parser, _F.detector, _F.max_features, _M.ratio)
    add_param_options(parser, _M, {"min_inliers": "RANSAC inliers a pair of photos needs",
                                   "min_confidence": "pair confidence inliers / (8 + 0.3 matches) needed",
                                   "pair_refine": "refit each accepted pair to Lucas-Kanade tracks (lk) or not; "
                                                  "--preset fast sets lk"})
    add_param_options(parser, _H, {"refine": "global refinement of the homographies"})
    add_param_options(parser, _F, {"work_megapix": "registration resolution in megapixels, <= 0 for full"})
    add_param_options(parser, _W, {"compose_megapix": "output resolution in megapixels per image, <= 0 for full"})
    parser.add_argument("--no-crop", action="store_true", help="keep the empty borders (default: crop them)")
    add_param_options(parser, _M, {"seed": "RANSAC seed"})
    parser.set_defaults(**{k: None for k in _PRESET_FLAGS})  # None: not given, the preset decides
    add_result_arguments(parser, overlay="write the panorama with each used photo's outline and name (--projection "
                                         "plane)",
                         json='print {"out", "used": [paths], "dropped": [{"image": path, "reason"}], "homographies", '
                              '"size", ...} on stdout')


#: peak bytes per composed input pixel (warped image, masks, seams and multiband pyramids, canvas share);
#: measured 6.8 GB for two 81 MP photos composed at full size (42 B/px) with some headroom
COMPOSE_BYTES_PER_PIXEL = 50


def _compose_within_budget(images: list, compose_megapix: float) -> float:
    """``compose_megapix``, lowered (with a note) when composing at it would exceed the memory budget."""
    import warnings

    from ..errors import BudgetWarning, memory_budget

    cap = memory_budget() / (COMPOSE_BYTES_PER_PIXEL * len(images)) / 1e6
    largest = max(img.shape[0] * img.shape[1] for img in images) / 1e6
    wanted = largest if compose_megapix <= 0 else min(compose_megapix, largest)
    if wanted <= cap:
        return compose_megapix
    warnings.warn(BudgetWarning(f"composing at {cap:.1f} megapixels per image instead of {wanted:.1f} to stay "
                                f"within the memory budget of {memory_budget() / 1e9:.3g} GB "
                                "(--compose-megapix, CVPIPE_MEMORY_BUDGET_GB)"), stacklevel=2)
    return cap


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from .. import io
    from ..errors import EstimationError, InputError
    from ..panorama import stitch

    # before any work: a panorama that cannot be written must not cost the stitching first
    io.check_output_path(args.out, "`-o`", io.IMAGE_WRITE_SUFFIXES)
    io.check_distinct_outputs([("`-o`", args.out), ("`--overlay`", args.overlay)],
                              [(f"IMAGE {k + 1}", path) for k, path in enumerate(args.images)])
    _check_distinct_images(args.images)
    images, positions, dropped = [], [], []
    for k, path in enumerate(progress(args.images, "read")):
        try:
            images.append(io.read_image(path, "color"))
            positions.append(k)
        except InputError as exc:
            dropped.append({"image": k, "reason": f"unreadable: {exc}"})
    if args.overlay and args.projection != "plane":
        raise InputError(f"`--overlay` draws the photos' outlines through plane homographies; it needs "
                         f"--projection plane, got {args.projection}")
    if len(images) < 2:
        why = "; ".join(d["reason"] for d in dropped)
        raise InputError(f"a panorama needs at least two readable images, got {len(images)}" + (f" ({why})" if why
                                                                                               else ""))
    from ..panorama.presets import preset_sections

    chosen = preset_sections(args.preset)
    given = {k: (getattr(chosen[sec], field) if getattr(args, k) is None else getattr(args, k))
             for k, (sec, field) in _PRESET_FLAGS.items()}
    try:
        params = dict(
            features=replace(chosen["features"], detector=given["detector"], work_megapix=args.work_megapix,
                             max_features=given["max_features"]),
            matching=replace(chosen["matching"], seed=args.seed, ratio=args.ratio, min_inliers=args.min_inliers,
                             min_confidence=args.min_confidence, pair_refine=given["pair_refine"]),
            homographies=replace(_H, refine=args.refine),
            warp=replace(_W, projection=args.projection,
                         compose_megapix=_compose_within_budget(images, args.compose_megapix)),
            blend=replace(_B, blender=args.blender, gain_compensation=args.gain_compensation,
                          gain_block=args.gain_block))
    except ValueError as exc:
        raise InputError(with_flags(str(exc), _HINTED + ("ratio", "compose_megapix", "gain_block"))) from exc
    try:
        with step(f"stitch {len(images)} images"):
            pano = stitch(images, **params, crop=not args.no_crop, rng=args.seed,
                           ids=[args.images[k] for k in positions])  # messages name the files
    except EstimationError as exc:
        raise EstimationError(with_flags(str(exc), _HINTED)) from exc
    for name, seconds in pano.timings.items():  # the library's own step timings, shown with -v
        log.info("  %s: %.3f s", name, seconds)
    reg = pano.registration
    for k, why in reg.dropped:
        dropped.append({"image": positions[k], "reason": with_flags(why, _HINTED)})
    dropped.sort(key=lambda d: d["image"])
    for d in dropped:  # inputs are named by their paths, as given
        d["image"] = args.images[d["image"]]
    plane = args.projection == "plane"
    homs = [(pano.to_panorama @ pano.homographies[a]) if plane else pano.homographies[a] for a in reg.used]
    homs = [H / H[2, 2] for H in homs]
    final_output()
    with io.all_or_none() as outs:  # the panorama and its overlay, both or neither
        io.save_image(outs.path(args.out), pano.image)
        if args.overlay:
            from ..overlays import draw_quads

            shapes = [images[a].shape for a in reg.used]
            quads = [_outline(H, sh[1], sh[0]) for H, sh in zip(homs, shapes)]
            io.save_image(outs.path(args.overlay), draw_quads(pano.image, quads, [Path(args.images[positions[a]]).name
                                                                                  for a in reg.used]))
    result = {
        "out": args.out,
        **({"overlay": args.overlay} if args.overlay else {}),
        "used": [args.images[positions[a]] for a in reg.used],
        "dropped": dropped,
        "homographies": [np.round(H, 10) for H in homs],
        "homographies_frame": "panorama" if plane else "reference",
        "reference": args.images[positions[reg.reference]],
        "size": [int(pano.image.shape[1]), int(pano.image.shape[0])],
        "model": reg.model,
    }
    if args.json:
        print(io.dumps_json(result))
    else:
        print(f"{args.out}: {result['size'][0]}x{result['size'][1]} from {len(result['used'])} images: "
              + ", ".join(result["used"]) + "".join(f"\n  dropped {d['image']}: {d['reason']}" for d in dropped))
    return 0


def _check_distinct_images(paths: list[str]) -> None:
    """Refuse a photo given twice (the same resolved path, also through a symlink): it would be stitched onto
    itself as one more image."""
    from ..errors import InputError

    first: dict[Path, int] = {}
    for k, path in enumerate(paths):
        j = first.setdefault(Path(path).resolve(), k)
        if j != k:
            raise InputError(f"IMAGE {k + 1} ({path}) is the same file as IMAGE {j + 1} ({paths[j]}); give each photo "
                             "once", file=path)


def _outline(H, width: int, height: int):
    """The outline of a ``width`` x ``height`` photo (corner pixel centres) mapped by ``H``, (4, 2)."""
    import numpy as np

    c = np.array([[0, 0, 1], [width - 1, 0, 1], [width - 1, height - 1, 1], [0, height - 1, 1]], float) @ H.T
    return c[:, :2] / c[:, 2:]
