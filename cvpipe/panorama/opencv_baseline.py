"""The baseline: ``cv2.Stitcher`` (panorama mode) at the same registration and compose resolutions as ours."""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from ..params import PanoramaFeaturesParams, PanoramaMatchParams, PanoramaWarpParams, section_or_default

#: cv2.Stitcher status codes -> names
OPENCV_STATUS = {0: "OK", 1: "ERR_NEED_MORE_IMGS", 2: "ERR_HOMOGRAPHY_EST_FAIL", 3: "ERR_CAMERA_PARAMS_ADJUST_FAIL"}


def opencv_stitch(images: Sequence[np.ndarray], work_megapix: float, compose_megapix: float,
                  min_confidence: float) -> tuple[str, np.ndarray | None, list[int]]:
    """The baseline: ``cv2.Stitcher`` (panorama mode) at the same registration and compose resolutions.

    Returns
    -------
    status : str
        ``"OK"`` or the name of OpenCV's error code.
    pano : (H, W, 3) uint8 or None
    used : list of int
        Input positions OpenCV kept (it drops the others without saying why).
    """
    st = cv2.Stitcher.create(cv2.Stitcher_PANORAMA)
    st.setRegistrationResol(float(work_megapix) if work_megapix > 0 else -1.0)
    st.setCompositingResol(float(compose_megapix) if compose_megapix > 0 else -1.0)
    st.setPanoConfidenceThresh(float(min_confidence))
    bgr = [img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) for img in images]
    code, pano = st.stitch(bgr)
    if code != 0:
        return OPENCV_STATUS.get(int(code), f"ERR_{int(code)}"), None, []
    return "OK", pano, [int(k) for k in np.asarray(st.component()).ravel()]


def opencv_stitch_with(images: Sequence[np.ndarray], features: PanoramaFeaturesParams | None,
                       matching: PanoramaMatchParams | None, warp: PanoramaWarpParams | None,
                       ) -> tuple[str, np.ndarray | None, list[int]]:
    """:func:`opencv_stitch` with our sections' settings: ``panorama.features.work_megapix``,
    ``panorama.warp.compose_megapix`` and ``panorama.match.min_confidence`` (the ``panorama_opencv_stitcher``
    stage's entry point; None: a section's defaults).

    Examples
    --------
    >>> from cvpipe.params import PanoramaFeaturesParams
    >>> from cvpipe.samples import photo
    >>> img = photo("astronaut")
    >>> status, pano, used = opencv_stitch_with([img[:, 200:], img[:, :320]], PanoramaFeaturesParams(), None, None)
    >>> status, sorted(used), pano.shape[1] > 480
    ('OK', [0, 1], True)
    """
    f = section_or_default(features, PanoramaFeaturesParams, "panorama.features")
    m = section_or_default(matching, PanoramaMatchParams, "panorama.match")
    w = section_or_default(warp, PanoramaWarpParams, "panorama.warp")
    return opencv_stitch(images, f.work_megapix, w.compose_megapix, m.min_confidence)
