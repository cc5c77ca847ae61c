"""``cvpipe logo``: which gallery brand is in each scene photo, and where."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from .. import io, logos
from ..compute import check_scheduler, map_items
from ..errors import CvpipeError, InputError
from ..features import DETECTORS, detect
from ..params import LogoFeaturesParams, LogoMatchParams, LogoVerifyParams

HELP = "recognise gallery logos in scene photos (brand or none, and the logo outline)"
EXAMPLE = "cvpipe logo data/samples/logo/scenes/scene_00.jpg --gallery data/samples/logo/gallery --json"


def gallery_files(folder: str | Path) -> list[tuple[str, Path]]:
    """``(brand, file)`` for ``DIR/<brand>.<ext>`` and ``DIR/<brand>/*.<ext>``, sorted.

    Raises
    ------
    InputError
        The folder does not exist or holds no image in either layout.
    """
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


def gallery_references(folder: str | Path, detector: str, max_features: int) -> list[logos.Reference]:
    """Read and detect every reference of a gallery folder (see :func:`gallery_files`)."""
    refs = []
    for brand, f in gallery_files(folder):
        gray = io.read_image(f, "gray")
        refs.append(logos.Reference(brand, str(f), detect(gray, detector, max_features),
                                    (gray.shape[1], gray.shape[0])))
    return refs


def load_gallery(folder: str | Path, detector: str, max_features: int, params: LogoMatchParams) -> logos.Gallery:
    """Read, detect and index a gallery folder (see :func:`gallery_files`)."""
    refs = gallery_references(folder, detector, max_features)
    return logos.build_gallery(refs, params.min_features, params.reference_features, params.register_references)


class SharedGallery:
    """The gallery's references, indexed where they land (once per worker): the trained matcher inside
    :class:`cvpipe.logos.Gallery` is an OpenCV object that cannot be pickled, so it is rebuilt, not shipped."""

    def __init__(self, references: list[logos.Reference], params: LogoMatchParams):
        self.references, self.params, self._gallery = list(references), params, None

    def __getstate__(self) -> dict:
        return {"references": self.references, "params": self.params}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["references"], state["params"])

    @property
    def gallery(self) -> logos.Gallery:
        if self._gallery is None:
            p = self.params
            self._gallery = logos.build_gallery(self.references, p.min_features, p.reference_features,
                                                p.register_references)
        return self._gallery


def _read_scenes(paths: list[str]):
    """``(scene, gray image or None, read error)`` per path, lazily (the image travels with its task)."""
    for path in paths:
        try:
            yield path, io.read_image(path, "gray"), None
        except CvpipeError as exc:
            yield path, None, exc


def recognize_scene(item: tuple, shared: tuple) -> dict:
    """The JSON record of one scene (an item of :func:`cvpipe.compute.map_items`): ``item`` from
    :func:`_read_scenes`, ``shared`` = (SharedGallery, method, max_features, min_long_side, match, verify, seed)."""
    scene, gray, error = item
    if error is not None:
        raise error
    g, method, max_features, min_long_side, mp, vp, seed = shared
    det = logos.recognize(g.gallery, detect(gray, method, max_features, min_long_side=min_long_side),
                          (gray.shape[1], gray.shape[0]), mp, vp, seed)
    return detection_json(scene, det)


def detection_json(scene: str, det: logos.Detection) -> dict:
    """The interface-contract record of one scene (``score`` is null when no hypothesis survived)."""
    return {"scene": scene, "brand": det.brand, "inliers": int(det.inliers),
            "score": round(float(det.score), 3) if math.isfinite(det.score) else None,
            "quad": None if det.quad is None else [[round(float(x), 2), round(float(y), 2)] for x, y in det.quad]}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    fp, mp, vp = LogoFeaturesParams(), LogoMatchParams(), LogoVerifyParams()
    parser.add_argument("scenes", nargs="+", metavar="SCENE", help="scene photos")
    parser.add_argument("--gallery", required=True, metavar="DIR",
                        help="reference logos: DIR/<brand>.<ext> or DIR/<brand>/*.<ext>")
    parser.add_argument("--method", default=fp.detector, choices=list(DETECTORS),
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
    parser.add_argument("--json", action="store_true", help="print a JSON list, one record per scene")
    parser.add_argument("--scheduler", default="", metavar="ADDR",
                        help="run the scenes on Dask: 'local' or a scheduler address tcp://host:port "
                             "(default: in process)")


def run(args: argparse.Namespace) -> int:
    if args.max_features < 1:
        raise InputError(f"`--max-features` must be a positive integer, got {args.max_features}")
    try:
        mp = LogoMatchParams(ratio=args.ratio)
        vp = LogoVerifyParams(score_threshold=args.threshold)
    except ValueError as exc:
        raise InputError(str(exc).replace("`ratio`", "`--ratio`")) from exc
    if args.min_long_side < 0:
        raise InputError(f"`--min-long-side` must be a non-negative number of pixels, got {args.min_long_side}")
    scheduler = check_scheduler(args.scheduler, "--scheduler")
    g = SharedGallery(gallery_references(args.gallery, args.method, args.max_features), mp)
    g.gallery  # noqa: B018 - index here too, so that a gallery error is one line before any scene runs
    records, failed = [], 0
    shared = (g, args.method, args.max_features, args.min_long_side, mp, vp, args.seed)
    for scene, res in zip(args.scenes, map_items(recognize_scene, _read_scenes(args.scenes), shared=shared,
                                                 scheduler=scheduler, total=len(args.scenes), progress="logo")):
        if res.ok:
            records.append(res.value)
        else:
            # one bad scene must not cost the answers for the others
            failed += 1
            print(f"cvpipe: error: {res.error}", file=sys.stderr)
            records.append({"scene": scene, "brand": None, "inliers": 0, "score": None, "quad": None,
                            "error": res.error})
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
