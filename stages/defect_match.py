"""Stage `defect_match`: match the reference's keypoints to every probe's, one .npz of index pairs per probe."""

import argparse
from pathlib import Path

from tqdm import tqdm

from cvpipe import io, matching
from cvpipe.features import Features
from cvpipe.params import MatchParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--features", required=True, help="outputs/defect/features (reference.npz, probes/*.npz)")
    ap.add_argument("--out", required=True, help="folder for <probe>.npz")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(MatchParams, "defect.match", args.params)
    feats = Path(args.features)
    ref = Features.from_arrays(io.load_npz(feats / "reference.npz"))
    counts = {}
    for f in tqdm(sorted((feats / "probes").glob("*.npz")), desc="match", disable=None):
        probe = Features.from_arrays(io.load_npz(f))
        idx = matching.match(ref.descriptors, probe.descriptors, p.ratio, p.cross_check, ref.binary)
        io.save_npz(Path(args.out) / f.name, index=idx)
        counts[f.stem] = len(idx)
    io.save_json(Path(args.out) / "summary.json", {"matches": counts})


if __name__ == "__main__":
    main()
