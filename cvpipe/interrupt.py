"""Ctrl-C for the ``cvpipe`` program and the stage scripts: the first one asks the work to stop, a second one stops it.

:func:`install` replaces Python's SIGINT handler by one that never raises. The first SIGINT only sets a flag
(:func:`seen`); the commands, the stage runner and the per-item loops call :func:`check` between items and steps,
which raises ``KeyboardInterrupt`` there, in ordinary Python code, and the program ends with exit status 130 and one
line (``cvpipe: error: interrupted``; with ``--json`` also the JSON record of a failure on stdout). A second SIGINT
prints that line and leaves at once with ``os._exit(130)``: temporaries are cleaned by the next write, as after any
killed process. A handler that never raises may run anywhere, also inside a compiled extension's call back into
Python, which must not fail.

:func:`finish` decides a program's exit status: an interrupt that arrived during the work but was never checked
turns it into 130. The handler stays in place through the interpreter's shutdown (its ``atexit`` functions,
dask's and the thread pools' threads): the last ``atexit`` function blocks SIGINT, and a Ctrl-C that arrived at any
moment before it still ends the process with 130 and the one line. It then leaves with ``os._exit`` and the decided
status (the standard streams flushed), so no SIGINT can arrive in a shutdown phase where Python has put back the
default action, which would kill the process by the signal.

:func:`results_out` marks that a command's results are going out: from then on an interrupt does not cut them
short (only a second Ctrl-C does, at once) and no record follows them on stdout; the first one still ends the
program with 130 and the line on stderr once they are out.

Without :func:`install` (cvpipe used as a library) nothing changes: Ctrl-C raises ``KeyboardInterrupt`` as usual and
:func:`check` only acts on :func:`mark`. This module imports only the standard library: the entry point installs the
handler before anything heavy is imported.
"""

from __future__ import annotations

import atexit
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
#: True once the results are going out (:func:`results_out`)
_going_out = False
#: the exit status :func:`finish` decided (None: not yet), with which the last ``atexit`` function leaves
_status: int | None = None


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
    # registered before anything but the standard library is imported: ``atexit`` runs its functions last in,
    # first out, so this one runs after every other one
    atexit.register(_leave)
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
    """Raise ``KeyboardInterrupt`` when an interrupt was recorded (until the results go out); called between items
    and steps."""
    if _seen and not _going_out:
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


def results_out() -> None:
    """Mark that the program's results are going out (files, then stdout): from here on :func:`check` no longer
    raises, and an interrupt is said by its line alone (see the module docstring)."""
    global _record, _going_out
    _record = None
    _going_out = True


def finish(code: int | str | None) -> int | str | None:
    """The exit status of a program whose work returned ``code``: 130 (with :func:`say`) when an interrupt arrived
    that nothing checked after it and the program had not already ended as interrupted (130), else ``code``.

    With the handler installed, a Ctrl-C after this call, up to the end of the interpreter's shutdown, still ends
    the program with 130 (see the module docstring); after an interrupt already said (130) SIGINT is ignored, so
    that the line is not said twice.
    """
    global _status
    if _seen and code != 130:
        say()
        code = 130
    if code == 130:
        ignore()
    _status = 0 if code is None else code if isinstance(code, int) else 1  # sys.exit's statuses: a message is 1
    return code


def _leave() -> None:
    """The last ``atexit`` function of a program that :func:`install` set up: SIGINT blocked (a late one stays
    pending instead of killing the process), the streams flushed, then ``os._exit`` with 130 when an interrupt
    came after :func:`finish` (said here), else with the status :func:`finish` decided."""
    if _status is None:  # the program did not get to finish(): Python's own shutdown, deaf to Ctrl-C
        ignore()
        return
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    if _status != 130 and (_seen or signal.SIGINT in signal.sigpending()):
        say()
        os._exit(130)
    os._exit(_status)


def run(main: Callable[[], int | str | None]) -> int | str | None:
    """The exit status of a program whose work is ``main()``: :func:`finish` of what it returned, or of the status of
    the ``SystemExit`` it raised (argparse's ``--help`` and ``--version``)."""
    try:
        code = main()
    except SystemExit as exc:
        code = exc.code
    return finish(code)
