"""``cvpipe logo``: which gallery brand is in each scene photo, and where."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ..params import LogoFeaturesParams, LogoMatchParams, LogoVerifyParams
from . import compile_note, overlay_paths, progress, step

if TYPE_CHECKING:
    from .. import logo

HELP = "recognise gallery logos in scene photos (brand or none, and the logo outline)"
EXAMPLE = ("cvpipe logo data/samples/logo/scenes/scene_00.jpg --gallery data/samples/logo/gallery "
           "--overlay logo.png --json")

#: ``--method`` choices: the keys of ``cvpipe.features.DETECTORS`` (a test keeps them equal)
DETECTORS = ("akaze", "brisk", "orb", "sift")


def gallery_files(folder: str | Path) -> list[tuple[str, Path]]:
    """``(brand, file)`` for ``DIR/<brand>.<ext>`` and ``DIR/<brand>/*.<ext>``, sorted.

    Raises
    ------
    InputError
        The folder does not exist or holds no image in either layout.
    """
    from .. import io
    from ..errors import InputError

    root = Path(folder)
    if not root.is_dir():
        raise InputError(f"{root}: gallery folder does not exist")
    items = [(f.stem, f) for f in io.list_images(root)]
    for sub in sorted(p for p in root.iterdir() if p.is_dir()):
        items += [(sub.name, f) for f in io.list_images(sub)]
    if not items:
        raise InputError(f"{root}: the gallery is empty; expected {root}/<brand>.png or {root}/<brand>/*.png "
                         f"(any of {', '.join(io.IMAGE_SUFFIXES)})")
    return sorted(items, key=lambda t: (t[0], str(t[1])))


def load_gallery(folder: str | Path, detector: str, max_features: int, params: LogoMatchParams) -> logo.Gallery:
    """Read, detect and index a gallery folder (see :func:`gallery_files`)."""
    from .. import io, logo
    from ..features import detect

    refs = []
    for brand, f in progress(gallery_files(folder), "gallery"):
        gray = io.read_image(f, "gray")
        refs.append(logo.Reference(brand, str(f), detect(gray, detector, max_features),
                                    (gray.shape[1], gray.shape[0])))
    return logo.build_gallery(refs, params.min_features, params.reference_features)


def _logo_json(h) -> dict:
    return {"brand": h.brand, "score": round(float(h.score), 3), "inliers": int(h.inliers),
            "quad": [[round(float(x), 2), round(float(y), 2)] for x, y in h.quad]}


def detection_json(scene: str, det: logo.Detection, found: list | None = None) -> dict:
    """The interface-contract record of one scene (``score`` is null when no hypothesis survived)."""
    return {"scene": scene, "brand": det.brand, "inliers": int(det.inliers),
            "score": round(float(det.score), 3) if math.isfinite(det.score) else None,
            "quad": None if det.quad is None else [[round(float(x), 2), round(float(y), 2)] for x, y in det.quad],
            "logos": [_logo_json(h) for h in (found or [])]}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    fp, mp, vp = LogoFeaturesParams(), LogoMatchParams(), LogoVerifyParams()
    parser.add_argument("scenes", nargs="+", metavar="SCENE", help="scene photos")
    parser.add_argument("--gallery", required=True, metavar="DIR",
                        help="reference logos: DIR/<brand>.<ext> or DIR/<brand>/*.<ext>")
    parser.add_argument("--method", type=str.lower, default=fp.detector, choices=DETECTORS,
                        help=f"keypoint detector (default {fp.detector})")
    parser.add_argument("--max-features", type=int, default=fp.max_features,
                        help=f"keypoints per image (default {fp.max_features})")
    parser.add_argument("--min-long-side", type=int, default=fp.scene_min_long_side,
                        help=f"enlarge smaller scene photos to this long side before detection, 0 = never "
                             f"(default {fp.scene_min_long_side})")
    parser.add_argument("--ratio", type=float, default=mp.ratio, help=f"ratio test (default {mp.ratio})")
    parser.add_argument("--threshold", type=float, default=vp.score_threshold,
                        help=f"score (-log10 NFA) needed to name a brand (default {vp.score_threshold})")
    parser.add_argument("--seed", type=int, default=0, help="RANSAC seed (default 0)")
    parser.add_argument("--overlay", metavar="PNG",
                        help="write the scene with each found logo outlined and named; with several scenes, PNG "
                             "is a folder and each scene gets <scene>_logo.png")
    parser.add_argument("--json", action="store_true",
                        help='print a JSON list, one record per scene ({"scene", "brand", "inliers", "score", '
                             '"quad", "logos": [every brand found, best first], "overlay"})')


def run(args: argparse.Namespace) -> int:
    from .. import io, logo
    from ..errors import CvpipeError, InputError
    from ..features import detect
    from ..overlays import draw_quads

    if args.max_features < 1:
        raise InputError(f"`--max-features` must be a positive integer, got {args.max_features}")
    try:
        mp = LogoMatchParams(ratio=args.ratio)
        vp = LogoVerifyParams(score_threshold=args.threshold)
    except ValueError as exc:
        raise InputError(str(exc).replace("`ratio`", "`--ratio`")) from exc
    if args.min_long_side < 0:
        raise InputError(f"`--min-long-side` must be a non-negative number of pixels, got {args.min_long_side}")
    from .. import homography

    compile_note("logo", homography)
    with step(f"gallery ({args.method})"):
        gallery = load_gallery(args.gallery, args.method, args.max_features, mp)
    records, failed = [], 0
    for scene, picture in progress(list(zip(args.scenes, overlay_paths(args.scenes, args.overlay, "_logo"))), "logo"):
        try:
            with step(scene):
                gray = io.read_image(scene, "gray")  # as before: a JPEG decoded to gray is not cvtColor's gray
                det = logo.recognize(gallery, detect(gray, args.method, args.max_features,
                                                      min_long_side=args.min_long_side),
                                      (gray.shape[1], gray.shape[0]), mp, vp, args.seed)
            found = logo.every_logo(det, vp.score_threshold)
            records.append(detection_json(scene, det, found))
            if picture:
                io.save_image(picture, draw_quads(io.read_image(scene, "color"), [h.quad for h in found],
                                                  [f"{h.brand} ({h.score:.0f})" for h in found]))
                records[-1]["overlay"] = picture
        except CvpipeError as exc:
            # one bad scene must not cost the answers for the others
            failed += 1
            print(f"cvpipe: error: {exc}", file=sys.stderr)
            records.append({"scene": scene, "brand": None, "inliers": 0, "score": None, "quad": None, "logos": [],
                            "error": str(exc)})
    if args.json:
        print(io.dumps_json(records))
    else:
        for r in records:
            if "error" in r:
                print(f"{r['scene']}: error")
            elif r["brand"] is None:
                print(f"{r['scene']}: none")
            else:
                print(f"{r['scene']}: {r['brand']} (score {r['score']}, {r['inliers']} inliers)")
    return 2 if failed else 0
