"""Registration: the largest group of images that match one another, chained along the maximum spanning tree of the
match graph and refined jointly (:mod:`cvpipe.panorama.refine`).

Homographies map homogeneous pixel column vectors (x = column, y = row). A global homography ``G[i]`` maps pixels
of image ``i`` to pixels of the reference image; all of them are normalised to ``det(G) = 1``, which fixes their
sign so that points in front of the camera keep a positive third coordinate.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import EstimationError
from ..params import PanoramaHomographiesParams, PanoramaMatchParams, section_or_default
from .features import normalize_det
from .match import MatchGraph, _components
from .refine import _transfer_rms, refine_homographies, refine_rotations


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


def maximum_spanning_tree(nodes: Sequence[int], weights: dict) -> list[tuple[int, int]]:
    """Prim's algorithm on ``weights[(i, j)]`` (i < j), maximising the total weight; nodes must be connected.

    Examples
    --------
    >>> maximum_spanning_tree([0, 1, 2], {(0, 1): 5.0, (0, 2): 1.0, (1, 2): 3.0})
    [(0, 1), (1, 2)]
    """
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


def register_with(graph: MatchGraph, params: PanoramaHomographiesParams | None, rng,
                  ids: Sequence[int | str] | None = None) -> Registration:
    """:func:`register` with the ``panorama.homographies`` section (``refine``, ``max_points_per_pair``): the step
    of :func:`cvpipe.panorama.stitch` and of the ``panorama_homographies`` stage.

    Parameters
    ----------
    graph : MatchGraph
    params : PanoramaHomographiesParams or None
        The section (None: its defaults).
    rng : seed or Generator
        For the refinement's point subsets (the stage passes ``panorama.match.seed``).
    ids : sequence of int or str, optional
        How messages name the images, as :func:`register`.

    Returns
    -------
    Registration

    Examples
    --------
    >>> from cvpipe.panorama import features_of, match_graph_with
    >>> from cvpipe.params import PanoramaHomographiesParams
    >>> from cvpipe.samples import photo
    >>> img = photo("astronaut")
    >>> sizes, feats = features_of([img[:, 200:], img[:, :320]])
    >>> reg = register_with(match_graph_with(feats, sizes, None, 0), PanoramaHomographiesParams(refine="none"), 0)
    >>> reg.used
    (0, 1)
    """
    p = section_or_default(params, PanoramaHomographiesParams, "panorama.homographies")
    return register(graph, refine=p.refine, max_points_per_pair=p.max_points_per_pair, rng=rng, ids=ids)


def register_set(item: tuple, shared: tuple) -> tuple[Registration, float]:
    """Register one set from its match graph: the per-set work of the ``panorama_homographies`` stage, an item of
    :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    item : tuple
        ``(MatchGraph, file names)``.
    shared : tuple
        ``(PanoramaHomographiesParams, PanoramaMatchParams)``: the ``panorama.homographies`` section
        (:func:`register_with`) and the ``panorama.match`` section, whose ``seed`` seeds the refinement.

    Returns
    -------
    (Registration, float)
        The registration and the seconds it took.

    Raises
    ------
    EstimationError
        As :func:`register` (the stage records the set as failed, with the reason).
    """
    import time

    graph, files = item
    params, match = shared
    match = section_or_default(match, PanoramaMatchParams, "panorama.match")
    t0 = time.perf_counter()
    reg = register_with(graph, params, match.seed, ids=files)
    return reg, time.perf_counter() - t0
