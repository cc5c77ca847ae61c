"""Pictures of results (cvpipe.overlays): pure functions, checked on synthetic inputs with known answers."""

import numpy as np
import pytest

from cvpipe import overlays
from cvpipe.errors import InputError


def test_checkerboard_with_the_identity_alternates_a_and_b():
    a = np.full((64, 64, 3), 40, np.uint8)
    b = np.full((64, 64, 3), 200, np.uint8)
    out = overlays.checkerboard_warp(a, b, np.eye(3), tile=16)
    assert out.shape == a.shape
    # tile (row // 16 + col // 16) odd shows B, even shows A; sample tile centres away from interpolated borders
    for ty in range(4):
        for tx in range(4):
            want = 200 if (ty + tx) % 2 else 40
            assert (out[ty * 16 + 8, tx * 16 + 8] == want).all(), (ty, tx)


def test_checkerboard_darkens_a_where_b_does_not_reach():
    a = np.full((40, 80), 100, np.uint8)
    b = np.full((40, 40), 250, np.uint8)
    H = np.array([[1.0, 0, -40], [0, 1, 0], [0, 0, 1]])  # A's right half maps onto B; its left half falls outside
    out = overlays.checkerboard_warp(a, b, H, tile=8)
    assert (out[:, :38] == 50).all()  # A halved outside B's footprint
    assert set(np.unique(out[:, 42:])) <= {100, 250}


def test_checkerboard_rejects_a_singular_homography():
    img = np.zeros((8, 8), np.uint8)
    with pytest.raises(InputError, match="`H` must be a finite invertible 3x3 matrix"):
        overlays.checkerboard_warp(img, img, np.zeros((3, 3)))


def test_draw_quads_outlines_only_near_the_quad():
    img = np.zeros((100, 120), np.uint8)
    quad = np.array([[20, 20], [80, 20], [80, 70], [20, 70]], float)
    out = overlays.draw_quads(img, [quad], thickness=1)
    assert out.shape == (100, 120, 3)
    assert out[20, 50].any() and out[45, 80].any()  # on two sides of the outline
    assert not out[45, 50].any() and not out[95, 5].any()  # inside and far outside: untouched


def test_draw_quads_validation():
    img = np.zeros((10, 10), np.uint8)
    with pytest.raises(InputError, match="quad 0 must be 4 finite"):
        overlays.draw_quads(img, [np.zeros((3, 2))])
    with pytest.raises(InputError, match="one entry per quad"):
        overlays.draw_quads(img, [np.zeros((4, 2))], ["a", "b"])
    with pytest.raises(InputError, match="`image` must be"):
        overlays.draw_quads(np.zeros((10, 10), np.float32), [])


def test_disparity_colormap_marks_invalid_black_and_adds_a_bar():
    d = np.tile(np.linspace(0, 63, 80, dtype=np.float32), (50, 1))
    d[10:20, 10:20] = np.nan
    out = overlays.disparity_colormap(d, max_disp=63, bar_width=60)
    assert out.shape == (50, 80 + 60, 3) and out.dtype == np.uint8
    assert (out[10:20, 10:20] == 0).all()  # invalid = black
    assert not (out[30, :80] == 0).all(axis=1).any()  # every valid pixel has a colour
    # monotone scale: the turbo map's low end is blue-ish (B > R), its high end red-ish (R > B)
    lo, hi = out[30, 0].astype(int), out[30, 79].astype(int)
    assert lo[0] > lo[2] and hi[2] > hi[0]
    with pytest.raises(InputError, match="non-empty \\(H, W\\)"):
        overlays.disparity_colormap(np.zeros((2, 2, 2)))
