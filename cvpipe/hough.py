"""Hough line detection: the standard transform with ``cv2.HoughLines`` semantics, a probabilistic variant and metrics.

``hough_lines`` reproduces OpenCV's ``HoughLinesStandard`` cell for cell and vote for vote:

- accumulator geometry: ``numrho = round((2 (w + h) + 1) / rho)`` rho bins centred on ``(numrho - 1) // 2``, and
  ``numangle`` angles from ``min_theta`` in steps of ``theta`` (the last angle is dropped when it would repeat
  ``min_theta + pi``);
- trigonometric table in single precision: the angle accumulates in float32, ``sin``/``cos`` are evaluated in double
  and multiplied by the float32 ``1 / rho`` before rounding back to float32;
- each edge pixel (column ``x``, row ``y``) votes once per angle into bin ``rint(x cos' + y sin')`` with float32
  arithmetic and round-half-to-even (OpenCV's ``cvRound``);
- a cell is a line when its votes exceed ``threshold`` and it beats its 4 neighbours (strictly the lower rho and the
  lower angle, at least equal to the higher rho and the higher angle; cells outside the accumulator count 0);
- lines are sorted by votes, descending, ties by angle index, then rho index (OpenCV's ``hough_cmp_gt``);
- output ``rho = (r - (numrho - 1) // 2) * rho`` and ``theta = min_theta + n * theta`` in float32. The integer
  division is OpenCV >= 4.13 / 5.0 (PR #27992); before it, the centre was ``(numrho - 1) * 0.5``.

The voting kernel is numba with cached compilation: per angle, the rho bins of all edge pixels are computed in one
vectorised pass, then counted into four interleaved histograms (so consecutive increments of the same bin do not
wait on each other). Blocks of angles run on parallel threads when a core is free; each thread owns whole
accumulator rows, so there are no write races. ``hough_lines_probabilistic`` is our progressive probabilistic Hough transform
(Matas et al. 2000) returning segments like ``cv2.HoughLinesP``; it is seeded and reproducible but, like OpenCV's,
its result depends on the random point order, so it is not expected to match OpenCV's segment for segment.
"""

from __future__ import annotations

import functools
import math
import os
import time
from dataclasses import dataclass

import cv2
import numba
import numpy as np
from numba import njit, prange

from .errors import InputError, check_memory

__all__ = [
    "HoughGrid",
    "hough_grid",
    "hough_accumulator",
    "hough_lines",
    "hough_lines_opencv",
    "IMPLEMENTATIONS",
    "get_impl",
    "hough_lines_probabilistic",
    "canny_edges",
    "line_cells",
    "cell_agreement",
    "line_segment_matches",
    "segment_segment_matches",
    "truth_matches",
    "draw_lines",
    "draw_segments",
    "median_seconds",
]


# ------------------------------------------------------------------------------------------------- validation


def _check_edges(edges: np.ndarray) -> np.ndarray:
    """Return ``edges`` as a C-contiguous 2-D uint8 array (nonzero = edge), or raise naming the problem."""
    if not isinstance(edges, np.ndarray):
        raise InputError(f"`edges` must be a numpy array, got {type(edges).__name__}")
    if edges.ndim != 2:
        raise InputError(f"`edges` must be a 2-D (H, W) image, got shape {edges.shape}")
    if edges.size == 0:
        raise InputError(f"`edges` must not be empty, got shape {edges.shape}")
    if edges.dtype == np.bool_:
        return np.ascontiguousarray(edges).view(np.uint8)
    if edges.dtype != np.uint8:
        raise InputError(f"`edges` must be uint8 or bool (nonzero = edge), got dtype {edges.dtype}")
    return np.ascontiguousarray(edges)


def _check_positive(name: str, value: float) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"`{name}` must be a number, got {value!r}")
    if not math.isfinite(float(value)) or value <= 0:
        raise InputError(f"`{name}` must be > 0, got {value}")
    return float(value)


def _check_int(name: str, value: int, lo: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputError(f"`{name}` must be an integer, got {value!r}")
    if value < lo:
        raise InputError(f"`{name}` must be >= {lo}, got {value}")
    return int(value)


# ------------------------------------------------------------------------------------------------- geometry


@dataclass(frozen=True, eq=False)
class HoughGrid:
    """The accumulator geometry that ``cv2.HoughLines`` uses for an image of the given size.

    Attributes
    ----------
    numrho, numangle : int
        Accumulator size (rho bins x angle bins, without OpenCV's one-cell zero border).
    rho, theta, min_theta : float
        Bin sizes in pixels and radians as float32 values, and the first angle (float32).
    tab_cos, tab_sin : ndarray, shape (numangle,), float32
        ``cos(angle_n) / rho`` and ``sin(angle_n) / rho`` exactly as OpenCV tabulates them.
    """

    numrho: int
    numangle: int
    rho: float
    theta: float
    min_theta: float
    tab_cos: np.ndarray
    tab_sin: np.ndarray

    @property
    def center(self) -> int:
        """Index of the rho bin of rho = 0."""
        return (self.numrho - 1) // 2

    def rhos(self, r: np.ndarray) -> np.ndarray:
        """rho in pixels (float32) of rho bin indices ``r``."""
        return (np.asarray(r, np.int64) - self.center).astype(np.float32) * np.float32(self.rho)

    def thetas(self, n: np.ndarray) -> np.ndarray:
        """theta in radians (float32) of angle bin indices ``n``."""
        return np.float32(self.min_theta) + np.asarray(n, np.int64).astype(np.float32) * np.float32(self.theta)


def hough_grid(
    shape: tuple[int, int], rho: float = 1.0, theta: float = np.pi / 180, min_theta: float = 0.0,
    max_theta: float = np.pi,
) -> HoughGrid:
    """Accumulator geometry of ``cv2.HoughLines`` for an image of ``shape`` (H, W).

    Parameters
    ----------
    shape : (int, int)
        Image height and width in pixels.
    rho : float
        Distance resolution in pixels, > 0.
    theta : float
        Angle resolution in radians, in (0, pi].
    min_theta, max_theta : float
        Angle range in radians, 0 <= min_theta <= max_theta <= pi.

    Returns
    -------
    HoughGrid
    """
    rho = _check_positive("rho", rho)
    theta = _check_positive("theta", theta)
    if theta > np.pi:
        raise InputError(f"`theta` must be in (0, pi], got {theta}")
    for name, value in (("min_theta", min_theta), ("max_theta", max_theta)):
        if not isinstance(value, (int, float, np.integer, np.floating)) or not math.isfinite(float(value)):
            raise InputError(f"`{name}` must be a finite number, got {value!r}")
    if not 0.0 <= min_theta <= max_theta <= np.pi:
        raise InputError(f"need 0 <= `min_theta` <= `max_theta` <= pi, got min_theta={min_theta}, max_theta={max_theta}")
    # the accumulator is (angles + 2) x (distances + 2) int32, plus two float32 tables per angle: bounded before
    # anything is allocated (a tiny step would otherwise grow it to tens of GB)
    numangle = math.floor((max_theta - min_theta) / float(np.float32(theta))) + 1
    numrho = round((2 * (int(shape[0]) + int(shape[1])) + 1) / float(np.float32(rho)))
    check_memory((numangle + 2.0) * (numrho + 2.0) * 4 + numangle * 8.0,
                 f"the Hough accumulator ({numangle} angles x {numrho} distances)",
                 "raise the angle step `theta` (`--theta-deg`) or the distance step `rho` (`--rho`)")
    return _grid(int(shape[0]), int(shape[1]), float(rho), float(theta), float(min_theta), float(max_theta))


@functools.lru_cache(maxsize=64)
def _grid(h: int, w: int, rho: float, theta: float, min_theta: float, max_theta: float) -> HoughGrid:
    rho32, theta32 = np.float32(rho), np.float32(theta)
    step = float(theta32)  # OpenCV passes theta to HoughLinesStandard as float
    numangle = int(math.floor((max_theta - min_theta) / step)) + 1
    if numangle > 1 and abs(math.pi - (numangle - 1) * step) < step / 2:
        numangle -= 1
    # OpenCV's cvRound(double) rounds half to even; Python's round() does too
    numrho = int(round((2 * (w + h) + 1) / float(rho32)))
    irho = np.float32(1.0) / rho32
    # the angle accumulates in float32 one step at a time; add.accumulate is sequential, so it rounds the same way
    steps = np.full(numangle, theta32, np.float32)
    steps[0] = np.float32(min_theta)
    ang = np.add.accumulate(steps, dtype=np.float32).astype(np.float64)
    tab_cos = (np.cos(ang) * float(irho)).astype(np.float32)
    tab_sin = (np.sin(ang) * float(irho)).astype(np.float32)
    tab_cos.flags.writeable = False
    tab_sin.flags.writeable = False
    return HoughGrid(numrho, numangle, float(rho32), float(theta32), float(np.float32(min_theta)), tab_cos, tab_sin)


# ------------------------------------------------------------------------------------------------- numba kernels


@njit(cache=True)
def _edge_points(edges):
    """Coordinates (float32 x, float32 y) of the nonzero pixels in row-major order."""
    h, w = edges.shape
    count = 0
    for i in range(h):
        for j in range(w):
            count += edges[i, j] != 0
    # counted first: an (H * W) buffer would cost 8 bytes per pixel of a large, sparse edge map
    xs = np.empty(count, np.float32)
    ys = np.empty(count, np.float32)
    k = 0
    for i in range(h):
        for j in range(w):
            if edges[i, j] != 0:
                xs[k] = j
                ys[k] = i
                k += 1
    return xs, ys


@njit(cache=True)
def _vote_rows(xs, ys, tab_cos, tab_sin, acc, n_start, n_stop):
    """Fill accumulator rows ``n_start .. n_stop - 1`` (angles) of ``acc`` (with its zero border)."""
    numrho = acc.shape[1] - 2
    off = (numrho - 1) // 2 + 1
    npts = xs.shape[0]
    idx = np.empty(npts, np.int32)
    hist = np.zeros((4, numrho + 2), np.int32)
    full = npts - npts % 4
    for n in range(n_start, n_stop):
        c = tab_cos[n]
        s = tab_sin[n]
        # float32 products and sum, then round half to even: OpenCV's cvRound(j * tabCos[n] + i * tabSin[n]);
        # this loop vectorises
        for k in range(npts):
            idx[k] = np.int32(np.rint(xs[k] * c + ys[k] * s)) + off
        # four interleaved histograms: neighbouring pixels hit the same bin, and a single histogram would make every
        # increment wait for the previous one
        hist[:] = 0
        for k in range(0, full, 4):
            hist[0, idx[k]] += 1
            hist[1, idx[k + 1]] += 1
            hist[2, idx[k + 2]] += 1
            hist[3, idx[k + 3]] += 1
        for k in range(full, npts):
            hist[0, idx[k]] += 1
        for r in range(numrho + 2):
            acc[n + 1, r] = hist[0, r] + hist[1, r] + hist[2, r] + hist[3, r]


@njit(cache=True)
def _vote_serial(xs, ys, tab_cos, tab_sin, numrho):
    """Accumulator with OpenCV's one-cell zero border, shape (numangle + 2, numrho + 2), int32; one thread."""
    numangle = tab_cos.shape[0]
    acc = np.zeros((numangle + 2, numrho + 2), np.int32)
    _vote_rows(xs, ys, tab_cos, tab_sin, acc, 0, numangle)
    return acc


@njit(cache=True, parallel=True)
def _vote_parallel(xs, ys, tab_cos, tab_sin, numrho, nchunks):
    """As ``_vote_serial``, with the angles split into ``nchunks`` blocks voted in parallel."""
    numangle = tab_cos.shape[0]
    acc = np.zeros((numangle + 2, numrho + 2), np.int32)
    nchunks = max(1, min(nchunks, numangle))
    for chunk in prange(nchunks):
        # each block owns whole accumulator rows, so threads never write to the same cell
        _vote_rows(xs, ys, tab_cos, tab_sin, acc, chunk * numangle // nchunks, (chunk + 1) * numangle // nchunks)
    return acc


@njit(cache=True)
def _peaks(acc, threshold):
    """Angle index, rho index and votes of OpenCV's local maxima, sorted like ``hough_cmp_gt``."""
    na = acc.shape[0] - 2
    nr = acc.shape[1] - 2
    width = np.int64(nr + 2)
    cells = np.int64(na + 2) * width
    count = 0
    for n in range(1, na + 1):
        for r in range(1, nr + 1):
            v = acc[n, r]
            if (v > threshold and v > acc[n, r - 1] and v >= acc[n, r + 1]
                    and v > acc[n - 1, r] and v >= acc[n + 1, r]):
                count += 1
    bases = np.empty(count, np.int64)
    k = 0
    vmax = 0
    for n in range(1, na + 1):
        for r in range(1, nr + 1):
            v = acc[n, r]
            if (v > threshold and v > acc[n, r - 1] and v >= acc[n, r + 1]
                    and v > acc[n - 1, r] and v >= acc[n + 1, r]):
                bases[k] = n * width + r
                k += 1
                if v > vmax:
                    vmax = v
    # more votes first, then the smaller flat index (angle-major), as OpenCV's comparator: one int64 key per peak
    keys = np.empty(count, np.int64)
    for k in range(count):
        b = bases[k]
        keys[k] = np.int64(vmax - acc[b // width, b % width]) * cells + b
    keys.sort()
    ns = np.empty(count, np.int64)
    rs = np.empty(count, np.int64)
    votes = np.empty(count, np.int64)
    for k in range(count):
        b = keys[k] % cells
        ns[k] = b // width - 1
        rs[k] = b % width - 1
        votes[k] = acc[ns[k] + 1, rs[k] + 1]
    return ns, rs, votes


# ------------------------------------------------------------------------------------------------- standard


def _use_parallel(parallel: bool | None) -> bool:
    """Resolve ``parallel=None``: vote in parallel only when the machine has a core to spare.

    On a machine whose cores are busy with other work, a parallel vote waits at its barrier for a descheduled thread
    and is slower than one thread; the 1-minute load average is the cheap signal for that.
    """
    if parallel is not None:
        return bool(parallel)
    now = time.monotonic()
    if now - _AUTO_PARALLEL[0] > 1.0:  # asking costs ~0.1 ms, so at most once a second
        try:
            spare = os.getloadavg()[0] <= (os.cpu_count() or 1) - 0.5
        except OSError:  # pragma: no cover - platforms without a load average
            spare = True
        _AUTO_PARALLEL[:] = [now, spare and numba.get_num_threads() >= 2]
    return bool(_AUTO_PARALLEL[1])


#: [time of the last look (monotonic s), whether to vote in parallel]
_AUTO_PARALLEL: list = [-math.inf, False]


def hough_accumulator(edges: np.ndarray, grid: HoughGrid, parallel: bool | None = None) -> np.ndarray:
    """Vote the edge pixels of ``edges`` into the accumulator of ``grid``.

    Parameters
    ----------
    edges : ndarray, shape (H, W), uint8 or bool
        Edge map; nonzero pixels vote.
    grid : HoughGrid
        From ``hough_grid(edges.shape, ...)``.
    parallel : bool or None
        True votes blocks of angles on all numba threads, False on one thread (faster when the cores are busy),
        None picks parallel when the load average leaves a core free. The accumulator is the same either way.

    Returns
    -------
    ndarray, shape (numangle + 2, numrho + 2), int32
        Votes per (angle, rho) cell, with OpenCV's zero border: cell (n, r) is at ``[n + 1, r + 1]``.
    """
    edges = _check_edges(edges)
    xs, ys = _edge_points(edges)
    threads = numba.get_num_threads() if _use_parallel(parallel) else 1
    if threads > 1:
        return _vote_parallel(xs, ys, grid.tab_cos, grid.tab_sin, grid.numrho, threads)
    return _vote_serial(xs, ys, grid.tab_cos, grid.tab_sin, grid.numrho)


@njit(cache=True)
def _refine_fit(xs, ys, rhos, thetas, band, iterations):
    """Total-least-squares line through the edge pixels within ``band`` px of each line; (rho, theta) float64."""
    out_r = rhos.copy()
    out_t = thetas.copy()
    for i in range(rhos.shape[0]):
        rho, theta = rhos[i], thetas[i]
        for _ in range(iterations):
            c, s = math.cos(theta), math.sin(theta)
            cnt = 0
            sx = sy = 0.0
            for k in range(xs.shape[0]):
                if abs(xs[k] * c + ys[k] * s - rho) <= band:
                    cnt += 1
                    sx += xs[k]
                    sy += ys[k]
            if cnt < 3:
                break
            mx, my = sx / cnt, sy / cnt
            cxx = cyy = cxy = 0.0
            for k in range(xs.shape[0]):
                if abs(xs[k] * c + ys[k] * s - rho) <= band:
                    dx, dy = xs[k] - mx, ys[k] - my
                    cxx += dx * dx
                    cyy += dy * dy
                    cxy += dx * dy
            # the normal is the eigenvector of the smaller eigenvalue of the scatter matrix
            phi = 0.5 * math.atan2(2.0 * cxy, cxx - cyy)  # direction of the line
            new_t = phi + 0.5 * math.pi
            # keep the normal on the side of the detected one, then bring theta into [0, pi)
            if math.cos(new_t - theta) < 0:
                new_t += math.pi
            new_r = mx * math.cos(new_t) + my * math.sin(new_t)
            new_t = new_t % (2.0 * math.pi)
            if new_t >= math.pi:
                new_t -= math.pi
                new_r = -new_r
            rho, theta = new_r, new_t
        out_r[i] = rho
        out_t[i] = theta
    return out_r, out_t


def hough_lines(
    edges: np.ndarray,
    rho: float = 1.0,
    theta: float = np.pi / 180,
    threshold: int = 150,
    *,
    min_theta: float = 0.0,
    max_theta: float = np.pi,
    max_lines: int | None = None,
    refine: bool = False,
    parallel: bool | None = None,
) -> np.ndarray:
    """Standard Hough transform with the semantics of ``cv2.HoughLines`` (see the module docstring).

    Parameters
    ----------
    edges : ndarray, shape (H, W), uint8 or bool
        Edge map; nonzero pixels vote (x = column, y = row).
    rho : float
        Distance resolution in pixels, > 0.
    theta : float
        Angle resolution in radians, in (0, pi].
    threshold : int
        A cell is a line when it has more than ``threshold`` votes; >= 1.
    min_theta, max_theta : float
        Angle range in radians, as ``cv2.HoughLines``.
    max_lines : int or None
        Keep only the first ``max_lines`` lines (OpenCV's C++ ``linesMax``; Python's cv2 has no cap).
    refine : bool
        Replace each line's (rho, theta) by the total-least-squares line through the edge pixels within
        max(1.5, rho) px of it (two rounds; votes unchanged). Sub-bin accurate, but no longer the cell centres that
        ``cv2.HoughLines`` reports; theta stays in [0, pi).
    parallel : bool or None
        Vote on all numba threads (``numba.set_num_threads`` limits them), on one (False), or decide from the load
        average (None). The result is the same.

    Returns
    -------
    ndarray, shape (N, 3), float64
        ``[rho (px), theta (rad), votes]`` per line, sorted by votes (descending). Without ``refine`` the values are
        the float32 numbers that ``cv2.HoughLinesWithAccumulator`` returns, exactly.
    """
    edges = _check_edges(edges)
    threshold = _check_int("threshold", threshold, 1)
    if max_lines is not None:
        max_lines = _check_int("max_lines", max_lines, 1)
    grid = hough_grid(edges.shape, rho, theta, min_theta, max_theta)
    acc = hough_accumulator(edges, grid, parallel)
    ns, rs, votes = _peaks(acc, threshold)
    if max_lines is not None:
        ns, rs, votes = ns[:max_lines], rs[:max_lines], votes[:max_lines]
    rho_out, theta_out = grid.rhos(rs), grid.thetas(ns)
    if refine and len(ns):
        xs, ys = _edge_points(edges)
        band = max(1.5, grid.rho)
        rho_out, theta_out = _refine_fit(xs.astype(np.float64), ys.astype(np.float64), rho_out.astype(np.float64),
                                         theta_out.astype(np.float64), band, 2)
    out = np.empty((len(votes), 3), np.float64)
    out[:, 0] = rho_out
    out[:, 1] = theta_out
    out[:, 2] = votes
    return out


def hough_lines_opencv(
    edges: np.ndarray, rho: float = 1.0, theta: float = np.pi / 180, threshold: int = 150, *,
    min_theta: float = 0.0, max_theta: float = np.pi,
) -> np.ndarray:
    """``cv2.HoughLinesWithAccumulator`` with our validation and output layout ((N, 3) float64, no lines -> (0, 3))."""
    edges = _check_edges(edges)
    threshold = _check_int("threshold", threshold, 1)
    hough_grid(edges.shape, rho, theta, min_theta, max_theta)  # same validation as ours
    lines = cv2.HoughLinesWithAccumulator(edges, float(rho), float(theta), threshold,
                                          min_theta=float(min_theta), max_theta=float(max_theta))
    if lines is None:
        return np.zeros((0, 3), np.float64)
    return lines.reshape(-1, 3).astype(np.float64)


#: implementation name -> standard Hough function with the signature of ``hough_lines``
IMPLEMENTATIONS = {"ours": hough_lines, "opencv": hough_lines_opencv}


def get_impl(name: str):
    """The standard Hough function registered as ``name`` in ``IMPLEMENTATIONS``."""
    if name not in IMPLEMENTATIONS:
        raise InputError(f"`impl` must be one of {sorted(IMPLEMENTATIONS)}, got {name!r}")
    return IMPLEMENTATIONS[name]


# ------------------------------------------------------------------------------------------------- probabilistic


@njit(cache=True)
def _ppht(edges, order, tab_cos, tab_sin, numrho, threshold, min_length, max_gap, max_lines):
    """Progressive probabilistic Hough transform; returns (K, 4) int32 segments x1, y1, x2, y2."""
    h, w = edges.shape
    numangle = tab_cos.shape[0]
    acc = np.zeros((numangle, numrho), np.int32)
    mask = np.zeros((h, w), np.uint8)
    voted = np.zeros((h, w), np.uint8)
    xs = np.empty(order.shape[0], np.int64)
    ys = np.empty(order.shape[0], np.int64)
    k = 0
    for i in range(h):
        for j in range(w):
            if edges[i, j] != 0:
                mask[i, j] = 1
                xs[k] = j
                ys[k] = i
                k += 1
    off = (numrho - 1) // 2
    out = np.empty((max_lines, 4), np.int32)
    nout = 0
    ends = np.empty((2, 2), np.int64)
    tend = np.zeros(2, np.int64)
    for idx in order:
        x = xs[idx]
        y = ys[idx]
        if mask[y, x] == 0:
            continue
        fx = np.float32(x)
        fy = np.float32(y)
        best = threshold - 1
        best_n = -1
        for n in range(numangle):
            r = np.int64(np.rint(fx * tab_cos[n] + fy * tab_sin[n])) + off
            acc[n, r] += 1
            if acc[n, r] > best:
                best = acc[n, r]
                best_n = n
        voted[y, x] = 1
        if best_n < 0:
            continue
        # direction along the line: perpendicular to the normal (cos, sin); step one pixel on the major axis
        dx0 = -np.float64(tab_sin[best_n])
        dy0 = np.float64(tab_cos[best_n])
        if abs(dx0) >= abs(dy0):
            sx, sy = 1.0 if dx0 > 0 else -1.0, dy0 / abs(dx0)
        else:
            sx, sy = dx0 / abs(dy0), 1.0 if dy0 > 0 else -1.0
        for side in range(2):
            sgn = 1.0 if side == 0 else -1.0
            gap = 0
            ends[side, 0] = x
            ends[side, 1] = y
            tend[side] = 0
            t = 1
            while True:
                px = int(math.floor(x + sgn * sx * t + 0.5))
                py = int(math.floor(y + sgn * sy * t + 0.5))
                if px < 0 or px >= w or py < 0 or py >= h:
                    break
                if mask[py, px] != 0:
                    gap = 0
                    ends[side, 0] = px
                    ends[side, 1] = py
                    tend[side] = t
                else:
                    gap += 1
                    if gap > max_gap:
                        break
                t += 1
        good = max(abs(ends[1, 0] - ends[0, 0]), abs(ends[1, 1] - ends[0, 1])) >= min_length
        # clear the pixels of the walked segment; a kept segment also takes back their votes
        for side in range(2):
            sgn = 1.0 if side == 0 else -1.0
            for t in range(0 if side == 0 else 1, tend[side] + 1):
                px = int(math.floor(x + sgn * sx * t + 0.5))
                py = int(math.floor(y + sgn * sy * t + 0.5))
                if mask[py, px] != 0:
                    if good and voted[py, px] != 0:
                        qx = np.float32(px)
                        qy = np.float32(py)
                        for n in range(numangle):
                            r = np.int64(np.rint(qx * tab_cos[n] + qy * tab_sin[n])) + off
                            acc[n, r] -= 1
                        voted[py, px] = 0
                    mask[py, px] = 0
        if good:
            out[nout, 0] = ends[0, 0]
            out[nout, 1] = ends[0, 1]
            out[nout, 2] = ends[1, 0]
            out[nout, 3] = ends[1, 1]
            nout += 1
            if nout == max_lines:
                break
    return out[:nout].copy()


def hough_lines_probabilistic(
    edges: np.ndarray,
    rho: float = 1.0,
    theta: float = np.pi / 180,
    threshold: int = 50,
    min_line_length: float = 30.0,
    max_line_gap: float = 5.0,
    *,
    max_lines: int = 100_000,
    rng: int | np.random.Generator | None = None,
) -> np.ndarray:
    """Our progressive probabilistic Hough transform (segments, like ``cv2.HoughLinesP``).

    Edge pixels are visited in random order; each votes (with the same accumulator geometry as ``hough_lines``).
    When a vote lifts a cell above ``threshold``, the line of that cell is followed in both directions from the
    pixel across gaps of at most ``max_line_gap`` pixels; the pixels passed are removed from further voting, and
    if the run is at least ``min_line_length`` long it becomes a segment and its pixels' votes are taken back.
    Unlike OpenCV, only pixels that have voted are un-voted, so the accumulator never goes negative.

    Parameters
    ----------
    edges : ndarray, shape (H, W), uint8 or bool
        Edge map; nonzero pixels vote.
    rho, theta : float
        Accumulator resolution in pixels and radians.
    threshold : int
        Votes a cell needs to exceed before its line is followed; >= 1.
    min_line_length : float
        Shortest segment kept, in pixels along the major axis; >= 0.
    max_line_gap : float
        Longest run of missing pixels bridged, in pixels; >= 0.
    max_lines : int
        Stop after this many segments.
    rng : None, int or numpy Generator
        Random visiting order; ``None`` draws fresh entropy.

    Returns
    -------
    ndarray, shape (K, 4), int32
        Segments ``[x1, y1, x2, y2]`` in pixels, in the order they were found.
    """
    edges = _check_edges(edges)
    threshold = _check_int("threshold", threshold, 1)
    max_lines = _check_int("max_lines", max_lines, 1)
    for name, value in (("min_line_length", min_line_length), ("max_line_gap", max_line_gap)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not math.isfinite(float(value)) or value < 0:
            raise InputError(f"`{name}` must be a number >= 0, got {value!r}")
    grid = hough_grid(edges.shape, rho, theta)
    rng = np.random.default_rng(rng)
    npts = int(np.count_nonzero(edges))
    order = rng.permutation(npts).astype(np.int64)
    return _ppht(edges, order, grid.tab_cos, grid.tab_sin, grid.numrho, threshold,
                 float(min_line_length), int(math.floor(max_line_gap)), min(max_lines, max(npts, 1)))


# ------------------------------------------------------------------------------------------------- edges


def canny_edges(gray: np.ndarray, low: float = 50.0, high: float = 150.0, *, aperture: int = 3,
                l2_gradient: bool = False, blur_sigma: float = 0.0) -> np.ndarray:
    """Canny edge map (uint8, 255 = edge) of a grayscale image, with an optional Gaussian pre-blur.

    Parameters
    ----------
    gray : ndarray, shape (H, W), uint8
        Grayscale image.
    low, high : float
        Hysteresis thresholds on the gradient magnitude, 0 <= low <= high.
    aperture : int
        Sobel aperture: 3, 5 or 7.
    l2_gradient : bool
        Use the L2 gradient norm instead of L1.
    blur_sigma : float
        Gaussian sigma in pixels applied before Canny; 0 = none.
    """
    if not isinstance(gray, np.ndarray) or gray.ndim != 2 or gray.size == 0 or gray.dtype != np.uint8:
        shape = getattr(gray, "shape", None)
        raise InputError(f"`gray` must be a non-empty 2-D uint8 image, got {type(gray).__name__} shape {shape}")
    if not (0 <= low <= high):
        raise InputError(f"need 0 <= `low` <= `high`, got low={low}, high={high}")
    if aperture not in (3, 5, 7):
        raise InputError(f"`aperture` must be one of [3, 5, 7], got {aperture}")
    if blur_sigma < 0:
        raise InputError(f"`blur_sigma` must be >= 0, got {blur_sigma}")
    if blur_sigma > 0:
        gray = cv2.GaussianBlur(gray, (0, 0), blur_sigma)
    return cv2.Canny(gray, float(low), float(high), apertureSize=aperture, L2gradient=bool(l2_gradient))


# ------------------------------------------------------------------------------------------------- metrics


def _as_lines(lines: np.ndarray) -> np.ndarray:
    """``lines`` as a float64 (N, k) array with k >= 2 (an empty input becomes (0, 3))."""
    arr = np.asarray(lines, np.float64)
    if arr.size == 0:
        return np.zeros((0, 3), np.float64)
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise InputError(f"`lines` must have shape (N, 2) or (N, 3), got {arr.shape}")
    return arr


def line_cells(lines: np.ndarray, rho: float = 1.0, theta: float = np.pi / 180, min_theta: float = 0.0) -> np.ndarray:
    """Accumulator cell (angle index, rho index relative to rho = 0) of each line, shape (N, 2) int64."""
    lines = _as_lines(lines)
    rho32, theta32 = float(np.float32(rho)), float(np.float32(theta))
    n = np.rint((lines[:, 1] - float(np.float32(min_theta))) / theta32).astype(np.int64)
    r = np.rint(lines[:, 0] / rho32).astype(np.int64)
    return np.stack([n, r], axis=1)


def cell_agreement(ours: np.ndarray, ref: np.ndarray, rho: float = 1.0, theta: float = np.pi / 180,
                   min_theta: float = 0.0) -> dict:
    """How many of the reference lines ``ref`` appear in the same accumulator cell in ``ours``.

    Returns
    -------
    dict
        ``reproduced`` (count), ``ref_lines``, ``our_lines``, ``parity`` (reproduced / ref_lines; 1.0 when both are
        empty), ``same_votes`` (reproduced lines whose votes agree too), ``same_order`` (identical cell sequence).
    """
    ours, ref = _as_lines(ours), _as_lines(ref)
    a = line_cells(ours, rho, theta, min_theta)
    b = line_cells(ref, rho, theta, min_theta)
    ours_map = {tuple(c): i for i, c in enumerate(a.tolist())}
    votes = ours.shape[1] > 2 and ref.shape[1] > 2
    reproduced = same_votes = 0
    for j, c in enumerate(b.tolist()):
        i = ours_map.get(tuple(c))
        if i is not None:
            reproduced += 1
            same_votes += int(votes and ours[i, 2] == ref[j, 2])
    parity = reproduced / len(b) if len(b) else (1.0 if len(a) == 0 else 0.0)
    return {"reproduced": reproduced, "ref_lines": len(b), "our_lines": len(a), "parity": parity,
            "same_votes": same_votes, "same_order": bool(len(a) == len(b) and np.array_equal(a, b))}


def _undirected_angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.abs(a - b) % np.pi
    return np.minimum(d, np.pi - d)


def line_segment_matches(lines: np.ndarray, segments: np.ndarray, dist_px: float = 2.0,
                         angle_deg: float = 1.0) -> np.ndarray:
    """Which ground-truth segments some (infinite) Hough line passes along.

    A segment is found when a line makes an angle of at most ``angle_deg`` with it and both of its end points lie
    within ``dist_px`` of the line.

    Parameters
    ----------
    lines : ndarray, shape (N, >=2)
        ``[rho, theta, ...]`` in cv2.HoughLines conventions.
    segments : ndarray, shape (M, 4)
        ``[x1, y1, x2, y2]`` in 0-based pixel coordinates.

    Returns
    -------
    ndarray, shape (M,), bool
    """
    segments = np.asarray(segments, np.float64).reshape(-1, 4)
    lines = np.asarray(lines, np.float64)
    if len(lines) == 0 or len(segments) == 0:
        return np.zeros(len(segments), bool)
    rho, th = lines[:, 0][:, None], lines[:, 1][:, None]
    c, s = np.cos(th), np.sin(th)
    d1 = np.abs(segments[:, 0] * c + segments[:, 1] * s - rho)
    d2 = np.abs(segments[:, 2] * c + segments[:, 3] * s - rho)
    seg_dir = np.arctan2(segments[:, 3] - segments[:, 1], segments[:, 2] - segments[:, 0])
    ang = _undirected_angle_diff(th + np.pi / 2, seg_dir[None, :])
    ok = (d1 <= dist_px) & (d2 <= dist_px) & (ang <= np.deg2rad(angle_deg))
    return ok.any(axis=0)


def segment_segment_matches(found: np.ndarray, segments: np.ndarray, dist_px: float = 2.0, angle_deg: float = 1.0,
                            min_overlap: float = 0.5) -> np.ndarray:
    """Which ground-truth segments a detected segment covers.

    A ground-truth segment is found when a detected segment makes an angle of at most ``angle_deg`` with it, both
    ground-truth end points lie within ``dist_px`` of the detected segment's line, and the detected segment, projected
    onto the ground-truth segment, covers at least ``min_overlap`` of its length.

    Parameters
    ----------
    found, segments : ndarray, shape (N, 4) and (M, 4)
        ``[x1, y1, x2, y2]`` in 0-based pixel coordinates.

    Returns
    -------
    ndarray, shape (M,), bool
    """
    segments = np.asarray(segments, np.float64).reshape(-1, 4)
    found = np.asarray(found, np.float64).reshape(-1, 4)
    if len(found) == 0 or len(segments) == 0:
        return np.zeros(len(segments), bool)
    fdx, fdy = found[:, 2] - found[:, 0], found[:, 3] - found[:, 1]
    flen = np.hypot(fdx, fdy)
    flen = np.where(flen > 0, flen, 1.0)
    nx, ny = (-fdy / flen)[:, None], (fdx / flen)[:, None]
    off = (found[:, 0] * nx[:, 0] + found[:, 1] * ny[:, 0])[:, None]
    d1 = np.abs(segments[:, 0] * nx + segments[:, 1] * ny - off)
    d2 = np.abs(segments[:, 2] * nx + segments[:, 3] * ny - off)
    ang = _undirected_angle_diff(np.arctan2(fdy, fdx)[:, None],
                                 np.arctan2(segments[:, 3] - segments[:, 1], segments[:, 2] - segments[:, 0])[None, :])
    gdx, gdy = segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1]
    glen = np.hypot(gdx, gdy)
    gl = np.where(glen > 0, glen, 1.0)
    ux, uy = gdx / gl, gdy / gl
    t1 = (found[:, 0][:, None] - segments[:, 0]) * ux + (found[:, 1][:, None] - segments[:, 1]) * uy
    t2 = (found[:, 2][:, None] - segments[:, 0]) * ux + (found[:, 3][:, None] - segments[:, 1]) * uy
    lo, hi = np.maximum(np.minimum(t1, t2), 0.0), np.minimum(np.maximum(t1, t2), glen)
    cover = np.clip(hi - lo, 0.0, None) >= min_overlap * glen
    ok = (d1 <= dist_px) & (d2 <= dist_px) & (ang <= np.deg2rad(angle_deg)) & cover
    return ok.any(axis=0)


def truth_matches(lines: np.ndarray, truth: np.ndarray, rho_tol: float = 3.0, theta_tol: float = np.deg2rad(1.5)
                  ) -> np.ndarray:
    """Which true lines ``truth`` (M, 2) ``[rho, theta]`` a detected line (N, >=2) lies within tolerance of.

    (rho, theta) and (-rho, theta - pi) are the same line, so lines near theta = 0 and theta = pi are compared both
    ways. Returns (M,) bool.
    """
    truth = np.asarray(truth, np.float64).reshape(-1, 2)
    lines = np.asarray(lines, np.float64)
    if len(lines) == 0 or len(truth) == 0:
        return np.zeros(len(truth), bool)
    r, t = lines[:, 0][:, None], lines[:, 1][:, None]
    dt = np.abs(t - truth[:, 1])
    direct = (dt <= theta_tol) & (np.abs(r - truth[:, 0]) <= rho_tol)
    flipped = (np.abs(dt - np.pi) <= theta_tol) & (np.abs(r + truth[:, 0]) <= rho_tol)
    return (direct | flipped).any(axis=0)


def draw_lines(image: np.ndarray, lines: np.ndarray, color: tuple[int, int, int] = (0, 0, 255),
               thickness: int = 1) -> np.ndarray:
    """A BGR copy of ``image`` with the infinite lines ``[rho, theta, ...]`` drawn across it."""
    out = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    reach = 2 * (out.shape[0] + out.shape[1])
    for rho, theta in _as_lines(lines)[:, :2]:
        c, s = math.cos(theta), math.sin(theta)
        x0, y0 = rho * c, rho * s
        p1 = (int(round(x0 - reach * s)), int(round(y0 + reach * c)))
        p2 = (int(round(x0 + reach * s)), int(round(y0 - reach * c)))
        cv2.line(out, p1, p2, color, thickness, cv2.LINE_AA)
    return out


def draw_segments(image: np.ndarray, segments: np.ndarray, color: tuple[int, int, int] = (0, 255, 0),
                  thickness: int = 1) -> np.ndarray:
    """A BGR copy of ``image`` with the segments ``[x1, y1, x2, y2]`` drawn on it."""
    out = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    for x1, y1, x2, y2 in np.asarray(segments, np.int64).reshape(-1, 4):
        cv2.line(out, (int(x1), int(y1)), (int(x2), int(y2)), color, thickness, cv2.LINE_AA)
    return out


def median_seconds(fn, repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls after ``warmup`` untimed calls, in seconds."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def compare_runs(ours: dict, opencv: dict, truth: dict | None = None, rho_tol: float = 3.0,
                 theta_tol: float = np.deg2rad(1.5)) -> dict:
    """Agreement and truth recall of two ``hough_lines`` stage results (see ``stages/hough_lines.py``).

    Parameters
    ----------
    ours, opencv : dict
        ``{"rho", "theta", "images": [{"file", "lines": [[rho, theta, votes]]}]}`` per implementation.
    truth : dict or None
        Image stem -> (N, 2) true ``[rho, theta]`` lines, for the images that have truth.

    Returns
    -------
    dict
        ``per_image`` entries and the summary: ``parity_min``/``parity_mean`` (share of OpenCV's lines in the same
        cell), ``identical_images`` (same lines, votes and order) and, when any image has truth,
        ``recall_ours``/``recall_opencv`` (true lines found within the tolerances) and ``truth_images``.
    """
    from pathlib import PurePath

    stem = lambda name: PurePath(name).stem  # noqa: E731 - edge maps are PNGs of the same stem as the inputs
    ref = {stem(i["file"]): i for i in opencv["images"]}
    true = truth or {}
    rows, found = [], {"ours": [], "opencv": []}
    for mine in ours["images"]:
        name = stem(mine["file"])
        if name not in ref:
            raise InputError(f"image {name!r} is in ours but not in the opencv run")
        a, b = _as_lines(mine["lines"]), _as_lines(ref[name]["lines"])
        agree = cell_agreement(a, b, ours["rho"], ours["theta"])
        row = {"file": name, **agree, "identical": bool(a.shape == b.shape and np.array_equal(a, b))}
        if name in true:
            for key, lines in (("ours", a), ("opencv", b)):
                hit = truth_matches(lines, np.asarray(true[name], dtype=float).reshape(-1, 2), rho_tol, theta_tol)
                row[f"truth_found_{key}"] = int(hit.sum())
                found[key].append(hit)
            row["truth_lines"] = len(true[name])
        rows.append(row)
    parity = [r["parity"] for r in rows]
    out = {"images": len(rows), "parity_min": min(parity, default=1.0), "parity_mean": float(np.mean(parity or [1.0])),
           "identical_images": sum(r["identical"] for r in rows), "truth_images": len(found["ours"]),
           "per_image": rows}
    for key, hits in found.items():
        if hits:
            out[f"recall_{key}"] = float(np.concatenate(hits).mean()) if sum(map(len, hits)) else 1.0
    return out


def metrics_of(compared: dict) -> dict:
    """The flat numeric metrics of :func:`compare_runs` output, namespaced by image (``{"hough": {...}}``)."""
    summary = {k: v for k, v in compared.items() if k != "per_image"}
    per_image = {r["file"]: {k: (int(v) if isinstance(v, bool) else v) for k, v in r.items() if k != "file"}
                 for r in compared["per_image"]}
    return {"hough": {"all": summary, **per_image}}


def report_summary(metrics: dict, ours: dict, opencv: dict, pictures: list[dict], dropped: list[dict]) -> dict:
    """The report page's summary of the hough task (schema in ``cvpipe.report``), from ``compare_runs`` output.

    Parameters
    ----------
    metrics : dict
        ``compare_runs(ours, opencv, truth)``.
    ours, opencv : dict
        The two ``hough_lines`` stage results (for the parameters).
    pictures : list of dict
        ``{"path", "caption"}`` overlays, repo-relative paths.
    dropped : list of dict
        ``{"item", "reason"}`` for every input image that was not processed.
    """
    rows = metrics["per_image"]
    has_truth = metrics["truth_images"] > 0
    methods = []
    for key in ("ours", "opencv"):
        recall = metrics.get(f"recall_{key}")
        methods.append([key, int(sum(r["our_lines" if key == "ours" else "ref_lines"] for r in rows)),
                        metrics["parity_min"] if key == "ours" else 1.0,
                        "no ground truth" if recall is None else round(recall, 4)])
    none = "no ground truth"
    per_image = [[r["file"], r["ref_lines"], r["reproduced"], r["identical"], r.get("truth_found_ours", none),
                  r.get("truth_found_opencv", none), r.get("truth_lines", none)] for r in rows]
    truth_note = (f"{metrics['truth_images']} of {metrics['images']} images have true lines." if has_truth else
                  "These images have no ground truth: the table compares the two implementations only.")
    tables = [
        {"title": "Per method",
         "columns": ["method", "lines", "share of OpenCV's lines reproduced (min over images)",
                     "recall of true lines"],
         "rows": methods},
        {"title": "Per image",
         "columns": ["image", "OpenCV lines", "reproduced by ours", "identical output", "true lines found (ours)",
                     "true lines found (OpenCV)", "true lines"],
         "rows": per_image},
    ]
    if dropped:
        tables.append({"title": "Not processed", "columns": ["input", "reason"],
                       "rows": [[d["item"], d["reason"]] for d in dropped]})
    return {
        "task": "hough",
        "title": "Our standard Hough transform against cv2.HoughLines at identical parameters",
        "description": (
            f"Canny edges of each image, then both transforms with rho {ours['rho']:g} px, theta "
            f"{math.degrees(ours['theta']):g} deg, threshold {ours['threshold']}. Ours reproduces "
            f"{metrics['identical_images']} of {metrics['images']} images exactly (same cells, votes and order). "
            f"{truth_note} Overlays: ours in red (left), OpenCV's in green (right). Times: `dvc plots show` "
            "(outputs/timings) and `cvpipe bench hough`."),
        "pictures": pictures,
        "tables": tables,
    }


def quality_plot(metrics: dict) -> list[dict]:
    """``dvc plots`` rows ``{"image", "method", "lines", "true_found"}``: what each implementation found per image."""
    rows = []
    for r in metrics["per_image"]:
        for key, count in (("ours", r["our_lines"]), ("opencv", r["ref_lines"])):
            rows.append({"image": r["file"], "method": key, "lines": int(count),
                         "true_found": r.get(f"truth_found_{key}")})
    return rows
