"""``cvpipe stage NAME [ARGS...]``: run one pipeline stage (what a ``dvc.yaml`` written by ``cvpipe init`` calls).

The stage scripts ship with the package as :mod:`cvpipe.stages` (in this repository they are ``stages/``, which its
own ``dvc.yaml`` runs as ``python -m stages.NAME``: the same files). ``cvpipe stage NAME ARGS`` runs
``cvpipe.stages.NAME`` as a program with ``ARGS``, exactly as ``python -m`` would: its own arguments, parameters,
progress, one-line errors and exit status (``cvpipe stage NAME --help`` lists them).
"""

from __future__ import annotations

import argparse
import sys

HELP = "run one pipeline stage (what a dvc.yaml written by `cvpipe init` calls); `cvpipe stage NAME --help`"
EXAMPLE = "cvpipe stage --list"


def stage_names() -> list[str]:
    """The stages that ship with the package: the modules of :mod:`cvpipe.stages` (its runner excluded)."""
    import pkgutil

    from .. import stages

    return sorted(m.name for m in pkgutil.iter_modules(stages.__path__) if not m.name.startswith("_"))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", metavar="NAME", help="the stage (`cvpipe stage --list` names them all)", nargs="?")
    parser.add_argument("--list", action="store_true", help="print the names of the stages and exit")
    parser.add_argument("stage_args", nargs=argparse.REMAINDER, metavar="ARGS",
                        help="the stage's own arguments (`cvpipe stage NAME --help`)")


def run(args: argparse.Namespace) -> int:
    """Run the stage ``args.name`` with ``args.stage_args``; exits with the stage's status."""
    import runpy

    names = stage_names()
    if args.list:
        print("\n".join(names))
        return 0
    if args.name is None:
        raise ValueError("a stage name is needed; choose from: " + ", ".join(names))
    if args.name not in names:
        raise ValueError(f"unknown stage `{args.name}`; choose from: {', '.join(names)}")
    # importing the package pins the per-CPU code paths before numpy and OpenCV load (cvpipe.stages' docstring):
    # nothing of either has been imported by the command line so far
    from .. import stages  # noqa: F401

    sys.argv = [f"cvpipe stage {args.name}", *args.stage_args]
    runpy.run_module(f"cvpipe.stages.{args.name}", run_name="__main__", alter_sys=False)
    return 0
