"""Stage `logo_verify@det`: homography verification and the brand decision per scene, metrics, PR curve (pr.json)."""

import argparse
import math
import time
from pathlib import Path

from tqdm import tqdm

from cvpipe import io, logos
from cvpipe.features import Features
from cvpipe.params import LogoMatchParams, LogoVerifyParams, load_section
from stages.logo_match import load_gallery_features


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--gallery", required=True, help="folder of gallery feature .npz files")
    ap.add_argument("--scenes", required=True, help="folder of scene feature .npz files")
    ap.add_argument("--matches", required=True, help="folder written by logo_match")
    ap.add_argument("--truth", required=True, help="data/samples/logo/truth.json")
    ap.add_argument("--out", required=True, help="folder for decisions.json and inlier pairs")
    ap.add_argument("--metrics", required=True, help="metrics JSON file")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    mp = load_section(LogoMatchParams, "logo.match", args.params)
    vp = load_section(LogoVerifyParams, "logo.verify", args.params)
    gallery = load_gallery_features(Path(args.gallery), mp)
    match_s = io.load_json(Path(args.matches) / "timings.json")["match_s"]
    truth = {s["file"]: s for s in io.load_json(args.truth)["scenes"]}
    out, records = Path(args.out), []
    for name in tqdm(sorted(truth), desc=f"verify {gallery.detector}", disable=None):
        stem = Path(name).stem
        arrays = io.load_npz(Path(args.scenes) / f"{stem}.npz")
        scene, size = Features.from_arrays(arrays), tuple(int(v) for v in arrays["image_size"])
        t0 = time.perf_counter()
        hyps = logos.verify(gallery, logos.Matches.from_arrays(io.load_npz(Path(args.matches) / f"{stem}.npz")),
                            scene, size, vp, rng=0)
        det = logos.decide(hyps, vp)
        elapsed = time.perf_counter() - t0 + match_s[stem]
        best = det.best
        rec = {"scene": name, "brand": det.brand, "inliers": det.inliers,
               "score": det.score if math.isfinite(det.score) else None,
               "quad": None if det.quad is None else det.quad.tolist(), "truth": truth[name]["brand"],
               "truth_quad": truth[name]["quad"], "best_brand": best.brand if best else None,
               "reference": gallery.references[best.reference].name if best else None,
               "quad_error_px": (logos.quad_error(det.quad, truth[name]["quad"], cyclic=True)
                                 if det.brand and det.brand == truth[name]["brand"] else None),
               "seconds": elapsed}
        records.append(rec)
        if best is not None:
            io.save_npz(out / f"{stem}.npz", pairs=best.pairs, H=best.H,
                        gallery_xy=best.reference_xy,
                        scene_xy=scene.xy[best.pairs[:, 1]])
    ev = logos.evaluate([r["truth"] for r in records], [r["best_brand"] for r in records],
                        [r["score"] if r["score"] is not None else -math.inf for r in records], vp.score_threshold)
    errs = [r["quad_error_px"] for r in records if r["quad_error_px"] is not None]
    io.save_json(out / "decisions.json", {"detector": gallery.detector, "scenes": records})
    io.save_json(args.metrics, {k: ev[k] for k in ("precision", "recall", "accuracy", "answered", "correct",
                                                  "scenes", "positives")}
                 | {"time_per_scene_s": sorted(r["seconds"] for r in records)[len(records) // 2],
                    "quad_error_px_median": sorted(errs)[len(errs) // 2] if errs else None})
    io.save_json(out / "pr.json", [dict(c, method=gallery.detector) for c in ev["curve"]])


if __name__ == "__main__":
    main()
