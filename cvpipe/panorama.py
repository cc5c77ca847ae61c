"""Panorama registration: pairwise matching -> match-confidence graph -> global homographies.

The stages, in the order :func:`stitch` runs them (each is a pure function so the DVC stages can cache them):

1. :func:`working_images` shrinks the inputs to the registration resolution (like ``cv2.Stitcher``'s
   ``registrationResol``) and :func:`detect_all` finds features there.
2. :func:`match_graph` matches the candidate pairs (:func:`candidate_pairs`; float descriptors by exact brute force,
   :func:`ratio_matches`), fits a homography with :func:`cvpipe.homography.find_homography` and keeps
   an edge when its confidence ``inliers / (8 + 0.3 * matches)`` (Brown & Lowe's probabilistic check, also
   OpenCV's) and its inlier count pass, and the homography is plausible (orientation kept, bounded scale change).
3. :func:`register` keeps the largest connected component (the other images are dropped with a reason), picks the
   reference image at the centre of the maximum spanning tree of the confidence graph, chains homographies along
   that tree, and refines all of them jointly by least squares over the inliers of every accepted pair
   (Levenberg-Marquardt, :func:`levenberg_marquardt`). :func:`estimate_focal` gives the focal length that the
   cylindrical and spherical projections need.
4. :mod:`cvpipe.warping` and :mod:`cvpipe.blending` compose the result.

Homographies map homogeneous pixel column vectors (x = column, y = row). A global homography ``G[i]`` maps pixels
of image ``i`` to pixels of the reference image; all of them are normalised to ``det(G) = 1``, which fixes their
sign so that points in front of the camera keep a positive third coordinate.
"""

from __future__ import annotations

import heapq
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.spatial.transform import Rotation

from . import blending, warping
from .errors import EstimationError, InputError
from .features import Features, detect
from .homography import _cholesky_solve as spd_solve_kernel
from .homography import find_homography
from .matching import MatchIndex, match
from .params import (PanoramaBlendParams, PanoramaFeaturesParams, PanoramaHomographiesParams, PanoramaMatchParams,
                     PanoramaWarpParams)


# ------------------------------------------------------------------------------------------------ resolution


def scale_for(size: tuple[int, int], megapix: float) -> float:
    """The factor (<= 1) that brings an image of ``size = (w, h)`` to at most ``megapix`` million pixels.

    ``megapix <= 0`` means full resolution (factor 1), as in ``cv2.Stitcher``.
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
    """:func:`cvpipe.features.detect` on every image (in threads: OpenCV releases the GIL)."""
    with ThreadPoolExecutor(_workers()) as pool:
        return list(pool.map(lambda g: detect(g, detector, max_features), grays))


# ------------------------------------------------------------------------------------------------ match graph


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


#: most entries of one block of the query x train distance matrix in :func:`nearest_two` (16 M float32 = 64 MB)
DISTANCE_BLOCK = 1 << 24


def nearest_two(query: np.ndarray, train: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact nearest and second-nearest neighbours in ``train`` of every row of ``query`` (brute force).

    The squared distances come from one matrix product, ``|q|^2 + |t|^2 - 2 q t^T`` (``cv2.gemm``), which on
    1500 x 1500 SIFT descriptors is about twice as fast as FLANN's approximate search and exact.

    Parameters
    ----------
    query : (Nq, D) float32
    train : (Nt, D) float32, Nt >= 2

    Returns
    -------
    nearest : (Nq,) int64
        Index into ``train`` of each query's nearest neighbour.
    d1, d2 : (Nq,) float32
        Squared L2 distances to the nearest and the second nearest.
    """
    q = np.ascontiguousarray(query, np.float32)
    t = np.ascontiguousarray(train, np.float32)
    tt = np.einsum("ij,ij->i", t, t)[None, :]
    nearest = np.empty(len(q), np.int64)
    d1 = np.empty(len(q), np.float32)
    d2 = np.empty(len(q), np.float32)
    step = max(1, DISTANCE_BLOCK // max(len(t), 1))
    for lo in range(0, len(q), step):
        d = cv2.gemm(q[lo:lo + step], t, -2.0, None, 0.0, flags=cv2.GEMM_2_T)
        d += tt
        best = np.argmin(d, axis=1)
        rows = np.arange(len(d))
        nearest[lo:lo + step] = best
        d1[lo:lo + step] = d[rows, best]
        d[rows, best] = np.inf
        d2[lo:lo + step] = d.min(axis=1)
    qq = np.einsum("ij,ij->i", q, q)
    return nearest, np.maximum(d1 + qq, 0), np.maximum(d2 + qq, 0)


def ratio_matches(query: np.ndarray, train: np.ndarray, ratio: float) -> np.ndarray:
    """Exact ratio-test matches of float descriptors (:func:`nearest_two`), as :meth:`MatchIndex.query` returns
    them: (M, 2) int64 pairs ``[i_query, i_train]`` sorted by distance, best first."""
    if len(query) == 0 or len(train) < 2:  # no second neighbour: the generic matcher's conventions
        return match(query, train, ratio=ratio, binary=False)
    nearest, d1, d2 = nearest_two(query, train)
    keep = np.nonzero(d1 < ratio * ratio * d2)[0]
    keep = keep[np.argsort(d1[keep], kind="stable")]
    return np.column_stack([keep, nearest[keep]]).astype(np.int64)


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
    against the ground truth by about 4-8 % (see BENCHMARKS.md).

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
                refit_threshold: float = 0.0, rng=None) -> MatchGraph:
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
    rng : seed or Generator
        For RANSAC.

    Returns
    -------
    MatchGraph
    """
    rng = np.random.default_rng(rng)
    n = len(feats)
    M = np.zeros((n, n), np.int64)
    I = np.zeros((n, n), np.int64)
    C = np.zeros((n, n), np.float64)
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
        k = int(fit.inliers.sum())
        conf = k / (8.0 + 0.3 * len(pairs))
        I[i, j] = I[j, i] = k
        C[i, j] = C[j, i] = conf
        why = _plausible(fit.H, sizes[i])
        if k < min_inliers:
            why = f"{k} inliers < min_inliers {min_inliers}"
        elif conf < min_confidence:
            why = f"confidence {conf:.2f} < min_confidence {min_confidence}"
        if why:
            rejected[(i, j)] = why
            return
        H, keep = fit.H, fit.inliers
        if 0 < refit_threshold < ransac_threshold:
            H, keep = refit(src, dst, fit.H, fit.inliers, refit_threshold, min_inliers, sizes[i], rng)
        edges[(i, j)] = Edge(i, j, H / H[2, 2], src[keep], dst[keep], conf)

    # binary descriptors: one Hamming index per image, built once and queried by each of its partners; float
    # descriptors: exact brute force by a matrix product (faster than FLANN at these sizes)
    index: dict[int, MatchIndex] = {}
    binary = any(f.binary for f in feats)

    def full_match(ij):
        i, j = ij
        if not binary:
            return ratio_matches(feats[i].descriptors, feats[j].descriptors, ratio)
        if j not in index:
            index[j] = MatchIndex(feats[j].descriptors)
        return index[j].query(feats[i].descriptors, ratio=ratio)

    with ThreadPoolExecutor(_workers()) as pool:  # OpenCV's matchers and gemm release the GIL
        if binary:
            trains = sorted({j for _, j in todo})
            index.update(zip(trains, pool.map(lambda j: MatchIndex(feats[j].descriptors), trains)))
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


# ------------------------------------------------------------------------------------------------ registration


@dataclass(frozen=True)
class Registration:
    """Global alignment of the images that form one panorama.

    Attributes
    ----------
    used : tuple of int
        Input positions of the images in the panorama, ascending.
    dropped : tuple of (int, str)
        Input position and reason of every image left out.
    reference : int
        Input position of the reference image (its ``G`` is the identity).
    G : dict int -> (3, 3)
        Per used image, its pixels -> reference pixels, ``det = 1``.
    tree : tuple of (int, int)
        Edges of the maximum spanning tree the homographies were chained along.
    focal : float
        Focal length in reference pixels estimated from the homographies (for cylindrical/spherical).
    rms_chained, rms_refined : float
        RMS transfer error over all inliers of all accepted pairs (pixels), before and after joint refinement.
    model : str
        ``"rotation"``, ``"homography"`` or ``"chained"`` (no refinement): the model of the final ``G``.
    """

    used: tuple
    dropped: tuple
    reference: int
    G: dict
    tree: tuple
    focal: float
    rms_chained: float
    rms_refined: float
    model: str = "homography"

    def to_json(self) -> dict:
        return {"used": list(self.used), "dropped": [{"image": i, "reason": r} for i, r in self.dropped],
                "reference": self.reference, "G": {str(k): v for k, v in self.G.items()},
                "tree": [list(e) for e in self.tree], "focal": self.focal, "rms_chained": self.rms_chained,
                "rms_refined": self.rms_refined, "model": self.model}

    @classmethod
    def from_json(cls, d: dict) -> "Registration":
        return cls(tuple(d["used"]), tuple((x["image"], x["reason"]) for x in d["dropped"]), int(d["reference"]),
                   {int(k): np.asarray(v, float) for k, v in d["G"].items()}, tuple(tuple(e) for e in d["tree"]),
                   float(d["focal"]), float(d["rms_chained"]), float(d["rms_refined"]), str(d["model"]))


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


def maximum_spanning_tree(nodes: Sequence[int], weights: dict) -> list[tuple[int, int]]:
    """Prim's algorithm on ``weights[(i, j)]`` (i < j), maximising the total weight; nodes must be connected."""
    nodes = list(nodes)
    adj: dict[int, list[tuple[float, int]]] = {a: [] for a in nodes}
    for (i, j), w in weights.items():
        if i in adj and j in adj:
            adj[i].append((w, j))
            adj[j].append((w, i))
    seen = {nodes[0]}
    heap = [(-w, nodes[0], b) for w, b in adj[nodes[0]]]
    heapq.heapify(heap)
    tree = []
    while heap and len(seen) < len(nodes):
        negw, a, b = heapq.heappop(heap)
        if b in seen:
            continue
        seen.add(b)
        tree.append((a, b))
        for w, c in adj[b]:
            if c not in seen:
                heapq.heappush(heap, (-w, b, c))
    return tree


def _tree_centre(nodes: Sequence[int], tree: Sequence[tuple[int, int]], strength: dict[int, float]) -> int:
    """The node with the smallest eccentricity (fewest homographies chained to reach any other), ties broken by
    the largest total confidence."""
    adj: dict[int, list[int]] = {a: [] for a in nodes}
    for a, b in tree:
        adj[a].append(b)
        adj[b].append(a)

    def ecc(s):
        dist = {s: 0}
        todo = [s]
        while todo:
            a = todo.pop()
            for b in adj[a]:
                if b not in dist:
                    dist[b] = dist[a] + 1
                    todo.append(b)
        return max(dist.values())

    return min(nodes, key=lambda a: (ecc(a), -strength[a], a))


def _transfer_rms(G: dict, edges: dict) -> float:
    err, cnt = 0.0, 0
    for (i, j), e in edges.items():
        if i in G and j in G:
            Hij = np.linalg.inv(G[j]) @ G[i]
            p = warping.apply_h(Hij, e.src)
            err += float(np.sum((p - e.dst) ** 2))
            cnt += len(e.src)
    return float(np.sqrt(err / max(cnt, 1)))


def _blocks(G: dict, edges: dict, max_points_per_pair: int, rng) -> list:
    """(i, j, src, dst) per accepted pair inside ``G``, at most ``max_points_per_pair`` random inliers each."""
    blocks = []
    for (i, j), e in edges.items():
        if i not in G or j not in G:
            continue
        k = len(e.src)
        sel = np.sort(rng.choice(k, max_points_per_pair, replace=False)) if k > max_points_per_pair else np.arange(k)
        blocks.append((i, j, e.src[sel], e.dst[sel]))
    return blocks


def _solve(blocks: list, homs, x0: np.ndarray, columns, T: dict | None = None,
           Tr_inv: np.ndarray | None = None) -> np.ndarray:
    """Least squares over the symmetric transfer error of all ``blocks``; ``homs(x)`` gives the homographies,
    ``columns(a)`` the parameter columns image ``a`` depends on (for the sparse Jacobian).

    With ``T`` and ``Tr_inv`` the parameters are the 8 free entries of ``Hn_a`` in ``H_a = Tr_inv Hn_a T_a`` and the
    Jacobian is analytic; otherwise it is estimated by grouped finite differences."""
    keys = sorted({a for blk in blocks for a in blk[:2]})
    pos = {a: k for k, a in enumerate(keys)}
    e_i = np.array([pos[blk[0]] for blk in blocks])
    e_j = np.array([pos[blk[1]] for blk in blocks])
    edge = np.concatenate([np.full(len(blk[2]), k) for k, blk in enumerate(blocks)])
    src = np.concatenate([blk[2] for blk in blocks]).astype(np.float64)
    dst = np.concatenate([blk[3] for blk in blocks]).astype(np.float64)
    src_h = np.column_stack([src, np.ones(len(src))])
    dst_h = np.column_stack([dst, np.ones(len(dst))])
    n = len(src)

    def residuals(x):
        H = homs(x)
        Hs = np.stack([H[a] for a in keys])
        Hinv = np.linalg.inv(Hs)
        fwd = np.einsum("nij,nj->ni", (Hinv[e_j] @ Hs[e_i])[edge], src_h)
        bwd = np.einsum("nij,nj->ni", (Hinv[e_i] @ Hs[e_j])[edge], dst_h)
        return np.concatenate([(fwd[:, :2] / fwd[:, 2:] - dst).ravel(), (bwd[:, :2] / bwd[:, 2:] - src).ravel()])

    if T is None:
        # residual rows of edge k: forward 2p, 2p+1 and backward 2n + 2p, 2n + 2p + 1
        rows, cols = [], []
        for k, blk in enumerate(blocks):
            pts = np.nonzero(edge == k)[0]
            r = np.concatenate([2 * pts, 2 * pts + 1, 2 * n + 2 * pts, 2 * n + 2 * pts + 1])
            for a in blk[:2]:
                c = columns(a)
                if len(c):
                    rows.append(np.repeat(r, len(c)))
                    cols.append(np.tile(np.asarray(c), len(r)))
        sparsity = coo_matrix((np.ones(sum(len(r) for r in rows), np.int8),
                               (np.concatenate(rows), np.concatenate(cols))), shape=(4 * n, len(x0))).tocsr()
        sparsity.data[:] = 1
        sp = sparsity.tocsc()

        def jac(x):  # forward differences, one column at a time (used for the few rotation parameters)
            r0 = residuals(x)
            cols = []
            for k in range(len(x)):
                h = 1e-7 * max(1.0, abs(x[k]))
                xk = x.copy()
                xk[k] += h
                rows = sp.indices[sp.indptr[k]:sp.indptr[k + 1]]
                cols.append((rows, np.full(len(rows), k), (residuals(xk)[rows] - r0[rows]) / h))
            r, c, v = (np.concatenate([t[m] for t in cols]) for m in range(3))
            return coo_matrix((v, (r, c)), shape=(4 * n, len(x))).tocsr()
    else:
        col0 = {a: (columns(a)[0] if len(columns(a)) else -1) for a in keys}
        bounds = np.searchsorted(edge, np.arange(len(blocks) + 1))  # points are stored edge by edge
        C_ref = Tr_inv

        def derivatives(Ha, Hb_inv, Ta, Tb, pts_h):
            # residual proj(H_b^-1 H_a p) - q of one edge: (2m, 8) derivatives w.r.t. Hn_a (source), Hn_b (target)
            u = pts_h @ (Hb_inv @ Ha).T
            iw = 1.0 / u[:, 2:]
            C = Hb_inv @ C_ref
            B = np.stack([(C[0] - u[:, :1] * iw * C[2]) * iw, (C[1] - u[:, 1:2] * iw * C[2]) * iw], axis=1)
            q, w = pts_h @ Ta.T, u @ Tb.T
            Ja = (B[:, :, :, None] * q[:, None, None, :]).reshape(-1, 9)[:, :8]
            Jb = -(B[:, :, :, None] * w[:, None, None, :]).reshape(-1, 9)[:, :8]
            return Ja, Jb

        def normal(x, r):
            # J^T J and J^T r accumulated edge by edge in dense (8, 8) blocks: a residual touches two images only
            H = homs(x)
            Hinv = {a: np.linalg.inv(H[a]) for a in keys}
            A = np.zeros((len(x0), len(x0)))
            g = np.zeros(len(x0))
            fwd, bwd = r[:2 * n], r[2 * n:]
            for k, blk in enumerate(blocks):
                lo, hi = bounds[k], bounds[k + 1]
                for a, b, pts_h, res in ((blk[0], blk[1], src_h[lo:hi], fwd[2 * lo:2 * hi]),
                                         (blk[1], blk[0], dst_h[lo:hi], bwd[2 * lo:2 * hi])):
                    Ja, Jb = derivatives(H[a], Hinv[b], T[a], T[b], pts_h)
                    ca, cb = col0[a], col0[b]
                    if ca >= 0:
                        A[ca:ca + 8, ca:ca + 8] += Ja.T @ Ja
                        g[ca:ca + 8] += Ja.T @ res
                    if cb >= 0:
                        A[cb:cb + 8, cb:cb + 8] += Jb.T @ Jb
                        g[cb:cb + 8] += Jb.T @ res
                    if ca >= 0 and cb >= 0:
                        cross = Ja.T @ Jb
                        A[ca:ca + 8, cb:cb + 8] += cross
                        A[cb:cb + 8, ca:ca + 8] += cross.T
            return A, g

        x = levenberg_marquardt(residuals, None, x0, normal=normal)
        if not np.all(np.isfinite(x)):
            raise EstimationError("homography refinement diverged; set `refine: none` or raise `min_inliers`")
        return x

    x = levenberg_marquardt(residuals, jac, x0)
    if not np.all(np.isfinite(x)):
        raise EstimationError("homography refinement diverged; set `refine: none` or raise `min_inliers`")
    return x


def _cholesky_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Solve the symmetric positive definite system ``A x = b`` single-threaded (numba); None when not SPD.

    The systems are small (8 parameters per image); a threaded LAPACK call costs more in thread start-up than in
    arithmetic on a busy machine."""
    x = np.empty(len(b))
    ok = spd_solve_kernel(np.ascontiguousarray(A, np.float64), np.ascontiguousarray(b, np.float64), x)
    return x if ok and np.all(np.isfinite(x)) else None


def levenberg_marquardt(fun, jac, x0: np.ndarray, max_iter: int = 30, ftol: float = 1e-7,
                        normal=None) -> np.ndarray:
    """Minimise ``|fun(x)|^2`` by Levenberg-Marquardt on the normal equations.

    ``jac(x)`` returns the sparse (m, n) Jacobian; alternatively ``normal(x, r)`` returns ``(J^T J, J^T r)``
    directly (dense (n, n) and (n,)), for problems whose structure gives them without forming ``J``. With n in
    the hundreds and m in the tens of thousands, forming ``J^T J`` once per iteration is far cheaper than an
    iterative trust-region solver (``least_squares``' LSMR does hundreds of length-m vector operations per step,
    which thread-contended BLAS makes slow on a shared machine).
    Marquardt's scaling by ``diag(J^T J)`` makes the step invariant to the parameter units.

    Returns
    -------
    (n,) float64
        The parameters where the cost stopped decreasing by more than ``ftol`` (relative).
    """
    x = np.asarray(x0, np.float64).copy()
    r = fun(x)
    cost = float(r @ r)
    lam = 1e-4
    for _ in range(max_iter):
        if normal is not None:
            A, g = normal(x, r)
        else:
            J = jac(x)
            A, g = (J.T @ J).toarray(), J.T @ r
        d = np.diag(A).copy()
        d[d <= 0] = 1.0
        while lam < 1e10:
            step = _cholesky_solve(A + lam * np.diag(d), -g)
            if step is None:
                lam *= 10
                continue
            r_new = fun(x + step)
            c_new = float(r_new @ r_new)
            if np.isfinite(c_new) and c_new < cost:
                break
            lam *= 10
        else:
            return x  # no step lowers the cost: at a minimum
        x, r, decrease, cost = x + step, r_new, cost - c_new, c_new
        lam = max(lam / 10, 1e-12)
        if decrease <= ftol * cost:
            break
    return x


def refine_homographies(G: dict, edges: dict, sizes: Sequence[tuple[int, int]], reference: int,
                        max_points_per_pair: int, rng=None) -> dict:
    """Jointly refine the global homographies (8 parameters per image) over the inliers of all accepted pairs.

    Minimises, for every accepted pair (i, j) and inlier (p, q), the symmetric transfer error
    ``|G_j^-1 G_i p - q|^2 + |G_i^-1 G_j q - p|^2`` in pixels; the reference stays the identity. Coordinates are
    centred and scaled per image so the parameters are well conditioned; the Jacobian is sparse (a residual
    depends on two images only).

    Parameters
    ----------
    G : dict int -> (3, 3)
        Chained initial homographies (image -> reference pixels).
    edges : dict (i, j) -> Edge
    sizes : sequence of (w, h)
        Image sizes (indexed by input position).
    reference : int
    max_points_per_pair : int
        Inliers used per pair at most (a random subset; the rest add time, not accuracy).
    rng : seed or Generator

    Returns
    -------
    dict int -> (3, 3)
        Refined homographies, ``det = 1``.
    """
    rng = np.random.default_rng(rng)
    nodes = [a for a in sorted(G) if a != reference]
    if not nodes:
        return dict(G)
    slot = {a: k for k, a in enumerate(nodes)}
    T = {}
    for a in G:
        w, h = sizes[a]
        s = 2.0 / max(w, h)
        T[a] = np.array([[s, 0, -s * (w - 1) / 2], [0, s, -s * (h - 1) / 2], [0, 0, 1.0]])
    Tr, Tr_inv = T[reference], np.linalg.inv(T[reference])
    x0 = np.zeros(8 * len(nodes))
    for a in nodes:
        Hn = Tr @ G[a] @ np.linalg.inv(T[a])
        x0[8 * slot[a]: 8 * slot[a] + 8] = (Hn / Hn[2, 2]).ravel()[:8]

    def homs(x):
        H = {reference: np.eye(3)}
        for a in nodes:
            H[a] = Tr_inv @ np.append(x[8 * slot[a]: 8 * slot[a] + 8], 1.0).reshape(3, 3) @ T[a]
        return H

    def columns(a):
        return [] if a == reference else list(range(8 * slot[a], 8 * slot[a] + 8))

    x = _solve(_blocks(G, edges, max_points_per_pair, rng), homs, x0, columns, T, Tr_inv)
    return {a: normalize_det(H) for a, H in homs(x).items()}


def _intrinsics(f: float, size: tuple[int, int]) -> np.ndarray:
    w, h = size
    return np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation matrix closest to ``M`` in the Frobenius norm (SVD, determinant +1)."""
    U, _, Vt = np.linalg.svd(M)
    R = U @ Vt
    if np.linalg.det(R) < 0:
        R = U @ np.diag([1, 1, -1.0]) @ Vt
    return R


def refine_rotations(G: dict, edges: dict, sizes: Sequence[tuple[int, int]], reference: int, focal: float,
                     max_points_per_pair: int, rng=None) -> tuple[dict, float]:
    """Jointly refine a rotating-camera model ``G_i = K_ref R_i K_i^-1`` over the inliers of all accepted pairs.

    One shared focal length (pixels, principal points at the image centres) and three rotation parameters per
    non-reference image, the same symmetric transfer error as :func:`refine_homographies`. With 3 instead of 8
    degrees of freedom per image, the homographies extrapolate correctly far from the overlaps when the photos
    were taken by turning the camera (the usual panorama); views of a flat scene from moving positions do not fit
    it, which :func:`register` detects from the residuals.

    Returns
    -------
    G : dict int -> (3, 3)
        Refined homographies, ``det = 1``.
    focal : float
        Refined focal length in pixels.
    """
    rng = np.random.default_rng(rng)
    nodes = [a for a in sorted(G) if a != reference]
    slot = {a: k for k, a in enumerate(nodes)}
    Kr_inv = np.linalg.inv(_intrinsics(focal, sizes[reference]))
    x0 = np.zeros(1 + 3 * len(nodes))
    x0[0] = np.log(focal)
    for a in nodes:
        R = nearest_rotation(Kr_inv @ G[a] @ _intrinsics(focal, sizes[a]))
        x0[1 + 3 * slot[a]: 4 + 3 * slot[a]] = Rotation.from_matrix(R).as_rotvec()

    def homs(x):
        f = np.exp(x[0])
        Kr = _intrinsics(f, sizes[reference])
        H = {reference: np.eye(3)}
        for a in nodes:
            R = Rotation.from_rotvec(x[1 + 3 * slot[a]: 4 + 3 * slot[a]]).as_matrix()
            H[a] = Kr @ R @ np.linalg.inv(_intrinsics(f, sizes[a]))
        return H

    def columns(a):
        return [0] if a == reference else [0] + list(range(1 + 3 * slot[a], 4 + 3 * slot[a]))

    x = _solve(_blocks(G, edges, max_points_per_pair, rng), homs, x0, columns)
    return {a: normalize_det(H) for a, H in homs(x).items()}, float(np.exp(x[0]))


def estimate_focal(edges: dict, sizes: Sequence[tuple[int, int]]) -> float | None:
    """Focal length in pixels from pairwise homographies of a rotating camera (Szeliski & Shum, 1997).

    For ``H ~ K_j R K_i^-1`` with ``K = diag(f, f, 1)`` in centred coordinates, the orthogonality of the
    rows and columns of ``R`` gives two equations each for ``f_j`` and ``f_i``; each pair contributes
    ``sqrt(f_i f_j)`` and the median over pairs is returned (None when no pair gives one).
    """
    estimates = []
    for (i, j), e in edges.items():
        wi, hi = sizes[i]
        wj, hj = sizes[j]
        Ci = np.array([[1, 0, (wi - 1) / 2], [0, 1, (hi - 1) / 2], [0, 0, 1.0]])
        Cj_inv = np.array([[1, 0, -(wj - 1) / 2], [0, 1, -(hj - 1) / 2], [0, 0, 1.0]])
        h = (Cj_inv @ e.H @ Ci).ravel()
        h = h / np.cbrt(np.linalg.det(h.reshape(3, 3)))
        f_dst = _focal_from_rows(h)
        f_src = _focal_from_cols(h)
        if f_dst and f_src:
            estimates.append(np.sqrt(f_dst * f_src))
    return float(np.median(estimates)) if estimates else None


def _pick(d1: float, d2: float, v1: float, v2: float) -> float | None:
    # two estimates of f^2; prefer the one whose denominator is better conditioned
    if v1 < v2:
        v1, v2, d1, d2 = v2, v1, d2, d1
    if v1 > 0 and v2 > 0:
        return float(np.sqrt(v1 if abs(d1) > abs(d2) else v2))
    if v1 > 0:
        return float(np.sqrt(v1))
    return None


def _focal_from_rows(h: np.ndarray) -> float | None:
    # first two columns of K_j^-1 H K_i are orthogonal and of equal norm -> f_j
    d1 = h[6] * h[7]
    d2 = (h[7] - h[6]) * (h[7] + h[6])
    if d1 == 0 or d2 == 0:
        return None
    v1 = -(h[0] * h[1] + h[3] * h[4]) / d1
    v2 = (h[0] ** 2 + h[3] ** 2 - h[1] ** 2 - h[4] ** 2) / d2
    return _pick(d1, d2, v1, v2)


def _focal_from_cols(h: np.ndarray) -> float | None:
    # first two rows of K_j^-1 H K_i are orthogonal and of equal norm -> f_i
    d1 = h[0] * h[3] + h[1] * h[4]
    d2 = h[0] ** 2 + h[1] ** 2 - h[3] ** 2 - h[4] ** 2
    if d1 == 0 or d2 == 0:
        return None
    v1 = -h[2] * h[5] / d1
    v2 = (h[5] ** 2 - h[2] ** 2) / d2
    return _pick(d1, d2, v1, v2)


def _drop_reason(a: int, graph: MatchGraph, ids: Sequence[int | str]) -> str:
    others = np.arange(len(graph.sizes)) != a
    score = np.where(others, graph.inliers[a] * 10_000 + graph.matches[a], -1)
    best = int(np.argmax(score))
    if graph.matches[a][others].max() == 0:
        return "no feature matches with any other image"
    if any((min(a, b), max(a, b)) in graph.edges for b in range(len(graph.sizes)) if b != a):
        return "matches only images outside the main panorama"
    key = (min(a, best), max(a, best))
    why = graph.rejected.get(key, "no accepted pair")
    return f"shares no accepted pair with the others (best partner image {ids[best]}: {why})"


#: ``refine`` choices of :func:`register`
REFINEMENTS = ("auto", "homography", "rotation", "none")
#: ``auto`` keeps the rotation model while its RMS transfer error <= factor * homography RMS + slack (pixels)
ROTATION_RMS_FACTOR, ROTATION_RMS_SLACK = 1.5, 0.25


def register(graph: MatchGraph, *, refine: str, max_points_per_pair: int, rng=None,
             ids: Sequence[int | str] | None = None) -> Registration:
    """Global homographies of the largest group of images that match one another.

    Parameters
    ----------
    graph : MatchGraph
    refine : {"auto", "homography", "rotation", "none"}
        After chaining along the maximum spanning tree: :func:`refine_homographies`, :func:`refine_rotations`,
        nothing, or ``auto``: both, keeping the rotation model unless it fits clearly worse.
    max_points_per_pair : int
        Passed to :func:`refine_homographies`.
    rng : seed or Generator
    ids : sequence of int or str, optional
        How messages name the images (default: their positions; the stages pass file names).

    Raises
    ------
    EstimationError
        When no two images form an accepted pair.
    """
    if refine not in REFINEMENTS:
        raise ValueError(f"`refine` must be one of {list(REFINEMENTS)}, got {refine!r}")
    n = len(graph.sizes)
    ids = list(range(n)) if ids is None else list(ids)
    comps = _components(n, graph.edges)
    weight = {k: e.confidence for k, e in graph.edges.items()}

    def comp_key(c):
        return (len(c), sum(w for (i, j), w in weight.items() if i in c and j in c))

    main = max(comps, key=comp_key)
    if len(main) < 2:
        pairs = [f"{ids[i]}-{ids[j]}: {why}" for (i, j), why in sorted(graph.rejected.items())[:6]]
        raise EstimationError(
            "no two images share enough features for a panorama"
            + (f" ({'; '.join(pairs)})" if pairs else " (no pair had any matches)")
            + "; lower `min_confidence`/`min_inliers` or raise `max_features`/`work_megapix`")
    main_set = set(main)
    dropped = tuple((a, _drop_reason(a, graph, ids)) for a in range(n) if a not in main_set)
    tree = maximum_spanning_tree(sorted(main), weight)
    strength = {a: sum(w for (i, j), w in weight.items() if a in (i, j)) for a in main}
    ref = _tree_centre(sorted(main), tree, strength)
    adj: dict[int, list[int]] = {a: [] for a in main}
    for a, b in tree:
        adj[a].append(b)
        adj[b].append(a)
    G = {ref: np.eye(3)}
    todo = [ref]
    while todo:
        a = todo.pop()
        for b in adj[a]:
            if b in G:
                continue
            e = graph.edges[(min(a, b), max(a, b))]
            H_ba = np.linalg.inv(e.H) if e.i == a else e.H  # pixels of b -> pixels of a
            G[b] = normalize_det(G[a] @ H_ba)
            todo.append(b)
    edges = {k: e for k, e in graph.edges.items() if k[0] in main_set}
    rms0 = _transfer_rms(G, edges)
    focal = estimate_focal(edges, graph.sizes)
    if focal is None or not np.isfinite(focal):
        focal = float(max(graph.sizes[ref]))  # a ~53 degree field of view when the homographies say nothing
    model = "chained"
    if refine in ("homography", "auto"):
        G = refine_homographies(G, edges, graph.sizes, ref, max_points_per_pair, rng)
        model = "homography"
    rms1 = _transfer_rms(G, edges)
    if refine in ("rotation", "auto"):
        try:
            G_rot, f_rot = refine_rotations(G, edges, graph.sizes, ref, focal, max_points_per_pair, rng)
        except EstimationError:
            if refine == "rotation":
                raise
        else:
            rms_rot = _transfer_rms(G_rot, edges)
            # a rotating camera explains the matches almost as well as free homographies: prefer its 3 degrees of
            # freedom per image, which extrapolate correctly away from the overlaps
            if refine == "rotation" or rms_rot <= ROTATION_RMS_FACTOR * rms1 + ROTATION_RMS_SLACK:
                G, focal, rms1, model = G_rot, f_rot, rms_rot, "rotation"
    return Registration(tuple(sorted(main)), dropped, ref, G, tuple(tree), float(focal), rms0, rms1, model)


# ------------------------------------------------------------------------------------------------ whole pipeline


@dataclass(frozen=True)
class Panorama:
    """Result of :func:`stitch`.

    Attributes
    ----------
    image : (H, W, 3) uint8
        The panorama (cropped when asked).
    mask : (H, W) bool
        Pixels covered by at least one image.
    seams : (H, W) bool
        Seam lines between the images' blending regions (same frame as ``image``).
    registration : Registration
        At the registration resolution.
    homographies : dict int -> (3, 3)
        Input pixels (full resolution) -> reference pixels at the compose resolution ("plane" frame).
    to_panorama : (3, 3)
        Reference (compose resolution) plane pixels -> panorama pixels, valid for ``projection == "plane"``.
    crop : (x, y, w, h)
        Rectangle cut from the blended canvas.
    timings : dict str -> float
        Seconds per step.
    graph : MatchGraph
        The pairwise match graph (at the registration resolution ``graph.sizes``): every accepted pair's own
        homography, before any global model.
    """

    image: np.ndarray
    mask: np.ndarray
    seams: np.ndarray
    registration: Registration
    homographies: dict
    to_panorama: np.ndarray
    crop: tuple
    timings: dict
    graph: MatchGraph | None = None


def _check_images(images: Sequence[np.ndarray]) -> None:
    if len(images) < 2:
        raise InputError(f"a panorama needs at least two images, got {len(images)}")
    for k, img in enumerate(images):
        img = np.asarray(img)
        if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
            raise InputError(f"image {k} must be (H, W) or (H, W, 3) uint8, got shape {img.shape} dtype {img.dtype}")
        if min(img.shape[:2]) < 16:
            raise InputError(f"image {k} is {img.shape[1]}x{img.shape[0]}, expected at least 16x16 pixels")


def stitch(images: Sequence[np.ndarray], features: PanoramaFeaturesParams = PanoramaFeaturesParams(),
           matching: PanoramaMatchParams = PanoramaMatchParams(),
           homographies: PanoramaHomographiesParams = PanoramaHomographiesParams(),
           warp: PanoramaWarpParams = PanoramaWarpParams(), blend: PanoramaBlendParams = PanoramaBlendParams(),
           crop: bool = True, rng=None, ids: Sequence[int] | None = None) -> Panorama:
    """Stitch overlapping photos, given in any order, into one panorama.

    Parameters
    ----------
    images : sequence of (H, W) or (H, W, 3) uint8
        Grayscale or BGR photos; sizes may differ.
    features, matching, homographies, warp, blend : params dataclasses
        The stage parameters (defaults as in ``params.yaml``).
    crop : bool
        Cut the largest axis-aligned rectangle without empty pixels.
    rng : seed or Generator
        For RANSAC and the refinement's point subsets.
    ids : sequence of int, optional
        How messages name the images (default: their positions).

    Returns
    -------
    Panorama

    Raises
    ------
    InputError
        Fewer than two images, wrong dtype or shape.
    EstimationError
        No two images overlap, or the projection cannot hold the views (e.g. ``plane`` beyond 180 degrees).
    """
    _check_images(images)
    rng = np.random.default_rng(rng)
    t = {}
    t0 = time.perf_counter()
    grays, work_sizes = working_images(images, features.work_megapix)
    feats = detect_all(grays, features.detector, features.max_features)
    t["features"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    graph = match_graph(feats, work_sizes, ratio=matching.ratio, ransac_threshold=matching.ransac_threshold,
                        min_inliers=matching.min_inliers, min_confidence=matching.min_confidence,
                        candidates=matching.candidates, refit_threshold=matching.refit_threshold, rng=rng)
    t["match"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    reg = register(graph, refine=homographies.refine, max_points_per_pair=homographies.max_points_per_pair,
                   rng=rng, ids=ids)
    t["homographies"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    comp = compose_inputs(images, reg, work_sizes, warp.compose_megapix)
    warped = warping.warp_images(comp.images, comp.G, warp.projection, comp.focal, comp.ref_size,
                                 warp.max_canvas_megapix)
    t["warp"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    pano, mask, seams = blending.compose(warped, blend.blender, blend.bands, blend.gain_compensation)
    t["blend"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    rect = blending.largest_rectangle(mask) if crop else (0, 0, mask.shape[1], mask.shape[0])
    x, y, w, h = rect
    if w == 0 or h == 0:
        raise EstimationError("the panorama has no pixel covered by an image; check the homographies")
    t["crop"] = time.perf_counter() - t0
    to_pano = np.array([[1, 0, -warped.origin[0] - x], [0, 1, -warped.origin[1] - y], [0, 0, 1.0]])
    full_sizes = [(img.shape[1], img.shape[0]) for img in images]
    H_full = {}
    for k, a in enumerate(reg.used):
        H_full[a] = comp.G[k] @ resize_matrix(full_sizes[a], comp.sizes[k])
    return Panorama(pano[y:y + h, x:x + w], mask[y:y + h, x:x + w], seams[y:y + h, x:x + w], reg, H_full,
                    to_pano, tuple(int(v) for v in rect), t, graph)


@dataclass(frozen=True)
class ComposeInputs:
    """The used images at the compose resolution with their homographies (image -> reference pixels)."""

    images: list
    G: list
    sizes: list
    focal: float
    ref_size: tuple


def compose_inputs(images: Sequence[np.ndarray], reg: Registration, work_sizes: Sequence[tuple[int, int]],
                   compose_megapix: float) -> ComposeInputs:
    """Resize the used images to the compose resolution and re-express the registration there."""
    used = list(reg.used)
    full = [(images[a].shape[1], images[a].shape[0]) for a in used]
    comp_sizes = [resized_size(s, scale_for(s, compose_megapix)) for s in full]
    ref_pos = used.index(reg.reference)
    G = rescale_homographies([reg.G[a] for a in used], [work_sizes[a] for a in used], comp_sizes, ref_pos)
    scale = comp_sizes[ref_pos][0] / work_sizes[reg.reference][0]
    imgs = []
    for a, size in zip(used, comp_sizes):
        img = images[a] if images[a].ndim == 3 else cv2.cvtColor(images[a], cv2.COLOR_GRAY2BGR)
        imgs.append(resize(img, size))
    return ComposeInputs(imgs, G, comp_sizes, reg.focal * scale, comp_sizes[ref_pos])


# ------------------------------------------------------------------------------------------------ baseline

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
