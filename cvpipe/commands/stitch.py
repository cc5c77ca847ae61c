"""``cvpipe stitch IMAGE... -o PANO.png``: one seamless, cropped panorama from overlapping photos in any order."""

from __future__ import annotations

import argparse
import warnings
from dataclasses import replace

import numpy as np

from .. import io
from ..errors import BudgetWarning, InputError, memory_budget
from ..params import (PanoramaBlendParams, PanoramaFeaturesParams, PanoramaHomographiesParams, PanoramaMatchParams,
                      PanoramaWarpParams)
from ..warping import PROJECTIONS

HELP = "stitch overlapping photos (any order) into one seamless, cropped panorama"
EXAMPLE = "cvpipe stitch data/samples/panorama/coffee/*.jpg -o pano.png --projection plane --json"

_F, _M, _W, _B = PanoramaFeaturesParams(), PanoramaMatchParams(), PanoramaWarpParams(), PanoramaBlendParams()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("images", nargs="+", metavar="IMAGE", help="two or more overlapping photos, any order")
    parser.add_argument("-o", "--out", required=True, metavar="PANO.png", help="where to write the panorama")
    parser.add_argument("--projection", choices=PROJECTIONS, default=_W.projection,
                        help=f"panorama surface (default {_W.projection})")
    parser.add_argument("--blender", choices=("multiband", "feather"), default=_B.blender,
                        help=f"blending (default {_B.blender})")
    parser.add_argument("--detector", default=_F.detector, help=f"feature detector (default {_F.detector})")
    parser.add_argument("--work-megapix", type=float, default=_F.work_megapix,
                        help=f"registration resolution in megapixels, <= 0 for full (default {_F.work_megapix})")
    parser.add_argument("--compose-megapix", type=float, default=_W.compose_megapix,
                        help=f"output resolution in megapixels per image, <= 0 for full (default {_W.compose_megapix})")
    parser.add_argument("--no-crop", action="store_true", help="keep the empty borders (default: crop them)")
    parser.add_argument("--seed", type=int, default=_M.seed, help=f"RANSAC seed (default {_M.seed})")
    parser.add_argument("--json", action="store_true", help="print the result as JSON on stdout")


#: peak bytes per composed input pixel (warped image, masks, seams and multiband pyramids, canvas share);
#: measured 6.8 GB for two 81 MP photos composed at full size (42 B/px) with some headroom
COMPOSE_BYTES_PER_PIXEL = 50


def _compose_within_budget(images: list, compose_megapix: float) -> float:
    """``compose_megapix``, lowered (with a note) when composing at it would exceed the memory budget."""
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
    from ..panorama import stitch

    # before any work: a panorama that cannot be written must not cost the stitching first
    io.check_output_path(args.out, "`-o`", io.IMAGE_WRITE_SUFFIXES)
    images, positions, dropped = [], [], []
    for k, path in enumerate(args.images):
        try:
            images.append(io.read_image(path, "color"))
            positions.append(k)
        except InputError as exc:
            dropped.append({"image": k, "reason": f"unreadable: {exc}"})
    if len(images) < 2:
        why = "; ".join(d["reason"] for d in dropped)
        raise InputError(f"a panorama needs at least two readable images, got {len(images)}" + (f" ({why})" if why
                                                                                               else ""))
    compose_megapix = _compose_within_budget(images, args.compose_megapix)
    pano = stitch(
        images,
        features=replace(_F, detector=args.detector, work_megapix=args.work_megapix),
        matching=replace(_M, seed=args.seed),
        homographies=PanoramaHomographiesParams(),
        warp=replace(_W, projection=args.projection, compose_megapix=compose_megapix),
        blend=replace(_B, blender=args.blender),
        crop=not args.no_crop,
        rng=args.seed,
        ids=positions,
    )
    io.save_image(args.out, pano.image)
    reg = pano.registration
    for k, why in reg.dropped:
        dropped.append({"image": positions[k], "reason": why})
    dropped.sort(key=lambda d: d["image"])
    plane = args.projection == "plane"
    homs = [(pano.to_panorama @ pano.homographies[a]) if plane else pano.homographies[a] for a in reg.used]
    homs = [H / H[2, 2] for H in homs]
    result = {
        "used": [positions[a] for a in reg.used],
        "dropped": dropped,
        "homographies": [np.round(H, 10) for H in homs],
        "homographies_frame": "panorama" if plane else "reference",
        "reference": positions[reg.reference],
        "size": [int(pano.image.shape[1]), int(pano.image.shape[0])],
        "model": reg.model,
    }
    if args.json:
        print(io.dumps_json(result))
    else:
        print(f"{args.out}: {result['size'][0]}x{result['size'][1]} from images {result['used']}"
              + "".join(f"\n  dropped image {d['image']}: {d['reason']}" for d in dropped))
    return 0
