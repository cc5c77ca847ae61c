"""The ``cvpipe`` command.

Subcommands live in ``cvpipe.commands.<name>`` (see that package's docstring). Errors go to stderr as one line
``cvpipe: error: ...``; exit status 2 for bad input or arguments, 1 when the algorithm could not produce a result.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import os
import sys
import warnings
from types import ModuleType

from . import __version__
from .errors import BudgetWarning, CvpipeError

_SHOW_WARNING = warnings.showwarning

#: subcommand name -> module under ``cvpipe.commands`` (the order is the order of ``cvpipe --help``)
COMMANDS = {
    "logo": "logo",
    "hough": "hough",
    "inspect": "inspect",
    "homography": "homography",
    "stereo": "stereo",
    "stitch": "stitch",
    "bench": "bench",
}


def _load(package: str, names: dict[str, str]) -> dict[str, ModuleType]:
    """Import the command modules that exist; a task that has not landed yet is simply not offered."""
    found = {}
    for name, module in names.items():
        full = f"{package}.{module}"
        try:
            found[name] = importlib.import_module(full)
        except ModuleNotFoundError as exc:
            if exc.name != full:
                raise
    return found


def add_subcommands(parser: argparse.ArgumentParser, modules: dict[str, ModuleType], dest: str) -> None:
    """Add one subparser per module, with its one-line help and example."""
    sub = parser.add_subparsers(dest=dest, metavar="COMMAND", required=True)
    for name, module in modules.items():
        p = sub.add_parser(
            name,
            help=module.HELP,
            description=f"{module.HELP}\n\nexample:\n  {module.EXAMPLE}",
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_arguments(p)
        p.set_defaults(_run=module.run)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cvpipe",
        description="Reproducible classical computer-vision pipelines.",
        epilog="example:\n  cvpipe hough data/samples/hough/building.png --json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"cvpipe {__version__}")
    add_subcommands(parser, _load("cvpipe.commands", COMMANDS), "command")
    return parser


def _interrupted(exc: BaseException) -> bool:
    """True when ``exc`` is, or wraps, a KeyboardInterrupt (numba's parallel kernels re-raise Ctrl-C as SystemError)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        if isinstance(exc, SystemError) and "KeyboardInterrupt" in str(exc):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _classify(exc: BaseException) -> tuple[str, str | None, int]:
    """(one-line message, file or None, exit status) for an exception that ended a command."""
    if _interrupted(exc):
        return "interrupted", None, 130
    if isinstance(exc, CvpipeError):
        return str(exc), exc.file, exc.exit_code
    if isinstance(exc, MemoryError):
        return ("out of memory: the input is too large for this machine; use smaller images or see the memory "
                "budget (CVPIPE_MEMORY_BUDGET_GB) in the README"), None, 2
    if isinstance(exc, OSError):
        name = exc.filename
        why = exc.strerror or str(exc)
        return (f"{name}: {why}" if name else why), (None if name is None else str(name)), 2
    if isinstance(exc, ValueError):
        return str(exc), None, 2
    try:
        import cv2

        if isinstance(exc, cv2.error):
            msg = str(exc).strip().splitlines()
            last = msg[-1] if msg else "OpenCV error"
            if "Insufficient memory" in str(exc) or "Failed to allocate" in str(exc):
                return ("out of memory inside OpenCV: the input is too large for this machine; use smaller images "
                        "or see the memory budget (CVPIPE_MEMORY_BUDGET_GB) in the README"), None, 2
            return f"OpenCV failed: {last.strip()}", None, 1
    except ImportError:  # pragma: no cover - OpenCV is a dependency
        pass
    return f"internal error ({type(exc).__name__}: {exc}); set CVPIPE_DEBUG=1 for the traceback", None, 1


def _note(message, category, filename, lineno, file=None, line=None) -> None:
    """Our own warnings (work scaled down to fit the memory budget) as one ``cvpipe: note:`` line on stderr."""
    if issubclass(category, BudgetWarning):
        print(f"cvpipe: note: {message}", file=sys.stderr)
    else:
        _SHOW_WARNING(message, category, filename, lineno, file, line)


def _fail(message: str, file: str | None, code: int, json_mode: bool) -> int:
    """Print the one stderr line and, in ``--json`` mode, the one JSON record; return the exit status."""
    line = " ".join(str(message).split()) or "failed"  # one line, whatever the message holds
    print(f"cvpipe: error: {line}", file=sys.stderr)
    if json_mode:
        print(json.dumps({"error": line, "file": file, "exit": code}, sort_keys=True))
    sys.stdout.flush()
    return code


def _parse(parser: argparse.ArgumentParser, argv: list[str] | None, json_mode: bool):
    """``parser.parse_args`` with argparse's usage-and-error exit turned into the one-line contract."""
    buf = io.StringIO()
    try:
        with contextlib.redirect_stderr(buf):
            return parser.parse_args(argv), None
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
        text = buf.getvalue()
        if code == 0:  # --help, --version: argparse's own exit
            sys.stderr.write(text)
            raise
        lines = [ln for ln in text.strip().splitlines() if ln.strip()]
        last = lines[-1] if lines else "bad arguments"
        prog, sep, msg = last.partition(": error: ")
        where = prog.split(" ", 1)[1] if sep and " " in prog else ""
        msg = msg if sep else last
        hint = f" (see cvpipe {where + ' ' if where else ''}--help)"
        return None, _fail(f"{where + ': ' if where else ''}{msg}{hint}", None, code, json_mode)


def main(argv: list[str] | None = None) -> int:
    """Run ``cvpipe``; every failure is one stderr line (and one JSON record with ``--json``) and an exit status.

    Exit status: 0 success, 1 no result (:class:`~cvpipe.errors.EstimationError`, an unexpected failure), 2 bad
    input or arguments (:class:`~cvpipe.errors.InputError`, a missing or unreadable file, out of memory), 130
    interrupted (Ctrl-C, also inside numba's parallel kernels). ``CVPIPE_DEBUG=1`` re-raises for a traceback.
    """
    args_list = sys.argv[1:] if argv is None else list(argv)
    json_mode = "--json" in args_list
    debug = os.environ.get("CVPIPE_DEBUG", "") not in ("", "0")
    shown = warnings.showwarning
    warnings.showwarning = _note
    try:
        parser = build_parser()
        args, code = _parse(parser, args_list, json_mode)
        if args is None:
            return code
        return int(args._run(args) or 0)
    except BaseException as exc:  # noqa: BLE001 - the one place that turns every failure into the contract
        if isinstance(exc, SystemExit):
            raise
        if debug and not _interrupted(exc):
            raise
        if isinstance(exc, BrokenPipeError):  # the reader of stdout went away (``| head``): nothing left to say
            with contextlib.suppress(OSError):
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 141
        message, file, code = _classify(exc)
        return _fail(message, file, code, json_mode)
    finally:
        warnings.showwarning = shown


if __name__ == "__main__":
    sys.exit(main())
