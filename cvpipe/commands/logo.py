"""``cvpipe logo``: which gallery brand is in each scene photo, and where."""

from __future__ import annotations

import argparse
import math
import sys
import typing
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

from ..params import (HomographyEstimateParams, LogoFeaturesParams, LogoMatchParams, LogoMethod, LogoReportParams,
                      LogoVerifyParams)
from . import (DETECTORS, add_feature_arguments, add_result_arguments, final_output,  # noqa: F401
               note, overlay_paths, param_type, progress, read_images,
               step)  # DETECTORS: the ``--method`` choices (a test keeps them equal)

if TYPE_CHECKING:
    import numpy as np

    from .. import logo

HELP = "recognise gallery logos in scene photos (brand or none, and the logo outline)"
EXAMPLE = ("cvpipe logo data/samples/logo/scenes/scene_00.jpg --gallery data/samples/logo/gallery "
           "--overlay outputs/examples/logo.png --json")
#: ``--overlay`` with several scenes: ``<folder>/<scene stem>_logo.png``
SUFFIX = "_logo"
#: ``--method`` choices: the keys of ``cvpipe.logo.METHODS`` (a detector, or ``fused``; a test keeps them equal)
METHODS = typing.get_args(LogoMethod)


def gallery_files(folder: str | Path) -> list[tuple[str, Path]]:
    """``(brand, file)`` for ``DIR/<brand>.<ext>`` and ``DIR/<brand>/*.<ext>``, sorted; a note names each brand
    folder that holds no image.

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
    empty = []
    for sub in sorted(p for p in root.iterdir() if p.is_dir()):
        found = io.list_images(sub)
        items += [(sub.name, f) for f in found]
        if not found and not sub.name.startswith("."):
            empty.append(sub)
    if not items:
        raise InputError(f"{root}: the gallery is empty; expected {root}/<brand>.png or {root}/<brand>/*.png "
                         f"(any of {', '.join(io.IMAGE_SUFFIXES)})")
    brands = {b for b, _ in items}
    for sub in empty:
        if sub.name not in brands:  # DIR/<brand>.png beside an empty DIR/<brand>/ still gives the brand
            note(f"note: gallery brand {sub.name!r} is not used: its folder {sub} holds no images")
    return sorted(items, key=lambda t: (t[0], str(t[1])))


def gallery_references(files: Sequence[tuple[str, Path]], detectors: Sequence[str],
                       max_features: int) -> tuple[dict[str, list[logo.Reference]], dict[str, str]]:
    """Read every gallery image of ``files`` (:func:`gallery_files`) once and detect it with each of ``detectors``.

    Returns
    -------
    references : dict
        Detector -> one Reference per image file, blank ones included (they have no keypoints:
        :func:`cvpipe.logo.build_gallery` leaves them out).
    blank : dict
        Reference name -> ``"blank (one grey level, v)"`` for each image of one grey level.
    """
    from .. import io, logo
    from ..features import detect
    from ..logo.gallery import blank_reason, check_gallery_memory, features_nbytes

    refs: dict[str, list[logo.Reference]] = {d: [] for d in detectors}
    blank, held = {}, 0
    for images, (brand, f) in enumerate(progress(files, "gallery"), 1):
        gray = io.read_image(f, "gray")
        if (why := blank_reason(gray)) is not None:
            blank[str(f)] = why
        for d in detectors:
            refs[d].append(logo.Reference(brand, str(f), detect(gray, d, max_features),
                                          (gray.shape[1], gray.shape[0])))
            held += features_nbytes(refs[d][-1].features)  # every detector's galleries are held at once
            check_gallery_memory(held, images)  # refused while reading, before the whole folder is in memory
    return refs, blank


def note_unused(refs: dict[str, list[logo.Reference]], galleries: dict[str, logo.Gallery], blank: dict[str, str],
                min_features: int) -> None:
    """One note per brand that no gallery of ``galleries`` uses, naming each of its images and why; one per image
    that no gallery uses, of a brand still used.

    Parameters
    ----------
    refs : dict
        Detector -> what :func:`gallery_references` read for it (the same images, in the same order).
    galleries : dict
        Detector -> the gallery built from its references (``Gallery.dropped``: the names of those left out).
    blank : dict
        :func:`gallery_references`'s reasons of the blank images.
    min_features : int
        The keypoints a reference needs.
    """
    detectors = list(galleries)
    left_out = {d: set(galleries[d].dropped) for d in detectors}
    used_brands = set().union(*(galleries[d].brands for d in detectors))
    why: dict[str, list[tuple[str, str]]] = {}
    for k, r in enumerate(refs[detectors[0]]):
        if all(r.name in left_out[d] for d in detectors):
            counts = ", ".join(f"{len(refs[d][k].features)} keypoints with {d}" for d in detectors)
            reason = blank.get(r.name) or f"{counts}, fewer than the {min_features} needed"
            why.setdefault(r.brand, []).append((r.name, reason))
    for brand, items in sorted(why.items()):
        if brand in used_brands:
            for name, reason in items:
                note(f"note: gallery image {name} of brand {brand!r} is not used: {reason}")
        else:
            note(f"note: gallery brand {brand!r} is not used: " + "; ".join(f"{n}: {r}" for n, r in items))


#: the subfolder of ``--shape-photos`` that holds photos without any gallery brand
NO_BRAND_FOLDER = "none"


def shape_photo_files(folder: str | Path, brands: Sequence[str]) -> list[tuple[set[str], Path]]:
    """``(brands shown, file)`` of every photo of ``--shape-photos``: ``DIR/<brand>/*.<ext>`` (a gallery brand) and
    ``DIR/none/*.<ext>`` (none of them).

    Raises
    ------
    InputError
        The folder does not exist, a subfolder is neither a gallery brand nor ``none``, or no photo is found.
    """
    from .. import io
    from ..errors import InputError

    root = Path(folder)
    if not root.is_dir():
        raise InputError(f"{root}: --shape-photos folder does not exist")
    out = []
    for sub in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")):
        if sub.name != NO_BRAND_FOLDER and sub.name not in brands:
            raise InputError(f"{sub}: --shape-photos subfolders must be gallery brands or {NO_BRAND_FOLDER!r}; "
                             f"the gallery has {', '.join(sorted(brands))}")
        shown = set() if sub.name == NO_BRAND_FOLDER else {sub.name}
        out += [(shown, f) for f in io.list_images(sub)]
    if not out:
        raise InputError(f"{root}: no photos; expected {root}/<brand>/*.jpg (photos showing that gallery brand) and "
                         f"{root}/{NO_BRAND_FOLDER}/*.jpg (photos without any)")
    return out


def shape_cue(files: Sequence[tuple[str, Path]], photos: str | Path) -> tuple[list, np.ndarray]:
    """The gallery's silhouettes (:func:`cvpipe.logo.shape.shape_template`, one per gallery image of ``files``,
    :func:`gallery_files`) calibrated on the labelled photos of ``photos`` (:func:`shape_photo_files`); returns the
    kept templates and their thresholds."""
    from .. import io
    from ..logo import shape

    templates = [t for t in (shape.shape_template(io.read_image(f), b, str(f)) for b, f in files) if t is not None]
    labelled = shape_photo_files(photos, sorted({b for b, _ in files}))
    regions = [shape.scene_regions(io.read_image(f)) for _, f in progress(labelled, "shape photos")]
    thresholds = shape.calibrate_shapes(templates, shape.shape_scores(templates, regions),
                                        [str(f) for _, f in labelled], [b for b, _ in labelled])
    kept, levels = shape.kept_shapes(templates, thresholds)
    if kept:
        note(f"note: shape cue: {len(kept)} of {len(templates)} gallery silhouettes kept ("
             + ", ".join(sorted({t.brand for t in kept})) + ")")
    else:
        note(f"note: shape cue: none of the {len(templates)} gallery silhouettes is kept (each is a plain blob or "
             f"finds its brand on no photo of {photos} above its level on the other photos): it will name no brand")
    return kept, levels


def _shape_answer(scene: str, shapes: tuple) -> tuple[str, float, list] | None:
    """The shape cue's brand, margin and outline (the region's box) for the scene photo at ``scene``, or None."""
    from .. import io
    from ..logo import shape

    templates, thresholds = shapes
    if not templates:
        return None
    regions = shape.scene_regions(io.read_image(scene), {t.hue_bin for t in templates})
    scored = [shape.shape_score(t, regions) for t in templates]  # (score, box) each
    decision = shape.decide_shape(templates, thresholds, [score for score, _ in scored])
    if decision is None:
        return None
    brand, margin, i = decision
    x, y, w, h = scored[i][1]
    return brand, margin, [[x, y], [x + w, y], [x + w, y + h], [x, y + h]]


def recognize_scene(item: tuple, shared: tuple) -> tuple[dict, list, list]:
    """Recognise one scene, an item of :func:`cvpipe.compute.map_items` (runs on a worker).

    Parameters
    ----------
    item : tuple
        ``(scene name, gray image or None, read error or None)`` from :func:`cvpipe.commands.read_images`.
    shared : tuple
        ``({detector: Gallery}, max_features, min_long_side, LogoMatchParams, LogoVerifyParams, seed, shapes)``: the
        galleries of the method's detectors (a gallery travels to a worker as its references and is indexed again
        there, :class:`cvpipe.logo.Gallery`) and :func:`shape_cue`'s templates and thresholds, or None: where the
        method names no brand, the shape cue's answer (the scene is read again in colour).

    Returns
    -------
    record : dict
        The scene's JSON record (:func:`detection_json`).
    quads, labels : list
        The outline and the label of every logo found, best first, for the overlay.
    """
    import numpy as np

    from .. import logo
    from ..features import detect

    scene, gray, error = item
    if error is not None:
        raise error
    galleries, max_features, min_long_side, mp, vp, seed, shapes = shared
    scenes = {d: detect(gray, d, max_features, min_long_side=min_long_side) for d in galleries}
    det = logo.recognize_fused(galleries, scenes, (gray.shape[1], gray.shape[0]), mp, vp, seed)
    found = logo.every_logo(det, vp.score_threshold)
    record = detection_json(scene, det, found)
    if det.brand is None and shapes is not None and (cue := _shape_answer(scene, shapes)) is not None:
        brand, margin, quad = cue
        shown = {"brand": brand, "score": None, "inliers": 0, "quad": quad, "cue": "shape",
                 "shape_margin": round(margin, 3)}
        record.update({k: shown[k] for k in ("brand", "quad", "cue", "shape_margin")}, logos=[shown])
        return record, [np.array(quad, float)], [f"{brand} (shape)"]
    return record, [h.quad for h in found], [f"{h.brand} ({h.score:.0f})" for h in found]


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
    add_feature_arguments(parser, LogoReportParams().method, fp.max_features, mp.ratio, flag="--method",
                          choices=METHODS, what="a keypoint detector, or fused: SIFT, ORB and AKAZE under one "
                                                "decision, the most logos found at SIFT's precision for about 2.4x its "
                                                "time (logo.report.method)")
    parser.add_argument("--min-long-side", type=param_type(type(fp), "scene_min_long_side"),
                        default=fp.scene_min_long_side,
                        help=f"enlarge smaller scene photos to this long side before detection, 0 = never "
                             f"(default {fp.scene_min_long_side})")
    parser.add_argument("--threshold", type=param_type(type(vp), "score_threshold"), default=vp.score_threshold,
                        help=f"score (-log10 NFA) needed to name a brand (default {vp.score_threshold})")
    # a RANSAC seed, as homography.estimate.seed (every seed field is a params.Seed)
    parser.add_argument("--seed", type=param_type(HomographyEstimateParams, "seed"), default=0,
                        help="RANSAC seed (default 0)")
    parser.add_argument("--shape-photos", metavar="DIR",
                        help="labelled photos that calibrate the shape cue for smooth marks (a gallery image's "
                             f"colour silhouette): DIR/<brand>/*.jpg show that gallery brand, DIR/{NO_BRAND_FOLDER}/"
                             "*.jpg none; where the method names no brand, a scene gets the brand whose silhouette "
                             "clears its level on these photos (docs/logo.md)")
    add_result_arguments(parser, "write the scene with each found logo outlined and named", items="scenes",
                         suffix=SUFFIX, json='print a JSON list, one record per scene ({"scene", "brand", "inliers", '
                                             '"score", "quad", "logos": [every brand found, best first], "overlay"; '
                                             '"cue": "shape" and "shape_margin" when the shape cue named the brand})')


def run(args: argparse.Namespace) -> int:
    from .. import io
    from ..compute import check_scheduler, map_items, raise_unexpected
    from ..errors import CvpipeError
    from ..overlays import draw_quads

    # every number was checked by its field when parsed (param_type)
    mp = LogoMatchParams(ratio=args.ratio)
    vp = LogoVerifyParams(score_threshold=args.threshold)
    from .. import logo

    scheduler = check_scheduler(args.scheduler, "--scheduler")
    pictures = overlay_paths(args.scenes, args.overlay, SUFFIX)
    io.check_distinct_outputs([("`--overlay`", p) for p in pictures],
                              [(f"SCENE {k + 1}", path) for k, path in enumerate(args.scenes)])
    detectors = logo.method_detectors(args.method)
    with step(f"gallery ({', '.join(detectors)})"):
        # indexed before any scene runs, so that a gallery error is one line of its own
        files = gallery_files(args.gallery)
        refs, blank = gallery_references(files, detectors, args.max_features)
        galleries = {d: logo.build_gallery(refs[d], mp.min_features, mp.reference_features) for d in detectors}
    note_unused(refs, galleries, blank, mp.min_features)
    shapes = None
    if args.shape_photos:
        with step("shape cue"):
            shapes = shape_cue(files, args.shape_photos)
    records, failed = [], 0
    shared = (galleries, args.max_features, args.min_long_side, mp, vp, args.seed, shapes)
    scenes = read_images(args.scenes, "gray", named=True)
    items = map_items(recognize_scene, scenes, shared=shared, scheduler=scheduler,
                      total=len(args.scenes))
    # the results first: the bar counts scenes done, not started
    for res, (scene, picture) in zip(items, progress(list(zip(args.scenes, pictures)), "logo")):
        if not res.ok:
            raise_unexpected(res)  # a bug or an interrupt ends the command, as in a plain loop
            # one bad scene must not cost the answers for the others
            failed += 1
            print(f"cvpipe: error: {res.error}", file=sys.stderr)
            records.append({"scene": scene, "brand": None, "inliers": 0, "score": None, "quad": None, "logos": [],
                            "error": res.error})
            continue
        record, quads, labels = res.value
        records.append(record)
        if picture:
            try:
                io.save_image(picture, draw_quads(io.read_image(scene, "color"), quads, labels))
            except CvpipeError as exc:
                failed += 1
                print(f"cvpipe: error: {exc}", file=sys.stderr)
                records[-1]["error"] = str(exc)
                continue
            records[-1]["overlay"] = picture
    final_output()
    if args.json:
        print(io.dumps_json(records))
    else:
        for r in records:
            if "error" in r:
                print(f"{r['scene']}: error")
            elif r["brand"] is None:
                print(f"{r['scene']}: none")
            elif r.get("cue") == "shape":
                print(f"{r['scene']}: {r['brand']} (shape cue, margin {r['shape_margin']})")
            else:
                print(f"{r['scene']}: {r['brand']} (score {r['score']}, {r['inliers']} inliers)")
    return 2 if failed else 0
