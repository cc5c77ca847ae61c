"""From disparity to depth, point clouds and pictures a person reads.

All functions are pure: arrays in, arrays or bytes out (the command writes the bytes with ``cvpipe.io``).
Depth follows the Middlebury convention ``Z = focal * baseline / (d + doffs)``, in the unit of the baseline.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..errors import InputError


def _check_disp(disp) -> np.ndarray:
    d = np.asarray(disp)
    if d.ndim != 2 or not np.issubdtype(d.dtype, np.floating):
        raise InputError(f"`disp` must be a 2-D float array, got {d.dtype} {d.shape}")
    return d


def depth_from_disparity(disp, focal: float, baseline: float, doffs: float = 0.0) -> np.ndarray:
    """Depth of every pixel, ``Z = focal * baseline / (d + doffs)``.

    Parameters
    ----------
    disp : (H, W) float
        Disparity in pixels, NaN = invalid.
    focal : float
        Focal length in pixels (> 0).
    baseline : float
        Distance between the camera centres (> 0); depth comes out in its unit.
    doffs : float
        Difference of the principal points' columns (right minus left), pixels.

    Returns
    -------
    (H, W) float32
        Depth; NaN where the disparity is NaN, where ``d + doffs <= 0`` (a point at or beyond infinity) and where
        the depth is not a positive finite float32 (it rounds to 0 or overflows).

    Raises
    ------
    InputError
        ``focal``, ``baseline`` or ``doffs`` out of range, or a disparity with valid pixels none of which has a
        usable depth (every depth would be inf, 0 or undefined): the calibration does not fit the disparity.
    """
    d = _check_disp(disp)
    for name, v in (("focal", focal), ("baseline", baseline)):
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
            raise InputError(f"`{name}` must be a finite number > 0, got {v!r}")
    if not (isinstance(doffs, (int, float, np.floating)) and math.isfinite(doffs)):
        raise InputError(f"`doffs` must be finite, got {doffs!r}")
    den = d.astype(np.float64) + float(doffs)
    with np.errstate(all="ignore"):  # a huge focal x baseline or a tiny d + doffs: handled just below
        z = (float(focal) * float(baseline) / den).astype(np.float32)
        usable = (den > 0) & np.isfinite(z) & (z > 0)
    z[~usable] = np.nan
    if not usable.any() and np.isfinite(d).any():
        lo, hi = float(np.nanmin(d)), float(np.nanmax(d))
        raise InputError(f"no pixel has a usable depth: `focal` {focal:g} x `baseline` {baseline:g} / (disparity "
                         f"{lo:g}..{hi:g} + `doffs` {doffs:g}) is 0, inf or undefined (d + doffs <= 0) at every "
                         "pixel; check the calibration")
    return z


def point_cloud(depth, colors, focal: float, cx: float, cy: float) -> tuple[np.ndarray, np.ndarray]:
    """3-D points (pinhole back-projection) and colours of the pixels with a finite depth.

    Parameters
    ----------
    depth : (H, W) float
        Depth, NaN = invalid.
    colors : (H, W, 3) uint8 BGR or (H, W) uint8 gray
        The left image (rectified frame).
    focal, cx, cy : float
        Focal length and principal point, pixels.

    Returns
    -------
    xyz : (N, 3) float32
        ``X = (u - cx) Z / f``, ``Y = (v - cy) Z / f``, ``Z``; x right, y down, z forward (OpenCV camera frame).
        Points whose coordinates overflow float32 are left out.
    rgb : (N, 3) uint8
        Red, green, blue of each point.
    """
    z = np.asarray(depth)
    if z.ndim != 2:
        raise InputError(f"`depth` must be 2-D, got shape {z.shape}")
    c = np.asarray(colors)
    if c.shape[:2] != z.shape or c.dtype != np.uint8 or c.ndim not in (2, 3):
        raise InputError(f"`colors` must be uint8 of shape {z.shape} or {z.shape + (3,)}, got {c.dtype} {c.shape}")
    if not (math.isfinite(focal) and focal > 0):
        raise InputError(f"`focal` must be a finite number > 0, got {focal!r}")
    v, u = np.nonzero(np.isfinite(z))
    Z = z[v, u].astype(np.float64)
    with np.errstate(over="ignore", invalid="ignore"):  # coordinates beyond float32: those points are left out
        xyz = np.column_stack([(u - cx) * Z / focal, (v - cy) * Z / focal, Z]).astype(np.float32)
    keep = np.isfinite(xyz).all(axis=1)
    xyz, v, u = xyz[keep], v[keep], u[keep]
    rgb = np.repeat(c[v, u][:, None], 3, axis=1) if c.ndim == 2 else c[v, u][:, ::-1]
    return xyz, np.ascontiguousarray(rgb, dtype=np.uint8)


_PLY_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])


def ply_bytes(xyz, rgb, comment: str | None = None) -> bytes:
    """A binary little-endian PLY file of coloured points (what MeshLab, CloudCompare and Open3D read).

    Parameters
    ----------
    xyz : (N, 3) float
        Point coordinates (stored as float32).
    rgb : (N, 3) uint8
        Red, green, blue.
    comment : str, optional
        One header comment line (e.g. the unit).

    Returns
    -------
    bytes
        Header (``element vertex N``; properties x, y, z float, red, green, blue uchar) then 15 bytes per point.
    """
    p = np.asarray(xyz)
    c = np.asarray(rgb)
    if p.ndim != 2 or p.shape[1] != 3 or c.shape != p.shape or c.dtype != np.uint8:
        raise InputError(f"`xyz` must be (N, 3) and `rgb` (N, 3) uint8, got {p.shape} and {c.dtype} {c.shape}")
    body = np.empty(len(p), _PLY_DTYPE)
    body["x"], body["y"], body["z"] = p[:, 0], p[:, 1], p[:, 2]
    body["red"], body["green"], body["blue"] = c[:, 0], c[:, 1], c[:, 2]
    lines = ["ply", "format binary_little_endian 1.0"]
    if comment:
        lines.append("comment " + " ".join(str(comment).split()))
    lines += [f"element vertex {len(p)}", "property float x", "property float y", "property float z",
              "property uchar red", "property uchar green", "property uchar blue", "end_header"]
    return ("\n".join(lines) + "\n").encode("ascii") + body.tobytes()


def parse_ply(data: bytes) -> tuple[list[str], np.ndarray]:
    """Header lines and the vertex records of a PLY written by :func:`ply_bytes` (for checks and tests)."""
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise InputError("not a PLY file (no `ply` magic or no `end_header`)")
    header = data[:end].decode("ascii").splitlines()
    n = next(int(h.split()[2]) for h in header if h.startswith("element vertex"))
    body = data[end + len(b"end_header\n"):]
    if len(body) != n * _PLY_DTYPE.itemsize:
        raise InputError(f"PLY body holds {len(body)} bytes, expected {n} x {_PLY_DTYPE.itemsize}")
    return header, np.frombuffer(body, _PLY_DTYPE)


def _nice_ticks(lo: float, hi: float, n: int = 5) -> np.ndarray:
    span = hi - lo
    if not span > 0:
        return np.array([lo])
    raw = span / n
    mag = 10 ** math.floor(math.log10(raw))
    step = min((s * mag for s in (1, 2, 2.5, 5, 10) if s * mag >= raw), default=10 * mag)
    first = math.ceil(lo / step) * step
    return np.arange(first, hi + 1e-9 * span, step)


def colorize(values, lo: float | None = None, hi: float | None = None, unit: str = "px", label: str = "disparity",
             colormap: int = cv2.COLORMAP_TURBO, bar_width: int = 70) -> np.ndarray:
    """A colour-mapped picture of a scalar map with a labelled colour bar on its right.

    Parameters
    ----------
    values : (H, W) float
        Disparity, depth, ...; NaN = invalid (drawn black).
    lo, hi : float, optional
        The values mapped to the ends of the colour map (default: the 1st and 99th percentiles of the finite ones).
    unit : str
        Unit printed under the bar (``"px"``, ``"mm"``, ...).
    label : str
        Quantity printed above the bar.
    colormap : int
        An OpenCV colour map.
    bar_width : int
        Width of the colour bar panel, pixels (>= 40).

    Returns
    -------
    (H, W + bar_width, 3) uint8 BGR
    """
    v = _check_disp(values)
    if bar_width < 40:
        raise InputError(f"`bar_width` must be >= 40 pixels, got {bar_width}")
    finite = np.isfinite(v)
    if lo is None or hi is None:
        q = np.percentile(v[finite], (1, 99)) if finite.any() else np.array([0.0, 1.0])
        lo = float(q[0]) if lo is None else lo
        hi = float(q[1]) if hi is None else hi
    if not hi > lo:
        hi = lo + 1.0
    h, w = v.shape
    scaled = np.zeros(v.shape, np.uint8)
    scaled[finite] = np.clip((v[finite] - lo) / (hi - lo) * 255.0, 0, 255).astype(np.uint8)
    pic = cv2.applyColorMap(scaled, colormap)
    pic[~finite] = 0
    panel = np.full((h, bar_width, 3), 255, np.uint8)
    top, bottom = 22, max(23, h - 22)
    ramp = np.linspace(255, 0, bottom - top).astype(np.uint8)[:, None].repeat(14, axis=1)
    panel[top:bottom, 6:20] = cv2.applyColorMap(ramp, colormap)
    font, fs = cv2.FONT_HERSHEY_SIMPLEX, 0.38
    for t in _nice_ticks(lo, hi):
        y = int(round(bottom - 1 - (t - lo) / (hi - lo) * (bottom - top - 1)))
        cv2.line(panel, (20, y), (24, y), (0, 0, 0), 1)
        cv2.putText(panel, f"{t:g}", (26, y + 4), font, fs, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(panel, label[:10], (2, 14), font, fs, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(panel, f"[{unit}]"[:10], (2, min(h - 6, bottom + 16)), font, fs, (0, 0, 0), 1, cv2.LINE_AA)
    return np.hstack([pic, panel])
