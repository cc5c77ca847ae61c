"""The gallery: one index over the descriptors of every reference image of every brand, built once."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from typing import Sequence

import cv2
import numpy as np

from ..errors import EstimationError, InputError
from ..features import DETECTORS, Features, check_detector
from ..geometry import image_corners
from ..homography import find_homography
from ..matching import flann_matcher
from ..params import LogoVerifyParams
from .verify import shape_problem, significance


@dataclass(frozen=True)
class Reference:
    """One gallery image of a brand.

    Attributes
    ----------
    brand : str
        Brand name (the gallery file or folder name).
    name : str
        Where the image came from (file name), used in messages.
    features : Features
        Its keypoints and descriptors (positions in reference pixels).
    size : tuple of int
        (width, height) of the reference image in pixels.
    box : tuple of float, optional
        ``(x1, y1, x2, y2)`` corner pixel centres of the logo inside the reference image, when the reference is a
        whole photo with the logo boxed (features then come from inside the box, detected with the photo around
        it so that descriptors near the box edge see real context). Default: the whole image.
    """

    brand: str
    name: str
    features: Features
    size: tuple[int, int]
    box: tuple[float, float, float, float] | None = None

    @property
    def outline(self) -> np.ndarray:
        """(4, 2) logo outline in reference pixels, clockwise from the top-left."""
        if self.box is None:
            return image_corners(*self.size)
        x1, y1, x2, y2 = self.box
        return np.array([[x1, y1], [x2, y1], [x2, y2], [x1, y2]], np.float64)

    @property
    def area(self) -> float:
        """Area of the logo outline, px^2."""
        q = self.outline
        return float((q[1, 0] - q[0, 0]) * (q[2, 1] - q[1, 1]))


@dataclass(frozen=True, eq=False)
class Gallery:
    """The indexed gallery: stacked descriptors of every usable reference and a matcher trained on them.

    Attributes
    ----------
    detector : str
        Detector of every reference (scenes must use the same one).
    brands : tuple of str
        Sorted brand names.
    references : tuple of Reference
        Usable references (at least ``min_features`` keypoints).
    dropped : tuple of str
        Names of references left out for having too few keypoints.
    ref_of : (M,) int64
        Reference index of every stacked descriptor.
    local_of : (M,) int64
        Keypoint index inside its reference of every stacked descriptor.
    brand_of_ref : (R,) int64
        Index into ``brands`` of every reference.
    frame_of_ref : (R,) int64
        Shared frame of every reference (see :func:`register_references`); every reference is its own frame when
        the gallery was built without registration.
    to_frame : (R, 3, 3) float64
        Homography from each reference's pixels to the pixels of its frame's anchor reference.
    anchors : (F,) int64
        Anchor reference of every frame.
    """

    detector: str
    brands: tuple[str, ...]
    references: tuple[Reference, ...]
    dropped: tuple[str, ...]
    ref_of: np.ndarray
    local_of: np.ndarray
    brand_of_ref: np.ndarray
    matcher: cv2.DescriptorMatcher = field(repr=False)
    frame_of_ref: np.ndarray | None = None
    to_frame: np.ndarray | None = None
    anchors: np.ndarray | None = None

    def __post_init__(self):
        if self.frame_of_ref is None:  # no registration: every reference is its own frame
            n = len(self.references)
            object.__setattr__(self, "frame_of_ref", np.arange(n, dtype=np.int64))
            object.__setattr__(self, "to_frame", np.repeat(np.eye(3)[None], n, axis=0))
            object.__setattr__(self, "anchors", np.arange(n, dtype=np.int64))

    @property
    def binary(self) -> bool:
        return DETECTORS[self.detector][1]


def _prepare(desc: np.ndarray, binary: bool) -> np.ndarray:
    """RootSIFT for float descriptors (L1 normalise, square root): Hellinger instead of Euclidean distance, which
    matches SIFT histograms better; binary descriptors pass through."""
    if binary:
        return np.ascontiguousarray(desc, np.uint8)
    d = np.asarray(desc, np.float32)
    d = d / (np.abs(d).sum(axis=1, keepdims=True) + 1e-7)
    return np.ascontiguousarray(np.sqrt(np.maximum(d, 0)), np.float32)


def _strongest(f: Features, n: int) -> Features:
    """The ``n`` keypoints of highest detector response."""
    keep = np.sort(np.argsort(-np.asarray(f.response), kind="stable")[:n])
    return Features(f.xy[keep], f.size[keep], f.angle[keep], f.response[keep], f.descriptors[keep], f.detector)


def build_gallery(references: Sequence[Reference], min_features: int = 8,
                  max_features: int | None = None, register: bool = False,
                  links: dict[tuple[str, str], tuple[np.ndarray, int]] | None = None) -> Gallery:
    """Index the references of every brand once.

    Parameters
    ----------
    references : sequence of Reference
        At least one; all from the same detector.
    min_features : int
        References with fewer keypoints are dropped (listed in ``Gallery.dropped``): they cannot support a
        verified homography.
    max_features : int, optional
        Keep at most this many keypoints per reference, the strongest by detector response. The binary detectors
        find up to 4000 keypoints inside one boxed logo, and the brute-force Hamming search costs in proportion to
        the stacked total. Default: keep all.
    register : bool
        Map the references of each brand into shared frames (:func:`register_references`), so that verification
        pools the matches of every reference of a frame into one model. Default: every reference on its own.
    links : dict, optional
        Precomputed :func:`reference_links` of (a superset of) these references, keyed by reference names; only
        used with ``register``. Default: computed here.

    Raises
    ------
    InputError
        Empty gallery, or no reference with at least ``min_features`` keypoints (the message names the files).
    ValueError
        Mixed detectors or a bad ``min_features`` / ``max_features``.
    """
    if not isinstance(min_features, (int, np.integer)) or min_features < 4:
        raise ValueError(f"`min_features` must be an integer >= 4, got {min_features!r}")
    refs = list(references)
    if not refs:
        raise InputError("the gallery is empty: expected DIR/<brand>.<ext> or DIR/<brand>/*.<ext> images")
    detectors = sorted({r.features.detector for r in refs})
    if len(detectors) > 1:
        raise ValueError(f"gallery references must share one detector, got {detectors}")
    detector = detectors[0]
    check_detector(detector)
    for r in refs:
        if len(r.size) != 2 or min(r.size) < 1:
            raise ValueError(f"`size` of reference {r.name} must be (width, height) >= 1, got {r.size}")
        if r.box is not None:
            x1, y1, x2, y2 = r.box
            if not (0 <= x1 < x2 <= r.size[0] - 1 and 0 <= y1 < y2 <= r.size[1] - 1):
                raise ValueError(f"`box` of reference {r.name} must lie inside its {r.size[0]}x{r.size[1]} image "
                                 f"with x1 < x2 and y1 < y2, got {r.box}")
    if max_features is not None:
        if not isinstance(max_features, (int, np.integer)) or max_features < min_features:
            raise ValueError(f"`max_features` must be an integer >= `min_features` ({min_features}), got "
                             f"{max_features!r}")
        refs = [r if len(r.features) <= max_features else
                Reference(r.brand, r.name, _strongest(r.features, int(max_features)), r.size, r.box) for r in refs]
    usable = [r for r in refs if len(r.features) >= min_features]
    dropped = tuple(r.name for r in refs if len(r.features) < min_features)
    if not usable:
        names = ", ".join(f"{r.name} ({len(r.features)})" for r in refs)
        raise InputError(f"no gallery image yields at least {min_features} keypoints with {detector}: {names}")
    brands = tuple(sorted({r.brand for r in usable}))
    binary = DETECTORS[detector][1]
    desc = np.concatenate([_prepare(r.features.descriptors, binary) for r in usable])
    ref_of = np.concatenate([np.full(len(r.features), i, np.int64) for i, r in enumerate(usable)])
    local_of = np.concatenate([np.arange(len(r.features), dtype=np.int64) for r in usable])
    if binary:
        matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    else:
        matcher = flann_matcher()
    matcher.add([desc])
    # FLANN's randomised kd-trees draw from OpenCV's global generator: seeding it here makes the index (and so every
    # answer) a function of the gallery alone, not of whatever ran before in the process (this resets cv2's RNG)
    cv2.setRNGSeed(0)
    matcher.train()
    brand_of_ref = np.array([brands.index(r.brand) for r in usable], np.int64)
    if not register:
        return Gallery(detector, brands, tuple(usable), dropped, ref_of, local_of, brand_of_ref, matcher)
    if links is None:
        links = reference_links(usable)
    frame_of_ref, to_frame, anchors = register_references(usable, links)
    return Gallery(detector, brands, tuple(usable), dropped, ref_of, local_of, brand_of_ref, matcher,
                   frame_of_ref, to_frame, anchors)


def reference_links(references: Sequence[Reference], ratio: float = 0.8, threshold: float = 3.0,
                    min_inliers: int = 12, params: LogoVerifyParams | None = None,
                    rng=0) -> dict[tuple[str, str], tuple[np.ndarray, int]]:
    """Homographies between the references of each brand that show the same logo.

    Every pair of references of one brand is matched (nearest neighbour with Lowe's ratio test) and fitted by
    RANSAC; a link is kept when it has at least ``min_inliers`` inliers, its a-contrario score is positive, and
    the first logo outline maps onto the second as a plausible view of the same flat logo (convex, not mirrored,
    area 1/4 to 4 times the second outline's, anisotropy at most ``params.max_anisotropy``). Logo variants (a
    wordmark and an emblem of one brand) do not link, and stay separate.

    Parameters
    ----------
    references : sequence of Reference
    ratio : float
        Ratio-test threshold for reference-to-reference matches.
    threshold : float
        RANSAC threshold in pixels of the second reference.
    min_inliers : int
    params : LogoVerifyParams, optional
        ``max_anisotropy`` and ``max_perspective`` for the plausibility check.
    rng : None, int or Generator

    Returns
    -------
    dict
        ``(name_i, name_j) -> (H, inliers)`` with ``H`` mapping reference i's pixels to reference j's, for i
        before j in ``references``.
    """
    p = params or LogoVerifyParams()
    rng = np.random.default_rng(rng)
    refs = list(references)
    if not refs:
        return {}
    binary = DETECTORS[refs[0].features.detector][1]
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING if binary else cv2.NORM_L2)
    desc = [_prepare(r.features.descriptors, binary) for r in refs]
    link_params = replace(p, min_area=0.25, max_area=4.0)
    out: dict[tuple[str, str], tuple[np.ndarray, int]] = {}
    for i, j in itertools.combinations(range(len(refs)), 2):
        a, b = refs[i], refs[j]
        if a.brand != b.brand or len(desc[i]) < min_inliers or len(desc[j]) < min_inliers:
            continue
        knn = matcher.knnMatch(desc[i], desc[j], k=2)
        good = [m[0] for m in knn if len(m) == 2 and m[0].distance < ratio * m[1].distance]
        if len(good) < min_inliers:
            continue
        src = a.features.xy[[m.queryIdx for m in good]].astype(np.float64)
        dst = b.features.xy[[m.trainIdx for m in good]].astype(np.float64)
        try:
            fit = find_homography(src, dst, threshold=threshold, confidence=0.999, max_iters=2000, rng=rng)
        except EstimationError:
            continue
        n_in = int(np.sum(fit.inliers))
        if n_in < min_inliers:
            continue
        q = b.outline
        box_size = (q[1, 0] - q[0, 0] + 1.0, q[2, 1] - q[1, 1] + 1.0)
        if significance(n_in, len(good), threshold, box_size[0] * box_size[1], 1) <= 0:
            continue
        if shape_problem(fit.H, a.outline, box_size, link_params):
            continue
        out[(a.name, b.name)] = (np.asarray(fit.H, np.float64), n_in)
    return out


def register_references(references: Sequence[Reference], links: dict[tuple[str, str], tuple[np.ndarray, int]]
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Group linked references into frames and map each into its frame's anchor reference.

    The references joined by :func:`reference_links` form connected groups; the anchor of a group is its member
    with the most link inliers, and every other member is mapped into the anchor by composing the links along the
    maximum spanning tree (most inliers first) grown from the anchor. Matches to any member of a group can then be
    verified together as one model of the logo, which finds a logo that no single reference matches often enough.

    Returns
    -------
    frame_of_ref : (R,) int64
    to_frame : (R, 3, 3) float64
        Reference pixels -> anchor pixels (identity for the anchors).
    anchors : (F,) int64
    """
    refs = list(references)
    n = len(refs)
    index = {r.name: i for i, r in enumerate(refs)}
    adj: dict[int, dict[int, tuple[np.ndarray, int]]] = {i: {} for i in range(n)}
    for (na, nb), (H, n_in) in links.items():
        if na in index and nb in index:
            i, j = index[na], index[nb]
            adj[i][j] = (H, n_in)  # i -> j
            adj[j][i] = (np.linalg.inv(H), n_in)
    frame_of_ref = np.full(n, -1, np.int64)
    to_frame = np.repeat(np.eye(3)[None], n, axis=0)
    anchors: list[int] = []
    for start in range(n):
        if frame_of_ref[start] >= 0:
            continue
        comp, stack = {start}, [start]
        while stack:
            for j in adj[stack.pop()]:
                if j not in comp:
                    comp.add(j)
                    stack.append(j)
        anchor = max(sorted(comp), key=lambda i: sum(v[1] for v in adj[i].values()))
        f = len(anchors)
        anchors.append(anchor)
        frame_of_ref[anchor] = f
        # Prim's algorithm on inlier counts: attach the strongest link from the tree each time
        while True:
            best = max(((adj[i][j][1], j, i) for i in comp if frame_of_ref[i] == f for j in adj[i]
                        if frame_of_ref[j] < 0), default=None)
            if best is None:
                break
            _, child, parent = best
            frame_of_ref[child] = f
            H = to_frame[parent] @ adj[child][parent][0]
            to_frame[child] = H / H[2, 2]
    return frame_of_ref, to_frame, np.array(anchors, np.int64)
