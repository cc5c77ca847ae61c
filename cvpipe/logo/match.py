"""Tentative scene -> gallery matches: one k-nearest-neighbour query against the whole gallery."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..features import Features
from ..params import LogoMatchParams
from .._threads import max_threads
from ._hamming import hamming_k_nearest
from .gallery import Gallery, _prepare, binary_words


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

    #: the arrays of :meth:`to_arrays`, the keys a cached ``.npz`` must hold for :meth:`from_arrays`
    ARRAYS = ("ref", "gallery_idx", "scene_idx", "distance")

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {"ref": self.ref, "gallery_idx": self.gallery_idx, "scene_idx": self.scene_idx,
                "distance": self.distance}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> "Matches":
        return cls(np.asarray(arrays["ref"], np.int64), np.asarray(arrays["gallery_idx"], np.int64),
                   np.asarray(arrays["scene_idx"], np.int64), np.asarray(arrays["distance"], np.float32))


def match_scene(gallery: Gallery, scene: Features, params: LogoMatchParams | None = None) -> Matches:
    """Tentative matches of a scene's keypoints to every reference.

    Each scene descriptor gets its ``k`` nearest gallery descriptors (an exact search of binary descriptors, FLANN's
    approximate one of float descriptors). A neighbour of brand B is kept when its
    distance is below ``ratio`` times the distance of the nearest neighbour of any other brand (or of the k-th
    neighbour when all k belong to B), and at most the first ``per_reference`` neighbours in one reference count.
    Afterwards every reference keypoint keeps only its closest scene keypoint.

    Parameters
    ----------
    gallery : Gallery
    scene : Features
        From the same detector as the gallery.
    params : LogoMatchParams, optional
        ``ratio``, ``k`` and ``per_reference``; defaults from
        :class:`cvpipe.params.LogoMatchParams`.
    """
    p = params or LogoMatchParams()
    if scene.detector != gallery.detector:
        raise ValueError(f"scene features come from {scene.detector!r}, the gallery from {gallery.detector!r}")
    empty = Matches(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float32))
    if len(scene) == 0:
        return empty
    k = int(min(p.k, len(gallery.ref_of)))
    if gallery.binary:  # exact search, the queries over the kernels' threads (the same neighbours as cv2.BFMatcher)
        d, i = hamming_k_nearest(binary_words(scene.descriptors), gallery.words, k, max_threads())
        idx, dist = i.astype(np.int64), np.where(i >= 0, d, np.inf).astype(np.float32)
        n = len(idx)
    else:
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
    # matching the best references back into the scene (Lowe's ratio within the scene) was measured and rejected:
    # +1-2 photos on FlickrLogos, within run-to-run noise, for +0.1 s per SIFT scene (docs/notes/logo.md)
    # one-to-one per reference: keep the closest scene keypoint of every reference keypoint
    order = np.lexsort((m_dist, m_gal, m_ref))
    m_ref, m_gal, rows, m_dist = m_ref[order], m_gal[order], rows[order], m_dist[order]
    first = np.ones(len(m_ref), bool)
    first[1:] = (m_ref[1:] != m_ref[:-1]) | (m_gal[1:] != m_gal[:-1])
    return Matches(m_ref[first], m_gal[first], rows[first].astype(np.int64), m_dist[first].astype(np.float32))


def match_item(scene: Features, shared: tuple) -> tuple[Matches, float]:
    """Tentative matches of one scene: the per-scene work of the ``logo_match`` stage, an item of
    :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    scene : Features
        The scene's features.
    shared : tuple
        ``(Gallery, LogoMatchParams)``, sent once per worker (the gallery is indexed again there).

    Returns
    -------
    (Matches, float)
        :func:`match_scene`'s matches and the seconds they took.

    Raises
    ------
    InputError
        Features of another detector than the gallery's (the stage drops the scene with the reason).
    """
    import time

    from ..errors import InputError

    gallery, p = shared
    t0 = time.perf_counter()
    try:
        m = match_scene(gallery, scene, p)
    except InputError:
        raise
    except ValueError as exc:
        raise InputError(str(exc)) from None
    return m, time.perf_counter() - t0
