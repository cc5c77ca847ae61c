"""Stage `homography_match`: match the features of every sample pair (A -> B) and save the correspondences."""

import argparse
from pathlib import Path

from cvpipe import io, matching
from cvpipe.features import Features
from cvpipe.params import MatchParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--truth", required=True, help="data/samples/homography/truth.json (lists the pairs)")
    ap.add_argument("--features", required=True, help="folder of per-image feature .npz files")
    ap.add_argument("--out", required=True)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(MatchParams, "homography.match", args.params)
    feats_dir, out = Path(args.features), Path(args.out)
    counts = {}
    for pair in io.progress(io.load_json(args.truth)["pairs"], "match"):
        io.safe_name(pair["name"], f"{args.truth}: pair name")
        fa = Features.from_arrays(io.load_npz(feats_dir / Path(pair["a"]).with_suffix(".npz")))
        fb = Features.from_arrays(io.load_npz(feats_dir / Path(pair["b"]).with_suffix(".npz")))
        idx = matching.match(fa.descriptors, fb.descriptors, p.ratio, p.cross_check, fa.binary)
        io.save_npz(out / f"{pair['name']}.npz", index=idx, src=fa.xy[idx[:, 0]], dst=fb.xy[idx[:, 1]])
        counts[pair["name"]] = len(idx)
    io.save_json(out / "summary.json", {"matches": counts})


if __name__ == "__main__":
    main()
