"""The match graph: exact pairwise matching of the candidate pairs, a homography per pair, and the acceptance test.

:func:`match_graph` matches the candidate pairs (:func:`candidate_pairs`; float descriptors by exact brute force,
:func:`cvpipe.matching.ratio_matches`), fits a homography with :func:`cvpipe.homography.find_homography` and keeps an
edge when its confidence ``inliers / (8 + 0.3 * matches)`` (Brown & Lowe's probabilistic check, also OpenCV's) and
its inlier count pass, and the homography is plausible (orientation kept, bounded scale change).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Sequence

import cv2
import numpy as np
from threadpoolctl import ThreadpoolController

from ..errors import EstimationError
from ..features import Features
from ..homography import find_homography
from ..matching import nearest_two, ratio_matches
from ..params import PanoramaMatchParams, section_or_default
from . import _match
from .features import _workers
from .track import DEFAULT_PAIR_REFINE, PAIR_REFINE_CHOICES, corners, track_pair


@dataclass(frozen=True)
class Edge:
    """An accepted pair: ``H`` maps pixels of image ``i`` to image ``j``; ``src``/``dst`` are its inliers."""

    i: int
    j: int
    H: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    confidence: float


@dataclass(frozen=True)
class MatchGraph:
    """Every pair's matching statistics and the accepted edges.

    Attributes
    ----------
    sizes : list of (w, h)
        Image sizes the coordinates refer to.
    matches, inliers : (N, N) int
        Symmetric counts of ratio-test matches and of homography inliers per pair.
    confidence : (N, N) float
        ``inliers / (8 + 0.3 * matches)``; an edge needs at least ``min_confidence``.
    edges : dict (i, j) -> Edge
        Accepted pairs, ``i < j``.
    rejected : dict (i, j) -> str
        Why a pair with some matches was not accepted.
    """

    sizes: list
    matches: np.ndarray
    inliers: np.ndarray
    confidence: np.ndarray
    edges: dict = field(default_factory=dict)
    rejected: dict = field(default_factory=dict)

    #: the arrays of :meth:`to_arrays` every graph has (each edge adds ``edge_<i>_<j>_H``, ``_src``, ``_dst``), the
    #: keys a cached ``.npz`` must hold for :meth:`from_arrays`
    ARRAYS = ("sizes", "matches", "inliers", "confidence", "rejected")

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Named arrays for ``io.save_npz``."""
        out = {"sizes": np.array(self.sizes, np.int64), "matches": self.matches, "inliers": self.inliers,
               "confidence": self.confidence}
        for (i, j), e in self.edges.items():
            out[f"edge_{i}_{j}_H"] = e.H
            out[f"edge_{i}_{j}_src"] = e.src
            out[f"edge_{i}_{j}_dst"] = e.dst
        out["rejected"] = np.array([f"{i} {j} {why}" for (i, j), why in self.rejected.items()], dtype=str)
        return out

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> "MatchGraph":
        """Inverse of :meth:`to_arrays`."""
        conf = a["confidence"]
        edges = {}
        for key in a:
            if key.startswith("edge_") and key.endswith("_H"):
                i, j = (int(t) for t in key.split("_")[1:3])
                edges[(i, j)] = Edge(i, j, a[key], a[f"edge_{i}_{j}_src"], a[f"edge_{i}_{j}_dst"], float(conf[i, j]))
        rejected = {}
        for line in a["rejected"].tolist():
            i, j, why = line.split(" ", 2)
            rejected[(int(i), int(j))] = why
        return cls([tuple(int(v) for v in s) for s in a["sizes"]], a["matches"], a["inliers"], conf, edges,
                   rejected)


def _cross2(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _plausible(H: np.ndarray, size_i: tuple[int, int]) -> str | None:
    """Why ``H`` (image i -> j) cannot be a camera rotation or a view of a plane, or None when it can."""
    w, h = size_i
    corners = np.array([[0, 0, 1], [w, 0, 1], [w, h, 1], [0, h, 1]], float).T
    p = H @ corners
    if np.any(p[2] <= 1e-9 * np.abs(p).max()):
        return "homography sends a corner to infinity"
    q = (p[:2] / p[2]).T
    cross = [_cross2(q[(k + 1) % 4] - q[k], q[(k + 2) % 4] - q[(k + 1) % 4]) for k in range(4)]
    if not (all(c > 0 for c in cross) or all(c < 0 for c in cross)):
        return "homography folds the image (corners not convex)"
    if np.linalg.det(H[:2, :2]) <= 0:
        return "homography mirrors the image"
    area = 0.5 * abs(sum(_cross2(q[k], q[(k + 1) % 4]) for k in range(4)))
    ratio = area / float(w * h)
    if not 0.1 <= ratio <= 10:
        return f"homography changes the area by {ratio:.3g}x (outside 0.1..10)"
    return None


#: strongest features per image used to pick the candidate pairs
PREFILTER_FEATURES = 250
#: with ``pair_refine`` on, further RANSAC draws for a pair whose first model is implausible
RETRIES = 3


def hamming_ratio_matches(query: np.ndarray, train: np.ndarray, ratio: float) -> np.ndarray:
    """Lowe's ratio test on binary descriptors by exact brute force: (M, 2) int64 pairs ``[i_query, i_train]`` whose
    nearest Hamming distance is below ``ratio`` times the second nearest, best first (ties in query order).

    The two nearest of every query come as arrays: for 32-byte descriptors (ORB) from a compiled search that compares
    8 bytes per ``popcnt`` (1.6x faster than OpenCV's for 1500 x 1400 descriptors), otherwise from
    ``cv2.batchDistance`` (what ``cv2.BFMatcher.knnMatch`` computes, without a Python object per match); ties go to
    the earlier train row, as OpenCV's do.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> train = rng.integers(0, 256, (50, 32), dtype=np.uint8)
    >>> query = train[[3, 7]].copy()
    >>> query[0, 0] ^= 1  # one bit off
    >>> hamming_ratio_matches(query, train, 0.8).tolist()  # the exact copy first
    [[1, 7], [0, 3]]
    """
    query, train = np.asarray(query, np.uint8), np.asarray(train, np.uint8)
    if len(query) == 0 or len(train) == 0:
        return np.zeros((0, 2), np.int64)
    k = 2 if len(train) >= 2 else 1
    if k == 2 and query.shape[1] == train.shape[1] == 32:  # ORB's 32 bytes: the compiled search
        dist, idx = _match.hamming_two_nearest(np.ascontiguousarray(query), np.ascontiguousarray(train))
    else:
        dist, idx = cv2.batchDistance(query, train, cv2.CV_32S, normType=cv2.NORM_HAMMING, K=k)
    keep = np.ones(len(query), bool) if k == 1 else dist[:, 0] < ratio * dist[:, 1]
    rows = np.flatnonzero(keep)
    order = np.argsort(dist[rows, 0], kind="stable")
    return np.column_stack([rows[order], idx[rows[order], 0]]).astype(np.int64)


@lru_cache(maxsize=1)
def _blas() -> ThreadpoolController:
    return ThreadpoolController()


def one_blas_thread():
    """A context in which numpy's BLAS runs every call on the calling thread alone (``threadpoolctl``; the previous
    thread count is restored on leaving; it is process-wide, like ``cv2.setNumThreads``).

    The pairwise products run one pair per thread of a pool: with BLAS's own threads the calls from the pool's
    threads wait for each other (OpenBLAS runs one threaded call at a time), so two threads took as long as one
    (budapest, 15 pairs of 1500 SIFT descriptors: 125 ms, one at a time 130 ms; with one BLAS thread each, 72 ms).
    SIFT's descriptors hold integers whose products and sums are exact in float32 (128 * 255^2 < 2^24), so the
    distances, and so the matches, are the same bit for bit however BLAS orders the sums.
    """
    return _blas().limit(limits=1, user_api="blas")


def candidate_pairs(feats: Sequence[Features], ratio: float, candidates: int) -> tuple[list, dict]:
    """Pairs worth matching in full: every pair when ``candidates >= n - 1`` (or 0), else for every image the
    ``candidates`` images that share the most ratio-test matches among the strongest ``PREFILTER_FEATURES``
    features (Brown & Lowe consider the 6 best images per image). Returns the pairs ``(i, j), i < j`` and the
    prefilter match count of the pairs left out."""
    n = len(feats)
    everything = [(i, j) for i in range(n) for j in range(i + 1, n)]
    if candidates <= 0 or candidates >= n - 1:
        return everything, {}
    C = prefilter_counts([f.descriptors[:PREFILTER_FEATURES] for f in feats], ratio)  # sorted by response
    keep = set()
    for i in range(n):
        order = [j for j in np.argsort(-C[i], kind="stable") if j != i][:candidates]
        keep.update((min(i, int(j)), max(i, int(j))) for j in order)
    return sorted(keep), {ij: int(C[ij]) for ij in everything if ij not in keep}


def prefilter_counts(descriptors: Sequence[np.ndarray], ratio: float) -> np.ndarray:
    """Ratio-test match counts between every pair of small descriptor sets, by exact brute force.

    Parameters
    ----------
    descriptors : sequence of (n_i, D)
        One (small) descriptor set per image; float descriptors use the L2 distance, uint8 ones are packed bits
        (Hamming distance).
    ratio : float
        Lowe's ratio test (nearest < ``ratio`` * second nearest).

    Returns
    -------
    (N, N) int64
        Symmetric; entry (i, j), i < j, counts the descriptors of image i whose nearest neighbour in image j
        passes the ratio test.
    """
    n = len(descriptors)
    C = np.zeros((n, n), np.int64)
    binary = any(np.asarray(d).dtype == np.uint8 for d in descriptors)
    # the squared L2 distance of bit-unpacked 0/1 vectors is their Hamming distance, which the ratio test compares
    # directly; squared L2 distances of float descriptors compare with ratio^2
    desc = [np.unpackbits(np.asarray(d, np.uint8), axis=1) if binary else d for d in descriptors]
    r = ratio if binary else ratio * ratio
    for i in range(n):
        for j in range(i + 1, n):
            if len(desc[i]) and len(desc[j]) >= 2:
                _, d1, d2 = nearest_two(desc[i], desc[j])
                C[i, j] = C[j, i] = int(np.sum(d1 < r * d2))
    return C


def refit(src: np.ndarray, dst: np.ndarray, H: np.ndarray, inliers: np.ndarray, threshold: float,
          min_inliers: int, size_i: tuple[int, int], rng=None) -> tuple[np.ndarray, np.ndarray]:
    """Fit a pair's homography again to its inliers with a tighter ``threshold`` (RANSAC + LM on that subset).

    The first fit's threshold (3 px) lets matches with errors of up to 3 px pull on the least-squares estimate;
    refitting on the inliers within ``threshold`` of a consensus model of those inliers estimates the pair from
    its most precise matches. On the Adobe sets this lowered the geometric mean of the pairwise corner errors
    against the ground truth by about 4-8 % (see docs/notes/panorama.md).

    Parameters
    ----------
    src, dst : (N, 2) float
        All the pair's matches (pixels of image i and j).
    H : (3, 3)
        The first fit (i -> j).
    inliers : (N,) bool
        Its inliers.
    threshold : float
        Inlier threshold of the refit, pixels.
    min_inliers : int
        Fewest inliers the refit must keep; otherwise the first fit is returned.
    size_i : (w, h)
        Size of image i (the refit must stay plausible, :func:`_plausible`).
    rng : seed or Generator

    Returns
    -------
    H : (3, 3)
        The refitted homography, or ``H`` when the refit fails or keeps too few inliers.
    inliers : (N,) bool
        Its inliers among all N matches.
    """
    idx = np.flatnonzero(inliers)
    try:
        fit = find_homography(src[idx], dst[idx], threshold=threshold, rng=rng)
    except EstimationError:
        return H, inliers
    if int(fit.inliers.sum()) < min_inliers or _plausible(fit.H, size_i):
        return H, inliers
    keep = np.zeros(len(src), bool)
    keep[idx[fit.inliers]] = True
    return fit.H, keep


def match_graph(feats: Sequence[Features], sizes: Sequence[tuple[int, int]], *, ratio: float,
                ransac_threshold: float, min_inliers: int, min_confidence: float, candidates: int = 0,
                refit_threshold: float = 0.0, pair_refine: str = DEFAULT_PAIR_REFINE,
                images: Sequence[np.ndarray] | None = None, rng=None) -> MatchGraph:
    """Match every pair of images and keep the pairs that share a plausible homography.

    Parameters
    ----------
    feats : sequence of Features
        One per image (at the registration resolution).
    sizes : sequence of (w, h)
        Image sizes in pixels.
    ratio : float
        Lowe's ratio test.
    ransac_threshold : float
        Inlier reprojection threshold in pixels.
    min_inliers : int
        Fewest homography inliers for an edge.
    min_confidence : float
        Fewest ``inliers / (8 + 0.3 * matches)`` for an edge (1.0 in ``cv2.Stitcher``).
    candidates : int
        Match in full only each image's best candidates (:func:`candidate_pairs`); 0 matches every pair.
    refit_threshold : float
        When in (0, ``ransac_threshold``), an accepted pair's homography is fitted again to its inliers with this
        tighter threshold (:func:`refit`); acceptance is still decided by the first fit. 0: no refit.
    pair_refine : str
        One of :data:`~cvpipe.panorama.track.PAIR_REFINE_CHOICES`: ``"lk"`` fits an accepted pair's homography
        again to Lucas-Kanade tracks of image i's corners in the overlap (:func:`~cvpipe.panorama.track.track_pair`,
        instead of the refit; the refit when too few points track), and a pair whose matches fall short of
        ``min_confidence`` only is accepted when its tracks pass the same test (``inliers / (8 + 0.3 * tracked)``);
        it needs ``images``.
    images : sequence of (H, W) uint8, optional
        The grayscale images at the registration resolution (for ``pair_refine``).
    rng : seed or Generator
        For RANSAC.

    Returns
    -------
    MatchGraph
    """
    if pair_refine not in PAIR_REFINE_CHOICES:
        raise ValueError(f"`pair_refine` must be one of {list(PAIR_REFINE_CHOICES)}, got {pair_refine!r}")
    if pair_refine != "none" and (images is None or len(images) != len(feats)):
        raise ValueError(f"`pair_refine` {pair_refine!r} needs the images at the registration resolution, one per "
                         "features")
    rng = np.random.default_rng(rng)
    n = len(feats)
    M = np.zeros((n, n), np.int64)
    I = np.zeros((n, n), np.int64)
    C = np.zeros((n, n), np.float64)
    points: dict[int, np.ndarray] = {}  # each image's corners, found when a pair first tracks them
    todo, skipped = candidate_pairs(feats, ratio, candidates)
    rejected = {ij: f"not a candidate pair ({c} prefilter matches)" for ij, c in skipped.items()}
    edges = {}

    def verify(i: int, j: int, pairs: np.ndarray) -> None:
        rejected.pop((i, j), None)
        M[i, j] = M[j, i] = len(pairs)
        if len(pairs) < max(4, min_inliers):
            if len(pairs):
                rejected[(i, j)] = f"only {len(pairs)} matches"
            return
        src = feats[i].xy[pairs[:, 0]].astype(np.float64)
        dst = feats[j].xy[pairs[:, 1]].astype(np.float64)
        try:
            fit = find_homography(src, dst, threshold=ransac_threshold, rng=rng)
        except EstimationError as exc:
            rejected[(i, j)] = f"no homography ({exc})"
            return
        for _ in range(RETRIES if pair_refine == "lk" else 0):
            # RANSAC can stop early on a degenerate consensus (a mirrored model of many weak binary matches: seen
            # on samples/motorcycle, 28 inliers where the true model has 35, 2 of 5 seeds): draw again before judging
            if not _plausible(fit.H, sizes[i]):
                break
            try:
                again = find_homography(src, dst, threshold=ransac_threshold, rng=rng)
            except EstimationError:
                break
            if not _plausible(again.H, sizes[i]):
                fit = again
        k = int(fit.inliers.sum())
        conf = k / (8.0 + 0.3 * len(pairs))
        I[i, j] = I[j, i] = k
        C[i, j] = C[j, i] = conf
        implausible = _plausible(fit.H, sizes[i])
        why = implausible
        if k < min_inliers:
            why = f"{k} inliers < min_inliers {min_inliers}"
        elif conf < min_confidence:
            why = f"confidence {conf:.2f} < min_confidence {min_confidence}"
        H, keep = fit.H, fit.inliers
        if pair_refine == "lk" and implausible is None and k >= min_inliers:
            if i not in points:
                points[i] = corners(images[i])
            tracked = track_pair(images[i], images[j], H, points[i], min_inliers, rng=rng)
            if tracked is not None and not _plausible(tracked[0], sizes[i]):
                H, a, b, tried = tracked
                # the same test on the tracks: a pair the matches left just short of min_confidence (few binary
                # features in a small overlap) is accepted when its tracks pass it
                conf_t = len(a) / (8.0 + 0.3 * tried)
                if conf >= min_confidence or conf_t >= min_confidence:
                    if conf < min_confidence:
                        C[i, j] = C[j, i] = conf_t
                    edges[(i, j)] = Edge(i, j, H / H[2, 2], a, b, float(C[i, j]))
                    return
        if why:
            rejected[(i, j)] = why
            return
        if 0 < refit_threshold < ransac_threshold:
            H, keep = refit(src, dst, fit.H, fit.inliers, refit_threshold, min_inliers, sizes[i], rng)
        edges[(i, j)] = Edge(i, j, H / H[2, 2], src[keep], dst[keep], conf)

    # exact brute force: float descriptors by a matrix product (faster than FLANN at these sizes), binary ones by
    # Hamming distances (hamming_ratio_matches)
    binary = any(f.binary for f in feats)

    def full_match(ij):
        i, j = ij
        if not binary:
            return ratio_matches(feats[i].descriptors, feats[j].descriptors, ratio)
        return hamming_ratio_matches(feats[i].descriptors, feats[j].descriptors, ratio)

    # OpenCV and numpy's product release the GIL; one BLAS thread per product (one_blas_thread)
    with one_blas_thread(), ThreadPoolExecutor(_workers()) as pool:
        for (i, j), pairs in zip(todo, pool.map(full_match, todo)):
            verify(i, j, pairs)
    # the prefilter may miss the only link between two groups: try the skipped pairs that would join two
    # components, most promising first, until the graph is connected or none is left
    for ij in sorted(skipped, key=lambda ij: -skipped[ij]):
        comps = _components(n, edges)
        if len(comps) == 1:
            break
        where = {a: k for k, c in enumerate(comps) for a in c}
        if where[ij[0]] != where[ij[1]]:
            verify(*ij, full_match(ij))
    return MatchGraph([tuple(map(int, s)) for s in sizes], M, I, C, edges, rejected)


def _components(n: int, edges) -> list[list[int]]:
    parent = list(range(n))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for i, j in edges:
        parent[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for a in range(n):
        groups.setdefault(find(a), []).append(a)
    return list(groups.values())


def match_graph_with(feats: Sequence[Features], sizes: Sequence[tuple[int, int]],
                     params: PanoramaMatchParams | None, rng, images: Sequence[np.ndarray] | None = None
                     ) -> MatchGraph:
    """:func:`match_graph` with the ``panorama.match`` section (``ratio``, ``ransac_threshold``, ``min_inliers``,
    ``min_confidence``, ``candidates``, ``refit_threshold``): the step of :func:`cvpipe.panorama.stitch` and of the
    ``panorama_match`` stage.

    Parameters
    ----------
    feats : sequence of Features
        Each image's features at the registration resolution.
    sizes : sequence of (w, h)
        The images' sizes at that resolution.
    params : PanoramaMatchParams or None
        The ``panorama.match`` section (None: its defaults).
    rng : seed or Generator
        For RANSAC (the stage passes the section's ``seed``; ``stitch`` its own generator).
    images : sequence of (H, W) uint8, optional
        The grayscale images at the registration resolution, which ``pair_refine: lk`` tracks in.

    Returns
    -------
    MatchGraph

    Examples
    --------
    >>> from cvpipe.panorama import features_of
    >>> from cvpipe.params import PanoramaMatchParams
    >>> from cvpipe.samples import photo
    >>> img = photo("astronaut")
    >>> sizes, feats = features_of([img[:, 200:], img[:, :320]])
    >>> graph = match_graph_with(feats, sizes, PanoramaMatchParams(), 0)
    >>> list(graph.edges)  # the two crops overlap by 120 columns
    [(0, 1)]
    """
    p = section_or_default(params, PanoramaMatchParams, "panorama.match")
    return match_graph(feats, sizes, ratio=p.ratio, ransac_threshold=p.ransac_threshold, min_inliers=p.min_inliers,
                       min_confidence=p.min_confidence, candidates=p.candidates, refit_threshold=p.refit_threshold,
                       pair_refine=p.pair_refine, images=images, rng=rng)


def match_set(item: tuple, p) -> tuple[MatchGraph, float]:
    """The match graph of one set: the per-set work of the ``panorama_match`` stage, an item of
    :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    item : tuple
        ``(features, work sizes, grays)``: each image's :class:`~cvpipe.features.Features`, its ``(w, h)`` and its
        grey image at that size (None unless ``p.pair_refine`` tracks in them).
    p : PanoramaMatchParams
        The ``panorama.match`` section (:func:`match_graph_with`; its ``seed`` seeds RANSAC).

    Returns
    -------
    (MatchGraph, float)
        The graph (:func:`match_graph`) and the seconds it took.
    """
    import time

    feats, sizes, grays = item
    t0 = time.perf_counter()
    graph = match_graph_with(feats, sizes, p, p.seed, grays)
    return graph, time.perf_counter() - t0
