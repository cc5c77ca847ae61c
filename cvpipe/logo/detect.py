"""The recipe: match, verify and decide for one scene; every brand found, with non-maximum suppression."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from ..features import Features
from ..params import DEFAULT_EXTRA_SCORE, LogoMatchParams, LogoVerifyParams  # noqa: F401
# DEFAULT_EXTRA_SCORE is declared in cvpipe.params (re-exported here) so `cvpipe bench logo --help` needs no cv2
from .gallery import Gallery, Reference, build_gallery  # noqa: F401  (Reference, build_gallery: examples)
from .match import match_scene
from .verify import Hypothesis, verify


@dataclass(frozen=True)
class Detection:
    """The answer for one scene.

    Attributes
    ----------
    brand : str or None
        The recognised brand, None when no plausible hypothesis reaches the score threshold.
    score : float
        Score of the best plausible hypothesis (``-inf`` when there is none); compare with the threshold.
    inliers : int
        Its inlier count (0 when there is none).
    quad : (4, 2) float64 or None
        The logo outline in scene pixels when ``brand`` is not None.
    best : Hypothesis or None
        The best plausible hypothesis even when it is below the threshold (for precision-recall curves).
    hypotheses : list of Hypothesis
        Every reference that was verified, plausible or not.
    """

    brand: str | None
    score: float
    inliers: int
    quad: np.ndarray | None
    best: Hypothesis | None
    hypotheses: list[Hypothesis]


def decide(hypotheses: Sequence[Hypothesis], params: LogoVerifyParams | None = None) -> Detection:
    """The brand of the best plausible hypothesis when its score reaches ``score_threshold``, else none."""
    p = params or LogoVerifyParams()
    good = [h for h in hypotheses if h.plausible]
    if not good:
        return Detection(None, -np.inf, 0, None, None, list(hypotheses))
    best = max(good, key=lambda h: (h.score, h.inliers))
    if best.score >= p.score_threshold:
        return Detection(best.brand, best.score, best.inliers, best.quad, best, list(hypotheses))
    return Detection(None, best.score, best.inliers, None, best, list(hypotheses))


def recognize(gallery: Gallery, scene: Features, scene_size: tuple[int, int],
              match_params: LogoMatchParams | None = None, verify_params: LogoVerifyParams | None = None,
              rng=None) -> Detection:
    """Match, verify and decide for one scene (see the module docstring).

    Parameters
    ----------
    gallery : Gallery
    scene : Features
        Scene keypoints from the gallery's detector.
    scene_size : (width, height)
        Scene size in pixels.
    match_params : LogoMatchParams, optional
    verify_params : LogoVerifyParams, optional
    rng : None, int or Generator
        Seeds RANSAC.

    Returns
    -------
    Detection

    Examples
    --------
    A textured mark pasted into a flat grey scene is found where it was put:

    >>> import cv2
    >>> from cvpipe.features import detect
    >>> noise = (np.random.default_rng(0).random((24, 24)) * 255).astype(np.uint8)
    >>> mark = cv2.resize(noise, (192, 192), interpolation=cv2.INTER_CUBIC)
    >>> scene = np.full((480, 640), 128, np.uint8)
    >>> scene[100:292, 300:492] = mark
    >>> gallery = build_gallery([Reference("noise", "noise.png", detect(mark, "sift"), (192, 192))])
    >>> det = recognize(gallery, detect(scene, "sift"), (640, 480), rng=0)
    >>> det.brand, det.quad.round().tolist()
    ('noise', [[300.0, 100.0], [491.0, 100.0], [491.0, 291.0], [300.0, 291.0]])
    """
    if len(scene_size) != 2 or min(scene_size) < 1:
        raise ValueError(f"`scene_size` must be (width, height) >= 1, got {scene_size}")
    m = match_scene(gallery, scene, match_params)
    return decide(verify(gallery, m, scene, scene_size, verify_params, rng), verify_params)


#: two found outlines overlapping by more than this intersection-over-union are one logo (the better one is kept)
MAX_OVERLAP = 0.3


def quad_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two convex quadrilaterals ((4, 2) corner arrays, scene pixels).

    Examples
    --------
    >>> sq = np.array([[0, 0], [100, 0], [100, 100], [0, 100]], float)
    >>> round(quad_iou(sq, sq + [50, 0]), 3)
    0.333
    """
    pa, pb = np.asarray(a, np.float32).reshape(4, 2), np.asarray(b, np.float32).reshape(4, 2)
    area_a, area_b = abs(cv2.contourArea(pa)), abs(cv2.contourArea(pb))
    inter, _ = cv2.intersectConvexConvex(pa, pb)
    union = area_a + area_b - inter
    return float(inter / union) if union > 0 else 0.0


def every_logo(det: Detection, score_threshold: float, max_overlap: float = MAX_OVERLAP,
               extra_score: float | None = None) -> list[Hypothesis]:
    """Every logo found in a scene: the plausible hypotheses that reach the score thresholds, best first, after
    non-maximum suppression of overlapping outlines.

    Parameters
    ----------
    det : Detection
        From :func:`recognize` (or :func:`decide`).
    score_threshold : float
        Score the best logo needs (``logo.verify.score_threshold``).
    max_overlap : float
        A hypothesis whose outline overlaps a better kept one by more than this intersection-over-union is the same
        logo seen again (another reference, or a second fit) and is dropped.
    extra_score : float, optional
        Score every further logo needs; never below ``score_threshold``. Default :data:`DEFAULT_EXTRA_SCORE`.

    Returns
    -------
    list of Hypothesis
        The first entry, when there is one, is the scene's ``brand`` (the ordering of :func:`decide`).

    Examples
    --------
    >>> sq = np.array([[0, 0], [100, 0], [100, 100], [0, 100]], float)
    >>> def hyp(brand, score, dx):
    ...     return Hypothesis(brand, 0, 30, 20, score, np.eye(3), sq + [dx, 0], np.zeros((0, 2), np.int64))
    >>> det = Detection("a", 50.0, 20, sq, None, [hyp("a", 50.0, 0), hyp("b", 40.0, 10), hyp("c", 30.0, 300)])
    >>> [h.brand for h in every_logo(det, 0.0)]  # b overlaps a (IoU 0.82): the same logo
    ['a', 'c']
    >>> [h.brand for h in every_logo(det, 0.0, extra_score=35.0)]  # c is not strong enough for a second logo
    ['a']
    """
    extra = max(score_threshold, DEFAULT_EXTRA_SCORE if extra_score is None else extra_score)
    good = sorted((h for h in det.hypotheses if h.plausible and h.quad is not None and h.score >= score_threshold),
                  key=lambda h: (h.score, h.inliers), reverse=True)
    kept: list[Hypothesis] = []
    for h in good:
        if kept and h.score < extra:
            break  # sorted by score: no later one reaches it either
        if all(quad_iou(h.quad, k.quad) <= max_overlap for k in kept):
            kept.append(h)
    return kept


def verify_scene(item: tuple, shared: tuple) -> tuple[Detection, np.ndarray | None, float]:
    """Verify and decide one scene from its cached matches: the per-scene work of the ``logo_verify`` stage, an
    item of :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    item : tuple
        ``(Matches, scene Features, (width, height))``.
    shared : tuple
        ``(Gallery, LogoVerifyParams)``, sent once per worker.

    Returns
    -------
    (Detection, ndarray or None, float)
        The decision (RANSAC seeded with 0), the scene points of its best hypothesis' pairs ((K, 2), None when no
        hypothesis is plausible) and the seconds the verification took.
    """
    import time

    matches, scene, size = item
    gallery, p = shared
    t0 = time.perf_counter()
    det = decide(verify(gallery, matches, scene, size, p, rng=0), p)
    seconds = time.perf_counter() - t0
    return det, None if det.best is None else scene.xy[det.best.pairs[:, 1]], seconds
