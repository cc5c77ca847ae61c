"""The registration resolution and the features found there (the first step of :func:`cvpipe.panorama.stitch`).

Like ``cv2.Stitcher``'s ``registrationResol``, registration runs on copies shrunk to ``work_megapix``; the helpers
here convert homographies between resolutions (``cv2.resize`` aligns pixel areas).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Sequence

import cv2
import numpy as np

from ..errors import EstimationError
from ..features import Features, detect
from ..params import PanoramaFeaturesParams, section_or_default


def scale_for(size: tuple[int, int], megapix: float) -> float:
    """The factor (<= 1) that brings an image of ``size = (w, h)`` to at most ``megapix`` million pixels.

    ``megapix <= 0`` means full resolution (factor 1), as in ``cv2.Stitcher``.

    Examples
    --------
    >>> scale_for((2000, 1500), 0.6), scale_for((640, 480), 0.6), scale_for((2000, 1500), -1)
    (0.4472135954999579, 1.0, 1.0)
    """
    if megapix <= 0:
        return 1.0
    return float(min(1.0, np.sqrt(megapix * 1e6 / (size[0] * size[1]))))


def resized_size(size: tuple[int, int], scale: float) -> tuple[int, int]:
    """``(w, h)`` after scaling by ``scale`` (at least 1 pixel each)."""
    return max(1, int(round(size[0] * scale))), max(1, int(round(size[1] * scale)))


def resize_matrix(size: tuple[int, int], new_size: tuple[int, int]) -> np.ndarray:
    """(3, 3) homography from pixels of an image of ``size`` to pixels of its ``cv2.resize`` to ``new_size``.

    ``cv2.resize`` aligns pixel areas, so pixel centres map as ``x' = (x + 0.5) * sx - 0.5``.
    """
    sx, sy = new_size[0] / size[0], new_size[1] / size[1]
    return np.array([[sx, 0, 0.5 * sx - 0.5], [0, sy, 0.5 * sy - 0.5], [0, 0, 1.0]])


def resize(img: np.ndarray, new_size: tuple[int, int]) -> np.ndarray:
    """``img`` resized to ``new_size = (w, h)`` (area averaging when shrinking)."""
    if (img.shape[1], img.shape[0]) == tuple(new_size):
        return img
    shrink = new_size[0] < img.shape[1]
    return cv2.resize(img, tuple(new_size), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def normalize_det(H: np.ndarray) -> np.ndarray:
    """``H`` scaled to determinant 1 (a positive-scale representative, so ``w > 0`` means 'in front')."""
    d = np.linalg.det(H)
    if not np.isfinite(d) or abs(d) < 1e-300:
        raise EstimationError("a homography is singular; raise `min_inliers` or `min_confidence`")
    return H / np.cbrt(d)


def rescale_homographies(G: Sequence[np.ndarray], sizes_from: Sequence[tuple[int, int]],
                         sizes_to: Sequence[tuple[int, int]], reference: int) -> list[np.ndarray]:
    """Global homographies between images of ``sizes_from`` re-expressed for the same images at ``sizes_to``.

    Parameters
    ----------
    G : sequence of (3, 3)
        Image ``i`` -> reference pixels, both at ``sizes_from``.
    sizes_from, sizes_to : sequence of (w, h)
        Per image, the resolution ``G`` refers to and the one wanted.
    reference : int
        Position of the reference image in the sequences.
    """
    R = resize_matrix(sizes_from[reference], sizes_to[reference])
    out = []
    for Gi, a, b in zip(G, sizes_from, sizes_to):
        out.append(normalize_det(R @ Gi @ np.linalg.inv(resize_matrix(a, b))))
    return out


def working_images(images: Sequence[np.ndarray], megapix: float) -> tuple[list[np.ndarray], list[tuple[int, int]]]:
    """Grayscale copies at the registration resolution, and their sizes ``(w, h)``."""
    out, sizes = [], []
    for img in images:
        gray = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        size = resized_size((gray.shape[1], gray.shape[0]), scale_for((gray.shape[1], gray.shape[0]), megapix))
        out.append(resize(gray, size))
        sizes.append(size)
    return out, sizes


def _workers() -> int:
    return max(1, min(8, os.cpu_count() or 1))


def detect_all(grays: Sequence[np.ndarray], detector: str, max_features: int) -> list[Features]:
    """:func:`cvpipe.features.detect` on every image, one image per thread (OpenCV releases the GIL).

    OpenCV runs each detection on its own threads as well; inside a pool that already has one image per core those
    threads only compete with each other (on 2 cores, 1.83 -> 1.31 s wall for six SIFT detections, the same
    features), so OpenCV is set to one thread for the pool's duration (``cv2.setNumThreads`` is process-wide: the
    previous count is restored afterwards).
    """
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with ThreadPoolExecutor(_workers()) as pool:
            return list(pool.map(lambda g: detect(g, detector, max_features), grays))
    finally:
        cv2.setNumThreads(threads)


def features_of(images: Sequence[np.ndarray], params: PanoramaFeaturesParams | None = None,
                ) -> tuple[list[tuple[int, int]], list[Features]]:
    """The features of a set at the registration resolution, with the ``panorama.features`` section: the images
    shrunk to ``work_megapix`` (:func:`working_images`), then ``detector`` with ``max_features`` on each
    (:func:`detect_all`). The step of :func:`cvpipe.panorama.stitch` and of the ``panorama_features`` stage.

    Parameters
    ----------
    images : sequence of (H, W) or (H, W, 3) uint8
        Grayscale or BGR photos.
    params : PanoramaFeaturesParams or None
        The ``panorama.features`` section (None: its defaults).

    Returns
    -------
    (work sizes, features)
        Each image's ``(w, h)`` at the registration resolution and its :class:`~cvpipe.features.Features` there.

    Examples
    --------
    >>> from cvpipe.params import PanoramaFeaturesParams
    >>> from cvpipe.samples import photo
    >>> img = photo("astronaut")
    >>> sizes, feats = features_of([img, img[:, :256]], PanoramaFeaturesParams(work_megapix=0.1, max_features=300))
    >>> sizes  # each image shrunk to 0.1 MP: 512 x 512 and 256 x 512 keep their proportions
    [(316, 316), (224, 447)]
    >>> [len(f.xy) <= 300 for f in feats]
    [True, True]
    """
    sizes, feats, _ = features_and_images_of(images, params)
    return sizes, feats


def features_and_images_of(images: Sequence[np.ndarray], params: PanoramaFeaturesParams | None = None,
                           ) -> tuple[list[tuple[int, int]], list[Features], list[np.ndarray]]:
    """:func:`features_of`, and the grayscale images at the registration resolution that the features were found
    on (which the match step tracks in when ``panorama.match.pair_refine`` asks for it)."""
    p = section_or_default(params, PanoramaFeaturesParams, "panorama.features")
    grays, sizes = working_images(images, p.work_megapix)
    return sizes, detect_all(grays, p.detector, p.max_features), grays
