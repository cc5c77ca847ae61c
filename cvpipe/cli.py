"""The ``cvpipe`` command.

Subcommands live in ``cvpipe.commands.<name>`` (see that package's docstring). Errors go to stderr as one line
``cvpipe: error: ...``; exit status 2 for bad input or arguments, 1 when the algorithm could not produce a result.
"""

from __future__ import annotations

import argparse
import importlib
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


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
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
