"""Validated image reading, artifact formats and atomic writes.

This is the only module of the library that touches the disk. Every writer writes to a temporary file in the
destination folder and renames it, so an interrupted run never leaves a half-written output behind.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import json
import os
import re
import secrets
import threading
import zipfile
import zlib
from pathlib import Path
from typing import Any, Iterable, Iterator, TypeVar

import cv2
import numpy as np

from .errors import InputError, check_int

#: default upper bound on the pixel count of an input image (100 megapixels)
DEFAULT_MAX_PIXELS = 100_000_000
#: image file suffixes that the folder listings pick up
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm")
#: smallest accepted side of an input image, in pixels
MIN_SIDE = 8
# OpenCV applies the EXIF orientation in some modes and not in others (IMREAD_UNCHANGED): it is always left to
# :func:`orient`, so that every mode reads the same picture upright
_MODES = {"color": cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION,
          "gray": cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION, "unchanged": cv2.IMREAD_UNCHANGED}
#: the EXIF tag that says how the stored pixels are turned
EXIF_ORIENTATION = 0x0112


def _header(data: bytes) -> tuple[tuple[int, int] | None, int]:
    """((width, height) or None, EXIF orientation 1..8) from the file header, without decoding the pixels.

    The size is None when the header is not understood; the orientation is 1 (as stored) when the file has none,
    an invalid one, one that only a full decode would reach (a PNG ``eXIf`` chunk after the pixel data), or is a
    TIFF (OpenCV's TIFF decoder applies the orientation itself).
    """
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - pillow comes with scikit-image
        return None, 1
    Image.MAX_IMAGE_PIXELS = None  # our own limit applies, with our own message
    size, orientation = None, 1
    try:
        import io as _io
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # Pillow's complaints about corrupt metadata: our own checks follow
            with Image.open(_io.BytesIO(data)) as im:
                size = im.size
                # OpenCV's TIFF decoder turns the pixels itself, in every mode; PNG's getexif() would decode them
                if im.format != "TIFF" and (im.format != "PNG" or "exif" in im.info):
                    value = im.getexif().get(EXIF_ORIENTATION, 1)
                    orientation = value if isinstance(value, int) and 1 <= value <= 8 else 1
    except Exception:
        pass
    return size, orientation


def orient(img: np.ndarray, orientation: int) -> np.ndarray:
    """The image turned upright from its EXIF ``orientation`` (1..8; 1 = as stored), as a contiguous array.

    Parameters
    ----------
    img : (H, W) or (H, W, C) ndarray
        The pixels as stored in the file.
    orientation : int
        The EXIF orientation tag: 2 mirrored, 3 turned 180 degrees, 4 flipped, 5 transposed, 6 to be turned 90
        degrees clockwise, 7 transversed, 8 to be turned 90 degrees counter-clockwise; other values change nothing.

    Returns
    -------
    ndarray
        (W, H, ...) for orientations 5 to 8, else (H, W, ...).
    """
    turned = {
        2: lambda a: a[:, ::-1],
        3: lambda a: a[::-1, ::-1],
        4: lambda a: a[::-1],
        5: lambda a: a.swapaxes(0, 1),
        6: lambda a: np.rot90(a, -1),
        7: lambda a: a[::-1, ::-1].swapaxes(0, 1),
        8: lambda a: np.rot90(a, 1),
    }.get(orientation)
    return img if turned is None else np.ascontiguousarray(turned(img))


def _looks_truncated(data: bytes) -> bool:
    """True when a PNG or JPEG stream misses its end marker (a download or copy cut short)."""
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return b"IEND" not in data[-64:]
    if data[:2] == b"\xff\xd8":
        return b"\xff\xd9" not in data[-4096:]
    return False


#: the OpenCV log level in force before the first of the :func:`opencv_quiet` blocks still open, and their number
_quiet_state = {"depth": 0, "level": None}
_quiet_lock = threading.Lock()


@contextlib.contextmanager
def opencv_quiet() -> Iterator[None]:
    """Keep OpenCV's own log lines (libtiff's ``[ WARN ] ... TIFFRGBAImageOK``) off stderr inside the block.

    A file OpenCV cannot decode is our one-line error, which says more. OpenCV's log level is global: blocks open in
    several threads at once share one silence, and the level in force before the first is restored when the last ends.
    """
    log = cv2.utils.logging
    with _quiet_lock:
        if _quiet_state["depth"] == 0:
            _quiet_state["level"] = log.getLogLevel()
            log.setLogLevel(log.LOG_LEVEL_SILENT)
        _quiet_state["depth"] += 1
    try:
        yield
    finally:
        with _quiet_lock:
            _quiet_state["depth"] -= 1
            if _quiet_state["depth"] == 0:
                log.setLogLevel(_quiet_state["level"])


def _from_wide_samples(p: Path, data: bytes, raw: np.ndarray | None, mode: str) -> np.ndarray | None:
    """The image OpenCV's 8-bit modes refused, from ``raw`` (decoded with ``IMREAD_UNCHANGED``): float samples in
    [0, 1] scaled to 0..255 and rounded, as ``mode`` (gray or BGR) asks; None when ``raw`` is no image either.

    Raises
    ------
    InputError
        Float samples outside [0, 1], NaN or infinity, 32-bit integer samples, or a channel count other than 1, 3, 4.
    """
    if raw is None or raw.size == 0 or raw.dtype in (np.uint8, np.uint16):
        return None
    kind = "TIFF" if data[:4] in (b"II*\0", b"MM\0*") else "image"
    bits = raw.dtype.itemsize * 8
    if raw.dtype.kind != "f":
        raise InputError(f"{p}: {bits}-bit integer {kind}: expected 8- or 16-bit samples")
    expected = "expected 8- or 16-bit samples, or floats in [0, 1]"
    channels = 1 if raw.ndim == 2 else raw.shape[2]
    if channels not in (1, 3, 4):
        raise InputError(f"{p}: {bits}-bit float {kind} with {channels} channels: expected 1, 3 or 4")
    if not np.isfinite(raw).all():
        raise InputError(f"{p}: {bits}-bit float {kind} holding NaN or infinity: {expected}")
    lo, hi = float(raw.min()), float(raw.max())
    if lo < 0.0 or hi > 1.0:
        raise InputError(f"{p}: {bits}-bit float {kind} with values in [{lo:.4g}, {hi:.4g}]: {expected}")
    img = np.rint(raw * 255.0).astype(np.uint8)
    return to_gray(img) if mode == "gray" else to_bgr(img)


def _about_file(fn):
    """Attach the path argument to the InputError that ``fn`` raises (the CLI's JSON record names it)."""

    @functools.wraps(fn)
    def wrapper(path, *args, **kwargs):
        try:
            return fn(path, *args, **kwargs)
        except InputError as exc:
            if exc.file is None:
                exc.file = str(path)
            raise

    return wrapper


def existing_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a Path when it names a file; InputError naming it when it is missing or a folder (``what``:
    what the caller expected, e.g. "an image")."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    if p.is_dir():
        raise InputError(f"{p}: is a folder, expected {what} file")
    return p


@_about_file
def read_image(path: str | os.PathLike, mode: str = "color", max_pixels: int = DEFAULT_MAX_PIXELS) -> np.ndarray:
    """Read an image file with checks that name the file and say what was expected.

    Parameters
    ----------
    path : path-like
        Image file (PNG, JPEG, BMP, TIFF, WebP, PGM/PPM).
    mode : {"color", "gray", "unchanged"}
        ``color`` gives (H, W, 3) uint8 BGR, ``gray`` gives (H, W) uint8, ``unchanged`` keeps depth and channels.
    max_pixels : int
        Largest accepted width x height; larger images are refused before they are decoded.

    Returns
    -------
    ndarray
        The decoded image, upright: its EXIF orientation applied in every mode (:func:`orient`). In ``color`` and
        ``gray``, 16-bit samples are scaled to 8 bits (0..65535 to 0..255) and float samples (a float TIFF) are read
        as fractions of full scale, 0..1 to 0..255 rounded (the convention of float images in OpenCV's ``imshow``
        and scikit-image); no min-max stretch, which would give one scene other grey levels in every file.

    Raises
    ------
    InputError
        Missing file, empty file, not an image, truncated file, too small or too many pixels; in ``color`` and
        ``gray``, float samples outside [0, 1] (or NaN, infinity) and 32-bit integer samples, whose scale cvpipe does
        not guess.
    """
    if mode not in _MODES:
        raise ValueError(f"`mode` must be one of {sorted(_MODES)}, got {mode!r}")
    check_int("max_pixels", max_pixels, 1)
    p = existing_file(path, "an image")
    data = p.read_bytes()
    if not data:
        raise InputError(f"{p}: file is empty (0 bytes), expected an image")
    size, orientation = _header(data)
    if size is not None and size[0] * size[1] > max_pixels:
        raise InputError(
            f"{p}: {size[0]}x{size[1]} = {size[0] * size[1]} pixels exceeds the limit of {max_pixels} pixels"
        )
    if _looks_truncated(data):
        raise InputError(f"{p}: truncated image file (end marker missing)")
    buf = np.frombuffer(data, np.uint8)
    with opencv_quiet():
        img = cv2.imdecode(buf, _MODES[mode])
        if img is None and mode != "unchanged":
            # OpenCV's 8-bit modes refuse float and 32-bit integer samples: what the file holds decides the answer
            img = _from_wide_samples(p, data, cv2.imdecode(buf, cv2.IMREAD_UNCHANGED), mode)
    if img is None or img.size == 0:
        raise InputError(f"{p}: not a readable image (expected PNG, JPEG, BMP, TIFF, WebP or PGM/PPM)")
    img = orient(img, orientation)
    h, w = img.shape[:2]
    if h * w > max_pixels:
        raise InputError(f"{p}: {w}x{h} = {w * h} pixels exceeds the limit of {max_pixels} pixels")
    if min(h, w) < MIN_SIDE:
        raise InputError(f"{p}: {w}x{h} is too small, expected at least {MIN_SIDE}x{MIN_SIDE} pixels")
    if mode != "unchanged" and img.dtype != np.uint8:
        img = cv2.convertScaleAbs(img, alpha=255.0 / float(np.iinfo(img.dtype).max))
    return img


#: default upper bound on the size of a small text file we parse (a calibration file), bytes
DEFAULT_MAX_TEXT_BYTES = 1_000_000


@_about_file
def read_text(path: str | os.PathLike, what: str = "text", max_bytes: int = DEFAULT_MAX_TEXT_BYTES) -> str:
    """Read a small UTF-8 text file, refusing one over ``max_bytes`` without reading more than ``max_bytes + 1``.

    Parameters
    ----------
    path : path-like
        The file (a regular file, a pipe or a device such as ``/dev/zero``: at most ``max_bytes + 1`` bytes are read).
    what : str
        How the messages name its content, e.g. ``"calibration"``.
    max_bytes : int
        Largest accepted size, bytes.

    Returns
    -------
    str
        The file's text.

    Raises
    ------
    InputError
        Missing file, a folder, unreadable, over ``max_bytes``, not UTF-8 or holding NUL bytes.
    """
    check_int("max_bytes", max_bytes, 1)
    p = existing_file(path, f"a {what}")
    try:
        with open(p, "rb") as fh:
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise InputError(f"{p}: cannot read the {what} ({exc.strerror or exc})") from None
    if len(data) > max_bytes:
        raise InputError(f"{p}: the {what} file is larger than the limit of {max_bytes} bytes")
    if b"\0" in data:
        raise InputError(f"{p}: not a {what} file (it holds NUL bytes)")
    try:
        return data.decode("utf-8-sig")  # a byte-order mark is not part of the text
    except UnicodeDecodeError as exc:
        raise InputError(f"{p}: not a UTF-8 {what} file (byte {exc.start} is {data[exc.start]:#04x})") from None


def to_gray(img: np.ndarray) -> np.ndarray:
    """(H, W) uint8 grayscale from a gray, BGR or BGRA uint8 image."""
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    raise ValueError(f"`img` must be (H, W), (H, W, 3) or (H, W, 4), got shape {img.shape}")


def to_bgr(img: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 BGR from a gray, BGR or BGRA uint8 image."""
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.ndim == 3 and img.shape[2] == 3:
        return img
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    raise ValueError(f"`img` must be (H, W), (H, W, 3) or (H, W, 4), got shape {img.shape}")


def list_images(folder: str | os.PathLike) -> list[Path]:
    """Image files directly inside ``folder``, sorted by name."""
    d = Path(folder)
    if not d.is_dir():
        raise InputError(f"{d}: no such folder")
    return sorted(p for p in d.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def check_utf8_names(folder: str | os.PathLike) -> None:
    """Refuse a folder holding, at any depth, a file or folder whose name is not UTF-8.

    Such a name (Latin-1 ``caf\\xe9.png``) reaches Python as a string with a lone surrogate, which no UTF-8 output
    (JSON, ``dvc.lock``, the summary line) can hold: DVC's hashing of the data folder fails without naming it.

    Raises
    ------
    InputError
        ``"<folder>: the name b'caf\\xe9.png' is not UTF-8; rename it (names in a data folder must be UTF-8)"``,
        the first such name in a top-down walk, shown as its bytes.
    """
    for top, dirs, files in os.walk(folder):
        for name in sorted(dirs + files):
            try:
                name.encode("utf-8")
            except UnicodeEncodeError:
                raise InputError(f"{top}: the name {os.fsencode(name)!r} is not UTF-8; rename it (names in a data "
                                 "folder must be UTF-8)", file=os.path.join(top, name)) from None


#: marker in the names of our temporary files: ``.<name>.cvpipe-tmp-<pid>-<random><suffix>`` beside the output
TMP_MARKER = ".cvpipe-tmp-"
_TMP_RE = re.compile(r"^\..+\.cvpipe-tmp-(\d+)-[0-9a-f]{8}(\.[^.]*)?$")
#: folders whose stale temporaries this process has already removed
_SWEPT: set[Path] = set()


def _pid_alive(pid: int) -> bool:
    """True when a process with this id exists on this machine (or we may not signal it)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, under another user
        return True
    except OverflowError:
        return False
    return True


def remove_stale_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Delete our temporary files in ``folder`` whose writing process is gone (a run killed mid-write).

    Only names made by :func:`atomic_path` are considered, and only those whose process id is not running, so a
    concurrent writer's temporary is never touched. Returns the removed paths.
    """
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        m = _TMP_RE.match(entry.name)
        if m is None or _pid_alive(int(m.group(1))):
            continue
        try:
            if entry.is_file(follow_symlinks=False):
                os.unlink(entry.path)
                removed.append(Path(entry.path))
        except OSError:
            pass
    return removed


def check_output_path(path: str | os.PathLike, what: str = "output", suffixes: Iterable[str] | None = None) -> Path:
    """Refuse an output path that cannot be written, before any work is done.

    Parameters
    ----------
    path : path-like
        The file to be written.
    what : str
        How the message names it (e.g. ``"`-o`"``).
    suffixes : iterable of str, optional
        Accepted suffixes (lower case, with the dot); ``None`` accepts any.

    Raises
    ------
    InputError
        The path is a folder, its suffix is not accepted, or its folder is a file or not writable.
    """
    dest = Path(path)
    if dest.is_dir():
        raise InputError(f"{dest}: {what} is a folder, expected a file name", file=str(dest))
    if suffixes is not None:
        allowed = tuple(suffixes)
        if dest.suffix.lower() not in allowed:
            got = dest.suffix or "no suffix"
            one = allowed[0] if len(allowed) == 1 else f"one of {', '.join(allowed)}"
            raise InputError(f"{what} must end in {one}, got {dest} ({got})", file=str(dest))
    parent = dest.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f"{dest}: cannot create {what}, {parent} is not a folder", file=str(dest))
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{dest}: cannot write {what}, folder {parent} is not writable", file=str(dest))
    return dest


def check_output_folder(path: str | os.PathLike, what: str = "output folder") -> Path:
    """Refuse an output folder that is a file or cannot be created/written (see :func:`check_output_path`)."""
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise InputError(f"{d}: {what} is a file, expected a folder", file=str(d))
    check_output_path(d / "x", what)
    return d


#: suffixes that :func:`save_image` can encode
IMAGE_WRITE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm")


def safe_name(name: Any, what: str = "name") -> str:
    """``name`` when it can be used as one file name inside an output folder, else a one-line InputError.

    Names read from data or truth files become file names; one with a separator, ``..``, an absolute path, a NUL
    or nothing at all could write outside the output folder or nowhere, so it is refused.
    """
    if not isinstance(name, str) or not name or name in (".", ".."):
        raise InputError(f"{what} {name!r} is not a usable file name (empty, '.' or '..')")
    if "/" in name or "\\" in name or "\0" in name or (os.altsep and os.altsep in name) or os.path.isabs(name):
        raise InputError(f"{what} {name!r} is not a plain file name (it contains a path separator or NUL); "
                         "names from data files may not be paths")
    return name


def _temporary_beside(path: str | os.PathLike) -> Path:
    """Create and return an empty temporary file beside ``path`` (its folder created if needed).

    The temporary is ``.<name>.cvpipe-tmp-<pid>-<random><suffix>``, created with mode ``0o666`` less the umask (so
    the output honours the umask, unlike :func:`tempfile.mkstemp`'s 0600); the first write into a folder removes
    the temporaries that killed processes left there.
    """
    dest = Path(path)
    if dest.is_dir():
        raise InputError(f"{dest}: is a folder, expected a file name to write", file=str(dest))
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise InputError(f"{dest}: cannot create the folder {dest.parent} (a file is in the way)",
                         file=str(dest)) from None
    parent = dest.parent.resolve()
    if parent not in _SWEPT:
        remove_stale_temporaries(parent)
        _SWEPT.add(parent)
    while True:
        candidate = dest.parent / f".{dest.stem}{TMP_MARKER}{os.getpid()}-{secrets.token_hex(4)}{dest.suffix}"
        try:
            os.close(os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        return candidate


#: what a writer says of the OSErrors of a full disk or an exhausted quota (EDQUOT is absent on some systems)
_NO_SPACE = {code: text for code, text in ((errno.ENOSPC, "no space left on device"),
                                           (getattr(errno, "EDQUOT", None), "disk quota exceeded")) if code is not None}
_TMP_PARTS = re.compile(r"^\.(?P<stem>.+)\.cvpipe-tmp-\d+-[0-9a-f]{8}(?P<suffix>\.[^.]*)?$")


def _destination(path: Path) -> Path:
    """The output file that ``path`` is written for: ``path`` itself, or the file a temporary of
    :func:`_temporary_beside` becomes (through the temporaries of temporaries that nested writers make)."""
    while (m := _TMP_PARTS.match(path.name)) is not None:
        path = path.with_name(m["stem"] + (m["suffix"] or ""))
    return path


def _full_disk(exc: OSError, path: str | os.PathLike) -> InputError:
    """The one line of a full disk or quota (``exc``), naming the output file ``path`` is written for: an InputError,
    exit status 2, as the command can be rerun once there is room."""
    dest = _destination(Path(path))
    return InputError(f"{dest}: {_NO_SPACE[exc.errno]} while writing", file=str(dest))


@contextlib.contextmanager
def _naming_full_disk(path: str | os.PathLike) -> Iterator[None]:
    """:func:`_full_disk` for an OSError of a full disk or quota inside the block; other errors pass."""
    try:
        yield
    except OSError as exc:
        if exc.errno not in _NO_SPACE:
            raise
        raise _full_disk(exc, path) from exc


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it to ``path``, on any failure delete it.

    The temporary (see :func:`_temporary_beside`) is removed on every exception, KeyboardInterrupt included; one
    left by a killed process is removed by the next write into the same folder. A full disk or quota is one
    InputError naming ``path`` (``"<path>: no space left on device while writing"``).
    """
    tmp_path = None
    try:
        with _naming_full_disk(path):
            tmp_path = _temporary_beside(path)
            yield tmp_path
            os.replace(tmp_path, path)
    finally:
        if tmp_path is not None:
            with contextlib.suppress(OSError):
                tmp_path.unlink(missing_ok=True)


class OutputSet:
    """The outputs of one command, written all or none: see :func:`all_or_none`."""

    def __init__(self):
        self._pending: list[tuple[Path, Path]] = []  # (temporary, destination)

    def path(self, dest: str | os.PathLike) -> Path:
        """A temporary path beside ``dest`` with its suffix, to write ``dest``'s content to (with any writer of
        this module); it becomes ``dest`` when the whole set succeeds."""
        with _naming_full_disk(dest):
            tmp = _temporary_beside(dest)
        self._pending.append((tmp, Path(dest)))
        return tmp

    def _writing(self, exc: OSError) -> Path | None:
        """The destination whose temporary ``exc`` names, else the one handed out last (the file being written)."""
        for tmp, dest in reversed(self._pending):
            if exc.filename is not None and Path(os.fsdecode(exc.filename)) == tmp:
                return dest
        return self._pending[-1][1] if self._pending else None

    def _commit(self) -> None:
        for tmp, dest in self._pending:
            os.replace(tmp, dest)
        self._pending.clear()

    def _discard(self) -> None:
        for tmp, _ in self._pending:
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)
        self._pending.clear()


@contextlib.contextmanager
def all_or_none() -> Iterator[OutputSet]:
    """Write several output files all or none: each is written to a temporary beside it (``outs.path(dest)``), and
    only when the block succeeds are they renamed, one after the other, to their names; on any failure (an
    exception, Ctrl-C) every temporary is deleted and the files already there are left untouched. One killed
    process leaves only temporaries, which the next write into the folder removes. A full disk or quota is one
    InputError naming the output file being written, not its temporary.

    Examples
    --------
    >>> with all_or_none() as outs:                                  # doctest: +SKIP
    ...     save_image(outs.path("disparity.png"), picture)
    ...     save_npy(outs.path("depth.npy"), z)
    """
    outs = OutputSet()
    try:
        try:
            yield outs
            outs._commit()
        except OSError as exc:
            dest = outs._writing(exc) if exc.errno in _NO_SPACE else None
            if dest is None:
                raise
            raise _full_disk(exc, dest) from exc
    finally:
        outs._discard()


def _same_file(a: Path, b: Path) -> bool:
    if os.path.normcase(os.path.realpath(a)) == os.path.normcase(os.path.realpath(b)):
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)  # hard links, case-insensitive file systems
    except OSError:
        return False


def check_distinct_outputs(outputs: Iterable[tuple[str, str | os.PathLike | None]],
                           inputs: Iterable[tuple[str, str | os.PathLike | None]] = ()) -> None:
    """Refuse, before any work, outputs that name the same file or an input.

    Parameters
    ----------
    outputs : iterable of (name, path or None)
        Each output file and how messages name it (``"`-o`"``, ``"`--depth`"``); None entries are skipped.
    inputs : iterable of (name, path or None)
        The files the command reads (``"LEFT"``, ``"`--calib`"``).

    Raises
    ------
    InputError
        Two outputs resolve to one file (symbolic and hard links included), or an output is an input.
    """
    seen: list[tuple[str, Path]] = []
    ins = [(name, Path(p)) for name, p in inputs if p is not None]
    for name, p in outputs:
        if p is None:
            continue
        path = Path(p)
        for other, q in seen:
            if _same_file(path, q):
                raise InputError(f"{other} and {name} name the same file {path}; give each output its own name",
                                 file=str(path))
        for other, q in ins:
            if _same_file(path, q):
                raise InputError(f"{name} {path} is the input {other}; writing it would replace the input, give "
                                 "the output another name", file=str(path))
        seen.append((name, path))


def save_image(path: str | os.PathLike, img: np.ndarray, jpeg_quality: int = 95) -> None:
    """Write an image atomically; the format follows the suffix (PNG keeps 16-bit)."""
    dest = Path(path)
    params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)] if dest.suffix.lower() in (".jpg", ".jpeg") else []
    check_output_path(dest, "image output", IMAGE_WRITE_SUFFIXES)
    try:
        ok, buf = cv2.imencode(dest.suffix, img, params)
    except cv2.error:
        ok = False
    if not ok:
        raise InputError(f"{dest}: could not encode the image as {dest.suffix}", file=str(dest))
    with atomic_path(dest) as tmp:
        tmp.write_bytes(buf.tobytes())


#: largest width x height of a picture the pipeline draws for the report page (overlays, panels, montages): far
#: under the read limit :data:`DEFAULT_MAX_PIXELS`, so that the report stage reads back every picture the stages
#: wrote, whatever the size of the inputs, and the page stays light
PICTURE_MAX_PIXELS = 16_000_000


def picture_scale(width: int, height: int, max_pixels: int | None = None) -> float:
    """The factor (at most 1) that brings a ``width`` x ``height`` picture within ``max_pixels`` pixels.

    ``max_pixels`` None means :data:`PICTURE_MAX_PIXELS`. :func:`fit_picture` resizes by it.
    """
    limit = PICTURE_MAX_PIXELS if max_pixels is None else check_int("max_pixels", max_pixels, 1)
    return min(1.0, (limit / (width * height)) ** 0.5)


def fit_picture(img: np.ndarray, max_pixels: int | None = None) -> np.ndarray:
    """``img`` itself when its width x height is within ``max_pixels`` (None: :data:`PICTURE_MAX_PIXELS`), else
    ``img`` shrunk to fit, aspect ratio kept (area averaging, so thin lines fade rather than vanish).

    Parameters
    ----------
    img : (H, W) or (H, W, C) ndarray
    max_pixels : int, optional

    Returns
    -------
    ndarray
        ``(h, w, ...)`` with ``w * h <= max_pixels``: ``w = floor(W * f)``, ``h = floor(H * f)`` (at least 1),
        ``f`` = :func:`picture_scale`.
    """
    h, w = img.shape[:2]
    limit = PICTURE_MAX_PIXELS if max_pixels is None else check_int("max_pixels", max_pixels, 1)
    f = picture_scale(w, h, limit)
    if f >= 1.0:
        return img
    nw = min(limit, max(1, int(w * f)))
    nh = min(max(1, int(h * f)), max(1, limit // nw))  # a product rounded up past the limit loses a row
    return cv2.resize(img, (nw, nh), interpolation=cv2.INTER_AREA)


def save_picture(path: str | os.PathLike, img: np.ndarray, max_pixels: int | None = None) -> None:
    """Write a picture for the report page atomically, shrunk by :func:`fit_picture` when it has more than
    ``max_pixels`` (None: :data:`PICTURE_MAX_PIXELS`); the format follows the suffix, as :func:`save_image`."""
    save_image(path, fit_picture(img, max_pixels))


def save_npz(path: str | os.PathLike, **arrays: Any) -> None:
    """Write named arrays to a compressed ``.npz`` atomically (no object arrays, so no pickle is needed to load)."""
    clean = {}
    for key, value in arrays.items():
        arr = np.asarray(value)
        if arr.dtype == object:
            raise ValueError(f"array `{key}` has dtype object, which .npz cannot store without pickle")
        clean[key] = arr
    # np.savez stamps each member with the current time; fixed stamps make equal arrays give equal bytes, so DVC
    # sees an unchanged output as unchanged and a fresh clone's run reproduces dvc.lock exactly.
    with atomic_path(path) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            for key in sorted(clean):
                info = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                with zf.open(info, "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, clean[key], allow_pickle=False)


#: what a damaged ``.npz`` or ``.npy`` raises while it is read (a cut-off or corrupted file, a pickled array)
_ARRAY_FILE_ERRORS = (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error)


def _expecting(keys: tuple[str, ...]) -> str:
    return f"; expected an .npz holding {', '.join(f'`{k}`' for k in keys)}" if keys else ""


@_about_file
def load_npz(path: str | os.PathLike, keys: Iterable[str] = ()) -> dict[str, np.ndarray]:
    """Read every array of an ``.npz`` written by :func:`save_npz` (``allow_pickle=False``).

    Parameters
    ----------
    path : path-like
        The ``.npz`` file (a stage's cached output or a user's ``truth.npz``).
    keys : iterable of str
        The arrays the caller needs; the messages name them.

    Returns
    -------
    dict
        Array name -> array, every array of the file.

    Raises
    ------
    InputError
        One line naming the file and ``keys``: missing, not a zip of ``.npy`` arrays, cut off or corrupted, an
        array that needs pickle, or one of ``keys`` missing.
    """
    keys = tuple(keys)
    p = existing_file(path, "an .npz")
    try:
        with open(p, "rb") as fh:
            magic = fh.read(4)
    except OSError as exc:
        raise InputError(f"{p}: cannot read the .npz ({exc.strerror or exc}){_expecting(keys)}") from exc
    if not magic:
        raise InputError(f"{p}: file is empty (0 bytes){_expecting(keys) or ', expected an .npz archive'}")
    if magic[:2] != b"PK":  # every zip starts so; a bare .npy or a text file does not
        raise InputError(f"{p}: not an .npz archive (a zip of .npy arrays){_expecting(keys)}")
    try:
        with np.load(p, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except _ARRAY_FILE_ERRORS as exc:
        raise InputError(f"{p}: not a readable .npz archive ({exc}){_expecting(keys)}") from exc
    missing = [k for k in keys if k not in arrays]
    if missing:
        raise InputError(f"{p}: missing array(s) {', '.join(f'`{k}`' for k in missing)}{_expecting(keys)}")
    return arrays


@_about_file
def load_npy(path: str | os.PathLike, what: str = "array") -> np.ndarray:
    """Read one array saved by :func:`numpy.save` (``allow_pickle=False``), naming the file when it cannot.

    Parameters
    ----------
    path : path-like
        The ``.npy`` file.
    what : str
        How the messages name its content, e.g. ``"disparity"``.

    Raises
    ------
    InputError
        Missing, empty, cut off, corrupted, or an array that needs pickle.
    """
    p = existing_file(path, "an .npy")
    try:
        arr = np.load(p, allow_pickle=False)
    except _ARRAY_FILE_ERRORS as exc:
        raise InputError(f"{p}: not a readable .npy {what} array ({exc})") from exc
    if not isinstance(arr, np.ndarray):
        arr.close()
        raise InputError(f"{p}: an .npz archive, expected a single .npy {what} array")
    return arr


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return _jsonable(obj.item())
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def dumps_json(obj: Any) -> str:
    """Sorted-key JSON text; numpy values become plain numbers, NaN/inf become null."""
    return json.dumps(_jsonable(obj), sort_keys=True, indent=2, allow_nan=False)


def save_json(path: str | os.PathLike, obj: Any) -> None:
    """Write sorted-key JSON atomically."""
    text = dumps_json(obj) + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


#: default upper bound on the size of a JSON file we parse, bytes (a stage's own results; users' truth files have
#: their own, smaller limit: :data:`cvpipe.datasets.TRUTH_MAX_BYTES`)
DEFAULT_MAX_JSON_BYTES = 512_000_000


@_about_file
def load_json(path: str | os.PathLike, max_bytes: int = DEFAULT_MAX_JSON_BYTES, what: str = "JSON") -> Any:
    """Read a JSON file, naming the file when it is missing, too large or malformed.

    Parameters
    ----------
    path : path-like
        The file (read as :func:`read_text` does: at most ``max_bytes + 1`` bytes).
    max_bytes : int
        Largest accepted size, bytes.
    what : str
        How the messages name its content, e.g. ``"truth JSON"``.

    Returns
    -------
    object
        The parsed document (no type checks: the caller checks what it reads).

    Raises
    ------
    InputError
        Missing file, a folder, over ``max_bytes``, not UTF-8, not valid JSON or nested too deeply to parse.
    """
    p = Path(path)
    text = read_text(p, what, max_bytes)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{p}: not valid JSON ({exc})") from exc
    except RecursionError:
        raise InputError(f"{p}: not a usable {what} file (lists or objects nested too deeply)") from None


T = TypeVar("T")


def progress(iterable: Iterable[T], desc: str, total: int | None = None) -> Iterable[T]:
    """``iterable`` with a tqdm progress bar on stderr, shown only when stderr is a terminal (quiet under DVC/CI).

    Used by every per-image loop of the stages and benchmarks, so they all behave the same way; each item is handed
    out after :func:`cvpipe.interrupt.check`, so a Ctrl-C ends the loop between items.
    """
    from tqdm import tqdm

    from . import interrupt

    return interrupt.checked(tqdm(iterable, desc=desc, total=total, disable=None, dynamic_ncols=True))
