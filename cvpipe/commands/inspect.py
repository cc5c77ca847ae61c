"""``cvpipe inspect REFERENCE PROBE...``: judge probes faulty or perfect against a golden reference."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from types import SimpleNamespace
from typing import TYPE_CHECKING

from ..params import DefectDiffParams, DefectFeaturesParams, DefectRegionParams, DefectRegisterParams
from . import compile_note, overlay_paths, progress, with_flags

if TYPE_CHECKING:
    from .. import defects

HELP = "judge probe images faulty or perfect against a golden reference and outline the defects"
EXAMPLE = "cvpipe inspect data/samples/defect/reference.png data/samples/defect/probes/*.png --out out/ --json"

#: the defaults of defects.InspectParams (the same dataclasses), without importing the algorithm module
_DEFAULTS = SimpleNamespace(features=DefectFeaturesParams(), diff=DefectDiffParams(), regions=DefectRegionParams(),
                            register=DefectRegisterParams())
#: ``--detector`` choices: the keys of ``cvpipe.features.DETECTORS`` (a test keeps them equal)
DETECTORS = ("akaze", "brisk", "orb", "sift")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("reference", help="golden reference image")
    parser.add_argument("probes", nargs="+", metavar="PROBE", help="probe images of the same part")
    parser.add_argument("--out", help="folder for overlays (<probe>_regions.png, <probe>_diff.png)")
    parser.add_argument("--detector", type=str.lower, choices=DETECTORS, default=_DEFAULTS.features.detector,
                        help=f"keypoints for the coarse registration (default {_DEFAULTS.features.detector})")
    parser.add_argument("--threshold", type=float, default=_DEFAULTS.regions.threshold,
                        help="difference threshold as a fraction of the reference contrast "
                             f"(default {_DEFAULTS.regions.threshold:g})")
    parser.add_argument("--tolerance", type=int, default=_DEFAULTS.diff.tolerance_radius,
                        help=f"misregistration tolerated, px (default {_DEFAULTS.diff.tolerance_radius})")
    parser.add_argument("--min-area", type=int, default=_DEFAULTS.regions.min_area,
                        help=f"smallest defect kept, px (default {_DEFAULTS.regions.min_area})")
    parser.add_argument("--pad", type=float, default=_DEFAULTS.regions.pad,
                        help=f"pad the probe boxes by this many px (default {_DEFAULTS.regions.pad:g})")
    parser.add_argument("--overlay", metavar="PNG",
                        help="write the probe with its defect boxes; with several probes PNG is a folder "
                             "(<probe>_regions.png)")
    parser.add_argument("--ecc-levels", type=int, default=_DEFAULTS.register.ecc_levels,
                        help=f"pyramid levels of the ECC refinement (default {_DEFAULTS.register.ecc_levels})")
    parser.add_argument("--json", action="store_true", help="print the results as JSON on stdout")


def params_from_args(args: argparse.Namespace) -> defects.InspectParams:
    """The inspection parameters: the dataclass defaults with the command-line overrides (validated there)."""
    from .. import defects

    p = defects.InspectParams()
    try:
        return replace(p, features=replace(p.features, detector=args.detector),
                       diff=replace(p.diff, tolerance_radius=args.tolerance),
                       register=replace(p.register, ecc_levels=args.ecc_levels),
                       regions=replace(p.regions, threshold=args.threshold, min_area=args.min_area, pad=args.pad,
                                       seed_threshold=max(p.regions.seed_threshold, args.threshold)))
    except ValueError as exc:
        raise ValueError(f"bad option: {exc}") from exc


def result_dict(probe: str, r: defects.Inspection) -> dict:
    """The JSON record of one inspected probe (the interface contract of DESIGN.md)."""
    import numpy as np

    return {"probe": probe, "verdict": r.verdict, "score": round(r.score, 3),
            "regions": np.round(r.probe_regions, 2).tolist(), "H": r.registration.H.tolist()}


def run(args: argparse.Namespace) -> int:
    from .. import defects, homography, io
    from ..errors import CvpipeError, EstimationError
    from ..features import detect

    params = params_from_args(args)
    compile_note("inspect", homography)
    reference = io.read_image(args.reference, "color")
    ref_gray = io.to_gray(reference)
    ref_feats = detect(ref_gray, params.features.detector, params.features.max_features)
    results, failed = [], 0
    for path, picture in progress(list(zip(args.probes, overlay_paths(args.probes, args.overlay, "_regions"))),
                                  "inspect"):
        try:
            probe = io.read_image(path, "color")
            r = defects.inspect(ref_gray, io.to_gray(probe), params, reference_features=ref_feats)
        except CvpipeError as exc:
            exc = type(exc)(with_flags(str(exc), ["ecc_levels"]))  # the hint names this command's flag
            failed += 1
            print(f"cvpipe: error: {path}: {exc}", file=sys.stderr)
            results.append({"probe": path, "verdict": None, "score": None, "regions": [], "H": None,
                            "error": str(exc)})
            continue
        results.append(result_dict(path, r))
        if args.out:
            stem = Path(path).stem
            io.save_image(Path(args.out) / f"{stem}_regions.png", defects.draw_regions(probe, r.probe_regions))
            io.save_image(Path(args.out) / f"{stem}_diff.png", defects.heat_map(r.difference.diff, r.threshold))
            results[-1]["overlay"] = str(Path(args.out) / f"{stem}_regions.png")
        if picture:
            io.save_image(picture, defects.draw_regions(probe, r.probe_regions))
            results[-1]["overlay"] = picture
    if args.out:
        io.save_json(Path(args.out) / "inspect.json", results)
    if args.json:
        print(io.dumps_json(results))
    else:
        for res in results:
            if "error" not in res:
                print(f"{res['probe']}: {res['verdict']} (score {res['score']:.1f}, {len(res['regions'])} regions)")
    if failed == len(results):
        raise EstimationError(f"no probe could be registered to {args.reference}")
    return 1 if failed else 0
