"""The baseline: ``cv2.Stitcher`` (panorama mode) at the same registration and compose resolutions as ours, and the
homographies that its cameras imply (:func:`camera_homographies`), so that its geometry can be measured against
ground truth like ours (docs/panorama.md, "cv2.Stitcher's homographies").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np

from ..params import PanoramaFeaturesParams, PanoramaMatchParams, PanoramaWarpParams, section_or_default

#: cv2.Stitcher status codes -> names
OPENCV_STATUS = {0: "OK", 1: "ERR_NEED_MORE_IMGS", 2: "ERR_HOMOGRAPHY_EST_FAIL", 3: "ERR_CAMERA_PARAMS_ADJUST_FAIL"}


def camera_homographies(K: Sequence[np.ndarray], R: Sequence[np.ndarray], work_scale: float) -> list[np.ndarray]:
    """Per camera of ``cv2.Stitcher``, the homography from its input image's full-resolution pixels to a common
    frame (ray directions), so that ``inv(G[j]) @ G[i]`` maps image i to image j in full-resolution pixels.

    ``cv2.Stitcher`` registers copies resized by ``work_scale`` (``cv2.resize`` with ``fx = fy = work_scale``,
    which maps pixel centres as ``x_w = (x + 0.5) * s - 0.5``: the matrix ``S``); its camera ``(K, R)`` sends the
    work pixel ``x_w`` to the ray ``R K^-1 x_w`` (the warpers' convention, ``R`` camera -> panorama frame). So
    ``G = R K^-1 S``, and the pair homography is ``S^-1 K_j R_j^T R_i K_i^-1 S``. The cameras stay at the work
    scale whatever the compose resolution (their ``ppx`` is half the work image's width).

    Parameters
    ----------
    K : sequence of (3, 3)
        ``camera.K()`` per camera, work-scale pixels.
    R : sequence of (3, 3)
        ``camera.R`` per camera (rotation).
    work_scale : float
        ``Stitcher.workScale()``.

    Returns
    -------
    list of (3, 3)

    Examples
    --------
    Two cameras of focal 100 at work scale 0.5, the second turned by 0.1 rad about the vertical axis:

    >>> import numpy as np
    >>> K = np.array([[100.0, 0, 50], [0, 100, 40], [0, 0, 1]])
    >>> c, s = np.cos(0.1), np.sin(0.1)
    >>> R1 = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    >>> G = camera_homographies([K, K], [np.eye(3), R1], 0.5)
    >>> H = np.linalg.inv(G[1]) @ G[0]           # image 0 -> image 1, full-resolution pixels
    >>> p = H @ [100.5, 80.5, 1.0]  # the full-resolution pixel at work pixel (50, 40), the principal point...
    >>> round(float(p[0] / p[2]), 2)  # ...moves 100 tan(0.1) = 10.03 work px = 20.07 full px to the left
    80.43
    """
    S = np.array([[work_scale, 0, 0.5 * work_scale - 0.5], [0, work_scale, 0.5 * work_scale - 0.5], [0, 0, 1.0]])
    return [np.asarray(r, np.float64) @ np.linalg.inv(np.asarray(k, np.float64)) @ S for k, r in zip(K, R)]


@dataclass(frozen=True)
class OpenCVStitch:
    """Result of :func:`opencv_stitch_cameras`.

    Attributes
    ----------
    status : str
        ``"OK"`` or the name of OpenCV's error code.
    pano : (H, W, 3) uint8 or None
    used : list of int
        Input positions OpenCV kept (it drops the others without saying why).
    homographies : dict int -> (3, 3)
        Per kept input, :func:`camera_homographies`: ``inv(H[j]) @ H[i]`` maps input i to input j (full-resolution
        pixels), as cv2.Stitcher's cameras imply.
    work_scale : float
    """

    status: str
    pano: np.ndarray | None
    used: list
    homographies: dict = field(default_factory=dict)
    work_scale: float = 1.0


def opencv_stitch_cameras(images: Sequence[np.ndarray], work_megapix: float, compose_megapix: float,
                          min_confidence: float, seed: int | None = 0) -> OpenCVStitch:
    """``cv2.Stitcher`` (panorama mode) at the same registration and compose resolutions, with the homographies its
    cameras imply (public API only: ``cameras()``, ``component()``, ``workScale()``).

    ``seed`` seeds OpenCV's RNG (``cv2.setRNGSeed``, which its RANSAC draws from) before stitching, so that a run
    is repeatable; None leaves it alone.
    """
    st = cv2.Stitcher.create(cv2.Stitcher_PANORAMA)
    st.setRegistrationResol(float(work_megapix) if work_megapix > 0 else -1.0)
    st.setCompositingResol(float(compose_megapix) if compose_megapix > 0 else -1.0)
    st.setPanoConfidenceThresh(float(min_confidence))
    bgr = [img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) for img in images]
    if seed is not None:
        cv2.setRNGSeed(int(seed))
    code, pano = st.stitch(bgr)
    if code != 0:
        return OpenCVStitch(OPENCV_STATUS.get(int(code), f"ERR_{int(code)}"), None, [])
    used = [int(k) for k in np.asarray(st.component()).ravel()]
    cams = st.cameras()
    G = camera_homographies([c.K() for c in cams], [c.R for c in cams], float(st.workScale()))
    return OpenCVStitch("OK", pano, used, dict(zip(used, G)), float(st.workScale()))


def opencv_stitch(images: Sequence[np.ndarray], work_megapix: float, compose_megapix: float,
                  min_confidence: float) -> tuple[str, np.ndarray | None, list[int]]:
    """The baseline: ``cv2.Stitcher`` (panorama mode) at the same registration and compose resolutions
    (:func:`opencv_stitch_cameras` without the cameras, OpenCV's RNG left alone).

    Returns
    -------
    status : str
        ``"OK"`` or the name of OpenCV's error code.
    pano : (H, W, 3) uint8 or None
    used : list of int
        Input positions OpenCV kept (it drops the others without saying why).
    """
    r = opencv_stitch_cameras(images, work_megapix, compose_megapix, min_confidence, seed=None)
    return r.status, r.pano, r.used


def opencv_stitch_with(images: Sequence[np.ndarray], features: PanoramaFeaturesParams | None,
                       matching: PanoramaMatchParams | None, warp: PanoramaWarpParams | None) -> OpenCVStitch:
    """:func:`opencv_stitch_cameras` with our sections' settings: ``panorama.features.work_megapix``,
    ``panorama.warp.compose_megapix``, ``panorama.match.min_confidence`` and ``panorama.match.seed`` (the
    ``panorama_opencv_stitcher`` stage's entry point; None: a section's defaults).

    Examples
    --------
    >>> from cvpipe.params import PanoramaFeaturesParams
    >>> from cvpipe.samples import photo
    >>> img = photo("astronaut")
    >>> r = opencv_stitch_with([img[:, 200:], img[:, :320]], PanoramaFeaturesParams(), None, None)
    >>> r.status, sorted(r.used), r.pano.shape[1] > 480, sorted(r.homographies)
    ('OK', [0, 1], True, [0, 1])
    """
    f = section_or_default(features, PanoramaFeaturesParams, "panorama.features")
    m = section_or_default(matching, PanoramaMatchParams, "panorama.match")
    w = section_or_default(warp, PanoramaWarpParams, "panorama.warp")
    return opencv_stitch_cameras(images, f.work_megapix, w.compose_megapix, m.min_confidence, seed=m.seed)
