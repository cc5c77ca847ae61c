"""One module per `cvpipe` subcommand, plus the output helpers they share (progress bars, step timings, notes).

Each module defines ``HELP`` (one line), ``EXAMPLE`` (one command line that runs on the bundled samples),
``add_arguments(parser)`` and ``run(args) -> int``. ``cvpipe.cli`` lists them in ``COMMANDS``; a module that is
absent is simply not offered. ``HELP`` and ``EXAMPLE`` are plain string literals (``cvpipe --help`` reads them from
the source), and module level imports stay light: OpenCV, numpy and the algorithm modules are imported inside
``run()``, so that ``cvpipe <cmd> --help`` answers at once.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
from typing import Iterable, Iterator, TypeVar

from .. import interrupt

T = TypeVar("T")

log = logging.getLogger("cvpipe")

#: set by :func:`configure_output` from ``-q``: no progress bars, no notes
_quiet = False


def configure_output(verbose: int = 0, quiet: bool = False) -> None:
    """Route ``cvpipe`` logging to stderr: warnings by default, steps with ``-v``, debug with ``-vv``, only errors
    with ``-q`` (which also hides progress bars and notes)."""
    global _quiet
    _quiet = bool(quiet)
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(int(verbose), 2)]
    log.setLevel(level)
    if not any(isinstance(h, _StderrHandler) for h in log.handlers):
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("cvpipe: %(message)s"))
        log.addHandler(handler)
        log.propagate = False


class _StderrHandler(logging.StreamHandler):
    """A handler writing to the current ``sys.stderr`` (which tests and embedding programs may replace)."""

    def __init__(self):
        super().__init__(sys.stderr)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):
        pass


def progress(items: Iterable[T], desc: str, total: int | None = None) -> Iterable[T]:
    """``items`` with a tqdm bar on stderr (none when stderr is not a terminal, with ``-q`` or for a single item),
    each handed out after :func:`cvpipe.interrupt.check`: a Ctrl-C ends the command between items."""
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    if _quiet or (total is not None and total < 2):
        return interrupt.checked(items)
    from tqdm import tqdm

    return interrupt.checked(tqdm(items, desc=desc, total=total, disable=None, dynamic_ncols=True, leave=False))


@contextlib.contextmanager
def step(name: str) -> Iterator[None]:
    """Log ``name`` and its wall time at INFO level (shown with ``-v``).

    A Ctrl-C recorded before the step or during it (:func:`cvpipe.interrupt.check`) ends the command at the step's
    start or end, before the command writes or prints anything from a step that may be incomplete.
    """
    interrupt.check()
    t0 = time.perf_counter()
    yield
    log.info("%s: %.3f s", name, time.perf_counter() - t0)
    interrupt.check()


def final_output() -> None:
    """Mark where the command's work is done and its results go out (files, then stdout).

    An interrupt recorded before this point ends the command here (exit 130, nothing of the results written). One
    from here on no longer cuts the results short (:func:`cvpipe.interrupt.results_out`): they are written whole,
    and the command then ends with exit 130 and the line on stderr (no failure record follows them on stdout); a
    second Ctrl-C still ends the process at once, leaving whole files or none.
    """
    interrupt.check()
    interrupt.results_out()


def note(message: str) -> None:
    """A one-line note on stderr (silenced by ``-q``)."""
    if not _quiet:
        print(f"cvpipe: {message}", file=sys.stderr, flush=True)


#: detector choices of every command: the keys of ``cvpipe.features.DETECTORS`` (a test keeps them equal)
DETECTORS = ("akaze", "brisk", "orb", "sift")


def add_feature_arguments(parser, detector: str, max_features: int, ratio: float, flag: str = "--detector",
                          choices: tuple[str, ...] = DETECTORS, what: str = "keypoint detector") -> None:
    """``--detector`` (or ``flag``, whose ``choices`` default to :data:`DETECTORS`, its help ``what``),
    ``--max-features`` and ``--ratio``, with the defaults of the command's parameter sections, the numbers checked by
    the fields they set (:func:`param_type`)."""
    from ..params import FeaturesParams, MatchParams

    parser.add_argument(flag, dest=flag.lstrip("-").replace("-", "_"), type=str.lower, choices=choices,
                        default=detector, help=f"{what} (default {detector})")
    parser.add_argument("--max-features", type=param_type(FeaturesParams, "max_features"), default=max_features,
                        help=f"keypoints per image (default {max_features})")
    parser.add_argument("--ratio", type=param_type(MatchParams, "ratio"), default=ratio,
                        help=f"Lowe's ratio test (default {ratio})")


def param_type(cls, name: str):
    """The argparse ``type`` of a flag that sets the field ``name`` of the section class ``cls``: the text becomes the
    field's ``int`` or ``float`` and is checked by the field's own declarations
    (:func:`cvpipe.params.check_field`: range, finiteness, C ``int``), so that a flag takes what its params.yaml key
    takes. A value it refuses is the one line naming the flag (``cvpipe: error: stitch: `--seed` must be in [0,
    2147483647], got -1``); a limit set by another field is checked when the command builds the section."""
    import argparse

    from ..errors import InputError
    from ..params import check_field

    convert = float if cls.model_fields[name].annotation is float else int

    def parse(text: str):
        value = convert(text)  # a ValueError: argparse's "invalid int value: 'x'"
        try:
            return check_field(cls, name, value)
        except InputError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix(f"`{name}` ")) from None

    parse.__name__ = convert.__name__
    return parse


def add_param_options(parser, section, helps: dict[str, str]) -> None:
    """One ``--field-name`` option per ``helps`` entry, declared by the field of the parameter ``section`` (a
    :class:`cvpipe.params.Section` instance): its default, its type and range (:func:`param_type`) and, for a
    ``Literal`` field, its choices, which ``--help`` lists. The help text gets ``(default X)`` appended."""
    import typing

    for name, text in helps.items():
        default = getattr(section, name)
        annotation = type(section).model_fields[name].annotation
        choices = typing.get_args(annotation) if typing.get_origin(annotation) is typing.Literal else None
        numeric = isinstance(default, (int, float)) and not isinstance(default, bool)
        kind = param_type(type(section), name) if numeric and not choices else type(default)
        shown = f"{default:g}" if isinstance(default, float) else default
        parser.add_argument("--" + name.replace("_", "-"), type=kind, choices=choices, default=default,
                            help=f"{text} (default {shown})")


def add_result_arguments(parser, overlay: str, json: str, items: str | None = None, suffix: str = "") -> None:
    """``--overlay PNG``, ``--json`` and, for a command that runs several ``items`` (a plural noun) one by one,
    ``--scheduler ADDR``; its pictures go to a folder, one ``<item stem><suffix>.png`` each (:func:`overlay_paths`)."""
    if items:
        overlay += f"; with several {items}, PNG is a folder (<{items[:-1]}>{suffix}.png)"
    parser.add_argument("--overlay", metavar="PNG", help=overlay)
    parser.add_argument("--json", action="store_true", help=json)
    if items:
        parser.add_argument("--scheduler", default="", metavar="ADDR",
                            help=f"run the {items} on Dask: 'local' or a scheduler address tcp://host:port "
                                 "(default: in process)")


def read_images(paths: Iterable[str], mode: str, named: bool = False) -> Iterator[tuple]:
    """``(image or None, read error or None)`` per path (``(path, image, error)`` when ``named``), lazily: the
    image travels with its task and a read error fails only its own item."""
    from .. import io
    from ..errors import CvpipeError

    for path in paths:
        try:
            item: tuple = (io.read_image(path, mode), None)
        except CvpipeError as exc:
            item = (None, exc)
        yield (path, *item) if named else item


def overlay_paths(inputs: list[str], overlay: str | None, suffix: str) -> list[str | None]:
    """Where each input's picture goes: ``overlay`` itself for one input (unless it ends in a slash), else
    ``overlay/<input stem><suffix>.png`` (numbered when two inputs share a stem); None each without ``--overlay``."""
    from pathlib import Path

    if not overlay:
        return [None] * len(inputs)
    if len(inputs) == 1 and not overlay.endswith(("/", os.sep)):
        return [overlay]
    stems = [Path(s).stem for s in inputs]
    # inputs with one stem from different folders must not overwrite each other's picture
    names = [f"{k:03d}_{st}" if stems.count(st) > 1 else st for k, st in enumerate(stems)]
    return [str(Path(overlay) / f"{n}{suffix}.png") for n in names]


def with_flags(message: str, names: Iterable[str]) -> str:
    """``message`` with each parameter name in ``names`` (``min_inliers``) spelt as its flag (``--min-inliers``).

    Algorithm modules name parameters as ``params.yaml`` does; on the command line the hint must name the flag.
    """
    import re

    for name in names:
        flag = "--" + name.replace("_", "-")
        message = re.sub(rf"`?(?<![\w-]){re.escape(name)}(?![\w-])`?", flag, message)
    return message
