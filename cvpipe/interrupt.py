"""Ctrl-C and SIGTERM for the ``cvpipe`` program and the stage scripts: the first signal asks the work to stop, a
second one stops it.

:func:`install` replaces Python's handlers of SIGINT and SIGTERM by one that never raises. The first signal only sets
a flag (:func:`seen`); the commands, the stage runner and the per-item loops call :func:`check` between items and
steps, which raises ``KeyboardInterrupt`` there, in ordinary Python code, and the program ends with one line on stderr
(``cvpipe: error: interrupted`` after a SIGINT, ``cvpipe: error: terminated`` after a SIGTERM; with ``--json`` also
the JSON record of a failure on stdout) and the signal's exit status, 128 + its number (:func:`status`: 130 and 143,
what a shell reports for a process the signal ended). The first signal sets the words and the status. A second
signal of either kind prints that line and leaves at once with ``os._exit``: temporaries are cleaned by the next
write, as after any killed process. A handler that never raises may run anywhere, also inside a compiled extension's
call back into Python, which must not fail.

In what follows "an interrupt" is either signal and 130 its status (143 for SIGTERM).

:func:`finish` decides a program's exit status: an interrupt that arrived during the work but was never checked
turns it into 130. The handler stays in place through the interpreter's shutdown (its ``atexit`` functions,
dask's and the thread pools' threads): the last ``atexit`` function blocks both signals, and one that arrived at any
moment before it still ends the process with its status and the one line. It then leaves with ``os._exit`` and the
decided status (the standard streams flushed), so no signal can arrive in a shutdown phase where Python has put back
the default action, which would kill the process by the signal.

:func:`results_out` marks that a command's results are going out: from then on an interrupt does not cut them
short (only a second Ctrl-C does, at once) and no record follows them on stdout; the first one still ends the
program with 130 and the line on stderr once they are out.

Without :func:`install` (cvpipe used as a library) nothing changes: Ctrl-C raises ``KeyboardInterrupt`` as usual,
SIGTERM ends the process, and :func:`check` only acts on :func:`mark`. This module imports only the standard library
(not even ``json``: the record is formatted here): the entry point installs the handler before anything heavy is
imported.
"""

from __future__ import annotations

import atexit
import os
import signal
import sys

TYPE_CHECKING = False
if TYPE_CHECKING:  # annotations only: ``typing`` and ``collections.abc`` are not imported at run time
    from collections.abc import Callable, Iterable, Iterator

#: signal -> the word of the line and the record (the exit status is 128 + the signal's number)
REASONS = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated"}

#: the first signal recorded (None: none yet)
_signal: int | None = None
_installed = False
#: the signals whose handler :func:`install` set
_handled: set[int] = set()
#: who says an interrupt (``cvpipe``, a stage's name), and whether the JSON record follows the line on stdout
_name = "cvpipe"
_record = False
#: True once the results are going out (:func:`results_out`)
_going_out = False
#: the exit status :func:`finish` decided (None: not yet), with which the last ``atexit`` function leaves
_status: int | None = None


def install(name: str = "cvpipe", record: bool = False) -> bool:
    """Handle SIGINT and SIGTERM with a flag (see the module docstring); True when the SIGINT handler is in place.

    Parameters
    ----------
    name : str
        Who says the interrupt: the line on stderr is ``<name>: error: interrupted`` (or ``terminated``).
    record : bool
        Also write the failure record ``{"error", "exit", "file"}`` (``--json``) as one line on stdout.

    Returns
    -------
    bool
        True when the handler is in place (a second call only changes ``name`` and ``record``). False, and SIGINT
        left as it was, when SIGINT is not at Python's default handler: a program started with SIGINT ignored
        (``nohup``, a background job) stays deaf to it, and an embedding program keeps its own handler. SIGTERM is
        taken over likewise only from its default action.
    """
    global _installed, _name, _record
    _name, _record = name, record
    if _installed:  # called again (a stage that knows its full name once its arguments are parsed): only the words
        return True
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return False
    for signum, default in ((signal.SIGINT, signal.default_int_handler), (signal.SIGTERM, signal.SIG_DFL)):
        if signal.getsignal(signum) is default:
            signal.signal(signum, _on_signal)
            _handled.add(signum)
    # registered before anything but the standard library is imported: ``atexit`` runs its functions last in,
    # first out, so this one runs after every other one
    atexit.register(_leave)
    _installed = True
    return True


def _on_signal(signum, frame) -> None:
    global _signal
    if _signal is not None:
        exit_now()
    _signal = signum


def seen() -> bool:
    """True once an interrupt was recorded (a signal through :func:`install`'s handler, or :func:`mark`)."""
    return _signal is not None


def reason() -> str:
    """``"interrupted"`` or ``"terminated"``: the word for the signal recorded (a SIGINT when none was)."""
    return REASONS[signal.SIGINT if _signal is None else _signal]


def status() -> int:
    """The exit status of the program an interrupt ends: 128 + the signal's number (130 when none was recorded)."""
    return 128 + (signal.SIGINT if _signal is None else _signal)


def mark() -> None:
    """Record an interrupt that reached this process another way (a ``KeyboardInterrupt`` a library swallowed)."""
    global _signal
    if _signal is None:
        _signal = signal.SIGINT


def check() -> None:
    """Raise ``KeyboardInterrupt`` when an interrupt was recorded (until the results go out); called between items
    and steps."""
    if _signal is not None and not _going_out:
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
    # the sorted-key failure record of cvpipe.cli
    record = f'{{"error": "{reason()}", "exit": {status()}, "file": null}}' if _record else None
    for stream, text in ((sys.__stderr__, f"{_name}: error: {reason()}"), (sys.__stdout__, record)):
        if text is None:
            continue
        try:
            stream.write(text + "\n")
            stream.flush()
        except (OSError, ValueError, AttributeError):  # closed, or no such stream: nothing left to say
            pass


def ignore() -> None:
    """Ignore the signals :func:`install` handles from now on: the program is ending (it says why itself) and a
    further one must neither cut that short nor say it twice."""
    for signum in _handled:
        signal.signal(signum, signal.SIG_IGN)


def exit_now() -> None:
    """Say the interrupt (:func:`say`) and leave the process at once with its exit status (:func:`status`)."""
    ignore()
    say()
    os._exit(status())


def results_out() -> None:
    """Mark that the program's results are going out (files, then stdout): from here on :func:`check` no longer
    raises, and an interrupt is said by its line alone (see the module docstring)."""
    global _record, _going_out
    _record = False
    _going_out = True


def finish(code: int | str | None) -> int | str | None:
    """The exit status of a program whose work returned ``code``: the interrupt's (:func:`status`, with :func:`say`)
    when one arrived that nothing checked after it and the program had not already ended with that status, else
    ``code``.

    With the handler installed, a signal after this call, up to the end of the interpreter's shutdown, still ends
    the program with its status (see the module docstring); after an interrupt already said, the signals are
    ignored, so that the line is not said twice.
    """
    global _status
    if _signal is not None and code != status():
        say()
        code = status()
    if _signal is not None or code == 130:
        ignore()
    _status = 0 if code is None else code if isinstance(code, int) else 1  # sys.exit's statuses: a message is 1
    return code


def _leave() -> None:
    """The last ``atexit`` function of a program that :func:`install` set up: the signals blocked (a late one stays
    pending instead of killing the process), the streams flushed, then ``os._exit`` with the interrupt's status
    when one came after :func:`finish` (said here), else with the status :func:`finish` decided."""
    global _signal
    if _status is None:  # the program did not get to finish(): Python's own shutdown, deaf to the signals
        ignore()
        return
    signal.pthread_sigmask(signal.SIG_BLOCK, _handled)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    if _signal is None:
        _signal = next((s for s in (signal.SIGINT, signal.SIGTERM) if s in signal.sigpending() & _handled), None)
    if _signal is not None and _status != status():
        say()
        os._exit(status())
    os._exit(_status)


def run(main: Callable[[], int | str | None]) -> int | str | None:
    """The exit status of a program whose work is ``main()``: :func:`finish` of what it returned, or of the status of
    the ``SystemExit`` it raised (argparse's ``--help`` and ``--version``)."""
    try:
        code = main()
    except SystemExit as exc:
        code = exc.code
    return finish(code)
