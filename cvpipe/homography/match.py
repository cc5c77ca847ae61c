"""Putative correspondences between two views: keypoints, descriptors and the ratio test."""

from __future__ import annotations

import numpy as np

from ..params import FeaturesParams, MatchParams

#: the ``homography.features`` / ``homography.match`` defaults: the one declaration of the keyword defaults below
_FEATURES, _MATCH = FeaturesParams(), MatchParams()


def correspondences(gray_a: np.ndarray, gray_b: np.ndarray, detector: str = _FEATURES.detector,
                    max_features: int = _FEATURES.max_features, ratio: float = _MATCH.ratio,
                    cross_check: bool = _MATCH.cross_check) -> tuple[np.ndarray, np.ndarray]:
    """Putative point correspondences A -> B from keypoints, descriptors and the ratio test.

    Parameters
    ----------
    gray_a, gray_b : (H, W) uint8
        The two views.
    detector, max_features, ratio, cross_check
        As in ``cvpipe.features.detect`` and ``cvpipe.matching.match``.

    Returns
    -------
    src, dst : (M, 2) float64
        Matched keypoint positions in A and in B (pixels), best descriptor distance first.

    Examples
    --------
    >>> import numpy as np, skimage.data
    >>> from cvpipe.homography import correspondences
    >>> gray = skimage.data.camera()
    >>> src, dst = correspondences(gray, np.roll(gray, 10, axis=1), max_features=500)
    >>> bool(np.median(dst[:, 0] - src[:, 0]) == 10.0)
    True
    """
    from .. import features, matching

    fa = features.detect(gray_a, detector, max_features)
    fb = features.detect(gray_b, detector, max_features)
    idx = matching.match(fa.descriptors, fb.descriptors, ratio, cross_check, fa.binary)
    return fa.xy[idx[:, 0]].astype(np.float64), fb.xy[idx[:, 1]].astype(np.float64)
