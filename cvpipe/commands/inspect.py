"""``cvpipe inspect REFERENCE PROBE...``: judge probes faulty or perfect against a golden reference."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from .. import defects, io
from ..compute import check_scheduler, map_items
from ..errors import CvpipeError, EstimationError
from ..features import DETECTORS, detect

HELP = "judge probe images faulty or perfect against a golden reference and outline the defects"
EXAMPLE = "cvpipe inspect data/samples/defect/reference.png data/samples/defect/probes/*.png --out out/ --json"

_DEFAULTS = defects.InspectParams()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("reference", help="golden reference image")
    parser.add_argument("probes", nargs="+", metavar="PROBE", help="probe images of the same part")
    parser.add_argument("--out", help="folder for overlays (<probe>_regions.png, <probe>_diff.png)")
    parser.add_argument("--detector", choices=sorted(DETECTORS), default=_DEFAULTS.features.detector,
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
    parser.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    parser.add_argument("--scheduler", default="", metavar="ADDR",
                        help="run the probes on Dask: 'local' or a scheduler address tcp://host:port "
                             "(default: in process)")


def params_from_args(args: argparse.Namespace) -> defects.InspectParams:
    """The inspection parameters: the dataclass defaults with the command-line overrides (validated there)."""
    p = _DEFAULTS
    try:
        return replace(p, features=replace(p.features, detector=args.detector),
                       diff=replace(p.diff, tolerance_radius=args.tolerance),
                       regions=replace(p.regions, threshold=args.threshold, min_area=args.min_area, pad=args.pad,
                                       seed_threshold=max(p.regions.seed_threshold, args.threshold)))
    except ValueError as exc:
        raise ValueError(f"bad option: {exc}") from exc


def result_dict(probe: str, r: defects.Inspection) -> dict:
    """The JSON record of one inspected probe (the interface contract of DESIGN.md)."""
    return {"probe": probe, "verdict": r.verdict, "score": round(r.score, 3),
            "regions": np.round(r.probe_regions, 2).tolist(), "H": r.registration.H.tolist()}


def _read_probes(paths: list[str]):
    """``(probe, read error)`` per path, lazily: the image travels with the task, a read error fails only its item."""
    for path in paths:
        try:
            yield io.read_image(path, "color"), None
        except CvpipeError as exc:
            yield None, exc


def inspect_probe(item: tuple, shared: tuple) -> defects.Inspection:
    """Inspect one probe (an item of :func:`cvpipe.compute.map_items`): ``item`` = (BGR image or None, read error),
    ``shared`` = (reference gray, reference features, InspectParams)."""
    probe, error = item
    if error is not None:
        raise error
    ref_gray, ref_feats, params = shared
    return defects.inspect(ref_gray, io.to_gray(probe), params, reference_features=ref_feats)


def run(args: argparse.Namespace) -> int:
    params = params_from_args(args)
    reference = io.read_image(args.reference, "color")
    ref_gray = io.to_gray(reference)
    ref_feats = detect(ref_gray, params.features.detector, params.features.max_features)
    results, failed = [], 0
    items = map_items(inspect_probe, _read_probes(args.probes), shared=(ref_gray, ref_feats, params),
                      scheduler=check_scheduler(args.scheduler, "--scheduler"), progress="inspect",
                      total=len(args.probes))
    for path, res in zip(args.probes, items):
        if not res.ok:
            failed += 1
            print(f"cvpipe: error: {path}: {res.error}", file=sys.stderr)
            results.append({"probe": path, "verdict": None, "score": None, "regions": [], "H": None,
                            "error": res.error})
            continue
        r = res.value
        results.append(result_dict(path, r))
        if args.out:
            probe = io.read_image(path, "color")
            stem = Path(path).stem
            io.save_image(Path(args.out) / f"{stem}_regions.png", defects.draw_regions(probe, r.probe_regions))
            io.save_image(Path(args.out) / f"{stem}_diff.png", defects.heat_map(r.difference.diff, r.threshold))
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
