"""Methods: one detector, or the hypotheses of several detectors weighed under one a-contrario decision.

A method names the detectors whose hypotheses one decision weighs (:data:`METHODS`). For one detector this is the
plain recipe (:func:`cvpipe.logo.recognize`). For ``fused``, every detector matches the scene against its own
gallery index and verifies its own references; each hypothesis' number of false alarms is then counted over the
references tested by *all* the detectors (the multiple-test factor of :func:`cvpipe.logo.significance`), so that a
SIFT fit and an ORB fit of the same quality get the same score and the best of them is significant in the same sense
as a single detector's best: fewer than one chance fit expected in the scene over everything that was tried.
Detectors see different parts of a mark (blobs, corners, edges of a smooth shape), so one of them often verifies a
logo the others cannot.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from ..features import Features
from ..params import LogoMatchParams, LogoVerifyParams
from .detect import Detection, decide
from .gallery import Gallery
from .match import Matches, match_scene
from .verify import Hypothesis, tested_references, verify

#: ``--method`` -> the detectors whose hypotheses one decision weighs (each detector alone is a method too)
METHODS: dict[str, tuple[str, ...]] = {
    "sift": ("sift",),
    "orb": ("orb",),
    "brisk": ("brisk",),
    "akaze": ("akaze",),
    "fused": ("sift", "orb", "akaze"),
}


def method_detectors(method: str) -> tuple[str, ...]:
    """The detectors of ``method``; ``ValueError`` listing the choices when it is not in :data:`METHODS`."""
    if method not in METHODS:
        raise ValueError(f"`method` must be one of {sorted(METHODS)}, got {method!r}")
    return METHODS[method]


def verify_fused(galleries: Mapping[str, Gallery], matches: Mapping[str, Matches],
                 scenes: Mapping[str, Features], scene_size: tuple[int, int],
                 params: LogoVerifyParams | None = None, rng=None) -> list[Hypothesis]:
    """Every detector's hypotheses, scored against the references tested by all of them.

    Parameters
    ----------
    galleries, matches, scenes : mapping detector -> Gallery, Matches, Features
        One gallery index, the scene's tentative matches to it and the scene's keypoints per detector (same keys).
    scene_size : (width, height)
        Scene size in pixels.
    params : LogoVerifyParams, optional
    rng : None, int or Generator
        Seeds RANSAC. A seed (or None) starts every detector's RANSAC from it alike, so that a detector's
        hypotheses here are those it finds alone (:func:`cvpipe.logo.verify` with the same seed); a Generator is
        drawn from by the detectors in the order of ``galleries``.

    Returns
    -------
    list of Hypothesis
        Sorted by score (best first); ``Hypothesis.detector`` names the gallery each comes from.
    """
    if not set(galleries) == set(matches) == set(scenes):
        raise ValueError(f"`galleries`, `matches` and `scenes` must have the same detectors, got "
                         f"{sorted(galleries)}, {sorted(matches)}, {sorted(scenes)}")
    p = params or LogoVerifyParams()
    tests = sum(tested_references(matches[d], p) for d in galleries)
    out: list[Hypothesis] = []
    for d, g in galleries.items():
        # RANSAC finds a marginal fit (5-8 inliers) or not depending on its samples: each detector draws them as it
        # would alone, so that the fused decision only re-weighs the single detectors' hypotheses
        out += verify(g, matches[d], scenes[d], scene_size, p,
                      rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng), tests=tests)
    out.sort(key=lambda h: (h.score, h.inliers), reverse=True)
    return out


def recognize_fused(galleries: Mapping[str, Gallery], scenes: Mapping[str, Features], scene_size: tuple[int, int],
                    match_params: LogoMatchParams | None = None, verify_params: LogoVerifyParams | None = None,
                    rng=None) -> Detection:
    """Match, verify and decide for one scene with every detector of ``galleries`` under one decision.

    With one detector this is :func:`cvpipe.logo.recognize`.

    Parameters
    ----------
    galleries : mapping detector -> Gallery
    scenes : mapping detector -> Features
        The scene's keypoints from each gallery's detector.
    scene_size : (width, height)
    match_params : LogoMatchParams, optional
    verify_params : LogoVerifyParams, optional
    rng : None, int or Generator

    Returns
    -------
    Detection
        ``best.detector`` says which detector's hypothesis won.
    """
    if len(scene_size) != 2 or min(scene_size) < 1:
        raise ValueError(f"`scene_size` must be (width, height) >= 1, got {scene_size}")
    for d, g in galleries.items():
        if d != g.detector:
            raise ValueError(f"gallery under {d!r} holds {g.detector!r} features")
    matches = {d: match_scene(g, scenes[d], match_params) for d, g in galleries.items()}
    return decide(verify_fused(galleries, matches, scenes, scene_size, verify_params, rng), verify_params)


def verify_method_scene(item: tuple, shared: tuple) -> tuple[Detection, np.ndarray | None, float]:
    """Verify and decide one scene from its cached matches with every detector of a method: the per-scene work of
    the ``logo_verify`` stage, an item of :func:`cvpipe.compute.map_items` (data in, data out).

    Parameters
    ----------
    item : tuple
        ``({detector: Matches}, {detector: scene Features}, (width, height))``.
    shared : tuple
        ``({detector: Gallery}, LogoVerifyParams)``, sent once per worker.

    Returns
    -------
    (Detection, ndarray or None, float)
        The decision (RANSAC seeded with 0), the scene points of its best hypothesis' pairs ((K, 2), None when no
        hypothesis is plausible) and the seconds the verification took.
    """
    import time

    matches, scenes, size = item
    galleries, p = shared
    t0 = time.perf_counter()
    det = decide(verify_fused(galleries, matches, scenes, size, p, rng=0), p)
    seconds = time.perf_counter() - t0
    best = det.best
    return det, None if best is None else scenes[best.detector].xy[best.pairs[:, 1]], seconds
