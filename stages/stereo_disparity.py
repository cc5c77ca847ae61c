"""Stage `stereo_disparity@<method>`: disparity of the sample pair, its 16-bit PNG and its accuracy metrics."""

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from cvpipe import io, stereo
from cvpipe.params import SECTIONS, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--method", required=True, choices=sorted(stereo.METHODS))
    ap.add_argument("--samples", required=True, help="data/samples/stereo (left.png, right.png, truth.npz/.json)")
    ap.add_argument("--out", required=True, help="folder for disparity.npy, disparity.png and metrics.json")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    section = f"stereo.{args.method}"
    options = dataclasses.asdict(load_section(SECTIONS[section], section, args.params))
    samples, out = Path(args.samples), Path(args.out)
    left, right = io.read_image(samples / "left.png"), io.read_image(samples / "right.png")
    truth = io.load_npz(samples / "truth.npz")["disparity"]
    max_disp = int(io.load_json(samples / "truth.json")["max_disp"])

    t0 = time.perf_counter()
    stereo.compute_disparity(left, right, max_disp, args.method, **options)  # warm-up: numba cache load, allocations
    t1 = time.perf_counter()
    disp = stereo.compute_disparity(left, right, max_disp, args.method, **options)
    t2 = time.perf_counter()

    with io.atomic_path(out / "disparity.npy") as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, disp.astype(np.float32), allow_pickle=False)
    io.save_image(out / "disparity.png", stereo.to_png16(disp))
    io.save_json(out / "metrics.json", {"method": args.method, "max_disp": max_disp, **stereo.evaluate(disp, truth),
                                        "seconds": t2 - t1, "first_call_seconds": t1 - t0})


if __name__ == "__main__":
    main()
