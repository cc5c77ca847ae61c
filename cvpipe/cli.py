"""The ``cvpipe`` command.

Subcommands live in ``cvpipe.commands.<name>`` (see that package's docstring). Errors go to stderr as one line
``cvpipe: error: ...``; exit status 2 for bad input or arguments, 1 when the algorithm could not produce a result.

Start-up is kept short: ``cvpipe --help`` and ``--version`` import no subcommand module (each one-line ``HELP`` is
read from the module's source), and only the subcommand being run is imported and given its arguments. Command
modules keep OpenCV and the algorithm modules inside ``run()``, so ``cvpipe <cmd> --help`` stays light too.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import importlib
import importlib.util
import io
import json
import os
import re
import sys
import warnings
import weakref
from types import ModuleType

from . import __version__, interrupt
from .errors import BudgetWarning, CvpipeError

_SHOW_WARNING = warnings.showwarning

#: subcommand name -> module under ``cvpipe.commands`` (the order is the order of ``cvpipe --help``)
COMMANDS = {
    "logo": "logo",
    "hough": "hough",
    "inspect": "inspect",
    "defect": "inspect",  # the task's name (params.yaml, dvc.yaml, outputs): an alias of `inspect`
    "homography": "homography",
    "stereo": "stereo",
    "stitch": "stitch",
    "panorama": "stitch",  # the task's name (params.yaml, dvc.yaml, outputs): an alias of `stitch`
    "bench": "bench",
    "init": "init",
    "stage": "stage",
}

EXAMPLE = "cvpipe hough data/samples/hough/synthetic_grid.png --threshold 100 --max-lines 10"


def _load(package: str, names: dict[str, str]) -> dict[str, ModuleType]:
    """Import every module of ``names`` (name -> module in ``package``); a missing one is an error, not a hidden
    command."""
    return {name: importlib.import_module(f"{package}.{module}") for name, module in names.items()}


def module_constants(full: str, names: tuple[str, ...] = ("HELP", "EXAMPLE")) -> dict[str, str] | None:
    """The string constants ``names`` of module ``full``, read from its source without importing it.

    Returns None when the module does not exist. A constant that is not a plain string literal is taken from the
    imported module instead (correct, only slower).
    """
    spec = importlib.util.find_spec(full)
    if spec is None or not spec.origin or not spec.origin.endswith(".py"):
        return None
    with open(spec.origin, encoding="utf-8") as fh:
        tree = ast.parse(fh.read(), spec.origin)
    found: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            key = node.targets[0].id
            if key in names:
                try:
                    found[key] = ast.literal_eval(node.value)
                except ValueError:
                    pass
    if any(not isinstance(found.get(k), str) for k in names):
        module = importlib.import_module(full)
        found = {k: getattr(module, k) for k in names}
    return found


class LazyCommands:
    """Subcommands of a parser whose arguments are added only when that subcommand is the one being run: only its
    module is imported (start-up), with argparse's public API alone (:func:`load_chosen` finds the one named).

    Parameters
    ----------
    parser : argparse.ArgumentParser
    package : str
        The package holding one module per subcommand, each with ``HELP``, ``EXAMPLE``, ``add_arguments`` and ``run``.
    names : dict
        Subcommand name -> module in ``package`` (a module that does not exist gives no subcommand).
    dest : str
        The namespace attribute that receives the subcommand's name.
    """

    def __init__(self, parser: argparse.ArgumentParser, package: str, names: dict[str, str], dest: str):
        sub = parser.add_subparsers(dest=dest, metavar="COMMAND", required=True)
        self.parsers: dict[str, argparse.ArgumentParser] = {}
        self._modules: dict[str, str] = {}
        for name, module in names.items():
            full = f"{package}.{module}"
            consts = module_constants(full)
            if consts is None:
                continue
            text = f"{consts['HELP']}\n\nexample:\n  {consts['EXAMPLE']}"
            self.parsers[name] = sub.add_parser(name, help=consts["HELP"], description=text,
                                                formatter_class=argparse.RawDescriptionHelpFormatter)
            self._modules[name] = full
        _LAZY[parser] = self

    def load(self, name: str) -> argparse.ArgumentParser:
        """The subparser ``name`` with its arguments (imports its module on first use)."""
        p = self.parsers[name]
        module_name = self._modules.pop(name, None)
        if module_name is not None:
            module = importlib.import_module(module_name)
            module.add_arguments(p)
            # the example goes last, after the arguments, where a reader of --help looks for it
            p.epilog = f"example:\n  {module.EXAMPLE}"
            p.description = module.HELP
            add_global_flags(p, suppress=True)
            p.set_defaults(_run=module.run)
        return p


#: parser -> its lazy subcommands (a parser's options before its subcommand take no values, so the first word of the
#: command line that is not an option names the subcommand)
_LAZY: "weakref.WeakKeyDictionary[argparse.ArgumentParser, LazyCommands]" = weakref.WeakKeyDictionary()


def add_subcommands(parser: argparse.ArgumentParser, package: str, names: dict[str, str], dest: str) -> LazyCommands:
    """Add one lazily built subparser per module of ``package`` that exists, with its one-line help and example."""
    return LazyCommands(parser, package, names, dest)


def load_chosen(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.ArgumentParser:
    """Give the subcommands that ``argv`` names (and theirs, for ``bench NAME``) their arguments; returns the parser
    of the innermost one named (``parser`` itself when none is)."""
    chosen, rest = parser, list(argv)
    while (lazy := _LAZY.get(chosen)) is not None:
        k = next((i for i, word in enumerate(rest) if not word.startswith("-")), None)
        if k is None or rest[k] not in lazy.parsers:
            break
        chosen, rest = lazy.load(rest[k]), rest[k + 1:]
    return chosen


class CommandParser(argparse.ArgumentParser):
    """An argument parser that gives the subcommands a command line names their arguments before parsing it
    (:func:`load_chosen`), and reports arguments a subcommand does not accept with that subcommand's usage (argparse
    would print the top-level usage, which does not say what the subcommand takes)."""

    def parse_known_args(self, args=None, namespace=None):
        load_chosen(self, sys.argv[1:] if args is None else list(args))
        return super().parse_known_args(args, namespace)

    def parse_args(self, args=None, namespace=None):
        argv = sys.argv[1:] if args is None else list(args)
        chosen = load_chosen(self, argv)
        parsed, extras = self.parse_known_args(argv, namespace)
        if extras:
            chosen.error(f"unrecognized arguments: {' '.join(extras)}")
        return parsed


def command_parser(*names: str) -> argparse.ArgumentParser:
    """The parser of ``cvpipe NAME...`` with its arguments, e.g. ``command_parser("bench", "guard")``."""
    return load_chosen(build_parser(), list(names))


def add_global_flags(parser: argparse.ArgumentParser, suppress: bool = False) -> None:
    """``-v`` / ``-q``, on the top-level parser and (``suppress``: without overriding it) after a subcommand."""
    default = argparse.SUPPRESS if suppress else 0
    group = parser.add_argument_group("output")
    group.add_argument("-v", "--verbose", action="count", default=default,
                       help="log each step with its time on stderr (-vv: debug)")
    group.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS if suppress else False,
                       help="no progress bars or notes on stderr, errors only")


def build_parser() -> argparse.ArgumentParser:
    parser = CommandParser(
        prog="cvpipe",
        description="Reproducible classical computer-vision pipelines.",
        epilog=f"example:\n  {EXAMPLE}\n\n"
               "The examples run on the bundled samples in data/samples (built by `dvc repro samples`).\n"
               "`cvpipe COMMAND --help` describes a command and ends with an example.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"cvpipe {__version__}")
    add_global_flags(parser)
    add_subcommands(parser, "cvpipe.commands", COMMANDS, "command")
    return parser


def _interrupted(exc: BaseException) -> bool:
    """True when ``exc`` is, or wraps, a KeyboardInterrupt (also a SystemError naming it: what Python raises when an
    extension returns a result with an exception set, such as a KeyboardInterrupt raised during its call)."""
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
    if _interrupted(exc):  # a Ctrl-C or a SIGTERM (cvpipe.interrupt): its word and its exit status
        return interrupt.reason(), None, interrupt.status()
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
    """Our own warnings (work scaled down to fit the memory budget) as one ``cvpipe: note:`` line on stderr (none with
    ``-q``)."""
    if issubclass(category, BudgetWarning):
        from .commands import note

        note(f"note: {message}")
    else:
        _SHOW_WARNING(message, category, filename, lineno, file, line)


def _unraisable(hook):
    """A ``sys.unraisablehook`` that records a ``KeyboardInterrupt`` raised where it cannot propagate.

    Python code run from C (a ``__del__``, a callback of a compiled library) cannot pass an exception on; Python
    would print its traceback and carry on. The interrupt is recorded instead (:func:`cvpipe.interrupt.mark`), and the
    command stops at its next check (:func:`cvpipe.interrupt.check`) with exit 130 and one line.
    """

    def on_unraisable(info):
        if info.exc_type is not None and issubclass(info.exc_type, KeyboardInterrupt):
            interrupt.mark()
            return
        hook(info)

    return on_unraisable


#: a terminal control sequence (colours, bold): ESC [ parameters letter
_ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def _fail(message: str, file: str | None, code: int, json_mode: bool) -> int:
    """Print the one stderr line and, in ``--json`` mode, the one JSON record; return the exit status."""
    # one line of plain text, whatever the message holds (a library's message may carry terminal colour codes)
    line = " ".join(_ANSI.sub("", str(message)).split()) or "failed"
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
        # a value refused by the parameter a flag sets (cvpipe.commands.param_type): "`--seed` must be in ..."
        msg = re.sub(r"^argument (\S+): must ", r"`\1` must ", msg)
        hint = f" (see cvpipe {where + ' ' if where else ''}--help)"
        return None, _fail(f"{where + ': ' if where else ''}{msg}{hint}", None, code, json_mode)


def main(argv: list[str] | None = None) -> int:
    """Run ``cvpipe``; every failure is one stderr line (and one JSON record with ``--json``) and an exit status.

    Exit status: 0 success, 1 no result (:class:`~cvpipe.errors.EstimationError`, an unexpected failure), 2 bad
    input or arguments (:class:`~cvpipe.errors.InputError`, a missing or unreadable file, out of memory), 130
    interrupted (Ctrl-C, also during a compiled extension's call), 143 terminated (SIGTERM, handled as a Ctrl-C;
    :mod:`cvpipe.interrupt`). ``CVPIPE_DEBUG=1`` re-raises for a traceback.
    """
    args_list = sys.argv[1:] if argv is None else list(argv)
    json_mode = "--json" in args_list
    debug = os.environ.get("CVPIPE_DEBUG", "") not in ("", "0")
    shown, unraisable = warnings.showwarning, sys.unraisablehook
    warnings.showwarning = _note
    sys.unraisablehook = _unraisable(unraisable)
    try:
        interrupt.check()  # one that came during the start-up: no command, no --version, just the interrupt
        parser = build_parser()
        args, code = _parse(parser, args_list, json_mode)
        if args is None:
            return code
        from .commands import configure_output

        configure_output(verbose=args.verbose, quiet=args.quiet)
        interrupt.check()
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
        if _interrupted(exc):
            interrupt.ignore()  # ending now: a further signal must not add a second line
        return _fail(message, file, code, json_mode)
    finally:
        warnings.showwarning = shown
        sys.unraisablehook = unraisable


if __name__ == "__main__":  # ``python -m cvpipe.cli``: the program, with its Ctrl-C handling (as cvpipe._entry)
    interrupt.install(record="--json" in sys.argv[1:])
    sys.exit(interrupt.run(main))
