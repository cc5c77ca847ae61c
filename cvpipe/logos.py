"""Logo recognition: which gallery brand is in a scene photo, and where.

A gallery holds one or more reference images per brand. Their descriptors are stacked into one index that is built
once; every scene descriptor is matched against the whole gallery in one k-nearest-neighbour query, and Lowe's
ratio test compares the best neighbour of a brand with the best neighbour of any *other* brand (so several
reference photos of the same brand do not reject each other's matches). Each reference with enough tentative
matches is verified by a RANSAC homography (:func:`cvpipe.homography.find_homography`; for SIFT by default after an
affine RANSAC has picked the consistent matches, see :data:`MODELS`) and plausibility checks on it: the projected
reference outline must be convex and not mirrored, of sane area relative to the scene, without extreme anisotropy
or perspective, and the inliers must cover a fair part of the reference.

An inlier must land within the RANSAC threshold of its predicted position *and* agree with the model in keypoint
orientation and scale (the reference keypoint's angle and size carried through the model's local Jacobian,
:func:`map_poses`): a chance match agrees in all three far less often than in position alone, which keeps chance
fits rare on busy, enlarged scenes. References of one brand that register to each other can optionally be mapped
into one shared frame (:func:`register_references`) and verified as one model.

The score is an a-contrario significance, ``-log10`` of the expected number of equally good chance fits: the
binomial tail of seeing ``inliers - 4`` of the ``matches - 4`` other matches agree with their prediction when they
are spread at random over the scene with random orientations and scales, times the chance that the 4 sample
matches agree in orientation and scale, multiplied by the number of 4-point hypotheses and of references tried.
Unlike a raw inlier count, it does not grow with the number of tentative matches that a cluttered scene or a
feature-rich reference produces, so it is comparable across brands and separates true logos from the 6-10 inlier
fits that RANSAC finds on any busy photo.

The module takes arrays only; reading the gallery folder lives in the command, stage and benchmark code.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np
from scipy.special import gammaln
from scipy.stats import binom

from .errors import EstimationError, InputError
from .features import DETECTORS, Features, check_detector
from .homography import find_homography
from .params import LogoMatchParams, LogoVerifyParams, replace

_FLANN_KDTREE = 1


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
            return outline(self.size)
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


@dataclass(frozen=True)
class Matches:
    """Tentative scene -> gallery matches of one scene.

    Attributes
    ----------
    ref : (M,) int64
        Reference index of each match.
    gallery_idx : (M,) int64
        Keypoint index inside that reference.
    scene_idx : (M,) int64
        Scene keypoint index.
    distance : (M,) float32
        Descriptor distance.
    """

    ref: np.ndarray
    gallery_idx: np.ndarray
    scene_idx: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return len(self.ref)

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {"ref": self.ref, "gallery_idx": self.gallery_idx, "scene_idx": self.scene_idx,
                "distance": self.distance}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> "Matches":
        return cls(np.asarray(arrays["ref"], np.int64), np.asarray(arrays["gallery_idx"], np.int64),
                   np.asarray(arrays["scene_idx"], np.int64), np.asarray(arrays["distance"], np.float32))


@dataclass(frozen=True)
class Hypothesis:
    """The verified (or rejected) homography of one reference in one scene.

    Attributes
    ----------
    brand : str
    reference : int
        Index into ``Gallery.references``.
    matches : int
        Tentative matches of this reference (after one-to-one filtering).
    inliers : int
        RANSAC inliers (0 when no homography could be fitted).
    score : float
        ``-log10`` NFA (see the module docstring); ``-inf`` when rejected.
    H : (3, 3) float64 or None
        Reference pixels -> scene pixels.
    quad : (4, 2) float64 or None
        Reference outline (corner pixel centres, clockwise from top-left) in scene pixels.
    pairs : (K, 2) int64
        Inlier ``[reference keypoint, scene keypoint]`` index pairs.
    reason : str
        Why the hypothesis was rejected, empty when it passed every check.
    reference_xy : (K, 2) float64
        The inliers' reference keypoints in the pixels of ``reference`` (the frame's anchor).
    pair_refs : (K,) int64
        Reference of each inlier pair (``pairs[:, 0]`` indexes that reference's keypoints); differs from
        ``reference`` when the frame pools several registered references.
    """

    brand: str
    reference: int
    matches: int
    inliers: int
    score: float
    H: np.ndarray | None
    quad: np.ndarray | None
    pairs: np.ndarray
    reason: str = ""
    reference_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    pair_refs: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def plausible(self) -> bool:
        return not self.reason


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


# ------------------------------------------------------------------------------------------------ the gallery


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
        matcher = cv2.FlannBasedMatcher({"algorithm": _FLANN_KDTREE, "trees": 4}, {"checks": 64})
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


# ----------------------------------------------------------------------------------------------- matching


def match_scene(gallery: Gallery, scene: Features, params: LogoMatchParams | None = None) -> Matches:
    """Tentative matches of a scene's keypoints to every reference.

    Each scene descriptor gets its ``k`` nearest gallery descriptors. A neighbour of brand B is kept when its
    distance is below ``ratio`` times the distance of the nearest neighbour of any other brand (or of the k-th
    neighbour when all k belong to B), and at most the first ``per_reference`` neighbours in one reference count.
    With ``reverse_shortlist`` > 0, the references with the most such matches are also matched the other way, each
    reference keypoint to its nearest scene keypoint with Lowe's ratio ``reverse_ratio`` (see
    :func:`_reverse_matches`), and both sets are pooled. Afterwards every reference keypoint keeps only its
    closest scene keypoint.

    Parameters
    ----------
    gallery : Gallery
    scene : Features
        From the same detector as the gallery.
    params : LogoMatchParams, optional
        ``ratio``, ``k``, ``per_reference``, ``reverse_shortlist`` and ``reverse_ratio``; defaults from
        :class:`cvpipe.params.LogoMatchParams`.
    """
    p = params or LogoMatchParams()
    if scene.detector != gallery.detector:
        raise ValueError(f"scene features come from {scene.detector!r}, the gallery from {gallery.detector!r}")
    empty = Matches(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float32))
    if len(scene) == 0:
        return empty
    k = int(min(p.k, len(gallery.ref_of)))
    knn = gallery.matcher.knnMatch(_prepare(scene.descriptors, gallery.binary), k=k)
    n = len(knn)
    idx = np.full((n, k), -1, np.int64)
    dist = np.full((n, k), np.inf, np.float32)
    for i, row in enumerate(knn):
        for j, m in enumerate(row):
            idx[i, j] = m.trainIdx
            dist[i, j] = m.distance
    valid = idx >= 0
    ref = np.where(valid, gallery.ref_of[np.maximum(idx, 0)], -1)
    brand = np.where(valid, gallery.brand_of_ref[np.maximum(ref, 0)], -1)
    # nearest distance of another brand for every neighbour: the first neighbour whose brand differs
    other = np.full((n, k), np.inf, np.float32)
    last = dist[np.arange(n), valid.sum(1) - 1]
    for j in range(k):
        differs = (brand != brand[:, j:j + 1]) & valid
        first = np.where(differs.any(1), dist[np.arange(n), np.argmax(differs, 1)], last)
        other[:, j] = first
    keep = valid & (dist < p.ratio * other)
    # at most `per_reference` neighbours in one reference: 2 keeps both twins of a symmetric mark (RANSAC picks the
    # consistent one), where 1 would keep a random twin and halve the inliers
    for j in range(1, k):
        keep[:, j] &= (ref[:, :j] == ref[:, j:j + 1]).sum(1) < p.per_reference
    rows, cols = np.nonzero(keep)
    if len(rows) == 0:
        return empty
    m_ref = ref[rows, cols]
    m_gal = gallery.local_of[idx[rows, cols]]
    m_dist = dist[rows, cols]
    if p.reverse_shortlist > 0:
        r_ref, r_gal, r_rows, r_dist = _reverse_matches(gallery, scene, m_ref, rows, p)
        m_ref, m_gal = np.r_[m_ref, r_ref], np.r_[m_gal, r_gal]
        rows, m_dist = np.r_[rows, r_rows], np.r_[m_dist, r_dist]
    # one-to-one per reference: keep the closest scene keypoint of every reference keypoint
    order = np.lexsort((m_dist, m_gal, m_ref))
    m_ref, m_gal, rows, m_dist = m_ref[order], m_gal[order], rows[order], m_dist[order]
    first = np.ones(len(m_ref), bool)
    first[1:] = (m_ref[1:] != m_ref[:-1]) | (m_gal[1:] != m_gal[:-1])
    return Matches(m_ref[first], m_gal[first], rows[first].astype(np.int64), m_dist[first].astype(np.float32))


def _reverse_matches(gallery: Gallery, scene: Features, m_ref: np.ndarray, m_scene: np.ndarray,
                     p: LogoMatchParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Reference -> scene matches of the ``reverse_shortlist`` references with the most forward-matched scene
    keypoints (at least 2): each reference keypoint's nearest scene keypoint, kept when it is closer than
    ``reverse_ratio`` times the second nearest (Lowe's test within the scene).

    The forward test compares a scene keypoint's neighbours across the whole gallery, so a keypoint of a generic
    shape (a ring, a letter's corner) that several brands share fails it even where the logo is plainly there; the
    reverse test only asks whether the scene holds one clear counterpart of that reference keypoint.
    """
    empty = (np.zeros(0, np.int64),) * 3 + (np.zeros(0, np.float32),)
    if len(scene) < 2 or len(m_ref) == 0:
        return empty
    pairs = np.unique(np.c_[m_ref, m_scene], axis=0)  # distinct scene keypoints per reference
    counts = np.bincount(pairs[:, 0], minlength=len(gallery.references))
    short = np.argsort(-counts, kind="stable")[:p.reverse_shortlist]
    short = short[counts[short] >= 2]
    if len(short) == 0:
        return empty
    desc = [_prepare(gallery.references[int(r)].features.descriptors, gallery.binary) for r in short]
    query = np.concatenate(desc)
    scene_desc = _prepare(scene.descriptors, gallery.binary)
    if gallery.binary:  # exact Hamming search, one call for every shortlisted reference
        knn = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(query, scene_desc, k=2)
        nn = np.array([[m.trainIdx for m in row] for row in knn], np.int64)
        dist = np.array([[m.distance for m in row] for row in knn], np.float32)
    else:  # kd-trees over the scene; numpy in and out (no per-match Python objects)
        cv2.setRNGSeed(0)  # the kd-trees draw from OpenCV's global generator (see build_gallery)
        index = cv2.flann_Index(scene_desc, {"algorithm": _FLANN_KDTREE, "trees": 4})
        nn, dist2 = index.knnSearch(query, 2, params={"checks": 32})
        nn, dist = nn.astype(np.int64), np.sqrt(np.maximum(dist2, 0)).astype(np.float32)  # FLANN's L2 is squared
    keep = (nn[:, 1] >= 0) & (dist[:, 0] < p.reverse_ratio * dist[:, 1])
    ref = np.repeat(short.astype(np.int64), [len(d) for d in desc])
    local = np.concatenate([np.arange(len(d), dtype=np.int64) for d in desc])
    return ref[keep], local[keep], nn[keep, 0], dist[keep, 0]


# ------------------------------------------------------------------------------------------- verification


def outline(size: tuple[int, int]) -> np.ndarray:
    """(4, 2) corner pixel centres of a (width, height) image, clockwise from the top-left."""
    w, h = size
    return np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float64)


def project(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Map (N, 2) points by the 3x3 homography ``H``; raises EstimationError for points at infinity."""
    p = np.c_[np.asarray(pts, np.float64), np.ones(len(pts))] @ np.asarray(H, np.float64).T
    if np.any(np.abs(p[:, 2]) < 1e-12):
        raise EstimationError("a point maps to infinity")
    return p[:, :2] / p[:, 2:3]


def _polygon_area(q: np.ndarray) -> float:
    x, y = q[:, 0], q[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _hull_area(pts: np.ndarray) -> float:
    if len(pts) < 3:
        return 0.0
    return float(cv2.contourArea(cv2.convexHull(np.asarray(pts, np.float32))))


def shape_problem(H: np.ndarray, corners: np.ndarray, scene_size: tuple[int, int],
                  params: LogoVerifyParams | None = None) -> str:
    """Why the homography is not a plausible view of a flat logo, or ``""`` when it is.

    Parameters
    ----------
    H : (3, 3)
        Reference pixels -> scene pixels.
    corners : (4, 2)
        Logo outline in reference pixels, clockwise from the top-left (``Reference.outline``).
    scene_size : (width, height)
        Scene size in pixels.
    params : LogoVerifyParams, optional
        ``min_area``, ``max_area`` (outline area / scene area), ``max_anisotropy`` (ratio of the singular values
        of the local affine map at the reference centre: shear plus aspect change), ``max_perspective`` (ratio of
        the largest to the smallest local area scale over the four corners).
    """
    p = params or LogoVerifyParams()
    corners = np.asarray(corners, np.float64)
    w = np.c_[corners, np.ones(4)] @ np.asarray(H, np.float64)[2]
    if np.any(w <= 1e-9):
        return "outline crosses the horizon"
    quad = project(H, corners)
    edges = np.roll(quad, -1, axis=0) - quad
    cross = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    # the reference outline turns clockwise on screen (y down) = positive cross products; negative means mirrored
    if not np.all(cross > 0):
        return "outline not convex or mirrored"
    frac = _polygon_area(quad) / float(scene_size[0] * scene_size[1])
    if not p.min_area <= frac <= p.max_area:
        return f"outline covers {frac:.4f} of the scene, outside [{p.min_area}, {p.max_area}]"
    c = corners.mean(axis=0)
    hc = H @ np.r_[c, 1.0]
    J = (H[:2, :2] * hc[2] - np.outer(hc[:2], H[2, :2])) / hc[2] ** 2
    s = np.linalg.svd(J, compute_uv=False)
    if s[1] <= 0 or s[0] / s[1] > p.max_anisotropy:
        return f"anisotropy {s[0] / max(s[1], 1e-12):.1f} > {p.max_anisotropy}"
    # local area scale of a homography is det(H) / w^3
    persp = float((w.max() / w.min()) ** 3)
    if persp > p.max_perspective:
        return f"perspective area ratio {persp:.1f} > {p.max_perspective}"
    return ""


def fit_affine(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares affine map (3, 3), last row ``[0, 0, 1]``, from (N, 2) ``src`` to (N, 2) ``dst``, N >= 3."""
    X = np.c_[np.asarray(src, np.float64), np.ones(len(src))]
    M, *_ = np.linalg.lstsq(X, np.asarray(dst, np.float64), rcond=None)
    return np.r_[M.T, [[0.0, 0.0, 1.0]]]


def map_poses(H: np.ndarray, xy: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Keypoint orientations and scales carried through the homography ``H``.

    Parameters
    ----------
    H : (3, 3)
    xy : (N, 2)
        Keypoint positions before the mapping.
    pose : (N, 2)
        ``[angle in degrees, natural log of the keypoint size]`` (OpenCV's angle: image axes, y down).

    Returns
    -------
    (N, 2) poses after the mapping: the direction vector of each angle is mapped by the local Jacobian of ``H``,
    and the log size grows by the log of the Jacobian's area scale, halved (a length scale).
    """
    H = np.asarray(H, np.float64)
    xy = np.asarray(xy, np.float64)
    w = xy @ H[2, :2] + H[2, 2]
    hx = xy @ H[:2, :2].T + H[:2, 2]
    J = (H[None, :2, :2] * w[:, None, None] - hx[:, :, None] * H[None, 2:3, :2]) / (w * w)[:, None, None]
    return _apply_jacobians(J, pose)


def _apply_jacobians(J: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Poses mapped by local linear maps ``J`` (..., 2, 2) that broadcast against ``pose`` (N, 2)."""
    a = np.deg2rad(pose[:, 0])
    ux = J[..., 0, 0] * np.cos(a) + J[..., 0, 1] * np.sin(a)
    uy = J[..., 1, 0] * np.cos(a) + J[..., 1, 1] * np.sin(a)
    det = np.abs(J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0])
    return np.stack([np.rad2deg(np.arctan2(uy, ux)), pose[:, 1] + 0.5 * np.log(np.maximum(det, 1e-300))], axis=-1)


def pose_agrees(predicted: np.ndarray, observed: np.ndarray, angle_tolerance: float,
                scale_tolerance: float) -> np.ndarray:
    """Whether predicted and observed ``[angle deg, log size]`` agree within the tolerances (degrees, ratio)."""
    d = np.abs((predicted[..., 0] - observed[..., 0] + 180.0) % 360.0 - 180.0)
    return (d <= angle_tolerance) & (np.abs(predicted[..., 1] - observed[..., 1]) <= np.log(scale_tolerance))


def pose_probability(angle_tolerance: float, scale_tolerance: float) -> float:
    """Chance that an unrelated match agrees in pose: orientation uniform over 360 degrees, log size ratio uniform
    over a factor of 4 either way (``ln 16``); 1 when the tolerances switch the check off."""
    return min(1.0, angle_tolerance / 180.0) * min(1.0, 2.0 * np.log(scale_tolerance) / np.log(16.0))


def affine_ransac(src: np.ndarray, dst: np.ndarray, threshold: float, hypotheses: int = 500,
                  rng=None, src_pose: np.ndarray | None = None, dst_pose: np.ndarray | None = None,
                  angle_tolerance: float = 180.0, scale_tolerance: float = 1e9) -> tuple[np.ndarray, np.ndarray]:
    """Robust affine map from putative correspondences: RANSAC over 3-point samples, evaluated all at once.

    A logo that covers a small part of the scene is seen almost affinely, and an affine map cannot fold the
    outline over the horizon, so it finds the right model among few, noisy matches where a free homography fits a
    chance configuration with a couple more inliers.

    Parameters
    ----------
    src, dst : (N, 2) float
        Reference and scene points, pixels; N >= 3.
    threshold : float
        Inlier distance in scene pixels.
    hypotheses : int
        3-point samples drawn (all triples when there are fewer).
    rng : None, int or Generator
    src_pose, dst_pose : (N, 2) float, optional
        ``[angle deg, log size]`` of the keypoints; when given, an inlier must also agree in orientation and scale
        with the model's prediction within ``angle_tolerance`` degrees and a ``scale_tolerance`` size ratio.

    Returns
    -------
    A : (3, 3) float64
        Reference -> scene, refitted by least squares on the inliers (a few rounds).
    inliers : (N,) bool

    Raises
    ------
    EstimationError
        Fewer than 3 correspondences or every sample degenerate (collinear).
    """
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    n = len(src)
    if n < 3:
        raise EstimationError(f"an affine map needs 3 correspondences, got {n}")
    rng = np.random.default_rng(rng)
    if n * (n - 1) * (n - 2) // 6 <= hypotheses:
        idx = np.array(list(itertools.combinations(range(n), 3)), np.int64)
    else:
        idx = rng.integers(0, n, (hypotheses, 3))
        idx = idx[(idx[:, 0] != idx[:, 1]) & (idx[:, 0] != idx[:, 2]) & (idx[:, 1] != idx[:, 2])]
    # the linear part L of each sample maps the edge vectors of the source triangle onto the target's: L = E D^-1
    d1, d2 = src[idx[:, 1]] - src[idx[:, 0]], src[idx[:, 2]] - src[idx[:, 0]]
    e1, e2 = dst[idx[:, 1]] - dst[idx[:, 0]], dst[idx[:, 2]] - dst[idx[:, 0]]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    ok = np.abs(det) > 1e-6 * (np.abs(np.c_[d1, d2]).max(axis=1) ** 2 + 1e-12)
    if not ok.any():
        raise EstimationError("every 3-point sample is collinear")
    d1, d2, e1, e2, det, idx = d1[ok], d2[ok], e1[ok], e2[ok], det[ok], idx[ok]
    L = np.empty((len(det), 2, 2))
    L[:, :, 0] = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / det[:, None]
    L[:, :, 1] = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) / det[:, None]
    t = dst[idx[:, 0]] - np.einsum("tij,tj->ti", L, src[idx[:, 0]])
    ex = L[:, 0, 0:1] * src[:, 0] + L[:, 0, 1:2] * src[:, 1] + t[:, 0:1] - dst[:, 0]  # (T, n)
    ey = L[:, 1, 0:1] * src[:, 0] + L[:, 1, 1:2] * src[:, 1] + t[:, 1:2] - dst[:, 1]
    err2 = ex * ex + ey * ey
    th2 = threshold * threshold
    inl = err2 < th2
    use_pose = src_pose is not None and dst_pose is not None
    if use_pose:
        inl &= pose_agrees(_apply_jacobians(L[:, None], src_pose), dst_pose[None], angle_tolerance, scale_tolerance)
    # most inliers; among equals the smallest truncated squared error (MSAC)
    best = int(np.argmax(inl.sum(axis=1) - np.minimum(err2, th2).sum(axis=1) / (th2 * n + 1.0)))
    inliers = inl[best]
    A = np.r_[np.c_[L[best], t[best]], [[0.0, 0.0, 1.0]]]
    for _ in range(3):  # local optimisation: refit on the inliers while that does not lose any
        if inliers.sum() < 3:
            break
        A2 = fit_affine(src[inliers], dst[inliers])
        in2 = np.linalg.norm(src @ A2[:2, :2].T + A2[:2, 2] - dst, axis=1) < threshold
        if use_pose:
            in2 &= pose_agrees(_apply_jacobians(A2[None, :2, :2], src_pose), dst_pose, angle_tolerance,
                               scale_tolerance)
        if in2.sum() < inliers.sum():
            break
        A, same, inliers = A2, np.array_equal(in2, inliers), in2
        if same:
            break
    return A, inliers


def significance(inliers: int, matches: int, threshold: float, area: float, n_refs: int,
                 pose_prob: float = 1.0) -> float:
    """``-log10`` of the number of false alarms of a homography with ``inliers`` among ``matches``.

    Parameters
    ----------
    inliers, matches : int
        Inlier and tentative match counts of one reference.
    threshold : float
        RANSAC reprojection threshold, scene pixels.
    area : float
        Scene area (px^2) over which chance matches spread.
    n_refs : int
        Number of references tested in this scene (multiple tests).
    pose_prob : float
        Chance that an unrelated match also agrees with the model in orientation and scale
        (:func:`pose_probability`; 1 when inliers are judged by position only). The 4 matches of the minimal sample
        fix the model's position but not the orientations and scales of their keypoints, so they count too.
    """
    if matches < 5 or inliers < (5 if pose_prob >= 1.0 else 4):
        return -np.inf
    prob = min(1.0, np.pi * threshold ** 2 / max(area, 1.0)) * pose_prob
    n, k = matches - 4, inliers - 4
    log_tail = binom.logsf(k - 1, n, prob) if k > 0 else 0.0  # ln P(X >= k)
    if not np.isfinite(log_tail):  # the tail underflows for huge inlier counts; its first term bounds it from below
        log_tail = binom.logpmf(k, n, prob)
    log_tail /= np.log(10)
    log_hyp = (gammaln(matches + 1) - gammaln(5) - gammaln(matches - 3)) / np.log(10)  # log10 C(matches, 4)
    return float(-(log_tail + 4 * np.log10(pose_prob) + log_hyp + np.log10(max(n_refs, 1))))


def _check(brand: str, r: int, ref: Reference, H: np.ndarray, inl: np.ndarray, src: np.ndarray, dst: np.ndarray,
           g_idx: np.ndarray, s_idx: np.ndarray, m_ref: np.ndarray, scene_size: tuple[int, int], n_tested: int,
           p: LogoVerifyParams, pose_prob: float = 1.0) -> Hypothesis:
    """Plausibility checks and score of one fitted model (see :func:`verify`); ``src`` in the anchor's pixels."""
    # one inlier per scene keypoint: the matches of one scene keypoint to several references of a frame agree
    _, first = np.unique(np.where(inl, s_idx, -1), return_index=True)
    keep = np.zeros(len(inl), bool)
    keep[first] = True
    keep &= inl
    n_in = int(keep.sum())
    n_matches = len(np.unique(s_idx))
    pairs = np.c_[g_idx[keep], s_idx[keep]]
    reason = shape_problem(H, ref.outline, scene_size, p)
    quad = None if reason.startswith("outline crosses") else project(H, ref.outline)
    if not reason and n_in < p.min_inliers:
        reason = f"{n_in} inliers < {p.min_inliers}"
    if not reason:
        spread = _hull_area(src[keep]) / ref.area
        if spread < p.min_spread:
            reason = f"inliers cover {spread:.3f} of the reference < {p.min_spread}"
    score = -np.inf
    if not reason:
        area = float(scene_size[0] * scene_size[1])
        score = significance(n_in, n_matches, p.ransac_threshold, area, n_tested, pose_prob)
    return Hypothesis(brand, r, n_matches, n_in, score, H, quad, pairs, reason, src[keep], m_ref[keep])


def _reprojection_inliers(H: np.ndarray, src: np.ndarray, dst: np.ndarray, threshold: float,
                          poses: tuple | None = None, p: LogoVerifyParams | None = None) -> np.ndarray:
    """(N,) bool: ``src`` mapped by ``H`` lands within ``threshold`` pixels of ``dst`` (in front of the camera), and
    agrees in orientation and scale when ``poses = (src_pose, dst_pose)`` is given."""
    q = np.c_[src, np.ones(len(src))] @ H.T
    ok = q[:, 2] > 1e-9
    err = np.full(len(src), np.inf)
    err[ok] = np.linalg.norm(q[ok, :2] / q[ok, 2:3] - dst[ok], axis=1)
    inl = err < threshold
    if poses is not None and inl.any():
        agree = np.zeros(len(src), bool)
        agree[inl] = pose_agrees(map_poses(H, src[inl], poses[0][inl]), poses[1][inl], p.angle_tolerance,
                                 p.scale_tolerance)
        inl &= agree
    return inl


def _fit_homography(src: np.ndarray, dst: np.ndarray, ref: Reference, scene_size: tuple[int, int],
                    p: LogoVerifyParams, rng: np.random.Generator,
                    poses: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    fit = find_homography(src, dst, threshold=p.ransac_threshold, confidence=0.999, max_iters=p.max_iters, rng=rng)
    inl = np.asarray(fit.inliers, bool)
    if poses is not None:
        inl = _reprojection_inliers(fit.H, src, dst, p.ransac_threshold, poses, p)
    return fit.H, inl


def _fit_affine_homography(src: np.ndarray, dst: np.ndarray, ref: Reference, scene_size: tuple[int, int],
                           p: LogoVerifyParams, rng: np.random.Generator,
                           poses: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    # the affine RANSAC picks the consistent matches; a homography refitted on them replaces the affine map when it
    # is plausible and explains about as many of all the matches (within 10 %: the affine inlier band of a
    # perspective view is not the homography's, and a few matches near the band edge may swap sides)
    sp, dp = poses if poses is not None else (None, None)
    A, inl = affine_ransac(src, dst, p.ransac_threshold, p.affine_samples, rng, sp, dp, p.angle_tolerance,
                           p.scale_tolerance)
    if inl.sum() < 5:
        return A, inl
    try:
        fit = find_homography(src[inl], dst[inl], threshold=p.ransac_threshold, confidence=0.999,
                              max_iters=p.max_iters, rng=rng)
    except EstimationError:
        return A, inl
    h_inl = _reprojection_inliers(fit.H, src, dst, p.ransac_threshold, poses, p)
    if h_inl.sum() >= max(0.9 * inl.sum(), 5) and not shape_problem(fit.H, ref.outline, scene_size, p):
        return fit.H, h_inl
    return A, inl


#: ``logo.verify.model`` -> fitter(src, dst, reference, scene_size, params, rng, poses) -> (H (3, 3), inliers (N,) bool)
MODELS = {"homography": _fit_homography, "affine_homography": _fit_affine_homography}


def verify(gallery: Gallery, matches: Matches, scene: Features | np.ndarray, scene_size: tuple[int, int],
           params: LogoVerifyParams | None = None, rng=None) -> list[Hypothesis]:
    """Fit and check one model per gallery frame (a reference, or a group of registered references, see
    :func:`register_references`) that has at least ``min_matches`` tentatively matched scene keypoints.

    The fitter is ``params.model`` for float descriptors (SIFT) and ``params.binary_model`` for the binary ones (see
    :data:`MODELS`): binary detectors put their keypoints in dense clusters on texture, where 3-point affine samples
    find chance fits more easily than 4-point homographies. An inlier must land within ``ransac_threshold`` of its
    predicted position and, when the scene's keypoint orientations and sizes are given, agree with the model's
    predicted orientation (``angle_tolerance``) and scale (``scale_tolerance``); the score then counts that
    agreement as evidence (:func:`significance`). When the best RANSAC fit fails the checks, its inliers are set
    aside and the remaining matches are fitted again (at most ``max_models`` fits per frame); the number of fits
    enters the score's multiple-test count.

    Parameters
    ----------
    gallery : Gallery
    matches : Matches
        From :func:`match_scene`.
    scene : Features or (N, 2) float
        Scene keypoints; with bare positions (pixels) inliers are judged by position only.
    scene_size : (width, height)
        Scene size in pixels.
    params : LogoVerifyParams, optional
    rng : None, int or Generator
        Seeds RANSAC.

    Returns
    -------
    list of Hypothesis
        One per tested frame, sorted by score (best first); ``Hypothesis.reference`` is the frame's anchor.
    """
    p = params or LogoVerifyParams()
    rng = np.random.default_rng(rng)
    use_pose = isinstance(scene, Features) and (p.angle_tolerance < 180.0 or p.scale_tolerance < 16.0)
    scene_xy = np.asarray(scene.xy if isinstance(scene, Features) else scene, np.float64)
    scene_pose = (np.c_[scene.angle, np.log(np.maximum(scene.size, 1e-6))].astype(np.float64) if use_pose
                  else None)
    pose_prob = pose_probability(p.angle_tolerance, p.scale_tolerance) if use_pose else 1.0
    frame = gallery.frame_of_ref[matches.ref]
    frames = np.unique(frame)
    # a scene keypoint matched to several references of one frame counts once
    counts = {int(f): len(np.unique(matches.scene_idx[frame == f])) for f in frames}
    tested = [f for f in frames if counts[int(f)] >= p.min_matches]
    fitter = MODELS[p.binary_model if gallery.binary else p.model]
    out = []
    for f in tested:
        r = int(gallery.anchors[f])
        ref = gallery.references[r]
        sel = frame == f
        g_idx, s_idx, m_ref = matches.gallery_idx[sel], matches.scene_idx[sel], matches.ref[sel]
        src, src_pose = np.empty((len(g_idx), 2)), np.empty((len(g_idx), 2))
        for k in np.unique(m_ref):  # every reference's keypoints in the anchor's pixels
            at, kf = m_ref == k, gallery.references[int(k)].features
            xy = kf.xy[g_idx[at]].astype(np.float64)
            src[at] = project(gallery.to_frame[k], xy)
            if use_pose:
                pose = np.c_[kf.angle[g_idx[at]], np.log(np.maximum(kf.size[g_idx[at]], 1e-6))].astype(np.float64)
                src_pose[at] = map_poses(gallery.to_frame[k], xy, pose)
        dst = scene_xy[s_idx]
        dst_pose = scene_pose[s_idx] if use_pose else None
        brand = ref.brand
        none = np.zeros((0, 2), np.int64)
        hyp, left = None, np.ones(len(src), bool)
        # sequential RANSAC: an implausible best fit (a chance fit, or a fold made by the twin matches of a
        # symmetric mark) gives its inliers up and the rest is fitted again, up to `max_models` times
        for attempt in range(1, p.max_models + 1):
            if left.sum() < p.min_matches:
                break
            try:
                H, fit_inl = fitter(src[left], dst[left], ref, scene_size, p, rng,
                                    (src_pose[left], dst_pose[left]) if use_pose else None)
            except EstimationError as exc:
                if hyp is None:
                    hyp = Hypothesis(brand, r, counts[int(f)], 0, -np.inf, None, None, none, f"no homography: {exc}",
                                     np.zeros((0, 2)))
                break
            inl = np.zeros(len(src), bool)
            inl[np.flatnonzero(left)[fit_inl]] = True
            cand = _check(brand, r, ref, H, inl, src, dst, g_idx, s_idx, m_ref, scene_size,
                          len(tested) * attempt, p, pose_prob)
            if hyp is None or (hyp.reason and not cand.reason):
                hyp = cand
            if not cand.reason:
                break
            left &= ~inl
        out.append(hyp)
    out.sort(key=lambda h: (h.score, h.inliers), reverse=True)
    return out


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
    """
    if len(scene_size) != 2 or min(scene_size) < 1:
        raise ValueError(f"`scene_size` must be (width, height) >= 1, got {scene_size}")
    m = match_scene(gallery, scene, match_params)
    return decide(verify(gallery, m, scene, scene_size, verify_params, rng), verify_params)


# ------------------------------------------------------------------------------------------------- evaluation


def evaluate(truth: Sequence[str | None], predicted: Sequence[str | None], scores: Sequence[float],
             threshold: float) -> dict:
    """Precision, recall and accuracy of brand decisions, and the precision-recall curve over the threshold.

    Parameters
    ----------
    truth : sequence of str or None
        True brand per scene (None = no gallery logo).
    predicted : sequence of str or None
        Brand of the best plausible hypothesis per scene, *before* thresholding (None when there is none).
    scores : sequence of float
        Its score (``-inf`` when there is none).
    threshold : float
        The decision threshold (``score_threshold``).

    Returns
    -------
    dict
        ``precision`` (correct brand / scenes answered with a brand; 1.0 when nothing is answered), ``recall``
        (correct brand / scenes with a logo), ``accuracy`` (correct brand or correct none / all scenes), the counts,
        and ``curve``: a list of ``{"threshold", "precision", "recall"}`` at every distinct score.
    """
    if not (len(truth) == len(predicted) == len(scores)):
        raise ValueError(f"`truth`, `predicted` and `scores` must have equal lengths, got "
                         f"{len(truth)}, {len(predicted)}, {len(scores)}")
    s = np.asarray(scores, np.float64)
    correct = np.array([p is not None and p == t for p, t in zip(predicted, truth)])
    has = np.array([p is not None for p in predicted])
    positives = int(sum(t is not None for t in truth))
    negatives_truth = np.array([t is None for t in truth])

    def at(th: float) -> dict:
        answered = has & (s >= th)
        tp = int(np.sum(answered & correct))
        n_ans = int(answered.sum())
        right_none = int(np.sum(~answered & negatives_truth))
        return {"threshold": float(th), "answered": n_ans, "correct": tp,
                "precision": tp / n_ans if n_ans else 1.0,
                "recall": tp / positives if positives else 0.0,
                "accuracy": (tp + right_none) / len(truth) if len(truth) else 0.0}

    finite = sorted({float(v) for v in s[np.isfinite(s)]}, reverse=True)
    curve = [{k: v for k, v in at(t).items() if k in ("threshold", "precision", "recall")} for t in finite]
    result = at(threshold)
    result.update({"scenes": len(truth), "positives": positives, "curve": curve})
    return result


def quad_error(quad: np.ndarray | None, truth: np.ndarray | Sequence | None, cyclic: bool = False) -> float | None:
    """Mean distance in pixels between corresponding corners of two (4, 2) quads (None when either is None).

    With ``cyclic`` the smallest error over the four starting corners of ``quad``: the outline of a mark with
    rotational symmetry (or of a gallery view stored rotated) may legitimately start at another corner.
    """
    if quad is None or truth is None:
        return None
    q, t = np.asarray(quad, np.float64), np.asarray(truth, np.float64)
    if q.shape != (4, 2) or t.shape != (4, 2):
        raise ValueError(f"quads must be (4, 2), got {q.shape} and {t.shape}")
    shifts = range(4) if cyclic else range(1)
    return float(min(np.linalg.norm(np.roll(q, i, axis=0) - t, axis=1).mean() for i in shifts))


# --------------------------------------------------------------------------------------------------- pictures


def confusion(truth: Sequence[str | None], predicted: Sequence[str | None],
              labels: Sequence[str]) -> np.ndarray:
    """(L+1, L+1) int counts, rows = truth, columns = decision, over ``labels`` plus a last "none" class."""
    index = {b: i for i, b in enumerate(labels)}
    none = len(labels)
    m = np.zeros((none + 1, none + 1), np.int64)
    for t, p in zip(truth, predicted):
        m[index.get(t, none) if t is not None else none, index.get(p, none) if p is not None else none] += 1
    return m


def draw_confusion(matrix: np.ndarray, labels: Sequence[str], title: str, cell: int = 34) -> np.ndarray:
    """A confusion matrix as a BGR picture: rows = truth, columns = decision, darker = more scenes."""
    names = list(labels) + ["none"]
    n = len(names)
    if matrix.shape != (n, n):
        raise ValueError(f"`matrix` must be ({n}, {n}) for {n - 1} labels plus none, got {matrix.shape}")
    left, top = 120, 130
    img = np.full((top + n * cell + 10, left + n * cell + 10, 3), 255, np.uint8)
    font = cv2.FONT_HERSHEY_SIMPLEX
    cv2.putText(img, title, (8, 20), font, 0.55, (0, 0, 0), 1, cv2.LINE_AA)
    row_sum = np.maximum(matrix.sum(axis=1, keepdims=True), 1)
    for i in range(n):
        cv2.putText(img, names[i][:14], (6, top + i * cell + cell // 2 + 5), font, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
        label = np.full((cell, top - 30, 3), 255, np.uint8)
        cv2.putText(label, names[i][:14], (2, cell // 2 + 5), font, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
        rot = cv2.rotate(label, cv2.ROTATE_90_COUNTERCLOCKWISE)
        img[30:30 + rot.shape[0], left + i * cell:left + i * cell + rot.shape[1]] = rot
        for j in range(n):
            v = int(matrix[i, j])
            shade = int(255 - 200 * v / row_sum[i, 0])
            color = (shade, 255, shade) if i == j else (shade, shade, 255)
            x0, y0 = left + j * cell, top + i * cell
            cv2.rectangle(img, (x0, y0), (x0 + cell - 1, y0 + cell - 1), color, -1)
            cv2.rectangle(img, (x0, y0), (x0 + cell - 1, y0 + cell - 1), (200, 200, 200), 1)
            if v:
                cv2.putText(img, str(v), (x0 + 6, y0 + cell // 2 + 5), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    return img


def draw_detection(scene: np.ndarray, reference: np.ndarray, quad: np.ndarray | None,
                   gallery_xy: np.ndarray, scene_xy: np.ndarray, truth_quad: np.ndarray | None = None,
                   caption: str = "", height: int = 360) -> np.ndarray:
    """Reference beside scene (both scaled to ``height`` px): inlier matches as lines, the found outline in green,
    the true outline (when given) in blue, ``caption`` on top. BGR uint8 in, BGR uint8 out."""
    scene, reference = _bgr(scene), _bgr(reference)
    sr, ss = height / reference.shape[0], height / scene.shape[0]
    ref_s = cv2.resize(reference, (max(1, int(round(reference.shape[1] * sr))), height))
    sc_s = cv2.resize(scene, (max(1, int(round(scene.shape[1] * ss))), height))
    canvas = np.full((height + 26, ref_s.shape[1] + sc_s.shape[1] + 6, 3), 255, np.uint8)
    canvas[26:, :ref_s.shape[1]] = ref_s
    off = ref_s.shape[1] + 6
    canvas[26:, off:] = sc_s
    for (gx, gy), (sx, sy) in zip(np.asarray(gallery_xy), np.asarray(scene_xy)):
        p1 = (int(round(gx * sr)), int(round(gy * sr)) + 26)
        p2 = (int(round(sx * ss)) + off, int(round(sy * ss)) + 26)
        cv2.line(canvas, p1, p2, (0, 200, 255), 1, cv2.LINE_AA)
        cv2.circle(canvas, p2, 2, (0, 200, 255), -1, cv2.LINE_AA)
    for q, color in ((truth_quad, (255, 80, 0)), (quad, (0, 200, 0))):
        if q is not None:
            pts = np.round(np.asarray(q, np.float64) * ss + [off, 26]).astype(np.int32)
            cv2.polylines(canvas, [pts], True, color, 2, cv2.LINE_AA)
    cv2.putText(canvas, caption, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    return canvas


def _bgr(img: np.ndarray) -> np.ndarray:
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    return img[..., :3]


# ------------------------------------------------------------------------------------ pipeline results (pure)

#: what an accuracy cell says when no scene of the run has ground truth
NO_TRUTH = "no ground truth"


def scene_record(scene: str, det: Detection, reference: str | None, truth: tuple[str | None, np.ndarray | None]
                 | None = None) -> dict:
    """The JSON record of one scene's decision as the ``logo_verify`` stage stores it.

    Parameters
    ----------
    scene : str
        The scene's name (file stem).
    det : Detection
        From :func:`decide`.
    reference : str or None
        Name of the reference image of ``det.best`` (None when no hypothesis was plausible).
    truth : (brand, quad) or None
        The scene's ground truth (brand None = no gallery logo, quad (4, 2) or None); None when it has none.

    Returns
    -------
    dict
        ``scene``, ``brand`` (after the threshold), ``score`` (of the best plausible hypothesis, None when there is
        none), ``inliers``, ``quad``, ``best_brand`` (before the threshold), ``reference``, ``labelled`` and, for a
        labelled scene, ``truth``, ``truth_quad`` and ``quad_error_px`` (when the brand is right).
    """
    best = det.best
    rec = {"scene": scene, "brand": det.brand, "inliers": int(det.inliers),
           "score": float(det.score) if np.isfinite(det.score) else None,
           "quad": None if det.quad is None else np.asarray(det.quad, np.float64).tolist(),
           "best_brand": best.brand if best is not None else None, "reference": reference,
           "labelled": truth is not None}
    if truth is not None:
        brand, quad = truth
        rec.update(truth=brand, truth_quad=None if quad is None else np.asarray(quad, np.float64).tolist(),
                   quad_error_px=(quad_error(det.quad, quad, cyclic=True)
                                  if det.brand is not None and det.brand == brand else None))
    return rec


def evaluate_records(records: Sequence[dict], threshold: float) -> dict | None:
    """:func:`evaluate` over the labelled scene records of :func:`scene_record`, plus ``quad_error_px_median``
    (over the scenes whose brand is right, when any); None when no record is labelled."""
    lab = [r for r in records if r["labelled"]]
    if not lab:
        return None
    ev = evaluate([r["truth"] for r in lab], [r["best_brand"] for r in lab],
                  [r["score"] if r["score"] is not None else -np.inf for r in lab], threshold)
    errs = [r["quad_error_px"] for r in lab if r.get("quad_error_px") is not None]
    if errs:
        ev["quad_error_px_median"] = float(np.median(errs))
    return ev


def metric_key(name: str) -> str:
    """``name`` usable as one DVC metric key (DVC joins nested keys with dots)."""
    return name.replace(".", "_")


def found_counts(records: Sequence[dict], brands: Sequence[str]) -> dict[str, int]:
    """Scenes answered with each brand (every brand listed, 0 when never found)."""
    return {b: sum(r["brand"] == b for r in records) for b in brands}


def metrics_of(records: Sequence[dict], brands: Sequence[str], detector: str, threshold: float) -> dict:
    """The numeric metrics of one detector's run, ``{"logo": {detector: {"all": {...}, "found": {brand: n}}}}``.

    ``all`` always has the counts ``scenes`` and ``answered`` (scenes given a brand) and ``labelled`` (scenes with
    ground truth); with ground truth also ``precision``, ``recall``, ``accuracy``, ``correct``, ``positives`` (over
    the labelled scenes) and ``quad_error_px_median`` when some brand was right. No strings, no NaN.
    """
    summary = {"scenes": len(records), "answered": sum(r["brand"] is not None for r in records),
               "labelled": sum(bool(r["labelled"]) for r in records)}
    ev = evaluate_records(records, threshold)
    if ev is not None:
        summary.update({k: ev[k] for k in ("precision", "recall", "accuracy", "correct", "positives",
                                           "quad_error_px_median") if k in ev})
    found = {metric_key(b): n for b, n in found_counts(records, brands).items()}
    return {"logo": {metric_key(detector): {"all": summary, "found": found}}}


def pr_rows(records: Sequence[dict], detector: str, threshold: float) -> list[dict]:
    """``dvc plots`` rows ``{"threshold", "precision", "recall", "method"}`` of the precision-recall curve over the
    labelled scenes; empty without ground truth (an empty plot file is valid for ``dvc plots``)."""
    ev = evaluate_records(records, threshold)
    return [] if ev is None else [dict(c, method=detector) for c in ev["curve"]]


def found_plot(decisions: dict[str, Sequence[dict]], brands: Sequence[str]) -> list[dict]:
    """``dvc plots`` rows ``{"label", "brand", "method", "found"}``: scenes answered with each brand per detector
    (the quality plot that needs no ground truth)."""
    return [{"label": f"{b} ({m})", "brand": b, "method": m, "found": n}
            for m, recs in decisions.items() for b, n in found_counts(recs, brands).items()]


def pick_method(decisions: dict[str, Sequence[dict]], threshold: float, default: str) -> str:
    """The detector whose results the overlays show: the most accurate one with ground truth (ties: more correct
    answers, then the earlier one), else ``default`` when it ran, else the first."""
    scored = {m: evaluate_records(r, threshold) for m, r in decisions.items()}
    if any(v is not None for v in scored.values()):
        return max((m for m in decisions if scored[m] is not None),
                   key=lambda m: (scored[m]["accuracy"], scored[m]["correct"], -list(decisions).index(m)))
    return default if default in decisions else next(iter(decisions))


def merge_dropped(dropped: dict[str, Sequence[dict]]) -> list[dict]:
    """Per-detector ``{"item", "reason"}`` lists merged into one, each item and reason once with the detectors that
    dropped it (``{"item", "reason", "methods"}``), in first-seen order."""
    merged: dict[tuple[str, str], list[str]] = {}
    for m, items in dropped.items():
        for d in items:
            merged.setdefault((d["item"], d["reason"]), [])
            if m not in merged[(d["item"], d["reason"])]:
                merged[(d["item"], d["reason"])].append(m)
    return [{"item": i, "reason": r, "methods": ms} for (i, r), ms in merged.items()]


def report_summary(decisions: dict[str, Sequence[dict]], brands: Sequence[str], references: int,
                   threshold: float, pictures: list[dict], dropped: list[dict]) -> dict:
    """The report page's summary of the logo task (schema in ``cvpipe.report``).

    Parameters
    ----------
    decisions : dict
        Detector -> its scene records (:func:`scene_record`), every detector over the same scenes.
    brands : sequence of str
        The gallery's brands.
    references : int
        Number of gallery images.
    threshold : float
        The decision threshold the records were made with (``logo.verify.score_threshold``).
    pictures : list of dict
        ``{"path", "caption"}``, repo-relative paths.
    dropped : list of dict
        From :func:`merge_dropped`: every input that was not processed, with the detectors and the reason.
    """
    methods = list(decisions)
    scenes = sorted({r["scene"] for recs in decisions.values() for r in recs})
    first = decisions[methods[0]] if methods else []
    labelled = sum(bool(r["labelled"]) for r in first)
    rows = []
    for m in methods:
        ev = evaluate_records(decisions[m], threshold)
        acc = [NO_TRUTH] * 4 if ev is None else [
            round(ev["accuracy"], 3), round(ev["precision"], 3), round(ev["recall"], 3),
            round(ev["quad_error_px_median"], 2) if "quad_error_px_median" in ev else None]
        rows.append([m, len(decisions[m]), sum(r["brand"] is not None for r in decisions[m]), *acc])
    by_scene = {m: {r["scene"]: r for r in recs} for m, recs in decisions.items()}
    scene_rows = []
    for s in scenes:
        truth = next((r for m in methods for r in [by_scene[m].get(s)] if r is not None), None)
        row = [s, (truth.get("truth") or "none") if truth is not None and truth["labelled"] else NO_TRUTH]
        for m in methods:
            r = by_scene[m].get(s)
            row += (["not processed", None, None] if r is None else
                    [r["brand"] or "none", None if r["score"] is None else round(r["score"], 2), r["inliers"]])
        scene_rows.append(row)
    counts = {m: found_counts(decisions[m], brands) for m in methods}
    tables = [
        {"title": "Per detector",
         "columns": ["detector", "scenes", "brand found", "accuracy", "precision", "recall",
                     "outline error median (px)"], "rows": rows},
        {"title": "Found per brand (scenes answered with it)", "columns": ["brand", *methods],
         "rows": [[b, *(counts[m][b] for m in methods)] for b in brands]},
        {"title": "Per scene: brand found, score (-log10 NFA) and inliers per detector",
         "columns": ["scene", "true brand", *(f"{m} {c}" for m in methods for c in ("brand", "score", "inliers"))],
         "rows": scene_rows},
    ]
    if dropped:
        tables.append({"title": "Not processed", "columns": ["input", "reason"],
                       "rows": [[d["item"], f"{', '.join(d['methods'])}: {d['reason']}"] for d in dropped]})
    if labelled == len(first) and first:
        truth_note = f"All {labelled} scenes have ground truth."
    elif labelled:
        truth_note = (f"{labelled} of {len(first)} scenes have ground truth; accuracy, precision and recall count "
                      f"those only.")
    else:
        truth_note = "The scenes have no ground truth: the tables show what each detector found."
    return {
        "task": "logo", "title": "Logo recognition: which brand is in the scene and where",
        "description": (
            f"Every scene's features are matched against the gallery ({len(brands)} brands, {references} reference "
            f"images) in one index; each reference's best homography is verified (RANSAC plus shape checks) and "
            f"scored by its a-contrario significance (-log10 NFA); below {threshold:g} the answer is none. "
            f"{truth_note} Overlays: found outline in green, {'true outline in blue, ' if labelled else ''}"
            "inlier matches in orange. "
            "Times: `dvc plots show` (outputs/timings)."),
        "pictures": pictures,
        "tables": tables,
    }
