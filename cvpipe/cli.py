"""The ``cvpipe`` command.

Subcommands live in ``cvpipe.commands.<name>`` (see that package's docstring). Errors go to stderr as one line
``cvpipe: error: ...``; exit status 2 for bad input or arguments, 1 when the algorithm could not produce a result.

Start-up is kept short: ``cvpipe --help`` and ``--version`` import no subcommand module (each one-line ``HELP`` is
read from the module's source), and only the subcommand being run is imported and given its arguments. Command
modules keep OpenCV, numba and the algorithm modules inside ``run()``, so ``cvpipe <cmd> --help`` stays light too.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import importlib.util
import sys
from types import ModuleType

from . import __version__
from .errors import EstimationError

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

EXAMPLE = "cvpipe hough data/samples/hough/synthetic_grid.png --threshold 100 --max-lines 10"


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


class _LazySubParsers(argparse._SubParsersAction):
    """Subparsers whose arguments are added only when that subcommand is the one being parsed.

    Also reports arguments a subcommand does not accept with that subcommand's usage (argparse would print the
    top-level usage, which does not say what the subcommand takes).
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._modules: dict[str, str] = {}

    def add_lazy(self, name: str, module: str, help: str, example: str) -> argparse.ArgumentParser:
        p = self.add_parser(name, help=help, description=f"{help}\n\nexample:\n  {example}",
                            formatter_class=argparse.RawDescriptionHelpFormatter)
        self._modules[name] = module
        return p

    def load(self, name: str) -> argparse.ArgumentParser:
        """The subparser ``name`` with its arguments (imports its module on first use)."""
        p = self._name_parser_map[name]
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

    def __call__(self, parser, namespace, values, option_string=None):
        name = values[0]
        if name in self._name_parser_map:
            self.load(name)
        super().__call__(parser, namespace, values, option_string)
        extras = vars(namespace).pop(argparse._UNRECOGNIZED_ARGS_ATTR, None)
        if extras:
            self._name_parser_map[name].error(f"unrecognized arguments: {' '.join(extras)}")


def add_subcommands(parser: argparse.ArgumentParser, package: str, names: dict[str, str], dest: str) -> _LazySubParsers:
    """Add one lazily built subparser per module of ``package`` that exists, with its one-line help and example."""
    parser.register("action", "parsers", _LazySubParsers)
    sub = parser.add_subparsers(dest=dest, metavar="COMMAND", required=True)
    for name, module in names.items():
        full = f"{package}.{module}"
        consts = module_constants(full)
        if consts is not None:
            sub.add_lazy(name, full, consts["HELP"], consts["EXAMPLE"])
    return sub


def add_global_flags(parser: argparse.ArgumentParser, suppress: bool = False) -> None:
    """``-v`` / ``-q``, on the top-level parser and (``suppress``: without overriding it) after a subcommand."""
    default = argparse.SUPPRESS if suppress else 0
    group = parser.add_argument_group("output")
    group.add_argument("-v", "--verbose", action="count", default=default,
                       help="log each step with its time on stderr (-vv: debug)")
    group.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS if suppress else False,
                       help="no progress bars or notes on stderr, errors only")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
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


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from .commands import configure_output

    configure_output(verbose=args.verbose, quiet=args.quiet)
    try:
        return int(args._run(args) or 0)
    except EstimationError as exc:
        print(f"cvpipe: error: {exc}", file=sys.stderr)
        return 1
    except (ValueError, OSError) as exc:
        print(f"cvpipe: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cvpipe: error: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
