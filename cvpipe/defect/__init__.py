"""Defect inspection against a golden reference (the pipeline's task ``defect``, the CLI verb ``inspect``).

One module per step, as the DVC stages run them:

- :mod:`.register`: register the probe to the reference (keypoint matches, our RANSAC homography, then ECC
  refinement on a small pyramid; directly from a phase-correlation shift when keypoints fail) and warp the probe
  onto the reference grid (:func:`register_probe`, :func:`register_direct`, :func:`warp_probe`);
- :mod:`.diff`: fit gain and bias between the two on their overlap and take a difference that tolerates the last
  pixel or so of misregistration (the probe is compared against the min/max of the reference over a small disc and
  vice versa) (:func:`difference`);
- :mod:`.regions`: threshold it with hysteresis, clean it with morphology and turn the connected components into
  regions, in reference and probe pixels; a probe with at least one region is ``faulty`` (:func:`find_regions`,
  :func:`choose`);
- :mod:`.report`: pictures, scores against ground truth, metrics and the report page's summary.

:func:`inspect` below is the recipe that runs them all. Every homography maps reference pixels to probe pixels
(x = column, y = row).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import EstimationError
from ..features import Features
from ..params import DefectDiffParams, DefectRegionParams, InspectParams, load_inspect_params
from ._util import check_gray
from .diff import Difference, difference, difference_item, fit_gain_bias
from .regions import VERDICTS, Inspection, choose, find_regions, map_boxes, merge_boxes, regions_item
from .register import (ProbeRegistration, register_direct, register_item, register_probe, wants_alternative,
                       warp_probe, warp_to_reference)
from .report import draw_regions, evaluate, heat_map

__all__ = ["VERDICTS", "Difference", "InspectParams", "Inspection", "ProbeRegistration", "choose", "compare",
           "difference", "difference_item", "draw_regions", "evaluate", "find_regions", "fit_gain_bias", "heat_map",
           "inspect", "load_inspect_params", "map_boxes", "merge_boxes", "register_direct", "register_item",
           "register_probe", "regions_item", "wants_alternative", "warp_probe", "warp_to_reference"]


def compare(reference: np.ndarray, warped: np.ndarray, valid: np.ndarray, registration: ProbeRegistration,
            probe_shape: tuple[int, int], diff: DefectDiffParams | None = None,
            regions: DefectRegionParams | None = None) -> Inspection:
    """:func:`difference` then :func:`find_regions` for one registration: the verdict it leads to.

    Parameters
    ----------
    reference : (H, W) uint8
    warped, valid : (H, W)
        :func:`warp_probe` of the probe by ``registration.H``.
    registration : ProbeRegistration
    probe_shape : (h, w)
    diff, regions : DefectDiffParams, DefectRegionParams, optional

    Returns
    -------
    Inspection
        With ``registration`` and ``difference`` filled in.

    Examples
    --------
    >>> from cvpipe.samples import make_defect
    >>> board = make_defect(np.random.default_rng(0), n_faulty=2, n_perfect=1, size=240).images
    >>> reg = register_probe(board["reference.png"], board["probes/probe_02.png"])
    >>> warped, valid = warp_probe(board["probes/probe_02.png"], reg.H, (240, 240))
    >>> compare(board["reference.png"], warped, valid, reg, (240, 240)).verdict
    'perfect'
    """
    d = difference(reference, warped, valid, diff)
    return replace(find_regions(d, registration.H, probe_shape, regions), registration=registration)


def inspect(reference: np.ndarray, probe: np.ndarray, params: InspectParams | None = None, *,
            reference_features: Features | None = None) -> Inspection:
    """Register ``probe`` to ``reference``, compare them and judge the probe.

    The steps, each a function of its own (the DVC stages run them one by one): :func:`register_probe`,
    :func:`warp_probe`, :func:`compare` (:func:`difference` and :func:`find_regions`), and for a faulty probe
    registered by keypoints the same with :func:`register_direct`, keeping the result :func:`choose` picks.

    Parameters
    ----------
    reference, probe : (H, W) or (H, W, 3) uint8
    params : InspectParams, optional
    reference_features : Features, optional
        The reference's keypoints when inspecting many probes against one reference.

    Returns
    -------
    Inspection
        With ``registration`` and ``difference`` filled in.

    Raises
    ------
    InputError, EstimationError
        When the probe cannot be registered (see :func:`register_probe`); no verdict is given then.

    Examples
    --------
    >>> from cvpipe.metrics import box_iou
    >>> from cvpipe.samples import make_defect
    >>> board = make_defect(np.random.default_rng(0), n_faulty=2, n_perfect=1, size=240)
    >>> truth = board.truth["probes"][1]  # probe_01.png: a blob of extra material
    >>> r = inspect(board.images["reference.png"], board.images["probes/" + truth["file"]])
    >>> iou = box_iou(r.probe_regions, np.array(truth["boxes"]))  # found x true boxes
    >>> r.verdict, iou.shape, bool(iou[0, 0] >= 0.33)  # DeepPCB's matching criterion
    ('faulty', (1, 1), True)
    """
    p = params or InspectParams()
    ref, prb = check_gray("reference", reference), check_gray("probe", probe)
    reg = register_probe(ref, prb, p.register, reference_features=reference_features, features=p.features,
                         matching=p.match)
    result = compare(ref, *warp_probe(prb, reg.H, ref.shape), reg, prb.shape, p.diff, p.regions)
    if result.verdict != "faulty" or not wants_alternative(reg, p.register):
        return result
    try:
        alt = register_direct(ref, prb, p.register, matches=reg.matches, inliers=reg.inliers)
        other = compare(ref, *warp_probe(prb, alt.H, ref.shape), alt, prb.shape, p.diff, p.regions)
    except EstimationError:  # the alternative is only a second opinion: the first result stands
        return result
    return choose(result, other)
