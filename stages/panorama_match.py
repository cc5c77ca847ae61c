"""Stage `panorama_match`: per set, match every pair of images -> the match-confidence graph (.npz)."""

import argparse
import time
from pathlib import Path

from tqdm import tqdm

from cvpipe import io, panorama
from cvpipe.features import Features
from cvpipe.params import PanoramaMatchParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--features", required=True, help="folder of <set>/<image>.npz from panorama_features")
    ap.add_argument("--out", required=True, help="folder for <set>.npz")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(PanoramaMatchParams, "panorama.match", args.params)
    for d in tqdm(sorted(x for x in Path(args.features).iterdir() if x.is_dir()), desc="panorama match",
                  disable=None):
        arrays = [io.load_npz(f) for f in sorted(d.glob("*.npz"))]
        feats = [Features.from_arrays(a) for a in arrays]
        sizes = [tuple(int(v) for v in a["work_size"]) for a in arrays]
        t0 = time.perf_counter()
        graph = panorama.match_graph(feats, sizes, ratio=p.ratio, ransac_threshold=p.ransac_threshold,
                                     min_inliers=p.min_inliers, min_confidence=p.min_confidence,
                                     candidates=p.candidates, refit_threshold=p.refit_threshold, rng=p.seed)
        io.save_npz(Path(args.out) / f"{d.name}.npz", **graph.to_arrays(),
                    files=[str(a["image_file"]) for a in arrays], full_sizes=[a["full_size"] for a in arrays],
                    seconds=time.perf_counter() - t0)


if __name__ == "__main__":
    main()
