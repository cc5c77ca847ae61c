"""``cvpipe bench homography --data DIR``: our LO-RANSAC vs OpenCV RANSAC and USAC_MAGSAC on real pairs with ground
truth (Oxford affine, CMP homogr) and on a synthetic outlier sweep.

Every method gets the same SIFT correspondences and the same threshold, confidence and iteration cap. Runs are
interleaved (the method order rotates per repeat) after a warm-up, in this one process; times are medians, and the
ratios are ours / MAGSAC. The machine may be shared, so both wall-clock and process CPU time are recorded.
"""

from __future__ import annotations

import argparse
import csv
import os
import time
import typing
from pathlib import Path

from ..errors import EstimationError, InputError
from ..params import Detector, FeaturesParams, HomographyEstimateParams, MatchParams

#: --detector choices: the names of cvpipe.features.DETECTORS, read from the params model (no cv2 for --help)
DETECTORS = typing.get_args(Detector)

if typing.TYPE_CHECKING:  # annotations only: the modules are imported inside the functions that use them,
    # so that `cvpipe bench homography --help` imports neither numpy nor cv2
    import numpy as np


HELP = "our homography estimator vs OpenCV RANSAC/MAGSAC: Oxford + CMP pairs and a synthetic outlier sweep"
EXAMPLE = "cvpipe bench homography --data ../shared/data --repeats 5"

SETS = ("oxford", "cmp")
OXFORD = ("boat", "bikes", "leuven", "wall", "graf", "yosemite")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    f, m, e = FeaturesParams(), MatchParams(), HomographyEstimateParams()
    parser.add_argument("--data", default=os.environ.get("CVPIPE_DATA"),
                        help="root of the shared data sets (default: $CVPIPE_DATA)")
    parser.add_argument("--sets", nargs="+", choices=SETS, default=list(SETS), help="real data sets to run")
    parser.add_argument("--no-real", action="store_true", help="only the synthetic sweep")
    parser.add_argument("--no-synthetic", action="store_true", help="only the real pairs")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per method and pair (default 5)")
    parser.add_argument("--limit", type=int, help="at most this many real pairs (smoke runs)")
    parser.add_argument("--detector", choices=sorted(DETECTORS), default=f.detector)
    parser.add_argument("--max-features", type=int, default=f.max_features)
    parser.add_argument("--ratio", type=float, default=m.ratio)
    parser.add_argument("--threshold", type=float, default=e.threshold)
    parser.add_argument("--confidence", type=float, default=e.confidence)
    parser.add_argument("--max-iters", type=int, default=e.max_iters, help="iteration cap on the real pairs")
    parser.add_argument("--success-px", type=float, default=3.0, help="a pair succeeds within this corner error")
    parser.add_argument("--synthetic-points", type=int, default=1000)
    parser.add_argument("--synthetic-trials", type=int, default=10)
    parser.add_argument("--outliers", type=float, nargs="+", default=[0.5, 0.8, 0.9])
    parser.add_argument("--synthetic-max-iters", type=int, default=100_000,
                        help="iteration cap in the sweep (90 %% outliers need ~69000 at confidence 0.999)")
    parser.add_argument("--out", help="also write the full results as JSON to this file")
    parser.add_argument("--json", action="store_true", help="print JSON instead of the markdown tables")


# ------------------------------------------------------------------------------------------------- data


def real_pairs(root: Path, sets=SETS) -> list[dict]:
    """The benchmark pairs with ground truth H mapping A's pixels to B's.

    Oxford: ``<seq>/img1 -> imgN`` with ``H1toNp`` (1 -> N). CMP: ``pairs/<name>A -> <name>B`` with
    ``derived/<name>_H_A_to_B.txt`` (the original ``<name>_model.txt`` maps B -> A).
    """
    import numpy as np

    pairs: list[dict] = []
    if "oxford" in sets:
        base = root / "oxford_affine"
        for seq in OXFORD:
            d = base / seq
            if not d.is_dir():
                continue
            for hfile in sorted(d.glob("H1to*p")):
                k = hfile.name[len("H1to"):-1]
                if k == "1":
                    continue  # the identity
                if seq == "yosemite":
                    a, b = d / "yosemite1.jpg", d / f"yosemite{k}.jpg"
                else:
                    a, b = next(d.glob("img1.*")), next(d.glob(f"img{k}.*"))
                pairs.append({"set": "oxford", "name": f"{seq}_1to{k}", "a": a, "b": b, "H": np.loadtxt(hfile)})
    if "cmp" in sets:
        base = root / "cmp_homogr"
        table = base / "pairs.csv"
        if table.is_file():
            with open(table, newline="") as fh:
                for row in csv.DictReader(fh):
                    pairs.append({"set": "cmp", "name": row["name"], "a": base / row["imageA"],
                                  "b": base / row["imageB"], "H": np.loadtxt(base / row["H_A_to_B_derived"]),
                                  "vpts": np.loadtxt(base / row["validation_pts_derived"]).reshape(-1, 4)})
    return pairs


def synthetic_scene(rng: np.random.Generator, n: int, outlier_frac: float, noise: float = 1.0,
                    width: int = 640, height: int = 480) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A random perspective H (corners moved by up to 20 % of the size), n correspondences with Gaussian noise of
    ``noise`` px on dst, and ``outlier_frac`` of them replaced by uniform points. Returns (H, src, dst)."""
    import numpy as np
    from ..homography import transform_points

    corners = np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]], float)
    moved = corners + rng.uniform(-0.2, 0.2, (4, 2)) * [width, height]
    import cv2

    H = cv2.getPerspectiveTransform(corners.astype(np.float32), moved.astype(np.float32)).astype(np.float64)
    src = rng.uniform([0, 0], [width - 1, height - 1], (n, 2))
    dst = transform_points(H, src) + rng.normal(0.0, noise, (n, 2))
    k = int(round(outlier_frac * n))
    out = rng.choice(n, k, replace=False)
    lo, hi = dst.min(axis=0), dst.max(axis=0)
    dst[out] = rng.uniform(lo, hi, (k, 2))
    return H, src, dst


# ---------------------------------------------------------------------------------------------- timing


def _timed(method: str, src, dst, seed: int, **kw) -> tuple[np.ndarray | None, int, float, float]:
    """(H or None, inliers, wall seconds, CPU seconds) of one estimate."""
    from ..homography import estimate

    w0, c0 = time.perf_counter(), time.process_time()
    try:
        fit = estimate(method, src, dst, rng=seed, **kw)
        H, inl = fit.H, fit.num_inliers
    except EstimationError:
        H, inl = None, 0
    return H, inl, time.perf_counter() - w0, time.process_time() - c0


def _run_all(src, dst, repeats: int, H_true, size, vpts=None, **kw) -> dict:
    """Interleaved repeats of every method on one set of correspondences.

    ``vpts`` (K, 4) ``xA yA xB yB``: hand-clicked validation correspondences (CMP); their mean transfer error A -> B
    is recorded as ``vpts_error_px`` (the corner error extrapolates far outside a plane that covers part of A).
    """
    import numpy as np
    from ..homography import METHODS, transform_points
    from ..metrics import corner_error

    methods = list(METHODS)
    rec = {m: {"err": [], "wall": [], "cpu": [], "inliers": [], "vp": []} for m in methods}
    for r in range(repeats):
        order = methods[r % len(methods):] + methods[:r % len(methods)]
        for m in order:
            H, inl, wall, cpu = _timed(m, src, dst, seed=r, **kw)
            err = corner_error(H, H_true, *size) if H is not None else float("inf")
            rec[m]["err"].append(err)
            if vpts is not None:
                vp = (np.linalg.norm(transform_points(H, vpts[:, :2]) - vpts[:, 2:], axis=1).mean()
                      if H is not None else float("inf"))
                rec[m]["vp"].append(vp)
            rec[m]["wall"].append(wall)
            rec[m]["cpu"].append(cpu)
            rec[m]["inliers"].append(inl)
    return {m: {"corner_error_px": float(np.median(v["err"])), "time_ms": 1e3 * float(np.median(v["wall"])),
                "cpu_ms": 1e3 * float(np.median(v["cpu"])), "inliers": int(np.median(v["inliers"])),
                "vpts_error_px": float(np.median(v["vp"])) if v["vp"] else None}
            for m, v in rec.items()}


def _warm_up(kw: dict) -> float:
    """Run every method once (the first call of each in this process: OpenCV's initialisation, first allocations);
    returns ours' first-call time."""
    import numpy as np
    from ..homography import METHODS, estimate

    rng = np.random.default_rng(0)
    H, src, dst = synthetic_scene(rng, 200, 0.5)
    t0 = time.perf_counter()
    estimate("ours", src, dst, **kw)
    first = time.perf_counter() - t0
    for m in METHODS:
        estimate(m, src, dst, **kw)
    return first


def bench_real(root: Path, args) -> list[dict]:
    from tqdm import tqdm
    from .. import io
    from ..homography import METHODS, correspondences

    kw = dict(threshold=args.threshold, confidence=args.confidence, max_iters=args.max_iters)
    pairs = real_pairs(root, args.sets)
    if not pairs:
        raise InputError(f"{root}: no Oxford or CMP pairs found (expected oxford_affine/ and cmp_homogr/)")
    if args.limit:
        pairs = pairs[: args.limit]
    rows = []
    for p in tqdm(pairs, desc="pairs", disable=None):
        a, b = io.read_image(p["a"], "gray"), io.read_image(p["b"], "gray")
        src, dst = correspondences(a, b, args.detector, args.max_features, args.ratio)
        size = (a.shape[1], a.shape[0])
        row = {"set": p["set"], "pair": p["name"], "matches": len(src)}
        if len(src) < 4:
            row["methods"] = {m: {"corner_error_px": float("inf"), "time_ms": None, "cpu_ms": None, "inliers": 0,
                                  "vpts_error_px": float("inf") if "vpts" in p else None} for m in METHODS}
        else:
            row["methods"] = _run_all(src, dst, args.repeats, p["H"], size, p.get("vpts"), **kw)
        rows.append(row)
    return rows


def bench_synthetic(args) -> list[dict]:
    import numpy as np
    from tqdm import tqdm
    from ..homography import METHODS

    kw = dict(threshold=args.threshold, confidence=args.confidence, max_iters=args.synthetic_max_iters)
    rows = []
    for frac in args.outliers:
        rng = np.random.default_rng(int(round(frac * 1000)))
        per = {m: {"err": [], "wall": [], "cpu": []} for m in METHODS}
        ratios_wall, ratios_cpu = [], []
        for t in tqdm(range(args.synthetic_trials), desc=f"synthetic {frac:.0%}", disable=None):
            H, src, dst = synthetic_scene(rng, args.synthetic_points, frac)
            res = _run_all(src, dst, 1, H, (640, 480), **kw)
            for m, v in res.items():
                per[m]["err"].append(v["corner_error_px"])
                per[m]["wall"].append(v["time_ms"])
                per[m]["cpu"].append(v["cpu_ms"])
            ratios_wall.append(res["ours"]["time_ms"] / res["opencv_magsac"]["time_ms"])
            ratios_cpu.append(res["ours"]["cpu_ms"] / max(res["opencv_magsac"]["cpu_ms"], 1e-6))
        rows.append({
            "outliers": frac, "points": args.synthetic_points, "trials": args.synthetic_trials,
            "methods": {m: {"median_corner_error_px": float(np.median(v["err"])),
                            "max_corner_error_px": float(np.max(v["err"])),
                            "time_ms": float(np.median(v["wall"])), "cpu_ms": float(np.median(v["cpu"]))}
                        for m, v in per.items()},
            "ratio_ours_magsac_wall": float(np.median(ratios_wall)),
            "ratio_ours_magsac_cpu": float(np.median(ratios_cpu)),
        })
    return rows


def summarize(rows: list[dict], success_px: float) -> dict:
    import numpy as np
    from ..homography import METHODS

    out = {}
    for m in METHODS:
        errs = np.array([r["methods"][m]["corner_error_px"] for r in rows])
        times = [r["methods"][m]["time_ms"] for r in rows if r["methods"][m]["time_ms"] is not None]
        out[m] = {"median_corner_error_px": float(np.median(errs)), "pairs_within": int((errs <= success_px).sum()),
                  "pairs": len(errs), "median_time_ms": float(np.median(times)) if times else None}
        vp = np.array([r["methods"][m]["vpts_error_px"] for r in rows if r["methods"][m]["vpts_error_px"] is not None])
        if len(vp):
            out[m]["cmp_median_vpts_error_px"] = float(np.median(vp))
            out[m]["cmp_vpts_within"] = int((vp <= success_px).sum())
            out[m]["cmp_pairs"] = len(vp)
        better = sum(r["methods"][m]["corner_error_px"] < r["methods"]["opencv_magsac"]["corner_error_px"]
                     for r in rows)
        out[m]["pairs_better_than_magsac"] = int(better)
    return out


# ---------------------------------------------------------------------------------------------- report


def _f(v, fmt="{:.2f}") -> str:
    import numpy as np

    if v is None:
        return "-"
    return "fail" if not np.isfinite(v) else fmt.format(v)


def markdown(result: dict) -> str:
    from ..homography import METHODS

    lines = []
    names = {"ours": "ours", "opencv_ransac": "cv2 RANSAC", "opencv_magsac": "cv2 MAGSAC"}
    if result.get("real"):
        lines += [f"Real pairs: corner error in px (median of {result['repeats']} runs) and time per estimate in ms.",
                  "", "| set | pair | matches | " + " | ".join(f"{names[m]} px" for m in METHODS) + " | "
                  + " | ".join(f"{names[m]} ms" for m in METHODS) + " |",
                  "|---|---|---:|" + "---:|" * (2 * len(METHODS))]
        for r in result["real"]:
            lines.append(f"| {r['set']} | {r['pair']} | {r['matches']} | "
                         + " | ".join(_f(r["methods"][m]["corner_error_px"]) for m in METHODS) + " | "
                         + " | ".join(_f(r["methods"][m]["time_ms"]) for m in METHODS) + " |")
        cmp_rows = [r for r in result["real"] if r["methods"]["ours"].get("vpts_error_px") is not None]
        if cmp_rows:
            lines += ["", "CMP pairs: mean transfer error of the 8 hand-clicked validation points (px).", "",
                      "| pair | " + " | ".join(names[m] for m in METHODS) + " |", "|---|" + "---:|" * len(METHODS)]
            for r in cmp_rows:
                lines.append(f"| {r['pair']} | " + " | ".join(_f(r["methods"][m]["vpts_error_px"]) for m in METHODS)
                             + " |")
        s = result["summary"]
        px = f"{result['success_px']:g}"
        lines += ["", f"| method | median corner error (px) | pairs within {px} px | pairs more accurate than MAGSAC | "
                      f"CMP median validation-point error (px) | CMP within {px} px | median time (ms) |",
                  "|---|---:|---:|---:|---:|---:|---:|"]
        for m in METHODS:
            lines.append(f"| {names[m]} | {_f(s[m]['median_corner_error_px'])} | {s[m]['pairs_within']} / "
                         f"{s[m]['pairs']} | {s[m]['pairs_better_than_magsac'] if m != 'opencv_magsac' else '-'} | "
                         f"{_f(s[m].get('cmp_median_vpts_error_px'))} | {s[m].get('cmp_vpts_within', '-')} / "
                         f"{s[m].get('cmp_pairs', '-')} | {_f(s[m]['median_time_ms'])} |")
    if result.get("synthetic"):
        syn = result["synthetic"]
        lines += ["", f"Synthetic sweep: {syn[0]['points']} correspondences, 1 px noise, {syn[0]['trials']} scenes "
                      "per row; median corner error (px) and median time per estimate (ms).", "",
                  "| outliers | " + " | ".join(f"{names[m]} px" for m in METHODS) + " | "
                  + " | ".join(f"{names[m]} ms" for m in METHODS) + " | ours / MAGSAC (wall) | ours / MAGSAC (CPU) |",
                  "|---:|" + "---:|" * (2 * len(METHODS) + 2)]
        for r in syn:
            lines.append(f"| {r['outliers']:.0%} | "
                         + " | ".join(_f(r["methods"][m]["median_corner_error_px"]) for m in METHODS) + " | "
                         + " | ".join(_f(r["methods"][m]["time_ms"]) for m in METHODS)
                         + f" | {r['ratio_ours_magsac_wall']:.2f} | {r['ratio_ours_magsac_cpu']:.2f} |")
    if "first_call_s" in result:
        lines += ["", f"First call of ours in this process: {result['first_call_s']:.2f} s"
                      " (not included above)."]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from .. import io

    if args.repeats < 1:
        raise InputError(f"`--repeats` must be >= 1, got {args.repeats}")
    if args.synthetic_trials < 1 or args.synthetic_points < 8:
        raise InputError("`--synthetic-trials` must be >= 1 and `--synthetic-points` >= 8")
    for f in args.outliers:
        if not 0.0 <= f < 1.0:
            raise InputError(f"`--outliers` values must be in [0, 1), got {f}")
    result: dict = {"repeats": args.repeats, "success_px": args.success_px, "threshold": args.threshold,
                    "confidence": args.confidence, "detector": args.detector}
    kw = dict(threshold=args.threshold, confidence=args.confidence, max_iters=args.max_iters)
    result["first_call_s"] = _warm_up(kw)
    if not args.no_real:
        if not args.data:
            raise InputError("no data root: pass --data DIR or set CVPIPE_DATA (or use --no-real)")
        root = Path(args.data)
        if not root.is_dir():
            raise InputError(f"{root}: no such folder")
        result["real"] = bench_real(root, args)
        result["summary"] = summarize(result["real"], args.success_px)
    if not args.no_synthetic:
        result["synthetic"] = bench_synthetic(args)
    if args.out:
        io.save_json(args.out, result)
    print(io.dumps_json(result) if args.json else markdown(result))
    return 0
