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
from .diff import Difference, difference, fit_gain_bias
from .regions import VERDICTS, Inspection, choose, find_regions, map_boxes, merge_boxes
from .register import (ProbeRegistration, register_direct, register_probe, wants_alternative, warp_probe,
                       warp_to_reference)
from .report import draw_regions, evaluate, heat_map

__all__ = ["VERDICTS", "Difference", "InspectParams", "Inspection", "ProbeRegistration", "choose", "compare",
           "difference", "draw_regions", "evaluate", "find_regions", "fit_gain_bias", "heat_map", "inspect",
           "load_inspect_params", "map_boxes", "merge_boxes", "register_direct", "register_probe",
           "wants_alternative", "warp_probe", "warp_to_reference"]


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
    >>> import cv2, numpy as np
    >>> rng = np.random.default_rng(0)
    >>> ref = cv2.resize((rng.random((16, 16)) > 0.5).astype(np.uint8) * 160 + 50, (160, 160),
    ...                  interpolation=cv2.INTER_NEAREST)  # a random pattern of 10 px blocks
    >>> probe = cv2.warpAffine(ref, np.float32([[1, 0, 3], [0, 1, -2]]), (160, 160),
    ...                        borderMode=cv2.BORDER_REFLECT)  # the part moved by (+3, -2) px
    >>> reg = register_probe(ref, probe)
    >>> compare(ref, *warp_probe(probe, reg.H, ref.shape), reg, probe.shape).verdict
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
    >>> import cv2, numpy as np
    >>> rng = np.random.default_rng(0)
    >>> ref = cv2.resize((rng.random((16, 16)) > 0.5).astype(np.uint8) * 160 + 50, (160, 160),
    ...                  interpolation=cv2.INTER_NEAREST)  # a random pattern of 10 px blocks
    >>> probe = cv2.warpAffine(ref, np.float32([[1, 0, 3], [0, 1, -2]]), (160, 160),
    ...                        borderMode=cv2.BORDER_REFLECT)  # the part moved by (+3, -2) px
    >>> probe[70:82, 40:52] = 255 - probe[70:82, 40:52]  # a defect, in probe pixels
    >>> r = inspect(ref, probe)
    >>> x1, y1, x2, y2 = r.probe_regions[0]
    >>> r.verdict, len(r.regions), bool(x1 <= 40 and y1 <= 70 and x2 >= 52 and y2 >= 82)
    ('faulty', 1, True)
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
