"""The ``cvpipe`` program's entry point (the console script and ``python -m cvpipe``).

It imports only the standard library and :mod:`cvpipe.interrupt` before it takes over Ctrl-C and SIGTERM, so that
an interrupt at any moment after the interpreter started ends the same way: exit status 130, one line ``cvpipe:
error: interrupted`` on stderr (143 and ``terminated`` for a SIGTERM) and, with ``--json``, one JSON record on stdout
(see :mod:`cvpipe.interrupt`).
"""

from __future__ import annotations

import sys

from . import interrupt


def main() -> int | str | None:
    """Run ``cvpipe`` with the arguments of ``sys.argv``; returns its exit status (130 on any Ctrl-C, 143 on a
    SIGTERM)."""
    interrupt.install(record="--json" in sys.argv[1:])
    from . import cli

    return interrupt.run(cli.main)
