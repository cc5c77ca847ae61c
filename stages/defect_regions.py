"""Stage `defect_regions`: threshold, morphology and components -> regions and a verdict for every probe."""

import argparse
from pathlib import Path

from cvpipe import defects, io
from cvpipe.params import DefectRegionParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--diff", required=True, help="outputs/defect/diff")
    ap.add_argument("--registration", required=True, help="outputs/defect/register/registration.json")
    ap.add_argument("--out", required=True, help="results JSON (the `cvpipe inspect --json` records)")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(DefectRegionParams, "defect.regions", args.params)
    results = []
    for name, reg in sorted(io.load_json(args.registration).items()):
        if "error" in reg:
            results.append({"probe": name, "verdict": None, "score": None, "regions": [], "H": None,
                            "error": reg["error"]})
            continue
        z = io.load_npz(Path(args.diff) / f"{Path(name).stem}.npz")
        d = defects.Difference(z["diff"], z["valid"], float(z["gain"]), float(z["bias"]), float(z["noise"]),
                               float(z["contrast"]))
        r = defects.find_regions(d, z["H"], tuple(z["probe_shape"]), p)
        results.append({"probe": name, "verdict": r.verdict, "score": r.score, "regions": r.probe_regions,
                        "reference_regions": r.regions, "threshold": r.threshold, "H": z["H"]})
    io.save_json(args.out, results)


if __name__ == "__main__":
    main()
