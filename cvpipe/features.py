"""Keypoint detectors and descriptors behind one registry.

``DETECTORS`` maps a name to a factory; BRISK and AKAZE are reached through :func:`opencv_factory`, which finds
them in the main ``cv2`` namespace (OpenCV 4.x, and 5.x contrib builds) or in ``cv2.xfeatures2d`` (5.x, where they
moved to the contrib modules).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from .errors import BudgetWarning, InputError, check_int, memory_budget
from .params import FeaturesParams, section_or_default

#: the ``homography.features`` defaults: the one declaration of :func:`detect`'s keyword defaults
_FEATURES = FeaturesParams()


def opencv_factory(name: str) -> Callable[..., cv2.Feature2D]:
    """The ``cv2`` constructor ``<name>_create`` wherever this OpenCV build keeps it.

    Parameters
    ----------
    name : str
        OpenCV class name, e.g. ``"BRISK"`` or ``"AKAZE"``.

    Raises
    ------
    ImportError
        When neither ``cv2`` nor ``cv2.xfeatures2d`` has it: install ``opencv-contrib-python-headless``.
    """
    for namespace in (cv2, getattr(cv2, "xfeatures2d", None), getattr(cv2, "features2d", None)):
        if namespace is not None and hasattr(namespace, f"{name}_create"):
            return getattr(namespace, f"{name}_create")
    raise ImportError(
        f"this OpenCV build ({cv2.__version__}) has no {name}; install opencv-contrib-python-headless"
    )


def _sift(max_features: int) -> cv2.Feature2D:
    return cv2.SIFT_create(nfeatures=max_features)


def _orb(max_features: int) -> cv2.Feature2D:
    return cv2.ORB_create(nfeatures=max_features, scaleFactor=1.2, nlevels=8, fastThreshold=10)


def _brisk(max_features: int) -> cv2.Feature2D:
    return opencv_factory("BRISK")(thresh=20)


def _akaze(max_features: int) -> cv2.Feature2D:
    return opencv_factory("AKAZE")(threshold=0.0005)


#: detector name -> (factory(max_features), descriptors are binary)
DETECTORS: dict[str, tuple[Callable[[int], cv2.Feature2D], bool]] = {
    "sift": (_sift, False),
    "orb": (_orb, True),
    "brisk": (_brisk, True),
    "akaze": (_akaze, True),
}


@dataclass(frozen=True)
class Features:
    """Keypoints and descriptors of one image.

    Attributes
    ----------
    xy : (N, 2) float32
        Keypoint positions, x = column, y = row, in pixels.
    size : (N,) float32
        Keypoint diameter in pixels.
    angle : (N,) float32
        Orientation in degrees (-1 when the detector has none).
    response : (N,) float32
        Detector response (strength).
    descriptors : (N, D) float32 or uint8
        One row per keypoint; uint8 rows are packed bits for the binary detectors.
    detector : str
        Registry name of the detector that produced them.
    """

    xy: np.ndarray
    size: np.ndarray
    angle: np.ndarray
    response: np.ndarray
    descriptors: np.ndarray
    detector: str

    #: the arrays of :meth:`to_arrays`, the keys a cached ``.npz`` must hold for :meth:`from_arrays`
    ARRAYS = ("xy", "size", "angle", "response", "descriptors", "detector")

    def __len__(self) -> int:
        return len(self.xy)

    @property
    def binary(self) -> bool:
        return DETECTORS[self.detector][1]

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Named arrays for ``io.save_npz``."""
        return {
            "xy": self.xy, "size": self.size, "angle": self.angle, "response": self.response,
            "descriptors": self.descriptors, "detector": np.array(self.detector),
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> "Features":
        """Inverse of :meth:`to_arrays`."""
        detector = str(arrays["detector"])
        check_detector(detector)
        return cls(arrays["xy"], arrays["size"], arrays["angle"], arrays["response"], arrays["descriptors"], detector)


#: the arrays of a features stage's ``.npz`` per image (:func:`detect_item`): the features and ``image_size`` (w, h)
NPZ_ARRAYS = Features.ARRAYS + ("image_size",)


def check_detector(detector: str) -> None:
    """Raise ``ValueError`` listing the choices when ``detector`` is not registered."""
    if detector not in DETECTORS:
        raise ValueError(f"`detector` must be one of {sorted(DETECTORS)}, got {detector!r}")


def empty_descriptors(detector: str) -> np.ndarray:
    """A (0, D) descriptor array of the right dtype for ``detector``."""
    return np.zeros((0, 32), np.uint8) if DETECTORS[detector][1] else np.zeros((0, 128), np.float32)


#: peak bytes per pixel of detection (measured on 9 MP: SIFT's float pyramid from a 2x upsampled base ~236)
DETECTION_BYTES_PER_PIXEL = {"sift": 250, "akaze": 110, "brisk": 40, "orb": 10}


def detection_scale(shape: tuple[int, ...], detector: str) -> float:
    """1.0, or the factor (< 1) that brings detection on an image of ``shape`` within the memory budget.

    A smaller factor is announced with a :class:`cvpipe.errors.BudgetWarning` (the CLI prints it as a note).
    """
    need = float(shape[0]) * float(shape[1]) * DETECTION_BYTES_PER_PIXEL.get(detector, 250)
    budget = memory_budget()
    if need <= budget:
        return 1.0
    scale = math.sqrt(budget / need) * 0.98
    warnings.warn(BudgetWarning(f"{detector} keypoints of the {shape[1]}x{shape[0]} image detected at {scale:.2f}x "
                                f"size to stay within the memory budget of {budget / 1e9:.3g} GB "
                                "(CVPIPE_MEMORY_BUDGET_GB)"), stacklevel=3)
    return scale


def detect(gray: np.ndarray, detector: str = _FEATURES.detector, max_features: int = _FEATURES.max_features,
           mask: np.ndarray | None = None, min_long_side: int = 0) -> Features:
    """Detect keypoints and compute descriptors.

    Parameters
    ----------
    gray : (H, W) uint8
        Grayscale image.
    detector : {"sift", "orb", "brisk", "akaze"}
        Registry name.
    max_features : int
        Keep at most this many keypoints, the strongest by response.
    mask : (H, W) uint8, optional
        Detect only where non-zero.
    min_long_side : int
        An image whose longer side is shorter than this is enlarged (bicubic) to that length before detection, so
        that small structures (a logo a few dozen pixels wide) reach the detector's finest scale; positions and sizes
        are reported in the original image's pixels. 0 (default) detects at the given size.

    Returns
    -------
    Features
        Possibly empty (a blank image has no features); callers decide whether that is an error.
    """
    check_detector(detector)
    gray = np.asarray(gray)
    if gray.ndim != 2 or gray.dtype != np.uint8:
        raise ValueError(f"`gray` must be a (H, W) uint8 image, got shape {gray.shape} dtype {gray.dtype}")
    if gray.size == 0:
        raise InputError("`gray` is empty (0 pixels)")
    check_int("max_features", max_features, 1)
    check_int("min_long_side", min_long_side, 0)
    scale = min_long_side / max(gray.shape) if max(gray.shape) < min_long_side else 1.0
    fit = detection_scale(gray.shape, detector)  # huge images: detect at a size within the memory budget
    scale = fit if fit < 1.0 else scale
    if scale != 1.0:
        size_up = (int(round(gray.shape[1] * scale)), int(round(gray.shape[0] * scale)))
        sxy = np.array([size_up[0] / gray.shape[1], size_up[1] / gray.shape[0]], np.float64)
        gray = cv2.resize(gray, size_up, interpolation=cv2.INTER_CUBIC if scale > 1 else cv2.INTER_AREA)
        if mask is not None:
            mask = cv2.resize(np.asarray(mask, np.uint8), size_up, interpolation=cv2.INTER_NEAREST)
    factory, _ = DETECTORS[detector]
    keypoints, desc = factory(int(max_features)).detectAndCompute(gray, mask)
    if desc is None or not keypoints:
        z = np.zeros(0, np.float32)
        return Features(np.zeros((0, 2), np.float32), z, z, z, empty_descriptors(detector), detector)
    response = np.array([k.response for k in keypoints], np.float32)
    order = np.argsort(-response, kind="stable")[:max_features]
    xy = np.array([k.pt for k in keypoints], np.float32)[order]
    size = np.array([k.size for k in keypoints], np.float32)[order]
    if scale != 1.0:  # back to the original pixels (pixel centres: x = (x' + 0.5) / s - 0.5)
        xy = ((xy + 0.5) / sxy - 0.5).astype(np.float32)
        size = (size / np.sqrt(sxy.prod())).astype(np.float32)
    angle = np.array([k.angle for k in keypoints], np.float32)[order]
    return Features(xy, size, angle, response[order], np.ascontiguousarray(desc[order]), detector)


def detect_with(gray: np.ndarray, params: FeaturesParams | None = None, *, scene: bool = False) -> Features:
    """:func:`detect` with a ``<task>.features`` section (``homography.features``, ``defect.features``,
    ``logo.features``, ...): its ``detector`` and ``max_features``, and for a ``scene`` photo the section's
    ``scene_min_long_side`` when it has one (``logo.features``).

    Parameters
    ----------
    gray : (H, W) uint8
        Grayscale image.
    params : FeaturesParams or None
        The section, any :class:`~cvpipe.params.FeaturesParams` (None: its defaults).
    scene : bool
        The image is a scene photo (enlarged to ``scene_min_long_side`` when smaller); otherwise detected at its
        size.

    Returns
    -------
    Features

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.params import FeaturesParams, LogoFeaturesParams
    >>> img = np.zeros((120, 160), np.uint8)
    >>> img[30:90, 40:70] = 200; img[50:70, 100:140] = 120
    >>> f = detect_with(img, FeaturesParams(detector="orb", max_features=50))
    >>> f.detector, len(f.xy) <= 50
    ('orb', True)
    >>> g = detect_with(img, LogoFeaturesParams(scene_min_long_side=320), scene=True)  # found on a 2x enlargement
    >>> np.array_equal(g.xy, detect(img, "sift", 4000, min_long_side=320).xy)
    True
    """
    p = section_or_default(params, FeaturesParams, "<task>.features")
    return detect(gray, p.detector, p.max_features, min_long_side=getattr(p, "scene_min_long_side", 0) if scene else 0)


def detect_item(item: tuple, shared: FeaturesParams) -> tuple[dict[str, np.ndarray], float]:
    """Keypoints and descriptors of one image as the arrays of its ``.npz``: the per-image work of the
    ``<task>_features`` stages, an item of :func:`cvpipe.compute.map_items` (it may run on another machine: data
    in, data out).

    Parameters
    ----------
    item : tuple
        ``(gray image, scene)``: the image and whether it is a scene photo (:func:`detect_with`).
    shared : FeaturesParams
        The ``<task>.features`` section.

    Returns
    -------
    (dict, float)
        :meth:`Features.to_arrays` plus ``image_size`` ``(w, h)``, and the seconds the detection took.
    """
    import time

    gray, scene = item
    t0 = time.perf_counter()
    feats = detect_with(gray, shared, scene=scene)
    seconds = time.perf_counter() - t0
    return {**feats.to_arrays(), "image_size": gray.shape[::-1]}, seconds
