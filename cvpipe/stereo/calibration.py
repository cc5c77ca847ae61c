"""Stereo calibration files: the :class:`Calibration` of a rig and the parsers of a Middlebury ``calib.txt`` and an
OpenCV stereo YAML file. The parsers take the file's text (this module never touches the disk) and the file name
for the messages.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError
from ..io import DEFAULT_MAX_TEXT_BYTES

#: largest calibration text accepted, characters (:func:`cvpipe.io.read_text` caps the file's bytes the same way)
MAX_CALIB_CHARS = DEFAULT_MAX_TEXT_BYTES
#: deepest nesting of brackets, XML elements or YAML blocks accepted (the files OpenCV writes need 3); deeper text
#: is refused before a parser sees it, because OpenCV's parsers recurse once per level and overflow the stack
MAX_NESTING = 64
#: largest image side a calibration may be for, pixels
MAX_SIDE = 1_000_000

_OPEN_CLOSE = np.zeros(256, np.int8)
_OPEN_CLOSE[[ord("["), ord("{")]] = 1
_OPEN_CLOSE[[ord("]"), ord("}")]] = -1
_XML_OPEN = re.compile(rb"<[A-Za-z_:]")
_XML_CLOSE = re.compile(rb"</|/>")
_INDENT = re.compile(r"^[ \t]*(?=\S)", re.M)
_BLOCK_INDICATORS = re.compile(r"^[ \t]*((?:[-?](?:[ \t]+|$))+)", re.M)


def nesting_bound(text: str) -> int:
    """An upper bound on the nesting depth of a YAML, XML or ``calib.txt`` text, in linear time without recursion.

    The bound is the depth of the flow brackets ``[ {`` and of the XML elements (quotes and comments are not
    skipped, so it never underestimates), plus the number of distinct indentations times one more than the most
    block indicators (``- `` / ``? ``) that start one line (how deep YAML blocks can nest).

    Parameters
    ----------
    text : str
        The file's content.

    Returns
    -------
    int
    """
    data = text.encode("utf-8", "surrogatepass")
    if not data:
        return 0
    delta = _OPEN_CLOSE[np.frombuffer(data, np.uint8)].astype(np.int64)
    delta[[m.start() for m in _XML_OPEN.finditer(data)]] += 1
    delta[[m.start() for m in _XML_CLOSE.finditer(data)]] -= 1
    level = np.cumsum(delta)
    # depth with every surplus closing bracket ignored: the level above the lowest point reached so far
    flow = int((level - np.minimum(np.minimum.accumulate(level), 0)).max())
    indents = len(set(_INDENT.findall(text)))
    dashes = max((len(re.findall(r"[-?]", m.group(1))) for m in _BLOCK_INDICATORS.finditer(text)), default=0)
    return flow + indents * (1 + dashes)


def _check_text(text: str, source: str) -> None:
    """Refuse a calibration text that is too long or nested too deeply, before any parser sees it."""
    if not isinstance(text, str):
        raise InputError(f"{source}: the calibration must be text, got {type(text).__name__}")
    if len(text) > MAX_CALIB_CHARS:
        raise InputError(f"{source}: the calibration is {len(text)} characters long, over the limit of "
                         f"{MAX_CALIB_CHARS}")
    depth = nesting_bound(text)
    if depth > MAX_NESTING:
        raise InputError(f"{source}: brackets, elements or blocks nested about {depth} levels deep, over the limit "
                         f"of {MAX_NESTING}: not a calibration file")


def _integer(source: str, key: str, value, lo: int, hi: int) -> int:
    """``value`` (a number or its text) as an int in [lo, hi], else one line naming the file and the key."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{source}: `{key}` must be an integer in [{lo}, {hi}], got {value!r}") from None
    if not (math.isfinite(v) and v == int(v) and lo <= v <= hi):
        raise InputError(f"{source}: `{key}` must be an integer in [{lo}, {hi}], got {value!r}")
    return int(v)


def check_camera_matrix(K: np.ndarray, source: str, key: str, size=None) -> None:
    """Refuse a camera matrix that is not ``[fx s cx; 0 fy cy; 0 0 1]`` with ``fx, fy > 0``, finite, and whose
    principal point is inside the image or within half its size around it.

    Parameters
    ----------
    K : (3, 3) float
        The matrix.
    source, key : str
        The file and the key, for the message.
    size : (int, int), optional
        (width, height) of the image; without it the principal point is not checked.

    Raises
    ------
    InputError
        One line naming the file, the key and the entry.
    """
    if K.shape != (3, 3):
        raise InputError(f"{source}: `{key}` must be a 3x3 camera matrix, got shape {K.shape}", file=source)
    if not np.isfinite(K).all():
        raise InputError(f"{source}: `{key}` contains NaN or inf", file=source)
    for name, v in (("fx", K[0, 0]), ("fy", K[1, 1])):
        if not v > 0:
            raise InputError(f"{source}: `{key}` focal length {name} = {v:g} must be > 0", file=source)
    if K[2, 2] != 1:
        raise InputError(f"{source}: `{key}`[2, 2] must be 1 (a camera matrix [fx s cx; 0 fy cy; 0 0 1]), "
                         f"got {K[2, 2]:g}", file=source)
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0:
        raise InputError(f"{source}: `{key}` must have zeros below the diagonal (a camera matrix "
                         "[fx s cx; 0 fy cy; 0 0 1])", file=source)
    if size is not None:
        w, h = size
        for name, v, n in (("cx", K[0, 2], w), ("cy", K[1, 2], h)):
            lo, hi = -0.5 * n, 1.5 * n
            if not lo <= v <= hi:
                raise InputError(f"{source}: `{key}` principal point {name} = {v:g} must be in [{lo:g}, {hi:g}] "
                                 f"(inside the {w}x{h} image or within half its size around it)", file=source)


def _about_source(fn):
    """Attach the ``source`` argument (the file name) to the InputError that the parser ``fn`` raises."""

    @functools.wraps(fn)
    def wrapper(text, source=None, *args, **kwargs):
        if source is None:
            return fn(text, *args, **kwargs)
        try:
            return fn(text, source, *args, **kwargs)
        except InputError as exc:
            if exc.file is None:
                exc.file = str(source)
            raise

    return wrapper


def _check_size(size) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in size)
    except (TypeError, ValueError):
        raise InputError(f"`size` must be (width, height), got {size!r}") from None
    if w < 2 or h < 2:
        raise InputError(f"`size` must be at least (2, 2), got {size!r}")
    return w, h


@dataclass(frozen=True, eq=False)
class Calibration:
    """A stereo calibration: intrinsics, lens distortion and the pose of the right camera in the left's frame.

    Attributes
    ----------
    K1, K2 : (3, 3) float64
        Camera matrices (pixels) of the left and right camera.
    D1, D2 : (k,) float64
        OpenCV distortion coefficients (zeros for Middlebury).
    R : (3, 3) float64
        Rotation from the left to the right camera frame (``X_right = R X_left + T``).
    T : (3,) float64
        Translation, in ``unit`` (Middlebury: ``(-baseline, 0, 0)``).
    size : (int, int) or None
        (width, height) the calibration is for.
    doffs : float
        Middlebury's ``doffs`` (principal column of the right minus that of the left), pixels; 0 otherwise.
    ndisp : int or None
        Middlebury's bound on the disparities.
    unit : str
        Unit of ``T`` (``"mm"`` for Middlebury; ``"units of T"`` for OpenCV files, which do not say).
    rectified : bool
        True when the file describes an already rectified rig (Middlebury): no extrinsics to rectify with.
    source : str
        The file name, for messages.
    """

    K1: np.ndarray
    D1: np.ndarray
    K2: np.ndarray
    D2: np.ndarray
    R: np.ndarray
    T: np.ndarray
    size: tuple | None
    doffs: float = 0.0
    ndisp: int | None = None
    unit: str = "units of T"
    rectified: bool = False
    source: str = "<calibration>"

    @property
    def baseline(self) -> float:
        """Distance between the camera centres, in ``unit`` (computed without overflow or underflow)."""
        scale = float(np.abs(self.T).max())
        return scale * float(np.linalg.norm(self.T / scale)) if scale > 0 else 0.0

    def check_size(self, size) -> None:
        """Raise InputError naming the key when the images are not the size the calibration is for, or when a
        principal point lies far outside them (:func:`check_camera_matrix`)."""
        w, h = _check_size(size)
        if self.size is None:
            for key, K in (("K1", self.K1), ("K2", self.K2)):
                check_camera_matrix(K, self.source, key, (w, h))
            return
        cw, ch = self.size
        if (cw, ch) != (w, h):
            key = "width" if cw != w else "height"
            if not self.rectified:
                key = "image_size (or K1/K2)"
            raise InputError(f"{self.source}: `{key}` says {cw}x{ch} but the images are {w}x{h}", file=self.source)


_MB_MATRIX = re.compile(r"^\[(.*)\]$")


@_about_source
def parse_middlebury_calib(text: str, source: str = "calib.txt") -> Calibration:
    """Parse a Middlebury ``calib.txt`` (``cam0``, ``cam1``, ``doffs``, ``baseline``, ``width``, ``height``,
    ``ndisp``; other keys are ignored).

    Parameters
    ----------
    text : str
        The file's content: ``key=value`` lines, matrices as ``[a b c; d e f; g h i]``.
    source : str
        The file name, for messages.

    Returns
    -------
    Calibration
        ``rectified=True``, ``R = I``, ``T = (-baseline, 0, 0)`` in mm, no distortion.

    Raises
    ------
    InputError
        A text over :data:`MAX_CALIB_CHARS` or nested deeper than :data:`MAX_NESTING`, a missing key, an unreadable
        or non-finite value, a camera matrix that is not ``[fx 0 cx; 0 fy cy; 0 0 1]`` with ``fx, fy > 0`` and its
        principal point in or near the image (:func:`check_camera_matrix`), ``width``/``height`` not integers,
        ``baseline <= 0``, ``doffs`` beyond twice the width, ``ndisp`` not an integer in [1, width]: one line
        naming the file and the key.
    """
    _check_text(text, source)
    values: dict[str, str] = {}
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        if "=" not in line:
            raise InputError(f"{source}: expected `key=value` lines, got {line[:40]!r}")
        k, v = line.split("=", 1)
        values[k.strip()] = v.strip()
    for key in ("cam0", "cam1", "doffs", "baseline", "width", "height"):
        if key not in values:
            raise InputError(f"{source}: missing key `{key}`")

    def number(key: str) -> float:
        try:
            v = float(values[key])
        except ValueError:
            raise InputError(f"{source}: `{key}` must be a number, got {values[key]!r}") from None
        if not math.isfinite(v):
            raise InputError(f"{source}: `{key}` must be finite, got {values[key]!r}")
        return v

    w = _integer(source, "width", values["width"], 2, MAX_SIDE)
    h = _integer(source, "height", values["height"], 2, MAX_SIDE)

    def matrix(key: str) -> np.ndarray:
        m = _MB_MATRIX.match(values[key])
        try:
            rows = [[float(x) for x in r.split()] for r in m.group(1).split(";")] if m else None
            K = np.array(rows, dtype=np.float64)
        except (ValueError, AttributeError, TypeError):
            K = None
        if K is None or K.shape != (3, 3):
            raise InputError(f"{source}: `{key}` must be a 3x3 matrix like [f 0 cx; 0 f cy; 0 0 1]")
        check_camera_matrix(K, source, key, (w, h))
        return K

    K1, K2 = matrix("cam0"), matrix("cam1")
    baseline = number("baseline")
    if baseline <= 0:
        raise InputError(f"{source}: `baseline` must be > 0, got {baseline:g}")
    doffs = number("doffs")
    if not -2 * w <= doffs <= 2 * w:  # the difference of two principal columns that check_camera_matrix accepts
        raise InputError(f"{source}: `doffs` must be in [{-2 * w}, {2 * w}] (twice the width), got {doffs:g}")
    ndisp = _integer(source, "ndisp", values["ndisp"], 1, w) if "ndisp" in values else None
    return Calibration(K1=K1, D1=np.zeros(5), K2=K2, D2=np.zeros(5), R=np.eye(3),
                       T=np.array([-baseline, 0.0, 0.0]), size=(w, h), doffs=doffs, ndisp=ndisp,
                       unit="mm", rectified=True, source=source)


@_about_source
def parse_opencv_calib(text: str, source: str = "stereo.yml") -> Calibration:
    """Parse an OpenCV stereo calibration (YAML or XML as ``cv2.FileStorage`` writes it: ``K1``, ``D1``, ``K2``,
    ``D2``, ``R``, ``T``, and optionally ``image_width``/``image_height`` or ``image_size``).

    Parameters
    ----------
    text : str
        The file's content (``%YAML:1.0`` header and ``!!opencv-matrix`` nodes are fine).
    source : str
        The file name, for messages.

    Returns
    -------
    Calibration

    Raises
    ------
    InputError
        A text over :data:`MAX_CALIB_CHARS` or nested deeper than :data:`MAX_NESTING`, unparsable text, a missing
        key, a value that is not a matrix or has the wrong shape, NaN or inf, a camera matrix refused by
        :func:`check_camera_matrix` (the principal point is checked when the file gives the image size), ``R`` not
        a rotation, a zero ``T``, image sizes that are not integers: one line naming the file and the key.
    """
    _check_text(text, source)
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as exc:  # the Python binding wraps some parser errors in SystemError
        cause = exc.__cause__ or exc.__context__ or exc
        msg = str(cause).strip().splitlines()[-1] if str(cause).strip() else "parse error"
        raise InputError(f"{source}: not a readable OpenCV YAML/XML file ({msg})") from None
    if not fs.isOpened():
        raise InputError(f"{source}: not a readable OpenCV YAML/XML file")
    try:
        def mat(key: str, shape: tuple | None) -> np.ndarray:
            node = fs.getNode(key)
            if node.empty():
                raise InputError(f"{source}: missing key `{key}`")
            want = "a matrix" if shape is None else f"a {'x'.join(map(str, shape))} matrix"
            m = None
            if node.isMap():
                try:
                    m = node.mat()
                except cv2.error:
                    m = None
            if m is None:
                got = f"a list of {node.size()} values" if node.isSeq() else "a single value" if not node.isMap() \
                    else "a mapping that is not an !!opencv-matrix"
                raise InputError(f"{source}: `{key}` must be {want} (!!opencv-matrix with rows, cols, dt, data), "
                                 f"got {got}")
            m = np.asarray(m, dtype=np.float64)
            if shape is not None and m.size != int(np.prod(shape)):
                raise InputError(f"{source}: `{key}` must have {int(np.prod(shape))} entries {shape}, got {m.shape}")
            if not np.isfinite(m).all():
                raise InputError(f"{source}: `{key}` contains NaN or inf")
            return m.reshape(shape) if shape is not None else m.ravel()

        def integer(node, key: str) -> int:
            value = node.real() if node.isInt() or node.isReal() else node.string() if node.isString() else None
            return _integer(source, key, value, 2, MAX_SIDE)

        size = None
        wn, hn, sn = fs.getNode("image_width"), fs.getNode("image_height"), fs.getNode("image_size")
        if not wn.empty() and not hn.empty():
            size = (integer(wn, "image_width"), integer(hn, "image_height"))
        elif not sn.empty():
            if not (sn.isSeq() and sn.size() == 2):
                raise InputError(f"{source}: `image_size` must be [width, height]")
            size = (integer(sn.at(0), "image_size[0]"), integer(sn.at(1), "image_size[1]"))
        K1, K2 = mat("K1", (3, 3)), mat("K2", (3, 3))
        D1, D2 = mat("D1", None), mat("D2", None)
        R = mat("R", (3, 3))
        T = mat("T", (3,))
    finally:
        fs.release()
    for key, K in (("K1", K1), ("K2", K2)):
        check_camera_matrix(K, source, key, size)
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) <= 0:
        raise InputError(f"{source}: `R` is not a rotation matrix (R R^T = I, det R = +1)")
    for key, D in (("D1", D1), ("D2", D2)):
        if D.size not in (4, 5, 8, 12, 14):
            raise InputError(f"{source}: `{key}` must hold 4, 5, 8, 12 or 14 coefficients, got {D.size}")
    if not np.any(T):
        raise InputError(f"{source}: `T` is zero: the two cameras coincide (no baseline)")
    return Calibration(K1=K1, D1=D1, K2=K2, D2=D2, R=R, T=T, size=size, source=source)


@_about_source
def parse_calibration(text: str, source: str) -> Calibration:
    """A Middlebury ``calib.txt`` or an OpenCV stereo YAML/XML file, told apart by content.

    Raises
    ------
    InputError
        As :func:`parse_middlebury_calib` or :func:`parse_opencv_calib`; its ``file`` is ``source``.
    """
    _check_text(text, source)
    head = text.lstrip()[:200]
    if head.startswith("%YAML") or head.startswith("<?xml") or "!!opencv-matrix" in text or "K1" in head[:40]:
        return parse_opencv_calib(text, source)
    return parse_middlebury_calib(text, source)
