"""``cvpipe bench logo``: FlickrLogos-27 subset, the four detectors compared.

Protocol (see the data set's SOURCE.txt): the gallery is every box of the 80 boxed training photos, cropped, plus
``gallery/<Brand>.png``; the test scenes are the 50 query photos (brand known, no box) and the 20 no-logo photos.
Gallery features are detected once per method (the cached gallery); the time per scene covers scene feature
detection, matching and verification (not reading the file), measured per scene with the methods interleaved after a
warm-up, and reported as medians.

Several brands per photo: every scene is also scored by :func:`cvpipe.logo.every_logo` (every brand found, non-maximum
suppression of overlapping outlines) against all the brands the photo truly holds, which is its label plus the
documented corrections of ``flickrlogos_extra_labels.csv`` beside this module (photos whose label names one brand
where the photo shows several; the shared data set itself is never edited). The one-brand figures keep the data
set's own labels.

``--protocol loo`` is the tuning protocol, which never looks at the test scenes: every boxed training photo is a
scene twice, once against the gallery without that photo's own boxes (its brand is the answer) and once against the
gallery without its brand at all (a logo of an unknown brand: the answer is none).

Where ``fused`` is compared, the row ``fused+shape`` adds the shape cue of :mod:`cvpipe.logo.shape`: the fused
answer, and on the scenes where it names no brand the brand of the silhouette that clears its chance level most,
with that margin as its score (below the keypoint answers' scores, so it ranks after them). Its templates are cut
from the gallery's references and calibrated on the boxed training photos (in ``loo`` without the photo under
test); its time per scene is the fused method's plus the cue's where it runs.
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import time
import typing
from pathlib import Path

from ..errors import InputError
from ..params import (DEFAULT_EXTRA_SCORE, LogoFeaturesParams, LogoMatchParams, LogoMethod, LogoVerifyParams,
                      load_section)

if typing.TYPE_CHECKING:  # annotations only: the modules are imported inside the functions that use them,
    # so that `cvpipe bench logo --help` imports neither numpy nor cv2
    import numpy as np

    from .. import logo

#: brands a photo holds beyond its label in the subset (image, brand, reason): the benchmark's documented corrections
EXTRA_LABELS = Path(__file__).with_name("flickrlogos_extra_labels.csv")

HELP = "logo recognition on the FlickrLogos-27 subset: precision, recall, accuracy, PR curve, time per scene"
EXAMPLE = "cvpipe bench logo --data ../shared/data --json"
SUBSET = "flickrlogos27_subset"
#: the methods compared (each detector, and ``fused``: cvpipe.logo.METHODS), read from the params model (no cv2 for
#: --help)
METHODS = typing.get_args(LogoMethod)
#: the row of the fused method followed by the shape cue where it names no brand (:mod:`cvpipe.logo.shape`)
SHAPE_ROW = "fused+shape"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", default=os.environ.get("CVPIPE_DATA"),
                        help="data root holding flickrlogos27_subset/ (default: $CVPIPE_DATA)")
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS),
                        help="methods to compare: a detector, or fused (several under one decision; default: all)")
    parser.add_argument("--params", default="params.yaml",
                        help="params.yaml with the logo.* sections (default: params.yaml; dataclass defaults "
                             "when the file does not exist)")
    parser.add_argument("--min-box", type=int, default=16,
                        help="skip training boxes whose shorter side is below this many pixels (default 16)")
    parser.add_argument("--seed", type=int, default=0, help="RANSAC seed (default 0)")
    parser.add_argument("--protocol", choices=["test", "loo"], default="test",
                        help="test: the 70 test scenes (default); loo: leave-one-photo-out over the boxed training "
                             "photos, the protocol the parameters are tuned on")
    parser.add_argument("--scene-scale", type=float, default=1.0,
                        help="shrink every scene photo by this factor before detection (0.5 turns the training "
                             "photos' prominent logos into small ones, as in many query photos; default 1)")
    parser.add_argument("--extra-score", type=float, default=DEFAULT_EXTRA_SCORE,
                        help="score a second or later logo of a scene needs in the several-brands figures (default "
                             f"{DEFAULT_EXTRA_SCORE:g}, chosen on --protocol loo)")
    parser.add_argument("--json", action="store_true", help="print the full result (with PR curves) as JSON")


def load_subset(root: Path, min_box: int = 16) -> tuple[list[tuple[str, str, np.ndarray, tuple | None]],
                                                       list[tuple[str, str | None]]]:
    """Gallery references ``(brand, name, gray, box or None)`` and test scenes ``(path, brand or None)``.

    A boxed training photo gives one reference per box: the whole photo with the box (clipped to the image), so
    that keypoints come from inside the box while their descriptors see the photo around it.
    """
    import numpy as np
    from .. import io

    scenes_csv = root / "scenes.csv"
    if not scenes_csv.is_file():
        raise InputError(f"{scenes_csv}: no such file; expected the {SUBSET} folder (see its SOURCE.txt)")
    gallery: list[tuple[str, str, np.ndarray, tuple | None]] = []
    tests: list[tuple[str, str | None]] = []
    seen: set[tuple] = set()
    with scenes_csv.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    cache: dict[str, np.ndarray] = {}
    for row in rows:
        kind, brand, image = row["gt_kind"], row["brand"], row["image"]
        if kind == "bbox":
            x1, y1, x2, y2 = (int(float(row[k])) for k in ("x1", "y1", "x2", "y2"))
            key = (image, x1, y1, x2, y2)
            if key in seen or min(x2 - x1, y2 - y1) < min_box:
                continue
            seen.add(key)
            if image not in cache:
                cache[image] = io.read_image(root / image, "gray")
            img = cache[image]
            h, w = img.shape
            box = (max(x1, 0), max(y1, 0), min(x2, w - 1), min(y2, h - 1))
            gallery.append((brand, f"{image}[{x1},{y1},{x2},{y2}]", img, box))
        elif (image, kind) not in seen:
            seen.add((image, kind))
            tests.append((image, None if kind == "negative" or brand.lower() == "none" else brand))
    for f in io.list_images(root / "gallery"):
        gallery.append((f.stem, str(f.relative_to(root)), io.read_image(f, "gray"), None))
    return gallery, tests


def load_extra_labels(path: str | Path = EXTRA_LABELS) -> dict[str, set[str]]:
    """``image -> brands`` that a photo holds beyond its label (``image,brand,reason`` rows, each with a reason).

    Raises
    ------
    InputError
        The file is missing, lacks a column, or a row has an empty field (the message names the file and line).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file (the benchmark's label corrections)")
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        missing = {"image", "brand", "reason"} - set(reader.fieldnames or [])
        if missing:
            raise InputError(f"{path}: missing column(s) {', '.join(sorted(missing))}")
        extra: dict[str, set[str]] = {}
        for line, row in enumerate(reader, start=2):
            if not all((row[k] or "").strip() for k in ("image", "brand", "reason")):
                raise InputError(f"{path}:{line}: image, brand and reason must all be given")
            extra.setdefault(row["image"].strip(), set()).add(row["brand"].strip())
    return extra


def found_list(det: logo.Detection, score_threshold: float) -> list[list]:
    """``[[brand, score], ...]`` of :func:`cvpipe.logo.every_logo` with no stricter rule for later logos."""
    from .. import logo

    return [[h.brand, float(h.score)] for h in logo.every_logo(det, score_threshold, extra_score=score_threshold)]


def multi_evaluate(rows: list[dict], extra_score: float) -> dict:
    """Several-brands figures over ``rows`` (``{"truth_all": [brands], "found": found_list(...)}``): the first logo
    of a scene counts as found, each later one when its score reaches ``extra_score``; a scene's distinct found
    brands are compared with its true brands. Also the one-brand answer (the first logo), judged right when the
    photo holds that brand: its precision, and its recall over the photos that hold a gallery brand."""
    tp = answered = positives = one_tp = one_answered = with_logo = 0
    for r in rows:
        truth = set(r["truth_all"])
        with_logo += bool(truth)
        found = {b for i, (b, s) in enumerate(r["found"]) if i == 0 or s >= extra_score}
        tp += len(found & truth)
        answered += len(found)
        positives += len(truth)
        if r["found"]:
            one_answered += 1
            one_tp += r["found"][0][0] in truth
    return {"extra_score": float(extra_score), "answered": answered, "correct": tp, "positives": positives,
            "precision": tp / answered if answered else 1.0, "recall": tp / positives if positives else 0.0,
            "one_brand_precision": one_tp / one_answered if one_answered else 1.0,
            "one_brand_recall": one_tp / with_logo if with_logo else 0.0}


def multi_summary(rows: list[dict], extra_score: float, score_threshold: float) -> dict:
    """:func:`multi_evaluate` at ``extra_score`` plus ``sweep``: the figures at every distinct score of a later
    logo (and at ``score_threshold``), for choosing ``extra_score``."""
    import numpy as np

    later = sorted({s for r in rows for s in (x[1] for x in r["found"][1:]) if s >= score_threshold})
    out = multi_evaluate(rows, extra_score)
    out["sweep"] = [multi_evaluate(rows, s) for s in [score_threshold, *later, np.inf]]
    return out


def _shrink(gray: np.ndarray, scale: float) -> np.ndarray:
    """The scene photo shrunk by ``scale`` (area interpolation), or as it is for 1."""
    import cv2

    if scale == 1.0:
        return gray
    h, w = gray.shape[:2]
    return cv2.resize(gray, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA)


def _colour_reader(root: Path, scale: float = 1.0):
    """``name -> BGR image`` of the subset, read once each and shrunk by ``scale``."""
    from .. import io

    cache: dict[str, np.ndarray] = {}

    def read(name: str) -> np.ndarray:
        if name not in cache:
            cache[name] = _shrink(io.read_image(root / name), scale)
        return cache[name]
    return read


def shape_templates(gallery_imgs: list, read) -> list:
    """The shape templates of the gallery's references (:func:`cvpipe.logo.shape.shape_template`): a boxed training
    photo's box, a reference image whole; a template cut from a photo has that photo as its source."""
    from ..logo.shape import shape_template

    out = []
    for brand, name, _, box in gallery_imgs:
        photo = name.split("[")[0] if box is not None else None
        t = shape_template(read(photo or name), brand, name, box, source=photo)
        if t is not None:
            out.append(t)
    return out


def _training_photos(gallery_imgs: list, extra: dict[str, set[str]]) -> tuple[list[str], list[set[str]]]:
    """The boxed training photos and the brands each shows (its boxes' brands and the documented corrections)."""
    brands: dict[str, set[str]] = {}
    for brand, name, _, box in gallery_imgs:
        if box is not None:
            photo = name.split("[")[0]
            brands.setdefault(photo, set()).add(brand)
    photos = sorted(brands)
    return photos, [brands[p] | extra.get(p, set()) for p in photos]


def with_shape(answer: dict, decision) -> dict:
    """A fused answer (a benchmark row's scene record) with the shape cue's ``decision`` (``(brand, margin, i)`` of
    :func:`cvpipe.logo.shape.decide_shape`, or None) where the fused method named no brand."""
    if answer["brand"] is not None or decision is None:
        return dict(answer)
    brand, margin, _ = decision
    return {**answer, "brand": brand, "best_brand": brand, "score": margin, "inliers": 0, "detector": "shape",
            "found": [[brand, margin]]}


def _shape_protocol(templates: list, thresholds: np.ndarray) -> dict:
    from ..logo import kept_shapes

    kept, _ = kept_shapes(templates, thresholds)
    return {"templates": len(templates), "kept": len(kept),
            "kept_per_brand": {b: sum(t.brand == b for t in kept) for b in sorted({t.brand for t in kept})}}


def _mask(shape: tuple[int, int], box: tuple | None) -> np.ndarray | None:
    import numpy as np

    if box is None:
        return None
    mask = np.zeros(shape, np.uint8)
    x1, y1, x2, y2 = (int(round(v)) for v in box)
    mask[y1:y2 + 1, x1:x2 + 1] = 255
    return mask


def _params(path: str) -> tuple[LogoFeaturesParams, LogoMatchParams, LogoVerifyParams]:
    if Path(path).is_file():
        return (load_section(LogoFeaturesParams, "logo.features", path),
                load_section(LogoMatchParams, "logo.match", path), load_section(LogoVerifyParams, "logo.verify", path))
    return LogoFeaturesParams(), LogoMatchParams(), LogoVerifyParams()


def run_benchmark(root: Path, methods: list[str], fp: LogoFeaturesParams, mp: LogoMatchParams, vp: LogoVerifyParams,
                  min_box: int = 16, seed: int = 0, scene_scale: float = 1.0,
                  extra_score: float = DEFAULT_EXTRA_SCORE) -> dict:
    """Run every method on the subset; returns per-method metrics, curves, per-scene answers and timings."""
    from tqdm import tqdm
    from .. import io, logo
    from ..features import detect
    from ..logo import shape

    gallery_imgs, tests = load_subset(root, min_box)
    extra = load_extra_labels()
    needed = list(dict.fromkeys(d for m in methods for d in logo.method_detectors(m)))
    by_detector, detector_time = {}, {}
    for d in needed:
        t0 = time.perf_counter()
        refs = [logo.Reference(b, n, detect(g, d, fp.max_features, _mask(g.shape, box)), (g.shape[1], g.shape[0]),
                                box) for b, n, g, box in gallery_imgs]
        by_detector[d] = logo.build_gallery(refs, mp.min_features, mp.reference_features)
        detector_time[d] = time.perf_counter() - t0
    galleries = {m: {d: by_detector[d] for d in logo.method_detectors(m)} for m in methods}
    gallery_time = {m: sum(detector_time[d] for d in galleries[m]) for m in methods}

    def recognize(m: str, g: np.ndarray) -> logo.Detection:
        # a method detects its own keypoints, so that its time per scene covers everything it needs
        feats = {d: detect(g, d, fp.max_features, min_long_side=fp.scene_min_long_side) for d in galleries[m]}
        return logo.recognize_fused(galleries[m], feats, (g.shape[1], g.shape[0]), mp, vp, seed)

    scenes = [(f, b, _shrink(io.read_image(root / f, "gray"), scene_scale)) for f, b in tests]
    rows = [*methods, SHAPE_ROW] if "fused" in methods else list(methods)
    if SHAPE_ROW in rows:  # the shape cue's templates, calibrated on the boxed training photos
        t0 = time.perf_counter()
        read = _colour_reader(root)
        templates = shape_templates(gallery_imgs, read)
        photos, brands = _training_photos(gallery_imgs, extra)
        thresholds = shape.calibrate_shapes(templates, shape.shape_scores(
            templates, [shape.scene_regions(read(p)) for p in photos]), photos, brands)
        kept = [i for i, th in enumerate(thresholds) if th == th]  # not NaN
        kept_templates, kept_thresholds = [templates[i] for i in kept], thresholds[kept]
        hues = {t.hue_bin for t in kept_templates}
        gallery_time[SHAPE_ROW] = gallery_time["fused"] + time.perf_counter() - t0
        read_scene = _colour_reader(root, scene_scale)
        colour = {f: read_scene(f) for f, _, _ in scenes}
    # warm-up: one scene per method (FLANN, OpenCV thread pools, scipy imports)
    for m in methods:
        recognize(m, scenes[0][2])
    times = {m: [] for m in rows}
    answers = {m: [] for m in rows}
    for f, brand, g in tqdm(scenes, desc="logo bench", disable=None):
        for m in methods:  # interleaved, so load changes on the shared machine hit every method alike
            t0 = time.perf_counter()
            det = recognize(m, g)
            times[m].append(time.perf_counter() - t0)
            best = det.best
            answers[m].append({"scene": f, "truth": brand, "brand": det.brand,
                               "best_brand": best.brand if best else None, "score": det.score,
                               "inliers": det.inliers, "detector": best.detector if best else None,
                               "truth_all": sorted(({brand} - {None}) | extra.get(f, set())),
                               "found": found_list(det, vp.score_threshold)})
            if m == "fused" and SHAPE_ROW in rows:
                t0 = time.perf_counter()
                decision = None
                if det.brand is None:
                    regions = shape.scene_regions(colour[f], hues)
                    decision = shape.decide_shape(kept_templates, kept_thresholds,
                                                  [shape.shape_score(t, regions)[0] for t in kept_templates])
                times[SHAPE_ROW].append(times["fused"][-1] + time.perf_counter() - t0)
                answers[SHAPE_ROW].append(with_shape(answers["fused"][-1], decision))
    result = {"protocol": {"gallery_references": {m: sum(len(g.references) for g in galleries[m].values())
                                                  for m in methods},
                           "gallery_dropped": {m: sum(len(g.dropped) for g in galleries[m].values())
                                               for m in methods},
                           "test_scenes": len(tests), "with_logo": sum(b is not None for _, b in tests),
                           "score_threshold": vp.score_threshold, "scene_scale": scene_scale,
                           "extra_score": extra_score, "extra_labels": _extra_count(extra)},
              "methods": {}}
    if SHAPE_ROW in rows:
        result["protocol"]["shape"] = _shape_protocol(templates, thresholds)
    for m in rows:
        a = answers[m]
        ev = logo.evaluate([x["truth"] for x in a], [x["best_brand"] for x in a], [x["score"] for x in a],
                            vp.score_threshold)
        ev["time_per_scene_median_s"] = statistics.median(times[m])
        ev["gallery_index_s"] = gallery_time[m]
        _summarise(ev, a, vp.score_threshold)
        ev["several_brands"] = multi_summary(a, extra_score, vp.score_threshold)
        ev["scenes_detail"] = a
        result["methods"][m] = ev
    return result


def run_leave_one_out(root: Path, methods: list[str], fp: LogoFeaturesParams, mp: LogoMatchParams,
                      vp: LogoVerifyParams, min_box: int = 16, seed: int = 0, scene_scale: float = 1.0,
                      extra_score: float = DEFAULT_EXTRA_SCORE) -> dict:
    """The tuning protocol (see the module docstring): per-method metrics and per-scene answers, no timings."""
    import numpy as np
    from tqdm import tqdm
    from .. import logo
    from ..features import detect
    from ..logo import shape

    gallery_imgs, _ = load_subset(root, min_box)
    extra = load_extra_labels()
    photos: dict[str, tuple[str, np.ndarray]] = {}
    for brand, name, gray, box in gallery_imgs:
        if box is not None:
            photos.setdefault(name.split("[")[0], (brand, gray))
    result: dict = {"protocol": {"name": "leave-one-photo-out", "photos": len(photos), "scenes": 2 * len(photos),
                                 "score_threshold": vp.score_threshold, "scene_scale": scene_scale,
                                 "extra_score": extra_score, "extra_labels": _extra_count(extra)},
                    "methods": {}}
    needed = list(dict.fromkeys(d for m in methods for d in logo.method_detectors(m)))
    refs = {d: [(n.split("[")[0] if box is not None else None,
                 logo.Reference(b, n, detect(g, d, fp.max_features, _mask(g.shape, box)), (g.shape[1], g.shape[0]),
                                box)) for b, n, g, box in gallery_imgs] for d in needed}
    rows = [*methods, SHAPE_ROW] if "fused" in methods else list(methods)
    if SHAPE_ROW in rows:  # every template against every training photo once; each fold calibrates without its photo
        read = _colour_reader(root)
        templates = shape_templates(gallery_imgs, read)
        names, brands = _training_photos(gallery_imgs, extra)
        read_scene = _colour_reader(root, scene_scale)
        scores = shape.shape_scores(templates, [shape.scene_regions(read_scene(p)) for p in names])
        folds: list[dict] = []
    answers: dict[str, list[dict]] = {m: [] for m in rows}
    for photo, (brand, gray) in tqdm(sorted(photos.items()), desc="loo", disable=None):
        small = _shrink(gray, scene_scale)
        size = (small.shape[1], small.shape[0])
        scenes = {d: detect(small, d, fp.max_features, min_long_side=fp.scene_min_long_side) for d in needed}
        for truth in (brand, None):
            galleries = {d: logo.build_gallery([r for src, r in refs[d] if src != photo and
                                                (truth is not None or r.brand != brand)],
                                               mp.min_features, mp.reference_features) for d in needed}
            matches = {d: logo.match_scene(galleries[d], scenes[d], mp) for d in needed}
            # every brand the photo holds that this gallery knows (without its own brand: the others)
            truth_all = (({brand} | extra.get(photo, set())) - ({brand} if truth is None else set()))
            known = set(galleries[needed[0]].brands)
            for m in methods:
                ds = logo.method_detectors(m)
                det = logo.decide(logo.verify_fused({d: galleries[d] for d in ds}, {d: matches[d] for d in ds},
                                                    {d: scenes[d] for d in ds}, size, vp, seed), vp)
                answers[m].append({"scene": photo, "truth": truth, "brand": det.brand,
                                   "best_brand": det.best.brand if det.best else None, "score": det.score,
                                   "inliers": det.inliers, "detector": det.best.detector if det.best else None,
                                   "truth_all": sorted(truth_all & known),
                                   "found": found_list(det, vp.score_threshold)})
            if SHAPE_ROW in rows:
                use = [i for i, t in enumerate(templates) if t.source != photo and (truth is not None or
                                                                                    t.brand != brand)]
                calib = [j for j, p in enumerate(names) if p != photo]
                th = shape.calibrate_shapes([templates[i] for i in use], scores[np.ix_(use, calib)],
                                            [names[j] for j in calib], [brands[j] for j in calib])
                decision = shape.decide_shape([templates[i] for i in use], th, scores[use, names.index(photo)])
                answers[SHAPE_ROW].append(with_shape(answers["fused"][-1], decision))
                folds.append({"templates": len(use), "kept": int((th == th).sum())})
    if SHAPE_ROW in rows:
        result["protocol"]["shape"] = {"templates": len(templates),
                                       "kept_per_fold_median": statistics.median(f["kept"] for f in folds)}
    for m in rows:
        ev = logo.evaluate([x["truth"] for x in answers[m]], [x["best_brand"] for x in answers[m]],
                            [x["score"] for x in answers[m]], vp.score_threshold)
        _summarise(ev, answers[m], vp.score_threshold)
        ev["several_brands"] = multi_summary(answers[m], extra_score, vp.score_threshold)
        ev["scenes_detail"] = answers[m]
        result["methods"][m] = ev
    return result


def per_brand(answers: list[dict], threshold: float) -> dict[str, dict]:
    """``brand -> {"scenes", "found", "recall"}`` over the scenes whose one-brand label is that brand: found = the
    brand answered at ``threshold``."""
    out: dict[str, dict] = {}
    for a in answers:
        if a["truth"] is None:
            continue
        row = out.setdefault(a["truth"], {"scenes": 0, "found": 0})
        row["scenes"] += 1
        row["found"] += int(a["best_brand"] == a["truth"] and a["score"] >= threshold)
    for row in out.values():
        row["recall"] = row["found"] / row["scenes"]
    return dict(sorted(out.items()))


def _extra_count(extra: dict[str, set[str]]) -> int:
    return sum(len(v) for v in extra.values())


def _print_per_brand(res: dict) -> None:
    print("recall per brand (found / scenes labelled with it):")
    for m, ev in res["methods"].items():
        print(f"{m:11s} " + ", ".join(f"{b} {v['found']}/{v['scenes']}" for b, v in ev["per_brand"].items()))


def _print_several(res: dict) -> None:
    pr = res["protocol"]
    print(f"several brands per photo (labels plus {pr['extra_labels']} documented corrections, "
          f"{EXTRA_LABELS.name}; a later logo needs score >= {pr['extra_score']:g}):")
    print(f"{'method':11s} {'1-brand P':>9s} {'1-brand R':>9s} {'every P':>8s} {'every R':>8s} {'found':>6s} "
          f"{'right':>6s} {'true':>5s}")
    for m, ev in res["methods"].items():
        s = ev["several_brands"]
        print(f"{m:11s} {s['one_brand_precision']:9.3f} {s['one_brand_recall']:9.3f} {s['precision']:8.3f} "
              f"{s['recall']:8.3f} {s['answered']:6d} {s['correct']:6d} {s['positives']:5d}")


def _summarise(ev: dict, answers: list[dict], threshold: float) -> None:
    """Add the two operating points of the logo target (precision >= 0.95 at recall >= 0.70, BENCHMARKS "logo") and
    the recall per brand (:func:`per_brand`) to an :func:`cvpipe.logo.evaluate` result."""
    ev["per_brand"] = per_brand(answers, threshold)
    ev["best_precision_at_recall_0.70"] = max((c["precision"] for c in ev["curve"] if c["recall"] >= 0.70),
                                              default=None)
    ev["best_recall_at_precision_0.95"] = max((c["recall"] for c in ev["curve"] if c["precision"] >= 0.95),
                                              default=0.0)


def run(args: argparse.Namespace) -> int:
    from .. import io

    if not args.data:
        raise InputError("no data root: pass --data DIR or set CVPIPE_DATA")
    if not 0.05 <= args.scene_scale <= 1.0:
        raise InputError(f"`--scene-scale` must be in [0.05, 1], got {args.scene_scale}")
    if args.min_box < 1:
        raise InputError(f"`--min-box` must be a positive number of pixels, got {args.min_box}")
    root = Path(args.data)
    if (root / SUBSET).is_dir():
        root = root / SUBSET
    fp, mp, vp = _params(args.params)
    if args.protocol == "loo":
        res = run_leave_one_out(root, args.methods, fp, mp, vp, args.min_box, args.seed, args.scene_scale,
                                args.extra_score)
        if args.json:
            print(io.dumps_json(res))
            return 0
        pr = res["protocol"]
        print(f"FlickrLogos-27 subset, leave-one-photo-out: {pr['photos']} training photos, each as a scene with its "
              f"brand and without it ({pr['scenes']} scenes), score threshold {pr['score_threshold']}, scenes "
              f"scaled by {pr['scene_scale']}")
        print(f"{'method':11s} {'precision':>9s} {'recall':>7s} {'accuracy':>8s} {'R@P>=0.95':>9s}")
        for m, ev in res["methods"].items():
            print(f"{m:11s} {ev['precision']:9.3f} {ev['recall']:7.3f} {ev['accuracy']:8.3f} "
                  f"{ev['best_recall_at_precision_0.95']:9.3f}")
        _print_per_brand(res)
        _print_several(res)
        return 0
    res = run_benchmark(root, args.methods, fp, mp, vp, args.min_box, args.seed, args.scene_scale, args.extra_score)
    if args.json:
        print(io.dumps_json(res))
        return 0
    pr = res["protocol"]
    print(f"FlickrLogos-27 subset: {pr['test_scenes']} test scenes ({pr['with_logo']} with a logo), gallery "
          f"{pr['gallery_references']} references, score threshold {pr['score_threshold']}, scenes scaled by "
          f"{pr['scene_scale']}")
    print(f"{'method':11s} {'precision':>9s} {'recall':>7s} {'accuracy':>8s} {'P@R>=0.70':>9s} {'R@P>=0.95':>9s} "
          f"{'s/scene':>8s}")
    for m, ev in res["methods"].items():
        p70 = ev["best_precision_at_recall_0.70"]
        print(f"{m:11s} {ev['precision']:9.3f} {ev['recall']:7.3f} {ev['accuracy']:8.3f} "
              f"{'-' if p70 is None else f'{p70:.3f}':>9s} {ev['best_recall_at_precision_0.95']:9.3f} "
              f"{ev['time_per_scene_median_s']:8.3f}")
    _print_per_brand(res)
    _print_several(res)
    return 0
