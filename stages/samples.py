"""Stage `samples`: build the bundled sample data set into data/samples/<task>/ (images + truth.json)."""

import argparse
import shutil
import time
from pathlib import Path

from cvpipe import io, samples
from cvpipe.params import SamplesParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default="data/samples")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(SamplesParams, "samples", args.params)
    t0 = time.perf_counter()
    sets = samples.build_all(p.seed, p.logo_scenes, p.logo_negatives)
    out = Path(args.out)
    tmp = out.with_name(f".{out.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    for task, s in io.progress(sets.items(), "samples"):
        for name, img in s.images.items():
            io.save_image(tmp / task / name, img)
        for name, arrays in s.arrays.items():
            io.save_npz(tmp / task / name, **arrays)
        io.save_json(tmp / task / "truth.json", s.truth)
    (tmp / "README.md").write_text(samples.README, encoding="utf-8")
    shutil.rmtree(out, ignore_errors=True)
    tmp.rename(out)  # the finished folder appears in one step
    print(f"samples: {sum(len(s.images) for s in sets.values())} images in {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
