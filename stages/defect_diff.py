"""Stage `defect_diff`: gain/bias-corrected, misregistration-tolerant difference of every registered probe."""

import argparse
from pathlib import Path

from tqdm import tqdm

from cvpipe import defects, io
from cvpipe.params import DefectDiffParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--reference", required=True, help="data/samples/defect/reference.png")
    ap.add_argument("--registered", required=True, help="outputs/defect/register")
    ap.add_argument("--out", required=True, help="folder for <probe>.npz")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(DefectDiffParams, "defect.diff", args.params)
    ref = io.read_image(args.reference, "gray")
    for f in tqdm(sorted(Path(args.registered).glob("*.npz")), desc="diff", disable=None):
        reg = io.load_npz(f)
        d = defects.difference(ref, reg["warped"], reg["valid"], p)
        io.save_npz(Path(args.out) / f.name, diff=d.diff, valid=d.valid, gain=d.gain, bias=d.bias, noise=d.noise,
                    contrast=d.contrast, H=reg["H"], probe_shape=reg["probe_shape"])


if __name__ == "__main__":
    main()
