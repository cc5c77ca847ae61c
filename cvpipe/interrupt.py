"""Ctrl-C for the ``cvpipe`` program and the stage scripts: the first one asks the work to stop, a second one stops it.

:func:`install` replaces Python's SIGINT handler by one that never raises. The first SIGINT only sets a flag
(:func:`seen`); the commands, the stage runner and the per-item loops call :func:`check` between items and steps,
which raises ``KeyboardInterrupt`` there, in ordinary Python code, and the program ends with exit status 130 and one
line (``cvpipe: error: interrupted``; with ``--json`` also the JSON record of a failure on stdout). A second SIGINT
prints that line and leaves at once with ``os._exit(130)``: temporaries are cleaned by the next write, as after any
killed process. A handler that never raises may run anywhere, also inside a Python callback of numba's compiled
code, which must not fail.

:func:`finish` ends a program: SIGINT is ignored from then on (the interpreter's shutdown, numba's threads), and an
interrupt that arrived during the work but was never checked still turns the exit status into 130.

Without :func:`install` (cvpipe used as a library) nothing changes: Ctrl-C raises ``KeyboardInterrupt`` as usual and
:func:`check` only acts on :func:`mark`. This module imports only the standard library: the entry point installs the
handler before anything heavy is imported.
"""

from __future__ import annotations

import os
import signal
import sys

TYPE_CHECKING = False
if TYPE_CHECKING:  # annotations only: ``typing`` and ``collections.abc`` are not imported at run time
    from collections.abc import Callable, Iterable, Iterator

#: what ``cvpipe --json`` prints on stdout for an interrupt: the sorted-key failure record of :mod:`cvpipe.cli`
JSON_RECORD = '{"error": "interrupted", "exit": 130, "file": null}'

_seen = False
_installed = False
#: what an interrupted program prints: the line on stderr, and the record on stdout (None: no record)
_line = "cvpipe: error: interrupted"
_record: str | None = None


def install(line: str = "cvpipe: error: interrupted", record: str | None = None) -> bool:
    """Handle SIGINT with a flag (see the module docstring); True when the handler was installed.

    Parameters
    ----------
    line : str
        The one line written to stderr when the program ends because of an interrupt.
    record : str, optional
        One line written to stdout after ``line`` (the ``--json`` failure record), or None.

    Returns
    -------
    bool
        True when the handler is in place (a second call only changes ``line`` and ``record``). False, and SIGINT
        left as it was, when SIGINT is not at Python's default handler: a program started with SIGINT
        ignored (``nohup``, a background job) stays deaf to it, and an embedding program keeps its own handler.
    """
    global _installed, _line, _record
    _line, _record = line, record
    if _installed:  # called again (a stage that knows its full name once its arguments are parsed): only the words
        return True
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return False
    signal.signal(signal.SIGINT, _on_sigint)
    _installed = True
    return True


def _on_sigint(signum, frame) -> None:
    global _seen
    if _seen:
        exit_now()
    _seen = True


def seen() -> bool:
    """True once an interrupt was recorded (a SIGINT through :func:`install`'s handler, or :func:`mark`)."""
    return _seen


def mark() -> None:
    """Record an interrupt that reached this process another way (a ``KeyboardInterrupt`` a library swallowed)."""
    global _seen
    _seen = True


def check() -> None:
    """Raise ``KeyboardInterrupt`` when an interrupt was recorded; called between items and steps."""
    if _seen:
        raise KeyboardInterrupt


def checked(items: Iterable) -> Iterator:
    """``items``, with :func:`check` before each one is handed out."""
    for item in items:
        check()
        yield item


def say() -> None:
    """Write the interrupt's line to stderr (and its record to stdout), flushed; a closed stream is skipped.

    The process's own streams (``sys.__stderr__``, ``sys.__stdout__``): the handler may run while ``sys.stderr`` is
    redirected for a moment (the CLI captures argparse's messages).
    """
    for stream, text in ((sys.__stderr__, _line), (sys.__stdout__, _record)):
        if text is None:
            continue
        try:
            stream.write(text + "\n")
            stream.flush()
        except (OSError, ValueError, AttributeError):  # closed, or no such stream: nothing left to say
            pass


def ignore() -> None:
    """Ignore SIGINT from now on, when :func:`install` handles it: the program is ending (it says why itself) and a
    further Ctrl-C must neither cut that short nor say it twice."""
    if _installed:
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def exit_now() -> None:
    """Say the interrupt (:func:`say`) and leave the process at once with exit status 130."""
    ignore()
    say()
    os._exit(130)


def finish(code: int | str | None) -> int | str | None:
    """The exit status of a program whose work returned ``code``: 130 (with :func:`say`) when an interrupt arrived
    that nothing checked after it and the program had not already ended as interrupted (130), else ``code``.

    With the handler installed, SIGINT is ignored from here on: Python restores the default action of a handled
    signal while it shuts down, so a Ctrl-C then would kill the process by SIGINT instead of letting it end with the
    status of its finished work.
    """
    ignore()
    if _seen and code != 130:
        say()
        return 130
    return code


def run(main: Callable[[], int | str | None]) -> int | str | None:
    """The exit status of a program whose work is ``main()``: :func:`finish` of what it returned, or of the status of
    the ``SystemExit`` it raised (argparse's ``--help`` and ``--version``)."""
    try:
        code = main()
    except SystemExit as exc:
        code = exc.code
    return finish(code)
