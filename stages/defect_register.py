"""Stage `defect_register`: homography reference -> probe for every probe, and the probe warped onto the reference.

The registration is the one `cvpipe inspect` uses (``defects.register_for_inspection``), which needs the diff and
regions parameters too: a keypoint registration that would make the probe faulty is compared with the direct one.

A probe that cannot be registered is recorded with its reason in registration.json (no .npz), and the later
stages report it as an error instead of a verdict.
"""

import argparse
from pathlib import Path

import numpy as np
from tqdm import tqdm

from cvpipe import defects, io
from cvpipe.errors import CvpipeError
from cvpipe.features import Features



def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--images", required=True, help="data/samples/defect (reference.png, probes/*.png)")
    ap.add_argument("--features", required=True)
    ap.add_argument("--matches", required=True)
    ap.add_argument("--out", required=True, help="folder for <probe>.npz and registration.json")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = defects.load_inspect_params(args.params)
    images, feats, out = Path(args.images), Path(args.features), Path(args.out)
    ref = io.read_image(images / "reference.png", "gray")
    ref_feats = Features.from_arrays(io.load_npz(feats / "reference.npz"))
    summary = {}
    for path in tqdm(io.list_images(images / "probes"), desc="register", disable=None):
        probe = io.read_image(path, "gray")
        probe_feats = Features.from_arrays(io.load_npz(feats / "probes" / f"{path.stem}.npz"))
        matches = io.load_npz(Path(args.matches) / f"{path.stem}.npz")["index"]
        try:
            reg = defects.register_for_inspection(ref, probe, p, reference_features=ref_feats,
                                                  probe_features=probe_feats, matches=matches)
        except CvpipeError as exc:
            summary[path.name] = {"error": str(exc)}
            continue
        warped = defects.warp_to_reference(probe, reg.H, ref.shape)
        valid = defects.warp_to_reference(np.full(probe.shape, 255, np.uint8), reg.H, ref.shape) == 255
        io.save_npz(out / f"{path.stem}.npz", H=reg.H, warped=warped, valid=valid, probe_shape=probe.shape)
        summary[path.name] = {"H": reg.H, "H_features": reg.H_features, "matches": reg.matches,
                              "inliers": reg.inliers, "correlation": reg.correlation, "method": reg.method}
    io.save_json(out / "registration.json", summary)


if __name__ == "__main__":
    main()
