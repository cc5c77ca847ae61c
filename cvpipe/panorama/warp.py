"""Warping images into the panorama: canvas bounds and the plane, cylindrical and spherical projections.

Every image ``i`` comes with a homography ``G[i]`` (its pixels -> reference pixels, ``det = 1``). The projections
are parametrisations of the viewing directions of the reference camera ``K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]``
(``cx, cy`` the reference image centre, ``f`` the focal length in pixels):

* ``plane``: panorama coordinates are reference pixels ``(u, v)``;
* ``cylindrical``: ``u = f * theta`` (azimuth), ``v = f * y / sqrt(x^2 + z^2)`` for a ray ``(x, y, z)``;
* ``spherical``: ``u = f * theta``, ``v = f * phi`` (elevation).

For a rotating camera ``G[i] = K R_i K_i^-1``, so the pixel of image ``i`` that sees the reference ray ``r`` is
``G[i]^-1 K r``; that product is evaluated directly, which stays valid for rays the reference plane cannot hold
(beyond 90 degrees from its axis). Sampling is ours (:func:`canvas_to_image` builds the maps), ``cv2.remap`` does
the bilinear interpolation. :func:`compose_inputs` brings the used images and their homographies to the compose
resolution first.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import cv2
import numpy as np

from ..errors import BudgetError, EstimationError, memory_budget
from . import _warp
from .features import _workers, rescale_homographies, resize, resized_size, scale_for

if TYPE_CHECKING:
    from .register import Registration

PROJECTIONS = ("plane", "cylindrical", "spherical")


def check_projection(projection: str) -> None:
    """Raise ``ValueError`` listing the choices when ``projection`` is unknown."""
    if projection not in PROJECTIONS:
        raise ValueError(f"`projection` must be one of {list(PROJECTIONS)}, got {projection!r}")


def camera_matrix(focal: float, ref_size: tuple[int, int]) -> np.ndarray:
    """``K`` of the reference camera: focal ``focal`` pixels, principal point at the image centre."""
    w, h = ref_size
    return np.array([[focal, 0, (w - 1) / 2], [0, focal, (h - 1) / 2], [0, 0, 1.0]])


def image_to_canvas(pts: np.ndarray, G: np.ndarray, projection: str, focal: float,
                    ref_size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Panorama coordinates of image pixels.

    Parameters
    ----------
    pts : (N, 2)
        Pixels of the image.
    G : (3, 3)
        Image -> reference pixels, ``det(G) > 0``.
    projection : {"plane", "cylindrical", "spherical"}
    focal : float
        Reference focal length in pixels (unused for ``plane``).
    ref_size : (w, h)
        Reference image size.

    Returns
    -------
    uv : (N, 2) float64
        Panorama coordinates (not yet shifted to the canvas origin).
    ok : (N,) bool
        False where the point has no image in this projection (behind the reference plane for ``plane``).
    """
    check_projection(projection)
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    ph = np.column_stack([pts, np.ones(len(pts))])
    if projection == "plane":
        p = ph @ G.T
        ok = p[:, 2] > 1e-12 * np.abs(p).max(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return p[:, :2] / p[:, 2:3], ok
    r = ph @ (np.linalg.inv(camera_matrix(focal, ref_size)) @ G).T
    rho = np.hypot(r[:, 0], r[:, 2])
    ok = rho > 1e-12
    theta = np.arctan2(r[:, 0], r[:, 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        v = r[:, 1] / rho if projection == "cylindrical" else np.arctan2(r[:, 1], rho)
    return np.column_stack([focal * theta, focal * v]), ok


def canvas_to_image(u: np.ndarray, v: np.ndarray, G: np.ndarray, projection: str, focal: float,
                    ref_size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image pixels seen at panorama coordinates ``(u, v)``.

    ``u`` and ``v`` are broadcast against each other: a row ``u`` of shape (1, W) and a column ``v`` of shape
    (H, 1) give the (H, W) maps of a whole canvas box while evaluating the trigonometry once per column and row.

    Returns
    -------
    x, y : float arrays of the broadcast shape (float32 when ``u`` is float32)
        Image pixel coordinates.
    ok : bool array
        False where the ray is behind the image's camera.
    """
    M, alpha, chi, beta, gamma = _ray_factors(u, v, G, projection, focal, ref_size)

    def coordinate(m):
        h = m[0] * alpha + m[2] * chi
        return (h if gamma is None else h * gamma) + m[1] * beta

    z = coordinate(M[2])
    ok = z > 1e-12
    zs = np.where(ok, z, M.dtype.type(1))
    return coordinate(M[0]) / zs, coordinate(M[1]) / zs, ok


def _ray_factors(u: np.ndarray, v: np.ndarray, G: np.ndarray, projection: str, focal: float,
                 ref_size: tuple[int, int]) -> tuple:
    """``(M, alpha, chi, beta, gamma)``: the ray at ``(u, v)`` is ``(alpha(u) gamma(v), beta(v), chi(u) gamma(v))``
    (``gamma`` None: 1) and ``M`` (float32 when ``u`` is) takes rays to image pixels."""
    check_projection(projection)
    u, v = np.asarray(u), np.asarray(v)
    dtype = np.float32 if u.dtype == np.float32 else np.float64
    M = np.linalg.inv(G)
    # a ray is (alpha(u) gamma(v), beta(v), chi(u) gamma(v)), so every map coordinate is
    # gamma(v) * (m0 alpha(u) + m2 chi(u)) + m1 beta(v): one outer product per coordinate
    if projection == "plane":
        alpha, chi, beta, gamma = u, np.ones_like(u), v, None
    else:
        M = M @ camera_matrix(focal, ref_size)
        theta = u / dtype(focal)
        alpha, chi = np.sin(theta), np.cos(theta)
        if projection == "cylindrical":
            beta, gamma = v / dtype(focal), None
        else:
            phi = v / dtype(focal)
            beta, gamma = np.sin(phi), np.cos(phi)
    return M.astype(dtype), alpha, chi, beta, gamma


def _border(size: tuple[int, int], per_side: int = 48) -> np.ndarray:
    w, h = size
    t = np.linspace(0, 1, per_side, endpoint=False)
    x1, y1 = w - 1.0, h - 1.0
    return np.concatenate([np.column_stack([t * x1, 0 * t]), np.column_stack([x1 + 0 * t, t * y1]),
                           np.column_stack([x1 - t * x1, y1 + 0 * t]), np.column_stack([0 * t, y1 - t * y1])])


def warp_bounds(sizes: Sequence[tuple[int, int]], G: Sequence[np.ndarray], projection: str, focal: float,
                ref_size: tuple[int, int]) -> np.ndarray:
    """Integer panorama-coordinate boxes ``[x0, y0, x1, y1]`` (inclusive-exclusive) of every warped image.

    Raises
    ------
    EstimationError
        When part of an image has no place in the projection (``plane`` beyond 180 degrees).
    """
    boxes = []
    for k, (size, Gi) in enumerate(zip(sizes, G)):
        uv, ok = image_to_canvas(_border(size), Gi, projection, focal, ref_size)
        if not ok.all() or not np.isfinite(uv).all():
            raise EstimationError(
                f"warped image {k} reaches behind the reference view, which the `{projection}` projection cannot "
                "hold; use projection cylindrical or spherical")
        lo, hi = np.floor(uv.min(axis=0)), np.ceil(uv.max(axis=0)) + 1
        boxes.append([lo[0], lo[1], hi[0], hi[1]])
    return np.array(boxes, np.int64)


@dataclass(frozen=True)
class Warped:
    """Images warped into a common canvas.

    Attributes
    ----------
    images : list of (h_i, w_i, 3) uint8
        Each warped image, cut to its box.
    masks : list of (h_i, w_i) uint8
        255 where the warped image has a pixel.
    corners : list of (x, y)
        Top-left canvas pixel of each box.
    size : (W, H)
        Canvas size in pixels.
    origin : (x, y)
        Panorama coordinates of canvas pixel (0, 0).
    """

    images: list
    masks: list
    corners: list
    size: tuple
    origin: tuple


#: canvas pixels warped per strip by :func:`warp_image` (bounds its temporary float maps to a few tens of MB)
WARP_STRIP_PIXELS = 1 << 20


def warp_image(img: np.ndarray, G: np.ndarray, box: Sequence[int], projection: str, focal: float,
               ref_size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Warp one image onto the panorama box ``[x0, y0, x1, y1]``.

    Returns
    -------
    warped : (y1 - y0, x1 - x0[, 3]) uint8
    mask : (y1 - y0, x1 - x0) uint8, 255 where the image has a pixel
    """
    x0, y0, x1, y1 = (int(b) for b in box)
    warped = np.empty((y1 - y0, x1 - x0) + img.shape[2:], img.dtype)
    mask = np.empty((y1 - y0, x1 - x0), np.uint8)
    # float32 keeps 1e-3 px precision on canvases of thousands of pixels at half the cost
    u = np.arange(x0, x1, dtype=np.float32)
    h, w = img.shape[:2]
    # in strips of rows: the float maps of a whole box cost 8 B per pixel, a strip's stay small and are reused
    rows = max(1, min(y1 - y0, WARP_STRIP_PIXELS // max(1, x1 - x0)))
    mx, my = np.empty((rows, x1 - x0), np.float32), np.empty((rows, x1 - x0), np.float32)
    channels = 1 if img.ndim == 2 else img.shape[2]
    for r0 in range(y0, y1, rows):
        r1 = min(y1, r0 + rows)
        v = np.arange(r0, r1, dtype=np.float32)
        M, alpha, chi, beta, gamma = _ray_factors(u, v, G, projection, focal, ref_size)
        gamma = np.ones_like(beta) if gamma is None else gamma
        n, ok = r1 - r0, mask[r0 - y0:r1 - y0]
        # the maps as canvas_to_image computes them, with half a pixel of slack (the border samples themselves
        # belong to the image), -10 where the image has no pixel; in one compiled pass without temporaries
        _warp.canvas_maps(alpha, chi, beta, gamma, M, w - 0.5, h - 0.5, mx[:n], my[:n], ok)
        out = warped[r0 - y0:r1 - y0]
        cv2.remap(img, mx[:n], my[:n], cv2.INTER_LINEAR, dst=out, borderMode=cv2.BORDER_REPLICATE)
        _warp.clear_outside(out.reshape(n, -1), ok, channels)
    return warped, mask


def warp_images(images: Sequence[np.ndarray], G: Sequence[np.ndarray], projection: str, focal: float,
                ref_size: tuple[int, int], max_canvas_megapix: float) -> Warped:
    """Warp every image into one canvas.

    Parameters
    ----------
    images : sequence of (h, w, 3) uint8
    G : sequence of (3, 3)
        Each image's pixels -> reference pixels (same resolution as ``images``), ``det > 0``.
    projection : {"plane", "cylindrical", "spherical"}
    focal : float
        Reference focal length in pixels.
    ref_size : (w, h)
        Reference image size.
    max_canvas_megapix : float
        Refuse canvases larger than this (a plane projection of a wide view explodes).

    Raises
    ------
    EstimationError
        Canvas too large or views the projection cannot hold.
    BudgetError
        Warping and blending the canvas would exceed the memory budget (:func:`check_canvas_memory`).
    """
    check_projection(projection)
    if not focal > 0:
        raise ValueError(f"`focal` must be positive, got {focal}")
    sizes = [(im.shape[1], im.shape[0]) for im in images]
    boxes = warp_bounds(sizes, G, projection, focal, ref_size)
    ox, oy = int(boxes[:, 0].min()), int(boxes[:, 1].min())
    W, H = int(boxes[:, 2].max()) - ox, int(boxes[:, 3].max()) - oy
    if W * H > max_canvas_megapix * 1e6:
        raise EstimationError(
            f"the {projection} canvas would be {W}x{H} pixels (> max_canvas_megapix {max_canvas_megapix}); the "
            "views are too wide for this projection: use cylindrical or spherical, or lower compose_megapix")
    check_canvas_memory((W, H), boxes, projection, max_canvas_megapix)
    # one image per thread: cv2.remap and numpy's arithmetic on large arrays release the GIL
    with ThreadPoolExecutor(_workers()) as pool:
        done = list(pool.map(lambda k: warp_image(images[k], G[k], boxes[k], projection, focal, ref_size),
                             range(len(images))))
    corners = [(int(box[0]) - ox, int(box[1]) - oy) for box in boxes]
    return Warped([d[0] for d in done], [d[1] for d in done], corners, (W, H), (ox, oy))


#: pixels the multiband blend adds to each side of a box and of the canvas (``2 * 2**bands`` of padding and up to
#: ``2**bands`` of rounding; the default 5 bands: 64 + 32)
BLEND_PAD = 96
#: bytes per canvas pixel that stay allocated through the multiband blend (``blend.blend_multiband`` and
#: ``seams.seam_labels``), counted from the arrays they allocate: over the padded canvas, the float32 BGR
#: accumulator pyramid ``acc`` (12 B at level 0 + 12/3 B for the coarser levels) and the float32 weight sums of
#: levels >= 1 (4/3 B), about 17.3 B, rounded up to 18
PADDED_CANVAS_BYTES_PER_PIXEL = 18
#: over the canvas itself, the int16 seam labels
CANVAS_BYTES_PER_PIXEL = 2
#: bytes per pixel of each warped image's box kept until the blend ends: the uint8 BGR image and its mask
WARPED_BYTES_PER_PIXEL = 4
#: bytes per pixel of the padded box of the image being blended, alive while its pyramid is built: float32 image
#: (12 B), the first Laplacian level (12 B), the next Gaussian levels of image, mask and normalised image
#: (3 + 1 + 3 B), the next level's seam weight (1 B), the ownership mask (1 B) and the 3-channel copy of the
#: normaliser (3 B) = 36 B (the full-size float mask and weight are dropped before the Laplacian level exists)
BLEND_BOX_BYTES_PER_PIXEL = 36
#: bytes per pixel when the pyramid collapses at the end of the blend: the full-size float32 BGR result of the
#: last ``pyrUp`` over the padded canvas (12 B; clipped at 0 in place), then over the canvas the uint8 panorama
#: (3 B)
COLLAPSE_PADDED_BYTES_PER_PIXEL, COLLAPSE_BYTES_PER_PIXEL = 12, 3
#: the arrays counted above leave out OpenCV's and numpy's short-lived intermediate results (``np.maximum`` and
#: ``cv2.merge`` copies of the weights, comparison masks): tracemalloc measured peaks up to 10% above the count
#: (3.7 MP canvases), hence this margin
UNCOUNTED_MARGIN = 1.15


def canvas_memory(size: tuple[int, int], boxes: np.ndarray) -> int:
    """Estimated peak bytes of warping into a ``size = (W, H)`` canvas and blending it with multiband blending.

    The warped images and masks (:data:`WARPED_BYTES_PER_PIXEL` per pixel of each box) and the canvas arrays
    (:data:`PADDED_CANVAS_BYTES_PER_PIXEL`, :data:`CANVAS_BYTES_PER_PIXEL`) stay allocated throughout; on top of
    them comes the larger of the pyramid of the image being blended (:data:`BLEND_BOX_BYTES_PER_PIXEL` per pixel of
    its padded box) and the collapse of the accumulated pyramid, times :data:`UNCOUNTED_MARGIN`. For a large
    canvas this comes to 60-80 B per canvas pixel (tracemalloc measured 65-69 B per pixel for 3.7 MP canvases of
    three overlapping views, where the estimate gives 69-74 B); feather blending needs less.

    Parameters
    ----------
    size : (W, H)
        Canvas size in pixels.
    boxes : (N, 4)
        Each warped image's ``(x0, y0, x1, y1)`` box on the canvas.

    Examples
    --------
    >>> canvas_memory((1000, 1000), np.array([[0, 0, 600, 1000], [400, 0, 1000, 1000]]))
    76316134
    """
    W, H = size
    sides = [(int(b[2]) - int(b[0]), int(b[3]) - int(b[1])) for b in boxes]
    canvas, padded = W * H, (W + 2 * BLEND_PAD) * (H + 2 * BLEND_PAD)
    largest = max(((w + 2 * BLEND_PAD) * (h + 2 * BLEND_PAD) for w, h in sides), default=0)
    counted = (padded * PADDED_CANVAS_BYTES_PER_PIXEL + canvas * CANVAS_BYTES_PER_PIXEL
               + sum(w * h for w, h in sides) * WARPED_BYTES_PER_PIXEL
               + max(largest * BLEND_BOX_BYTES_PER_PIXEL,
                     padded * COLLAPSE_PADDED_BYTES_PER_PIXEL + canvas * COLLAPSE_BYTES_PER_PIXEL))
    return int(counted * UNCOUNTED_MARGIN)


def check_canvas_memory(size: tuple[int, int], boxes: np.ndarray, projection: str,
                        max_canvas_megapix: float) -> None:
    """Refuse a canvas whose warp and multiband blend (:func:`canvas_memory`) would exceed the memory budget.

    Raises
    ------
    BudgetError
        One line naming ``panorama.warp.compose_megapix``, ``max_canvas_megapix`` and ``CVPIPE_MEMORY_BUDGET_GB``.
    """
    W, H = size
    need, budget = canvas_memory(size, boxes), memory_budget()
    if need > budget:
        limit = budget / need * W * H / 1e6  # canvas megapixels that would fit, at the same layout
        raise BudgetError(
            f"the {projection} canvas would be {W}x{H} pixels; warping and blending it need about {need / 1e9:.3g} GB, "
            f"over the memory budget of {budget / 1e9:.3g} GB, which holds about {limit:.3g} of the "
            f"`max_canvas_megapix` {max_canvas_megapix:g} megapixels: lower `panorama.warp.compose_megapix` or raise "
            "CVPIPE_MEMORY_BUDGET_GB")


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


def warp_set(item: tuple, p) -> tuple[Warped, dict, float]:
    """Warp one registered set into its canvas: the per-set work of the ``panorama_warp`` stage, an item of
    :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    item : tuple
        ``(registration record, images)``: the set's ``panorama_homographies`` JSON record and its full-size
        images (BGR uint8; None for the images the registration did not use).
    p : PanoramaWarpParams
        ``compose_megapix``, ``projection``, ``max_canvas_megapix``.

    Returns
    -------
    (Warped, dict, float)
        The warped images and masks, the set's ``warp.json`` record (``ok``, ``corners``, ``size``, ``origin``,
        ``G``, ``compose_sizes``, ``used``) and the seconds the warp took.

    Raises
    ------
    EstimationError, BudgetError
        As :func:`compose_inputs` and :func:`warp_images`.
    """
    import time

    from .register import Registration

    h, images = item
    reg = Registration.from_json(h)
    t0 = time.perf_counter()
    comp = compose_inputs(images, reg, [tuple(s) for s in h["work_sizes"]], p.compose_megapix)
    w = warp_images(comp.images, comp.G, p.projection, comp.focal, comp.ref_size, p.max_canvas_megapix)
    seconds = time.perf_counter() - t0
    record = {"ok": True, "corners": w.corners, "size": w.size, "origin": w.origin, "G": np.array(comp.G),
              "compose_sizes": comp.sizes, "used": list(reg.used)}
    return w, record, seconds
