"""The exact Hamming k-nearest search of binary logo galleries gives OpenCV's brute-force neighbours, ties included."""

import cv2
import numpy as np
import pytest

from cvpipe.logo._hamming import hamming_k_nearest
from cvpipe.logo.gallery import binary_words


def _bf(query: np.ndarray, train: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """cv2.BFMatcher(NORM_HAMMING).knnMatch as (n, k) distance and index arrays, -1 / 2**30 where it has fewer."""
    bf = cv2.BFMatcher(cv2.NORM_HAMMING)
    bf.add([train])
    bf.train()
    dist = np.full((len(query), k), 1 << 30, np.int64)
    idx = np.full((len(query), k), -1, np.int64)
    for i, row in enumerate(bf.knnMatch(query, k=k)):
        for j, m in enumerate(row):
            dist[i, j], idx[i, j] = m.distance, m.trainIdx
    return dist, idx


@pytest.mark.parametrize("width", [32, 61, 64])  # ORB, AKAZE, BRISK
@pytest.mark.parametrize("threads", [1, 2])
def test_k_nearest_are_opencvs_brute_force_neighbours_ties_included(width, threads):
    rng = np.random.default_rng(width)
    # few distinct bits: distances repeat a lot, so the order of equal distances is tested, not only the values
    query = (rng.random((300, width)) < 0.02).astype(np.uint8) * 255
    train = (rng.random((2000, width)) < 0.02).astype(np.uint8) * 255
    train[700] = train[30]  # exact duplicates: the earlier row comes first
    dist, idx = hamming_k_nearest(binary_words(query), binary_words(train), 8, threads)
    want_d, want_i = _bf(query, train, 8)
    assert len(np.unique(dist)) < 40  # the data do tie
    assert np.array_equal(dist, want_d) and np.array_equal(idx, want_i)


def test_fewer_train_rows_than_k_leave_the_rest_empty():
    rng = np.random.default_rng(1)
    query, train = rng.integers(0, 256, (5, 32), np.uint8), rng.integers(0, 256, (3, 32), np.uint8)
    dist, idx = hamming_k_nearest(binary_words(query), binary_words(train), 5, 2)
    want_d, want_i = _bf(query, train, 5)
    assert np.array_equal(idx, want_i) and np.array_equal(dist, want_d) and (idx[:, 3:] == -1).all()


def test_padding_to_whole_words_keeps_every_distance():
    rng = np.random.default_rng(2)
    a, b = rng.integers(0, 256, (4, 61), np.uint8), rng.integers(0, 256, (6, 61), np.uint8)
    words_a, words_b = binary_words(a), binary_words(b)
    assert words_a.shape == (4, 8) and words_a.dtype == np.uint64
    dist, idx = hamming_k_nearest(words_a, words_b, 6, 1)
    direct = np.unpackbits(a[:, None, :] ^ b[None, :, :], axis=2).sum(2)
    assert np.array_equal(np.take_along_axis(direct, idx, 1), dist)
