"""The standard Hough transform with ``cv2.HoughLines`` semantics, and OpenCV's own as the baseline.

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

The voting kernel (:mod:`cvpipe.hough._vote`, compiled Cython): the edge pixels are first paired with an
8-neighbour where they have one; per angle, the rho bins of all pixels are computed in one vectorised pass, and each
pair is counted with one histogram increment (by the difference of its two bins, at most 2) and each single pixel
with one, into two copies of each histogram used alternately (so consecutive increments of the same bin do not wait
on each other); the accumulator row is summed from them. Blocks of angles run on parallel OpenMP threads when a core
is free; each thread owns whole accumulator rows, so there are no write races.
"""

from __future__ import annotations

import functools
import math
import os
import time
from dataclasses import dataclass

import cv2
import numpy as np

from .._threads import max_threads
from ..errors import InputError, check_int, check_memory
from ..params import HoughLinesParams, section_or_default
from . import _vote

__all__ = ["HoughGrid", "hough_grid", "hough_accumulator", "hough_lines", "hough_lines_opencv", "IMPLEMENTATIONS",
           "get_impl", "hough_steps", "detect_lines"]

#: the ``hough.lines`` defaults: the one declaration of the accumulator defaults below (theta in radians, the one
#: conversion of a default; :func:`hough_steps` converts a given section)
_LINES = HoughLinesParams()
_THETA = math.radians(_LINES.theta_deg)


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
    shape: tuple[int, int], rho: float = _LINES.rho, theta: float = _THETA, min_theta: float = 0.0,
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

    Examples
    --------
    >>> import numpy as np
    >>> grid = hough_grid((480, 640), rho=1.0, theta=np.pi / 180)
    >>> grid.numangle, grid.numrho, grid.center  # numrho = round(2 (480 + 640) + 1)
    (180, 2241, 1120)
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


# ------------------------------------------------------------------------------------------------- standard


#: fewer votes than this (edge pixels x angles) are cast on one thread. On 2 cores (OpenMP with passive waiting, see
#: :mod:`cvpipe`; random line drawings in 300 x 300 and 640 x 480, best of 81 calls, load average 1.4-1.5) both
#: threads break even with one at 0.2M votes and take 0.65-0.87x its time at 0.37-0.55M (the samples' drawings:
#: 0.5M), 0.64-0.74x at 0.9-1M (York Urban photos: 1.5-13M)
_PARALLEL_MIN_VOTES = 250_000


def _use_parallel(parallel: bool | None) -> bool:
    """Resolve ``parallel=None``: vote in parallel only when the machine has a core to spare (and, decided by the
    kernel, for at least ``_PARALLEL_MIN_VOTES`` votes).

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
        _AUTO_PARALLEL[:] = [now, spare and max_threads() >= 2]
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
        True votes blocks of angles on all OpenMP threads, False on one thread (faster when the cores are busy),
        None picks parallel when the load average leaves a core free. The accumulator is the same either way.

    Returns
    -------
    ndarray, shape (numangle + 2, numrho + 2), int32
        Votes per (angle, rho) cell, with OpenCV's zero border: cell (n, r) is at ``[n + 1, r + 1]``.

    Examples
    --------
    >>> import numpy as np
    >>> edges = np.zeros((60, 80), np.uint8)
    >>> edges[20, :] = 255  # the row y = 20: theta = 90 deg, rho = 20 px, 80 pixels
    >>> grid = hough_grid(edges.shape)
    >>> acc = hough_accumulator(edges, grid, parallel=False)
    >>> int(acc[90 + 1, grid.center + 20 + 1])  # angle 90, rho 20, behind the one-cell border
    80
    """
    edges = _check_edges(edges)
    threads = max_threads() if _use_parallel(parallel) else 1
    min_votes = _PARALLEL_MIN_VOTES if parallel is None else 0
    return _vote.vote(edges, grid.tab_cos, grid.tab_sin, grid.numrho, threads, min_votes)


def hough_lines(
    edges: np.ndarray,
    rho: float = _LINES.rho,
    theta: float = _THETA,
    threshold: int = _LINES.threshold,
    *,
    min_theta: float = 0.0,
    max_theta: float = np.pi,
    max_lines: int | None = None,
    refine: bool = _LINES.refine,
    parallel: bool | None = None,
) -> np.ndarray:
    """Standard Hough transform with the semantics of ``cv2.HoughLines`` (see :mod:`cvpipe.hough.transform`).

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
        Vote on all OpenMP threads (``OMP_NUM_THREADS`` or :func:`cvpipe._threads.set_max_threads` limits them), on
        one (False), or decide from the load average (None). The result is the same.

    Returns
    -------
    ndarray, shape (N, 3), float64
        ``[rho (px), theta (rad), votes]`` per line, sorted by votes (descending). Without ``refine`` the values are
        the float32 numbers that ``cv2.HoughLinesWithAccumulator`` returns, exactly.

    Examples
    --------
    >>> import numpy as np
    >>> edges = np.zeros((60, 80), np.uint8)
    >>> edges[20, :] = 255  # the row y = 20: theta = 90 deg, rho = 20 px, 80 pixels
    >>> hough_lines(edges, 1.0, np.pi / 180, 60).tolist()
    [[20.0, 1.5707963705062866, 80.0]]
    """
    edges = _check_edges(edges)
    threshold = check_int("threshold", threshold, 1)
    if max_lines is not None:
        max_lines = check_int("max_lines", max_lines, 1)
    grid = hough_grid(edges.shape, rho, theta, min_theta, max_theta)
    acc = hough_accumulator(edges, grid, parallel)
    ns, rs, votes = _vote.peaks(acc, threshold)
    if max_lines is not None:
        ns, rs, votes = ns[:max_lines], rs[:max_lines], votes[:max_lines]
    rho_out, theta_out = grid.rhos(rs), grid.thetas(ns)
    if refine and len(ns):
        xs, ys = _vote.edge_points(edges)
        band = max(1.5, grid.rho)
        rho_out, theta_out = _vote.refine_fit(xs.astype(np.float64), ys.astype(np.float64),
                                              rho_out.astype(np.float64), theta_out.astype(np.float64), band, 2)
    out = np.empty((len(votes), 3), np.float64)
    out[:, 0] = rho_out
    out[:, 1] = theta_out
    out[:, 2] = votes
    return out


def hough_lines_opencv(
    edges: np.ndarray, rho: float = _LINES.rho, theta: float = _THETA, threshold: int = _LINES.threshold, *,
    min_theta: float = 0.0, max_theta: float = np.pi,
) -> np.ndarray:
    """``cv2.HoughLinesWithAccumulator`` with our validation and output layout ((N, 3) float64, no lines -> (0, 3)).

    Examples
    --------
    >>> import numpy as np
    >>> edges = np.zeros((60, 80), np.uint8)
    >>> edges[20, :] = 255  # the row y = 20: theta = 90 deg, rho = 20 px, 80 pixels
    >>> lines = hough_lines_opencv(edges, 1.0, np.pi / 180, 60)
    >>> lines.tolist()
    [[20.0, 1.5707963705062866, 80.0]]
    >>> np.array_equal(lines, hough_lines(edges, 1.0, np.pi / 180, 60))
    True
    """
    edges = _check_edges(edges)
    threshold = check_int("threshold", threshold, 1)
    hough_grid(edges.shape, rho, theta, min_theta, max_theta)  # same validation as ours
    lines = cv2.HoughLinesWithAccumulator(edges, float(rho), float(theta), threshold,
                                          min_theta=float(min_theta), max_theta=float(max_theta))
    if lines is None:
        return np.zeros((0, 3), np.float64)
    return lines.reshape(-1, 3).astype(np.float64)


#: implementation name -> standard Hough function with the signature of ``hough_lines``
IMPLEMENTATIONS = {"ours": hough_lines, "opencv": hough_lines_opencv}


def get_impl(name: str):
    """The standard Hough function registered as ``name`` in ``IMPLEMENTATIONS``.

    Examples
    --------
    >>> get_impl("opencv") is hough_lines_opencv
    True
    >>> sorted(IMPLEMENTATIONS)
    ['opencv', 'ours']
    """
    if name not in IMPLEMENTATIONS:
        raise InputError(f"`impl` must be one of {sorted(IMPLEMENTATIONS)}, got {name!r}")
    return IMPLEMENTATIONS[name]


def hough_steps(params: HoughLinesParams | None = None) -> tuple[float, float]:
    """The accumulator steps of the ``hough.lines`` section in this package's units: ``(rho in pixels, theta in
    radians)``, the one place where the section's ``theta_deg`` becomes the radians of ``cv2.HoughLines``.

    Examples
    --------
    >>> from cvpipe.params import HoughLinesParams
    >>> hough_steps(HoughLinesParams(rho=2.0, theta_deg=90.0))
    (2.0, 1.5707963267948966)
    """
    p = section_or_default(params, HoughLinesParams, "hough.lines")
    return p.rho, math.radians(p.theta_deg)


def detect_lines(edges: np.ndarray, params: HoughLinesParams | None = None, method: str = "ours", *,
                 parallel: bool | None = None) -> np.ndarray:
    """The lines of ``edges`` with the ``hough.lines`` parameters, by ``method`` (a key of :data:`IMPLEMENTATIONS`).

    The entry point of the ``hough_lines`` stage: ``rho``, ``theta_deg`` (converted by :func:`hough_steps`) and
    ``threshold`` go to :func:`hough_lines` or :func:`hough_lines_opencv`; ``refine`` applies to ``ours`` only
    (OpenCV has no refinement) and ``repeats`` is the stage's timing count, not used here.

    Parameters
    ----------
    edges : ndarray, shape (H, W), uint8 or bool
        Edge map; nonzero pixels vote.
    params : HoughLinesParams or None
        The ``hough.lines`` section (None: its defaults).
    method : {"ours", "opencv"}
    parallel : bool or None
        Passed to :func:`hough_lines` (``ours`` only).

    Returns
    -------
    ndarray, shape (N, 3), float64
        ``[rho (px), theta (rad), votes]`` per line, as :func:`hough_lines`.

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.params import HoughLinesParams
    >>> edges = np.zeros((60, 80), np.uint8)
    >>> edges[20, :] = 255  # the row y = 20: theta = 90 deg, rho = 20 px, 80 pixels
    >>> detect_lines(edges, HoughLinesParams(threshold=60)).tolist()
    [[20.0, 1.5707963705062866, 80.0]]
    >>> np.array_equal(detect_lines(edges, HoughLinesParams(threshold=60), "opencv"),
    ...                hough_lines(edges, 1.0, np.pi / 180, 60))
    True
    """
    p = HoughLinesParams() if params is None else params
    fn = get_impl(method)
    rho, theta = hough_steps(p)
    if fn is hough_lines:
        return hough_lines(edges, rho, theta, p.threshold, refine=p.refine, parallel=parallel)
    return fn(edges, rho, theta, p.threshold)
