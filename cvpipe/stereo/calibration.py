"""Stereo calibration files: the :class:`Calibration` of a rig and the parsers of a Middlebury ``calib.txt`` and an
OpenCV stereo YAML file. The parsers take the file's text (this module never touches the disk) and the file name
for the messages.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError


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
        """Distance between the camera centres, in ``unit``."""
        return float(np.linalg.norm(self.T))

    def check_size(self, size) -> None:
        """Raise InputError naming the key when the images are not the size the calibration is for."""
        w, h = _check_size(size)
        if self.size is None:
            return
        cw, ch = self.size
        if (cw, ch) != (w, h):
            key = "width" if cw != w else "height"
            if not self.rectified:
                key = "image_size (or K1/K2)"
            raise InputError(f"{self.source}: `{key}` says {cw}x{ch} but the images are {w}x{h}")


_MB_MATRIX = re.compile(r"^\[(.*)\]$")


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
        A missing key or an unreadable value: one line naming the file and the key.
    """
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

    def matrix(key: str) -> np.ndarray:
        m = _MB_MATRIX.match(values[key])
        try:
            rows = [[float(x) for x in r.split()] for r in m.group(1).split(";")] if m else None
            K = np.array(rows, dtype=np.float64)
        except (ValueError, AttributeError, TypeError):
            K = None
        if K is None or K.shape != (3, 3) or not np.isfinite(K).all() or K[0, 0] <= 0:
            raise InputError(f"{source}: `{key}` must be a 3x3 matrix like [f 0 cx; 0 f cy; 0 0 1]")
        return K

    def number(key: str, kind=float):
        try:
            v = kind(float(values[key]))
        except ValueError:
            raise InputError(f"{source}: `{key}` must be a number, got {values[key]!r}") from None
        if not math.isfinite(v):
            raise InputError(f"{source}: `{key}` must be finite")
        return v

    K1, K2 = matrix("cam0"), matrix("cam1")
    baseline = number("baseline")
    if baseline <= 0:
        raise InputError(f"{source}: `baseline` must be > 0, got {baseline}")
    w, h = number("width", int), number("height", int)
    ndisp = number("ndisp", int) if "ndisp" in values else None
    return Calibration(K1=K1, D1=np.zeros(5), K2=K2, D2=np.zeros(5), R=np.eye(3),
                       T=np.array([-baseline, 0.0, 0.0]), size=(w, h), doffs=number("doffs"), ndisp=ndisp,
                       unit="mm", rectified=True, source=source)


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
        Unparsable text, a missing key or a matrix of the wrong shape: one line naming the file and the key.
    """
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
            m = None if node.empty() else node.mat()
            if m is None:
                raise InputError(f"{source}: missing key `{key}`")
            m = np.asarray(m, dtype=np.float64)
            if shape is not None and m.size != int(np.prod(shape)):
                raise InputError(f"{source}: `{key}` must have {int(np.prod(shape))} entries {shape}, got {m.shape}")
            if not np.isfinite(m).all():
                raise InputError(f"{source}: `{key}` contains NaN or inf")
            return m.reshape(shape) if shape is not None else m.ravel()

        K1, K2 = mat("K1", (3, 3)), mat("K2", (3, 3))
        D1, D2 = mat("D1", None), mat("D2", None)
        R = mat("R", (3, 3))
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-4):
            raise InputError(f"{source}: `R` is not a rotation matrix")
        T = mat("T", (3,))
        size = None
        wn, hn, sn = fs.getNode("image_width"), fs.getNode("image_height"), fs.getNode("image_size")
        if not wn.empty() and not hn.empty():
            size = (int(wn.real()), int(hn.real()))
        elif not sn.empty() and sn.isSeq() and sn.size() == 2:
            size = (int(sn.at(0).real()), int(sn.at(1).real()))
    finally:
        fs.release()
    for key, D in (("D1", D1), ("D2", D2)):
        if D.size not in (4, 5, 8, 12, 14):
            raise InputError(f"{source}: `{key}` must hold 4, 5, 8, 12 or 14 coefficients, got {D.size}")
    if np.linalg.norm(T) == 0:
        raise InputError(f"{source}: `T` is zero: the two cameras coincide (no baseline)")
    return Calibration(K1=K1, D1=D1, K2=K2, D2=D2, R=R, T=T, size=size, source=source)


def parse_calibration(text: str, source: str) -> Calibration:
    """A Middlebury ``calib.txt`` or an OpenCV stereo YAML/XML file, told apart by content."""
    head = text.lstrip()[:200]
    if head.startswith("%YAML") or head.startswith("<?xml") or "!!opencv-matrix" in text or "K1" in head[:40]:
        return parse_opencv_calib(text, source)
    return parse_middlebury_calib(text, source)
