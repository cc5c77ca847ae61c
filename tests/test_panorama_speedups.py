"""The panorama's speed-ups (blocked nearest-two matching, prefilter counts, homography refinement,
row/column canvas maps, multiband, refit): each must give what the plain computation gives."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cvpipe import matching, panorama
from cvpipe.geometry import apply_homography
from cvpipe.homography import find_homography

from test_panorama import _corner_error


# ---- each speed-up must give what the plain computation gives ----


def _sift_like(rng, n, d=128):
    # SIFT descriptors are float32 holding integers 0..255 (and dot products stay exact in float32)
    return rng.integers(0, 256, (n, d)).astype(np.float32)


def test_pairwise_products_on_one_blas_thread_are_the_same_and_the_thread_count_comes_back():
    from threadpoolctl import threadpool_info

    from cvpipe.panorama.match import one_blas_thread

    def blas_threads():
        return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]

    rng = np.random.default_rng(1)
    q, t = _sift_like(rng, 1500), _sift_like(rng, 1400)
    before = blas_threads()
    many = matching.nearest_two(q, t)
    with one_blas_thread():
        assert set(blas_threads()) == {1}
        one = matching.nearest_two(q, t)
    assert blas_threads() == before
    # SIFT's integer-valued descriptors: every product and partial sum is exact in float32 (128 * 255^2 < 2^24),
    # so however BLAS splits the sums over threads, the distances are the same bit for bit
    for a, b in zip(many, one):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("block", [matching.DISTANCE_BLOCK, 4000])
def test_nearest_two_and_ratio_matches_equal_brute_force(block, monkeypatch):
    monkeypatch.setattr(matching, "DISTANCE_BLOCK", block)  # 4000 entries: the query in blocks of 10 rows
    rng = np.random.default_rng(0)
    q, t = _sift_like(rng, 300), _sift_like(rng, 400)
    t[:50] = q[:50] + rng.integers(-3, 4, (50, 128))  # 50 true matches among random descriptors
    d = ((q.astype(np.float64)[:, None, :] - t[None, :, :]) ** 2).sum(-1)
    order = np.sort(d, axis=1)
    nearest, d1, d2 = matching.nearest_two(q, t)
    assert np.array_equal(nearest, np.argmin(d, axis=1))
    # squared distances of ~1e6 from a float32 product: within 1e-5 relative of the float64 ones
    np.testing.assert_allclose(d1, order[:, 0], rtol=1e-5)
    np.testing.assert_allclose(d2, order[:, 1], rtol=1e-5)
    pairs = matching.ratio_matches(q, t, 0.8)
    keep = np.sqrt(order[:, 0]) < 0.8 * np.sqrt(order[:, 1])
    assert set(map(tuple, pairs.tolist())) == {(i, int(np.argmin(d[i]))) for i in np.nonzero(keep)[0]}
    assert {(i, i) for i in range(50)} <= set(map(tuple, pairs.tolist()))
    assert np.all(np.diff(d[pairs[:, 0], pairs[:, 1]]) >= 0)  # best first, like MatchIndex.query
    assert matching.ratio_matches(q[:0], t, 0.8).shape == (0, 2)


@pytest.mark.parametrize("binary", [False, True])
def test_prefilter_counts_equal_opencv_brute_force(binary):
    rng = np.random.default_rng(1)
    if binary:
        desc = [rng.integers(0, 256, (120, 32)).astype(np.uint8) for _ in range(3)]
        desc[1][:40] = desc[0][:40] ^ (rng.random((40, 32)) < 0.02).astype(np.uint8)
        bf = cv2.BFMatcher(cv2.NORM_HAMMING)
    else:
        desc = [_sift_like(rng, 120) for _ in range(3)]
        desc[1][:40] = desc[0][:40] + rng.integers(-3, 4, (40, 128))
        bf = cv2.BFMatcher(cv2.NORM_L2)
    C = panorama.prefilter_counts(desc, 0.8)
    for i, j in [(0, 1), (0, 2), (1, 2)]:
        want = sum(m.distance < 0.8 * n.distance for m, n in bf.knnMatch(desc[i], desc[j], k=2))
        assert C[i, j] == C[j, i] == want
    assert C[0, 1] >= 40  # the planted matches pass the ratio test


def _exact_correspondences(G, sizes, edges, rng):
    """Noise-free inlier sets of the pairs ``edges`` of images related by the global homographies ``G``."""
    out = {}
    for i, j in edges:
        w, h = sizes[i]
        src = rng.uniform([0, 0], [w - 1, h - 1], (400, 2))
        dst = apply_homography(np.linalg.inv(G[j]) @ G[i], src)
        inside = (dst[:, 0] >= 0) & (dst[:, 0] < sizes[j][0]) & (dst[:, 1] >= 0) & (dst[:, 1] < sizes[j][1])
        H = np.linalg.inv(G[j]) @ G[i]
        out[(i, j)] = panorama.Edge(i, j, H / H[2, 2], src[inside], dst[inside], 5.0)
    return out


def test_refine_homographies_recovers_known_homographies_from_a_perturbed_start():
    rng = np.random.default_rng(2)
    sizes = [(400, 300)] * 4
    G = {0: np.eye(3)}
    for k, tx in enumerate([250.0, 500.0, 750.0], start=1):
        G[k] = panorama.normalize_det(np.array([[1.02, 0.01 * k, tx], [-0.01, 0.98, 8.0 * k], [2e-5 * k, -1e-5, 1.0]]))
    edges = _exact_correspondences(G, sizes, [(0, 1), (1, 2), (2, 3), (0, 2)], rng)
    sigma = np.array([[3e-3, 3e-3, 2.0], [3e-3, 3e-3, 2.0], [3e-6, 3e-6, 0]])
    start = {a: (H if a == 0 else panorama.normalize_det(H + rng.normal(0, sigma))) for a, H in G.items()}
    assert max(_corner_error(np.linalg.inv(G[a]) @ start[a], np.eye(3), sizes[a]) for a in G) > 2.0
    refined = panorama.refine_homographies(start, edges, sizes, 0, 200, rng=0)
    # noise-free correspondences: the least-squares minimum is the truth, reached to LM's stopping tolerance
    for a in G:
        assert _corner_error(np.linalg.inv(G[a]) @ refined[a], np.eye(3), sizes[a]) < 1e-3


@pytest.mark.parametrize("projection", panorama.warp.PROJECTIONS)
def test_canvas_maps_from_row_and_column_equal_the_full_grid(projection):
    G = np.array([[1.01, 0.02, 300], [-0.01, 0.99, -40], [2e-5, 1e-5, 1.0]])
    u = np.arange(-200, 900, 7, dtype=np.float32)
    v = np.arange(-100, 600, 5, dtype=np.float32)
    x, y, ok = panorama.warp.canvas_to_image(u[None, :], v[:, None], G, projection, 700.0, (640, 480))
    U, V = np.meshgrid(u.astype(np.float64), v.astype(np.float64))
    xe, ye, oke = panorama.warp.canvas_to_image(U, V, G, projection, 700.0, (640, 480))
    assert x.shape == U.shape and x.dtype == np.float32 and np.array_equal(ok, oke)
    # float32 maps of coordinates up to ~1000 px: a few 1e-4 px of rounding
    assert np.abs(x - xe)[ok].max() < 2e-3 and np.abs(y - ye)[ok].max() < 2e-3




@pytest.mark.parametrize("projection", ["plane", "cylindrical", "spherical"])
@pytest.mark.parametrize("channels", [3, 1])
def test_warp_image_equals_remap_with_the_maps_of_canvas_to_image(projection, channels, monkeypatch):
    # the compiled maps in strips of rows (17 rows here, so several strips and a short last one) give exactly what
    # cv2.remap gives with canvas_to_image's float32 maps over the whole box, zero outside the image
    monkeypatch.setattr(panorama.warp, "WARP_STRIP_PIXELS", 17 * 300)
    rng = np.random.default_rng(6)
    img = cv2.GaussianBlur(rng.integers(0, 256, (120, 160, 3)).astype(np.uint8), (0, 0), 1.5)
    img = img if channels == 3 else np.ascontiguousarray(img[..., 1])
    G = np.array([[0.9, 0.08, 30.0], [-0.05, 1.1, 12.0], [2e-4, -1e-4, 1.0]])
    (box,) = panorama.warp.warp_bounds([(160, 120)], [G], projection, 300.0, (160, 120))
    warped, mask = panorama.warp.warp_image(img, G, box, projection, 300.0, (160, 120))
    x0, y0, x1, y1 = (int(b) for b in box)
    u, v = np.arange(x0, x1, dtype=np.float32)[None, :], np.arange(y0, y1, dtype=np.float32)[:, None]
    x, y, ok = panorama.warp.canvas_to_image(u, v, G, projection, 300.0, (160, 120))
    ok &= (x > -0.5) & (x < 159.5) & (y > -0.5) & (y < 119.5)
    mx, my = np.where(ok, x, np.float32(-10)), np.where(ok, y, np.float32(-10))
    want = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    want[~ok] = 0
    assert warped.shape[0] > 3 * 17 and 0.3 < ok.mean() < 1
    assert np.array_equal(mask, np.where(ok, 255, 0).astype(np.uint8)) and np.array_equal(warped, want)


def test_compiled_two_nearest_hamming_equals_opencv_with_ties():
    from cvpipe.panorama import _match

    rng = np.random.default_rng(8)
    q = rng.integers(0, 256, (300, 32), dtype=np.uint8)
    t = rng.integers(0, 256, (350, 32), dtype=np.uint8)
    t[:100] = q[:100] ^ (rng.random((100, 32)) < 0.05).astype(np.uint8)
    t[200:220] = t[:20]  # a later twin of a nearest row: OpenCV keeps the earlier row first
    q[250:260] = t[300:310]  # distance 0
    dist, idx = _match.hamming_two_nearest(q, t)
    want_d, want_i = cv2.batchDistance(q, t, cv2.CV_32S, normType=cv2.NORM_HAMMING, K=2)
    assert np.array_equal(dist, want_d) and np.array_equal(idx, want_i)
    assert (dist[:20, 0] == dist[:20, 1]).all() and (idx[:20, 0] < idx[:20, 1]).all()

def test_hamming_ratio_matches_equal_opencv_knn_matcher():
    from cvpipe.panorama.match import hamming_ratio_matches

    rng = np.random.default_rng(4)
    q = rng.integers(0, 256, (400, 32), dtype=np.uint8)
    t = rng.integers(0, 256, (500, 32), dtype=np.uint8)
    t[:150] = q[:150] ^ (rng.random((150, 32)) < 0.04).astype(np.uint8)  # 150 true matches, a few bits off
    t[150:160] = t[140:150]  # exact twins in the train set: equal distances, the ratio test must refuse those
    knn = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(q, t, k=2)
    want = [(m.queryIdx, m.trainIdx, m.distance) for m, n in knn if m.distance < 0.8 * n.distance]
    want.sort(key=lambda r: r[2])  # stable: ties stay in query order
    got = hamming_ratio_matches(q, t, 0.8)
    assert got.tolist() == [[a, b] for a, b, _ in want]
    assert 100 < len(got) < 150 and not set(got[:, 0].tolist()) & set(range(140, 150))

def test_multiband_keeps_pixels_far_from_the_seam_exact():
    rng = np.random.default_rng(3)
    a = rng.integers(0, 256, (120, 160, 3)).astype(np.uint8)
    b = rng.integers(0, 256, (120, 160, 3)).astype(np.uint8)
    full = np.full((120, 160), 255, np.uint8)
    w = panorama.warp.Warped([a, b], [full, full.copy()], [(0, 0), (100, 0)], (260, 120), (0, 0))
    labels = panorama.seam_labels(w)
    pano = panorama.blend_multiband(w, labels, 3)
    canvas = [np.zeros((120, 260, 3), np.uint8) for _ in range(2)]
    canvas[0][:, :160], canvas[1][:, 100:] = a, b
    # 3 bands: a seam's influence spreads over ~2 * (2 + 4 + 8) px; beyond 32 px of any other image's region each
    # pixel is exactly its own image's (within 1 grey level of rounding)
    for k in range(2):
        far = cv2.erode((labels == k).astype(np.uint8), np.ones((65, 65), np.uint8),
                        borderType=cv2.BORDER_REPLICATE) > 0
        assert far.sum() > 1000
        assert np.abs(pano[far].astype(int) - canvas[k][far]).max() <= 1
    assert (labels >= 0).all() and pano[labels >= 0].any()



def test_multiband_on_crops_in_threads_gives_the_whole_boxes_one_at_a_time(monkeypatch):
    from cvpipe.panorama import blend

    rng = np.random.default_rng(5)
    # five views in a row, each overlapping the next by 3/4: every image owns a strip much narrower than its box
    base = cv2.GaussianBlur(rng.integers(0, 256, (160, 520, 3)).astype(np.uint8), (0, 0), 2)
    imgs = [np.ascontiguousarray(base[:, 80 * k:80 * k + 200]) for k in range(5)]
    masks = [np.full((160, 200), 255, np.uint8) for _ in imgs]
    w = panorama.warp.Warped(imgs, masks, [(80 * k, 0) for k in range(5)], (520, 160), (0, 0))
    labels = panorama.seam_labels(w)
    gains = np.array([1.0, 1.1, 0.9, 1.05, 0.95])
    pano = panorama.blend_multiband(w, labels, 4, gains)
    monkeypatch.setattr(blend, "BLEND_THREADS", 1)
    assert np.array_equal(panorama.blend_multiband(w, labels, 4, gains), pano)  # added in image order either way
    # the plain computation: every image's pyramid over its whole padded box
    monkeypatch.setattr(blend, "_reach_of_own", lambda own, corner, box, P: box)
    whole = panorama.blend_multiband(w, labels, 4, gains)
    # the crop's border reflection stays outside what is read: float rounding only (1 grey level, rarely)
    d = np.abs(whole.astype(int) - pano)
    assert d.max() <= 1 and (d > 0).mean() < 1e-3, (d.max(), (d > 0).mean())

def test_bench_accuracy_measures_direct_and_composed_errors():
    from types import SimpleNamespace

    from cvpipe.bench import panorama as bench

    sizes = [(400, 300)] * 3
    G = {0: np.eye(3), 1: np.array([[1, 0, 300.0], [0, 1, 5], [0, 0, 1]]),
         2: np.array([[1, 0, 600.0], [0, 1, 10], [1e-5, 0, 1]])}
    gt = {(i, j): np.linalg.inv(G[j]) @ G[i] for i, j in [(1, 0), (2, 1), (2, 0)]}
    shift = np.array([[1, 0, 4.0], [0, 1, 0], [0, 0, 1]])  # a 4 px error in the graph's own homography 0 -> 1
    edges = {(0, 1): panorama.Edge(0, 1, shift @ np.linalg.inv(gt[(1, 0)]), None, None, 5.0),
             (1, 2): panorama.Edge(1, 2, np.linalg.inv(gt[(2, 1)]), None, None, 5.0)}
    graph = SimpleNamespace(sizes=sizes, edges=edges)
    acc = bench._accuracy(SimpleNamespace(graph=graph, homographies=G), gt, sizes)
    # composed from exact global homographies: no error at all
    assert acc["corner_error_median"] < 1e-9 and acc["corner_error_max"] < 1e-9
    # direct: pair (1, 0) is off by the inverse of a 4 px shift, (2, 1) exact, (2, 0) not an edge (a failure)
    assert acc["gt_pairs"] == 3 and acc["direct_pairs"] == 2
    assert acc["direct_error_median_matched"] == pytest.approx(2.0)
    assert acc["direct_error_median"] == pytest.approx(4.0)
    # direct, with the (exact) composed error standing in for the pair that is not an edge: errors 4, 0, 0
    assert acc["direct_or_composed_median"] == pytest.approx(0.0, abs=1e-9)
    # a consistent ground truth has a floor of 0; breaking one pair's consistency raises it
    assert bench._gt_floor(gt, sizes) < 1e-3
    gt[(2, 0)] = shift @ gt[(2, 0)]
    assert bench._gt_floor(gt, sizes) > 0.1


def test_refit_drops_imprecise_matches_and_recovers_the_homography():
    rng = np.random.default_rng(3)
    size = (640, 480)
    H_true = np.array([[0.98, 0.03, 210.0], [-0.02, 1.01, 12.0], [2e-5, -1e-5, 1.0]])
    # over the right half: 200 precise matches (0.2 px noise), 150 imprecise ones displaced by 2.2-2.8 px in random
    # directions (inside the 3 px RANSAC threshold, so the first fit keeps them), and 100 gross outliers
    src = rng.uniform([320, 0], [640, 480], (450, 2))
    dst = apply_homography(H_true, src)
    dst[:200] += rng.normal(0, 0.2, (200, 2))
    angle = rng.uniform(0, 2 * np.pi, 150)
    dst[200:350] += rng.uniform(2.2, 2.8, 150)[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])
    dst[350:] = rng.uniform([0, 0], [640, 480], (100, 2))
    first = find_homography(src, dst, threshold=3.0, rng=0)
    H, keep = panorama.refit(src, dst, first.H, first.inliers, 1.0, 10, size, rng=0)
    # 1 px is 5 sigma of the precise matches' noise and well below the imprecise ones' 2.2 px
    assert keep[:200].mean() > 0.95 and keep[200:350].mean() < 0.1 and not keep[350:].any()
    assert not (keep & ~first.inliers).any()
    # the first fit averages the imprecise matches in (0.9 px at the corners, which are extrapolated over the left
    # half); the refit's final reweighting still gives them small weights (cvpipe.homography's weights reach 3x the
    # threshold), so it lands between that and the 0.1 px of a fit to the precise matches alone: 0.43 px here
    err_refit, err_first = _corner_error(H, H_true, size), _corner_error(first.H, H_true, size)
    assert err_refit < 0.6 and err_refit < 0.75 * err_first
    # too few inliers left for the refit: the first fit is returned unchanged
    H2, keep2 = panorama.refit(src, dst, first.H, first.inliers, 1.0, 1000, size, rng=0)
    assert H2 is first.H and keep2 is first.inliers
