"""``cvpipe inspect REFERENCE PROBE...``: judge probes faulty or perfect against a golden reference."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from typing import TYPE_CHECKING

from ..params import DefectDiffParams, DefectRegionParams, DefectRegisterParams, InspectParams, replace
from . import (DETECTORS, add_result_arguments, final_output, overlay_paths, param_type, progress, read_images,
               with_flags)

if TYPE_CHECKING:
    from .. import defect as defects

HELP = "judge probe images faulty or perfect against a golden reference and outline the defects"
EXAMPLE = "cvpipe inspect data/samples/defect/reference.png data/samples/defect/probes/*.png --out outputs/examples/inspect/ --json"

#: the defaults of ``cvpipe.defect.inspect``, without importing the algorithm package
_DEFAULTS = InspectParams()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("reference", help="golden reference image")
    parser.add_argument("probes", nargs="+", metavar="PROBE", help="probe images of the same part")
    parser.add_argument("--out", help="folder for overlays (<probe>_regions.png, <probe>_diff.png; <folder>_<probe> "
                        "when two probes share a file name)")
    parser.add_argument("--detector", type=str.lower, choices=DETECTORS, default=_DEFAULTS.features.detector,
                        help=f"keypoints for the coarse registration (default {_DEFAULTS.features.detector})")
    parser.add_argument("--threshold", type=param_type(DefectRegionParams, "threshold"),
                        default=_DEFAULTS.regions.threshold,
                        help="difference threshold as a fraction of the reference contrast "
                             f"(default {_DEFAULTS.regions.threshold:g})")
    parser.add_argument("--tolerance", type=param_type(DefectDiffParams, "tolerance_radius"),
                        default=_DEFAULTS.diff.tolerance_radius,
                        help=f"misregistration tolerated, px (default {_DEFAULTS.diff.tolerance_radius})")
    parser.add_argument("--min-area", type=param_type(DefectRegionParams, "min_area"),
                        default=_DEFAULTS.regions.min_area,
                        help=f"smallest defect kept, px (default {_DEFAULTS.regions.min_area})")
    parser.add_argument("--pad", type=param_type(DefectRegionParams, "pad"),
                        default=_DEFAULTS.regions.pad,
                        help=f"pad the probe boxes by this many px (default {_DEFAULTS.regions.pad:g})")
    parser.add_argument("--ecc-levels", type=param_type(DefectRegisterParams, "ecc_levels"),
                        default=_DEFAULTS.register.ecc_levels,
                        help=f"pyramid levels of the ECC refinement (default {_DEFAULTS.register.ecc_levels})")
    add_result_arguments(parser, "write the probe with its defect boxes", json="print the results as JSON on stdout",
                         items="probes", suffix="_regions")


def params_from_args(args: argparse.Namespace) -> InspectParams:
    """The inspection parameters: the dataclass defaults with the command-line overrides (validated there)."""
    p = InspectParams()
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


def overlay_stems(probes: list[str]) -> list[str]:
    """One distinct file stem per probe: its own stem, or ``<folder>_<stem>`` (then ``_2``, ...) on a clash.

    Probes with equal file names from different folders (``a/p.png``, ``b/p.png``) must not overwrite each
    other's pictures.
    """
    stems = [Path(p).stem for p in probes]
    clash = {s for s in stems if stems.count(s) > 1}
    out, used = [], set()
    for path, stem in zip(probes, stems):
        name = stem
        if stem in clash:
            parent = Path(path).resolve().parent.name or "root"
            name = f"{parent}_{stem}"
        base, k = name, 2
        while name in used:
            name = f"{base}_{k}"
            k += 1
        used.add(name)
        out.append(name)
    return out


def inspect_probe(item: tuple, shared: tuple) -> defects.Inspection:
    """Inspect one probe, an item of :func:`cvpipe.compute.map_items` (runs on a worker).

    Parameters
    ----------
    item : tuple
        ``(BGR probe or None, read error or None)`` from :func:`cvpipe.commands.read_images`.
    shared : tuple
        ``(reference gray, reference features, InspectParams)``, sent once per worker.

    Returns
    -------
    cvpipe.defect.Inspection
    """
    from .. import defect as defects, io

    probe, error = item
    if error is not None:
        raise error
    ref_gray, ref_feats, params = shared
    return defects.inspect(ref_gray, io.to_gray(probe), params, reference_features=ref_feats)


def run(args: argparse.Namespace) -> int:
    from .. import defect as defects, io
    from ..compute import check_scheduler, item_error, map_items, raise_unexpected
    from ..errors import EstimationError, InputError
    from ..features import detect_with

    params = params_from_args(args)
    if args.out:
        io.check_output_folder(args.out, "`--out`")
    stems = overlay_stems(args.probes)
    pictures = overlay_paths(args.probes, args.overlay, "_regions")
    folder = [] if not args.out else [("`--out`", Path(args.out) / name) for name in
                                      [f"{st}{kind}.png" for st in stems for kind in ("_regions", "_diff")]
                                      + ["inspect.json"]]
    io.check_distinct_outputs(folder + [("`--overlay`", p) for p in pictures],
                              [("REFERENCE", args.reference)] + [(f"PROBE {k + 1}", path)
                                                                 for k, path in enumerate(args.probes)])
    reference = io.read_image(args.reference, "color")
    ref_gray = io.to_gray(reference)
    if int(ref_gray.max()) == int(ref_gray.min()):
        raise InputError(f"{args.reference}: the reference is blank (one grey level {int(ref_gray.min())}); "
                         "nothing to register probes to", file=args.reference)

    ref_feats = detect_with(ref_gray, params.features)
    results, errors = [], []
    # checked before any probe runs: a bad address is one line and nothing is written
    scheduler = check_scheduler(args.scheduler, "--scheduler")
    items = map_items(inspect_probe, read_images(args.probes, "color"), shared=(ref_gray, ref_feats, params),
                      scheduler=scheduler, total=len(args.probes))
    # the results first: the bar counts probes done, not started
    for res, (path, stem, picture) in zip(items, progress(list(zip(args.probes, stems, pictures)), "inspect")):
        if not res.ok:
            raise_unexpected(res)  # a bug or an interrupt ends the command, as in a plain loop
            exc = item_error(res, file=path)
            errors.append(exc)
            msg = with_flags(res.error, ["ecc_levels"])  # the hint names this command's flag
            msg = msg if str(path) in msg else f"{path}: {msg}"
            results.append({"probe": path, "verdict": None, "score": None, "regions": [], "H": None, "error": msg})
            continue
        r = res.value
        results.append(result_dict(path, r))
        if args.out or picture:
            probe = io.read_image(path, "color")  # the driver draws; the worker only sent the verdict back
        if args.out:
            io.save_image(Path(args.out) / f"{stem}_regions.png", defects.draw_regions(probe, r.probe_regions))
            io.save_image(Path(args.out) / f"{stem}_diff.png", defects.heat_map(r.difference.diff, r.threshold))
            results[-1]["overlay"] = str(Path(args.out) / f"{stem}_regions.png")
        if picture:
            io.save_image(picture, defects.draw_regions(probe, r.probe_regions))
            results[-1]["overlay"] = picture
    code = max((e.exit_code for e in errors), default=0)
    if len(errors) == len(results):
        # nothing to report: the failure itself is the one line (and the one JSON record)
        if len(errors) == 1:
            raise type(errors[0])(results[0]["error"], file=errors[0].file)
        raise (InputError if code == 2 else EstimationError)(
            f"none of the {len(errors)} probes could be inspected against {args.reference}; first: "
            f"{results[0]['error']}", file=errors[0].file)
    final_output()
    for res in results:
        if "error" in res:
            print(f"cvpipe: error: {res['error']}", file=sys.stderr)
    if args.out:
        io.save_json(Path(args.out) / "inspect.json", results)
    if args.json:
        print(io.dumps_json(results))
    else:
        for res in results:
            if "error" not in res:
                print(f"{res['probe']}: {res['verdict']} (score {res['score']:.1f}, {len(res['regions'])} regions)")
    return code
