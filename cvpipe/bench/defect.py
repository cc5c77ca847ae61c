"""``cvpipe bench defect --data DIR``: defect inspection on DeepPCB template/test pairs made realistic.

DeepPCB's pairs are pixel-aligned, binarised and every test image is faulty. Each pair therefore yields two probes:
the test image (faulty) and the template itself (perfect), each warped by its own seeded small random homography
(rotation up to 4 degrees, scale +-5 %, translation up to 15 px, slight perspective) with a gain/bias change, blur and
noise. The ground-truth boxes are mapped by the same homography. Ours (:func:`cvpipe.defect.inspect`) is compared
in the same process with the baseline, a plain registration + difference (SIFT + OpenCV RANSAC homography, plain
absolute difference, fixed threshold, connected components).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import typing
from pathlib import Path

from ..errors import CvpipeError, InputError
from ..params import InspectParams, replace

if typing.TYPE_CHECKING:  # annotations only: the modules are imported inside the functions that use them,
    # so that `cvpipe bench defect --help` imports neither numpy nor cv2
    import numpy as np


HELP = "defect inspection on DeepPCB pairs warped by random homographies (ours vs the seed project's plain difference)"
EXAMPLE = "cvpipe bench defect --data ../shared/data --limit 20"

IOU = 0.33  # DeepPCB's criterion
#: DeepPCB boxes enclose each defect with a margin (median ~9-10 px between the changed pixels and the box edge on
#: the trainval pairs), so regions are padded by this much before the IoU test; tight boxes are reported too.
DEEPPCB_PAD = 9.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", default=os.environ.get("CVPIPE_DATA"),
                        help="data root holding deeppcb/ (default: $CVPIPE_DATA)")
    parser.add_argument("--limit", type=int, default=0, help="use only the first N pairs (0 = all)")
    parser.add_argument("--split", choices=("all", "test", "trainval"), default="all",
                        help="DeepPCB split to use (default: all)")
    parser.add_argument("--seed", type=int, default=20261122, help="seed of the random warps")
    parser.add_argument("--pad", type=float, default=DEEPPCB_PAD,
                        help=f"box padding in px for DeepPCB's loose boxes (default {DEEPPCB_PAD:g})")
    parser.add_argument("--detector", help="keypoint detector for registration (default: defect.features)")
    parser.add_argument("--max-features", type=int, help="keypoints per image (default: defect.features)")
    parser.add_argument("--no-baseline", action="store_true", help="skip the baseline (the seed project's method)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument("--out", help="write results JSON here as well")


# --------------------------------------------------------------------------------------------------- data


def load_pairs(root: Path, split: str = "all") -> list[dict]:
    """DeepPCB pairs listed in ``PCBData/pairs.txt``: template/test paths, boxes (K, 4) and the split."""
    import numpy as np

    base = root / "deeppcb" / "PCBData"
    listing = base / "pairs.txt"
    if not listing.is_file():
        raise InputError(f"{listing}: not found; --data must be the folder that holds deeppcb/ (see its SOURCE.txt)")
    pairs = []
    for line in listing.read_text().splitlines():
        if not line.strip():
            continue
        stem, ann, sp = line.split()
        if split != "all" and sp != split:
            continue
        img = base / stem
        boxes = [list(map(float, row.split()[:4])) for row in (base / ann).read_text().splitlines() if row.strip()]
        pairs.append({"name": img.stem, "template": img.with_name(img.stem + "_temp.jpg"),
                      "test": img.with_name(img.stem + "_test.jpg"), "boxes": np.array(boxes).reshape(-1, 4),
                      "split": sp})
    if not pairs:
        raise InputError(f"{listing}: no pairs in split {split!r}")
    return pairs


def random_homography(rng: np.random.Generator, size: tuple[int, int], max_rot_deg: float = 4.0,
                      max_scale: float = 0.05, max_shift: float = 15.0, max_persp: float = 2e-5) -> np.ndarray:
    """A small homography about the image centre (reference -> probe pixels)."""
    import numpy as np

    w, h = size
    c = np.array([(w - 1) / 2, (h - 1) / 2])
    t = np.deg2rad(rng.uniform(-max_rot_deg, max_rot_deg))
    s = rng.uniform(1 - max_scale, 1 + max_scale)
    A = np.array([[s * np.cos(t), -s * np.sin(t), 0], [s * np.sin(t), s * np.cos(t), 0], [0, 0, 1]])
    A[2, :2] = rng.uniform(-max_persp, max_persp, 2)
    T = np.array([[1, 0, c[0] + rng.uniform(-max_shift, max_shift)],
                  [0, 1, c[1] + rng.uniform(-max_shift, max_shift)], [0, 0, 1]])
    C = np.array([[1, 0, -c[0]], [0, 1, -c[1]], [0, 0, 1]])
    H = T @ A @ C
    return H / H[2, 2]


def make_probe(img: np.ndarray, boxes: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray,
                                                                                     np.ndarray]:
    """Warp, relight, blur and add noise to ``img``; return (probe, H reference -> probe, boxes in the probe).

    Pixels the original does not cover are filled with its median (bare board). Boxes keep their mapped bounds,
    clipped to the frame; a box with less than half of its mapped area inside the frame is dropped.
    """
    import cv2
    import numpy as np
    from .. import defect

    h, w = img.shape[:2]
    H = random_homography(rng, (w, h))
    fill = float(np.median(img))
    warped = cv2.warpPerspective(img.astype(np.float32), H, (w, h), flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=fill)
    gain, bias = rng.uniform(0.75, 1.15), rng.uniform(-20, 20)
    out = warped * gain + bias
    sigma = rng.uniform(0.3, 1.2)
    out = cv2.GaussianBlur(out, (0, 0), sigma)
    out = out + rng.normal(0, rng.uniform(2, 5), out.shape)
    probe = np.clip(np.rint(out), 0, 255).astype(np.uint8)
    mapped = defect.map_boxes(boxes, H)
    clipped = mapped.copy()
    clipped[:, [0, 2]] = clipped[:, [0, 2]].clip(0, w)
    clipped[:, [1, 3]] = clipped[:, [1, 3]].clip(0, h)
    area = lambda b: (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])  # noqa: E731
    keep = area(clipped) >= 0.5 * area(mapped) if len(mapped) else np.zeros(0, bool)
    return probe, H, clipped[keep]


# --------------------------------------------------------------------------------------------------- baseline


def baseline_method(reference: np.ndarray, probe: np.ndarray, ref_feats, threshold: float = 50.0,
                min_area: int = 12) -> np.ndarray:
    """The baseline inspection: SIFT + cv2.findHomography, warp, ``cv2.absdiff``, fixed
    threshold, components.

    ``ref_feats`` are the reference's SIFT features. Returns the regions (K, 4) in probe pixels; raises
    ``CvpipeError`` when registration fails.
    """
    import cv2
    import numpy as np
    from .. import defect
    from ..features import detect
    from ..matching import match

    fq = detect(probe, "sift", 4000)
    m = match(ref_feats.descriptors, fq.descriptors, 0.75)
    if len(m) < 4:
        raise CvpipeError("too few matches")
    H, _ = cv2.findHomography(ref_feats.xy[m[:, 0]], fq.xy[m[:, 1]], cv2.RANSAC, 3.0)
    if H is None:
        raise CvpipeError("findHomography failed")
    warped = cv2.warpPerspective(probe, H, reference.shape[::-1], flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    mask = (cv2.absdiff(reference, warped) > threshold).astype(np.uint8)
    n, _, stats, _ = cv2.connectedComponentsWithStats(mask)
    boxes = [[x, y, x + w, y + h] for x, y, w, h, a in stats[1:] if a >= min_area]
    return defect.map_boxes(np.array(boxes, float).reshape(-1, 4), H)


# --------------------------------------------------------------------------------------------------- run


def _score(counts: dict, verdicts: list[tuple[str, str]]) -> dict:
    import numpy as np
    from ..metrics import DetectionCounts

    faulty = [v for t, v in verdicts if t == "faulty"]
    perfect = [v for t, v in verdicts if t == "perfect"]
    c: DetectionCounts = counts
    return {
        "accuracy": float(np.mean([t == v for t, v in verdicts])),
        "faulty_flagged": float(np.mean([v == "faulty" for v in faulty])) if faulty else None,
        "false_alarm_rate": float(np.mean([v != "perfect" for v in perfect])) if perfect else None,
        "errors": sum(v == "error" for _, v in verdicts),
        "precision": c.precision, "recall": c.recall, "f1": c.f1, "tp": c.tp, "fp": c.fp, "fn": c.fn,
    }


def evaluate(pairs: list[dict], seed: int, params: InspectParams, baseline: bool = True,
             progress: bool | None = None) -> dict:
    """Run ours (and the plain-difference baseline) on both probes of every pair; return metrics and
    timings."""
    import numpy as np
    from tqdm import tqdm
    from .. import defect, io
    from ..features import detect
    from ..metrics import DetectionCounts, match_boxes

    pad = params.regions.pad
    tight = replace(params.regions, pad=0.0)
    names = ["ours", "ours_tight_boxes"] + (["baseline"] if baseline else [])
    counts = {k: DetectionCounts(0, 0, 0) for k in names}
    verdicts = {k: [] for k in names}
    times = {"ours": [], "baseline": [], "reference_features": []}
    failures, n_direct, records = [], 0, []
    for k, pair in enumerate(tqdm(pairs, desc="defect", disable=progress)):
        rng = np.random.default_rng([seed, k])
        ref = io.read_image(pair["template"], "gray")
        test = io.read_image(pair["test"], "gray")
        t0 = time.perf_counter()
        fr = detect(ref, params.features.detector, params.features.max_features)
        times["reference_features"].append(time.perf_counter() - t0)
        fr_baseline = detect(ref, "sift", 4000) if baseline else None
        for truth_verdict, src, boxes in (("faulty", test, pair["boxes"]), ("perfect", ref, np.zeros((0, 4)))):
            probe, H, gt = make_probe(src, boxes, rng)
            t0 = time.perf_counter()
            try:
                r = defect.inspect(ref, probe, params, reference_features=fr)
                times["ours"].append(time.perf_counter() - t0)
                n_direct += r.registration.method == "direct"
                verdicts["ours"].append((truth_verdict, r.verdict))
                c = match_boxes(r.probe_regions, gt, IOU)[0]
                counts["ours"] += c
                records.append({"pair": pair["name"], "probe": truth_verdict, "verdict": r.verdict, "tp": c.tp,
                                "fp": c.fp, "fn": c.fn, "registration": r.registration.method})
                tight_boxes = defect.find_regions(r.difference, r.registration.H, probe.shape, tight).probe_regions
                verdicts["ours_tight_boxes"].append((truth_verdict, r.verdict))
                counts["ours_tight_boxes"] += match_boxes(tight_boxes, gt, IOU)[0]
            except CvpipeError as exc:
                times["ours"].append(time.perf_counter() - t0)
                failures.append({"pair": pair["name"], "probe": truth_verdict, "error": str(exc)})
                records.append({"pair": pair["name"], "probe": truth_verdict, "verdict": None, "tp": 0, "fp": 0,
                                "fn": len(gt), "registration": None})
                for name in ("ours", "ours_tight_boxes"):
                    verdicts[name].append((truth_verdict, "error"))
                    counts[name] += DetectionCounts(0, 0, len(gt))
            if baseline:
                t0 = time.perf_counter()
                try:
                    boxes_baseline = baseline_method(ref, probe, fr_baseline)
                    times["baseline"].append(time.perf_counter() - t0)
                    verdicts["baseline"].append((truth_verdict, "faulty" if len(boxes_baseline) else "perfect"))
                    counts["baseline"] += match_boxes(boxes_baseline, gt, IOU)[0]
                except CvpipeError:
                    times["baseline"].append(time.perf_counter() - t0)
                    verdicts["baseline"].append((truth_verdict, "error"))
                    counts["baseline"] += DetectionCounts(0, 0, len(gt))
    results = {name: _score(counts[name], verdicts[name]) for name in names}
    for name in results:
        key = "baseline" if name == "baseline" else "ours"
        results[name]["median_s_per_probe"] = statistics.median(times[key]) if times[key] else None
    return {"pairs": len(pairs), "probes": 2 * len(pairs), "iou": IOU, "pad": pad, "seed": seed,
            "detector": params.features.detector, "max_features": params.features.max_features,
            "direct_registrations": n_direct,
            "methods": results, "reference_features_median_s": statistics.median(times["reference_features"]),
            "failures": failures, "records": records}


def run(args: argparse.Namespace) -> int:
    import cv2
    from .. import defect, io

    if not args.data:
        raise InputError("no data root: pass --data DIR or set CVPIPE_DATA")
    if args.limit < 0:
        raise InputError(f"`--limit` must be >= 0, got {args.limit}")
    if args.pad < 0:
        raise InputError(f"`--pad` must be >= 0, got {args.pad}")
    pairs = load_pairs(Path(args.data), args.split)
    if args.limit:
        pairs = pairs[:args.limit]
    cv2.setRNGSeed(args.seed)
    # warm-up: the first call pays for lazy initialisation (FLANN, OpenCV's thread pool)
    warm = io.read_image(pairs[0]["template"], "gray")
    defect.inspect(warm, warm)
    params = InspectParams()
    feats = replace(params.features, **{k: v for k, v in (("detector", args.detector),
                                                           ("max_features", args.max_features)) if v is not None})
    params = replace(params, features=feats, regions=replace(params.regions, pad=args.pad))
    res = evaluate(pairs, args.seed, params, not args.no_baseline)
    if args.out:
        io.save_json(args.out, res)
    if args.json:
        print(io.dumps_json(res))
        return 0
    print(f"DeepPCB: {res['pairs']} pairs -> {res['probes']} probes (half faulty), IoU >= {IOU}, pad {args.pad:g} px")
    print(f"{'method':18} {'acc':>6} {'flagged':>8} {'false al':>8} {'err':>4} {'prec':>6} {'recall':>6} "
          f"{'F1':>6} {'s/probe':>8}")
    for name, m in res["methods"].items():
        print(f"{name:18} {m['accuracy']:6.3f} {m['faulty_flagged']:8.3f} {m['false_alarm_rate']:8.3f} "
              f"{m['errors']:4d} {m['precision']:6.3f} {m['recall']:6.3f} {m['f1']:6.3f} "
              f"{m['median_s_per_probe']:8.3f}")
    print(f"registration: {res['detector']} x {res['max_features']}, {res['direct_registrations']} probes aligned "
          f"directly (keypoints gave no homography, or the direct start aligned better)")
    if "baseline" in res["methods"]:
        ratio = res["methods"]["baseline"]["median_s_per_probe"] / res["methods"]["ours"]["median_s_per_probe"]
        print(f"time per probe, baseline / ours (same process, interleaved): {ratio:.2f}")
    print(f"reference features (once per reference): {res['reference_features_median_s']:.3f} s median")
    for f in res["failures"]:
        print(f"  registration failed: {f['pair']} {f['probe']}: {f['error']}")
    return 0
