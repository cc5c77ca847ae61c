"""Tentative scene -> gallery matches: one k-nearest-neighbour query against the whole gallery."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..features import Features
from ..matching import FLANN_KDTREE
from ..params import LogoMatchParams
from .gallery import Gallery, _prepare


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
        index = cv2.flann_Index(scene_desc, {"algorithm": FLANN_KDTREE, "trees": 4})
        nn, dist2 = index.knnSearch(query, 2, params={"checks": 32})
        nn, dist = nn.astype(np.int64), np.sqrt(np.maximum(dist2, 0)).astype(np.float32)  # FLANN's L2 is squared
    keep = (nn[:, 1] >= 0) & (dist[:, 0] < p.reverse_ratio * dist[:, 1])
    ref = np.repeat(short.astype(np.int64), [len(d) for d in desc])
    local = np.concatenate([np.arange(len(d), dtype=np.int64) for d in desc])
    return ref[keep], local[keep], nn[keep, 0], dist[keep, 0]
