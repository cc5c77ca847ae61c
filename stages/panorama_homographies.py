"""Stage `panorama_homographies`: per set, drop unmatched images, chain along the maximum spanning tree, refine."""

import argparse
import time
from pathlib import Path

from tqdm import tqdm

from cvpipe import io, panorama
from cvpipe.errors import EstimationError
from cvpipe.params import PanoramaHomographiesParams, PanoramaMatchParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--matches", required=True, help="folder of <set>.npz from panorama_match")
    ap.add_argument("--out", required=True, help="folder for <set>.json")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(PanoramaHomographiesParams, "panorama.homographies", args.params)
    seed = load_section(PanoramaMatchParams, "panorama.match", args.params).seed
    for f in tqdm(sorted(Path(args.matches).glob("*.npz")), desc="panorama homographies", disable=None):
        arrays = io.load_npz(f)
        graph = panorama.MatchGraph.from_arrays(arrays)
        t0 = time.perf_counter()
        out = {"files": arrays["files"].tolist(), "work_sizes": graph.sizes,
               "full_sizes": arrays["full_sizes"].tolist()}
        try:
            reg = panorama.register(graph, refine=p.refine, max_points_per_pair=p.max_points_per_pair, rng=seed)
            out.update(reg.to_json(), ok=True)
        except EstimationError as exc:  # recorded, so the report can say which set failed and why
            out.update(ok=False, error=str(exc))
        out["seconds"] = time.perf_counter() - t0
        io.save_json(Path(args.out) / f"{f.stem}.json", out)


if __name__ == "__main__":
    main()
