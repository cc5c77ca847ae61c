"""Panorama exposure compensation kinds (gain, channels, blocks, channel_blocks), the seam colour measure of the
benchmark, and the canvas memory budget."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cvpipe import panorama
from cvpipe.errors import InputError
from cvpipe.params import PanoramaBlendParams
from cvpipe.samples import fit, photo

from test_panorama import _two_constant, views  # noqa: F401 - fixtures used below


# ---- exposure compensation kinds (OpenCV's compensators: gain, channels, blocks, channel_blocks) ----

#: per-channel (B, G, R) gain of the second view against the first: a colour cast like exposure_error's sky
CAST = np.array([1.0, 0.8, 1.2])
LEFT, RIGHT = (slice(None), slice(0, 80)), (slice(None), slice(220, 300))  # each view alone, away from the seam


@pytest.fixture(scope="module")
def scene() -> np.ndarray:
    """A 300x160 photo darkened to 60 % (+20) so that no value scaled by ``CAST`` saturates, float64."""
    return fit(photo("astronaut"), 300, 160).astype(np.float64) * 0.6 + 20


def _cast_pair(scene: np.ndarray, gain_of_row=None) -> panorama.Warped:
    """Two 160x200 crops of ``scene`` overlapping over 100 columns; the second one's channels scaled by ``CAST``
    (and by ``gain_of_row(y)`` per row when given)."""
    a, b = scene[:, :200], scene[:, 100:] * CAST
    if gain_of_row is not None:
        b = b * gain_of_row(np.arange(160))[:, None, None]
    full = np.full((160, 200), 255, np.uint8)
    views = [np.clip(v + 0.5, 0, 255).astype(np.uint8) for v in (a, b)]
    return panorama.Warped(views, [full, full.copy()], [(0, 0), (100, 0)], (300, 160), (0, 0))


def _seam_cast(left: np.ndarray, right: np.ndarray, scene: np.ndarray) -> float:
    """Colour cast between the two sides of the seam: the largest relative difference of the (B, G, R) shares of the
    right side's mean colour and the left side's, each first divided by the shares of the same part of ``scene`` (so
    the scene's own colours cancel). 0 for views that differ by an exposure only, ~0.2 for ``CAST``."""
    def shares(img, truth):
        m, t = (x.reshape(-1, 3).astype(np.float64).mean(0) for x in (img, truth))
        return (m / m.sum()) / (t / t.sum())

    return float(np.abs(shares(right, scene[RIGHT]) / shares(left, scene[LEFT]) - 1).max())


def test_channel_gains_recover_a_per_channel_cast(scene):
    w = _cast_pair(scene)
    # a negligible prior (sigma_g = 1000) leaves the data term alone: the overlaps' channel means are equalised, so
    # g_b / g_a per channel = 1 / CAST; 1 % covers the uint8 rounding of the views (0.5 grey level in ~80)
    g = panorama.compensation_gains(w, "channels", sigma_g=1e3)
    np.testing.assert_allclose(g[1] / g[0], 1.0 / CAST, rtol=0.01)
    # the default prior (sigma_g = 0.1) keeps the gains near 1 and moves every channel the right way
    g = panorama.compensation_gains(w, "channels")
    assert np.all(np.abs(g - 1) < 0.2) and np.all(np.sign(g[1] / g[0] - 1) == np.sign(1 / CAST - 1))
    assert panorama.compensation_gains(w, "gain").shape == (2,)  # one grey gain per image cannot remove a cast


def test_channel_gains_leave_no_colour_cast_across_the_seam(scene):
    w = _cast_pair(scene)
    before = _seam_cast(w.images[0][:, :80], w.images[1][:, 120:], scene)
    assert before > 0.15  # CAST moves the G and R shares by ~20 %
    labels = panorama.seam_labels(w)
    exact = panorama.blend_multiband(w, labels, 5, panorama.compensation_gains(w, "channels", sigma_g=1e3))
    # fully equalised channels: both sides of the blend show one colour balance, within 3 % (the gains are within
    # 1 %, see above, and the coarsest pyramid level, 2^5 px, still mixes the views 70 px away from the seam)
    assert _seam_cast(exact[LEFT], exact[RIGHT], scene) < 0.03
    # the default prior balances gains near 1 against equal overlap means (Brown & Lowe's sigma_n = 10, sigma_g =
    # 0.1): at these ~80 grey levels about half of the cast goes (the 2x2 normal equations per channel give
    # 0.8 -> ~0.9); a single grey gain removes none of it
    pano, _, _ = panorama.compose(w, "multiband", 5, "channels")
    grey, _, _ = panorama.compose(w, "multiband", 5, "gain")
    assert _seam_cast(pano[LEFT], pano[RIGHT], scene) < 0.65 * before
    assert _seam_cast(grey[LEFT], grey[RIGHT], scene) > 0.9 * before


def test_block_gains_follow_an_exposure_that_varies_across_the_image(scene):
    # the second view also darkens from top (x1.15) to bottom (x0.85): one gain per channel cannot follow that,
    # a smooth map of gains over 32-pixel blocks can
    w = _cast_pair(scene, lambda y: 1.15 - 0.3 * y / 159)
    kw = {"sigma_g": 1e3}
    channels = panorama.overlap_difference(w, panorama.compensation_gains(w, "channels", **kw))
    blocks = panorama.overlap_difference(w, panorama.compensation_gains(w, "channel_blocks", 32, **kw))
    grey_blocks = panorama.overlap_difference(w, panorama.compensation_gains(w, "blocks", 32, **kw))
    before = panorama.overlap_difference(w)
    # (the grey-level difference hardly sees the cast itself: G x0.8 and R x1.2 almost cancel in grey)
    assert blocks < 0.5 * min(channels, before) and grey_blocks < 0.5 * min(channels, before)
    maps = panorama.compensation_gains(w, "channel_blocks", 32)
    assert [m.shape for m in maps] == [(160, 200, 3), (160, 200, 3)]
    # the second view's map rises from top to bottom (it undoes the darkening), smoothly: no jump between pixels
    # larger than a block's share of the 0.3 ramp
    col = maps[1][:, 100, 1]
    assert col[-1] > col[0] and np.abs(np.diff(col)).max() < 0.3 * 32 / 160


def test_gain_choices_are_checked():
    w = _two_constant(100, 120)
    with pytest.raises(ValueError, match="`gain_compensation` must be one of"):
        panorama.compensation_gains(w, "rgb")
    with pytest.raises(ValueError, match="`gain_block` must be an integer >= 4"):
        panorama.compensation_gains(w, "blocks", 2)
    with pytest.raises(ValueError, match="`gain_compensation` must be one of"):
        PanoramaBlendParams(gain_compensation="rgb")
    with pytest.raises(ValueError, match="`gain_block` must be in"):
        PanoramaBlendParams(gain_block=2)
    assert panorama.compensation_gains(w, "none") is None
    assert panorama.overlap_difference(w, None) == panorama.overlap_difference(w)


def test_bench_seam_colour_difference_separates_brightness_from_cast():
    from cvpipe.bench import panorama as bench

    labels = np.zeros((100, 400), np.int16)
    labels[:, 200:] = 1
    labels[:, :10] = -1  # uncovered border: the sides must stay clear of it
    left = np.full((100, 200, 3), 120, np.uint8)
    same = bench.seam_colour_difference(np.hstack([left, left]), labels)
    assert same["delta_e"] == pytest.approx(0.0, abs=1e-6) and same["rows"] == 25  # the top quarter of the rows
    # a neutral grey step changes L* only: a clear delta E, no cast (a*, b* of greys are 0 up to float32 rounding)
    step = bench.seam_colour_difference(np.hstack([left, np.full((100, 200, 3), 160, np.uint8)]), labels)
    assert step["delta_e"] > 10 and step["delta_ab"] < 0.1
    # the same brightness with less green on the right: a cast that delta ab shows
    cast = bench.seam_colour_difference(np.hstack([left, np.full((100, 200, 3), (120, 100, 120), np.uint8)]),
                                        labels)
    assert cast["delta_ab"] > 5
    assert bench.seam_colour_difference(left, np.zeros((100, 200), np.int16)) is None  # no seam


def test_canvas_over_the_memory_budget_is_refused_naming_what_to_change(views, monkeypatch):
    imgs, _ = views
    pano = panorama.stitch(imgs, rng=0)  # the default 4 GB budget: these ~0.2 MP canvases are far below it
    comp = panorama.compose_inputs(imgs, pano.registration, [(i.shape[1], i.shape[0]) for i in imgs], -1)
    w = panorama.warp.warp_images(comp.images, comp.G, "cylindrical", comp.focal, comp.ref_size, 200.0)
    boxes = np.array([(x, y, x + m.shape[1], y + m.shape[0]) for m, (x, y) in zip(w.masks, w.corners)])
    need = panorama.warp.canvas_memory(w.size, boxes)
    # the estimate counts at least the canvas arrays of the blend (20 B) and the collapse (15 B) per canvas pixel
    assert need >= 35 * w.size[0] * w.size[1]
    # a budget just under the estimate: refused before anything is warped, with one line naming what to change
    monkeypatch.setenv("CVPIPE_MEMORY_BUDGET_GB", str((need - 1000) / 1e9))
    with pytest.raises(InputError) as err:
        panorama.warp.warp_images(comp.images, comp.G, "cylindrical", comp.focal, comp.ref_size, 200.0)
    msg = str(err.value)
    assert "\n" not in msg
    for name in ("canvas would be", "over the memory budget", "`panorama.warp.compose_megapix`",
                 "`max_canvas_megapix` 200", "CVPIPE_MEMORY_BUDGET_GB"):
        assert name in msg, (name, msg)
    # stitch() goes through the same check: a tiny budget refuses the whole stitch the same way
    monkeypatch.setenv("CVPIPE_MEMORY_BUDGET_GB", "0.001")
    with pytest.raises(InputError, match="canvas would be .* over the memory budget of 0.001 GB"):
        panorama.stitch(imgs, rng=0)
    # a budget just over the estimate warps as before
    monkeypatch.setenv("CVPIPE_MEMORY_BUDGET_GB", str((need + 1000) / 1e9))
    again = panorama.warp.warp_images(comp.images, comp.G, "cylindrical", comp.focal, comp.ref_size, 200.0)
    assert again.size == w.size and all(np.array_equal(a, b) for a, b in zip(again.images, w.images))


def test_canvas_memory_estimate_bounds_the_measured_multiband_peak(views):
    import tracemalloc

    imgs, _ = views
    pano = panorama.stitch(imgs, rng=0)
    comp = panorama.compose_inputs(imgs, pano.registration, [(i.shape[1], i.shape[0]) for i in imgs], -1)
    tracemalloc.start()  # numpy (and OpenCV's output arrays, allocated through numpy) report to tracemalloc
    try:
        w = panorama.warp.warp_images(comp.images, comp.G, "plane", comp.focal, comp.ref_size, 200.0)
        panorama.compose(w, "multiband", PanoramaBlendParams().bands)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    boxes = np.array([(x, y, x + m.shape[1], y + m.shape[0]) for m, (x, y) in zip(w.masks, w.corners)])
    need = panorama.warp.canvas_memory(w.size, boxes)
    # an upper bound (the budget check must not let a canvas through that does not fit), but within 1.5x of the
    # measured peak (a looser bound would refuse canvases that fit); measured 1.15-1.25x on these views
    assert peak <= need <= 1.5 * peak, (peak, need)


#: runs the stitch command, then reports the peak resident memory of its own process on stderr (ru_maxrss, KiB)
_PEAK_RSS_LAUNCHER = """
import resource, runpy, sys
sys.argv = ["cvpipe", *sys.argv[1:]]
try:
    runpy.run_module("cvpipe.cli", run_name="__main__")
finally:
    print("peak_rss_kib", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)
"""


@pytest.mark.slow
def test_81_megapixel_stitch_peaks_under_the_memory_budget(tmp_path):
    import os
    import subprocess
    import sys

    # the sweep's 81 MP case (tests/test_sweep.py): a 9000 x 9000 texture stitched to itself (under a second name)
    rng = np.random.default_rng(0)
    img = cv2.resize(rng.integers(0, 256, (300, 300), dtype=np.uint8), (9000, 9000), interpolation=cv2.INTER_LINEAR)
    for _ in range(40):
        x, y = (int(v) for v in rng.integers(0, 8000, 2))
        cv2.rectangle(img, (x, y), (x + 900, y + 600), int(rng.integers(0, 256)), 9)
    big = tmp_path / "big81.png"
    cv2.imwrite(str(big), img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    del img
    twin = tmp_path / "big81_b.png"  # the same bytes under a second name: one path given twice is refused
    os.link(big, twin)
    budget_gb = 4.0
    env = dict(os.environ, CVPIPE_MEMORY_BUDGET_GB=str(budget_gb))
    proc = subprocess.run([sys.executable, "-c", _PEAK_RSS_LAUNCHER, "stitch", str(big), str(twin), "-o",
                           str(tmp_path / "pano.png")], capture_output=True, text=True, env=env, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-500:]
    assert "memory budget" in proc.stderr  # composed at a reduced size, and said so
    peak = int(proc.stderr.rsplit("peak_rss_kib", 1)[1].split()[0]) * 1024
    # the whole process (interpreter, OpenCV, the decoded 81 MP inputs and the blend) stays within the budget
    # it was given; measured 3.50 GB
    assert peak < budget_gb * 1e9, peak / 1e9
    pano = cv2.imread(str(tmp_path / "pano.png"))
    assert pano is not None and min(pano.shape[:2]) > 1000  # a real panorama came out
