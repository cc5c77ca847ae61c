"""Stage `homography_estimate@<method>`: a robust homography A -> B for every matched sample pair."""

import argparse
import time
from pathlib import Path

from tqdm import tqdm

from cvpipe import io
from cvpipe.errors import EstimationError
from cvpipe.homography import estimate
from cvpipe.params import HomographyEstimateParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--truth", required=True, help="data/samples/homography/truth.json (lists the pairs)")
    ap.add_argument("--matches", required=True, help="folder of <pair>.npz with src, dst (homography_match)")
    ap.add_argument("--method", required=True, help="ours, opencv_ransac or opencv_magsac")
    ap.add_argument("--out", required=True)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(HomographyEstimateParams, "homography.estimate", args.params)
    kw = dict(threshold=p.threshold, confidence=p.confidence, max_iters=p.max_iters)
    pairs = io.load_json(args.truth)["pairs"]
    out, results = Path(args.out), {}
    loaded = {q["name"]: io.load_npz(Path(args.matches) / f"{q['name']}.npz") for q in pairs}
    # warm-up (numba compilation, OpenCV initialisation) so that the recorded times are run times
    for m in loaded.values():
        if len(m["src"]) >= 4:
            try:
                estimate(args.method, m["src"], m["dst"], rng=p.seed, **kw)
            except EstimationError:
                pass
            break
    for q in tqdm(pairs, desc=f"estimate {args.method}", disable=None):
        io.safe_name(q["name"], f"{args.truth}: pair name")
        m = loaded[q["name"]]
        t0 = time.perf_counter()
        try:
            fit = estimate(args.method, m["src"], m["dst"], rng=p.seed, **kw)
        except (EstimationError, ValueError) as exc:
            results[q["name"]] = {"H": None, "matches": len(m["src"]), "inliers": 0, "error": str(exc)}
            continue
        dt = time.perf_counter() - t0
        io.save_npz(out / f"{q['name']}.npz", H=fit.H, inliers=fit.inliers)
        results[q["name"]] = {"H": fit.H, "matches": len(m["src"]), "inliers": fit.num_inliers,
                              "time_ms": 1e3 * dt}
    io.save_json(out / "estimates.json", {"method": args.method, "pairs": results})


if __name__ == "__main__":
    main()
