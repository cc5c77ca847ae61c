"""The ``cvpipe`` program's entry point (the console script and ``python -m cvpipe``).

It imports only ``os``, ``signal`` and ``sys`` before it takes over Ctrl-C, so that an interrupt at any moment after
the interpreter started ends the same way: exit status 130, one line ``cvpipe: error: interrupted`` on stderr and,
with ``--json``, one JSON record on stdout. Without it, a Ctrl-C during the import of :mod:`cvpipe.cli` (outside
any ``try``) ends in Python's default way (a traceback, or death by SIGINT), and a Ctrl-C that a library swallows
(numba runs Python callbacks from C during its first compile; some code catches everything) is lost and the
command exits 0.

Every SIGINT is also recorded (:func:`seen`): a command checks it between its steps
(:func:`cvpipe.commands.step`), and after the command returned, an interrupt that never surfaced still ends the
program with 130.
"""

from __future__ import annotations

import os
import signal
import sys

_seen = False


def seen() -> bool:
    """True once a Ctrl-C reached this process (through :func:`main`'s handler, or :func:`mark`)."""
    return _seen


def mark() -> None:
    """Record an interrupt (for one that was swallowed before it could propagate)."""
    global _seen
    _seen = True


def _on_sigint(signum, frame):
    mark()
    raise KeyboardInterrupt


def exit_interrupted(json_mode: bool) -> None:
    """Print the one line (and the JSON record with ``--json``) of an interrupt and leave at once with 130.

    ``os._exit``: a Ctrl-C that numba swallowed may have left CPython's "unhandled KeyboardInterrupt" mark, which
    would turn a normal exit into death by SIGINT; temporaries are already gone (context managers ran on the way
    out, and the next write cleans those of a killed process).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the line short
    try:
        sys.stderr.write("cvpipe: error: interrupted\n")
        sys.stderr.flush()
        if json_mode:  # the sorted-key record of cvpipe.cli's failures
            sys.stdout.write('{"error": "interrupted", "exit": 130, "file": null}\n')
        sys.stdout.flush()
    except (OSError, ValueError):  # a closed pipe or stream: nothing left to say
        pass
    os._exit(130)


def main() -> int:
    """Run ``cvpipe`` with the arguments of ``sys.argv``; returns its exit status (130 on any interrupt)."""
    json_mode = "--json" in sys.argv[1:]
    # not when SIGINT is ignored (a background job, nohup): the program must stay as deaf to it as it was started
    handled = signal.getsignal(signal.SIGINT) is signal.default_int_handler
    if handled:
        signal.signal(signal.SIGINT, _on_sigint)
    try:
        from . import cli

        code = cli.main()
        if handled:
            # the command is done. Python puts SIGINT back to its default action when it shuts down (not when it is
            # ignored), so a Ctrl-C during the shutdown (numba's threads, atexit) killed the process (-2) or
            # crashed it (-11) instead of letting it end with the command's status
            signal.signal(signal.SIGINT, signal.SIG_IGN)
    except KeyboardInterrupt:
        exit_interrupted(json_mode)
    if _seen:  # swallowed on its way out: the command's output may be incomplete
        exit_interrupted(json_mode)
    return code
