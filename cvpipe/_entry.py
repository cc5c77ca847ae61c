"""The ``cvpipe`` program's entry point (the console script and ``python -m cvpipe``).

It imports only ``os``, ``signal`` and ``sys`` before it takes over Ctrl-C, so that an interrupt at any moment after
the interpreter started ends the same way: exit status 130, one line ``cvpipe: error: interrupted`` on stderr and,
with ``--json``, one JSON record on stdout. Without it, a Ctrl-C during the import of :mod:`cvpipe.cli` (outside
any ``try``) ends in Python's default way (a traceback, or death by SIGINT), and a Ctrl-C that a library swallows
(numba runs Python callbacks from C during its first compile; some code catches everything) is lost and the
command exits 0.

Every SIGINT is also recorded (:func:`seen`): a command checks it between its steps
(:func:`cvpipe.commands.step`), and after the command returned, an interrupt that never surfaced still ends the
program with 130. An interrupt whose handler runs in numba's own Python code (a compiled kernel calling back into
it, or a kernel being compiled or loaded) is not raised there but delivered again 10 ms later, until it lands in
other code (:func:`_inside_numba`).
"""

from __future__ import annotations

import os
import signal
import sys

_seen = False
#: an interrupt that landed inside numba waits to be delivered again (:func:`_interrupt_again_soon`)
_retrying = False


def seen() -> bool:
    """True once a Ctrl-C reached this process (through :func:`main`'s handler, or :func:`mark`)."""
    return _seen


def mark() -> None:
    """Record an interrupt (for one that was swallowed before it could propagate)."""
    global _seen
    _seen = True


def _on_sigint(signum, frame):
    global _retrying
    mark()
    if _inside_numba(frame):
        _interrupt_again_soon()
        return
    _retrying = False
    raise KeyboardInterrupt


def _inside_numba(frame) -> bool:
    """True when the interrupted Python code belongs to numba or llvmlite, or the main thread holds numba's
    compiler lock (compiling a kernel, or loading one from its cache).

    A KeyboardInterrupt must not be raised there: compiled kernels call back into Python (``_numba_unpickle``
    fetches a constant while stereo's parallel ``_winner`` runs) and do not expect it to fail, and an interrupted
    load leaves a half-built kernel: a Ctrl-C at such a moment crashed the process with SIGSEGV in about 1 of 30
    tries. numba is only looked up in ``sys.modules``, never imported: this module stays stdlib-only.
    """
    numba = sys.modules.get("numba")
    if numba is None:
        return False
    lock = sys.modules.get("numba.core.compiler_lock")
    if lock is not None and lock.global_compiler_lock.is_locked():
        return True
    file = frame.f_code.co_filename if frame is not None else ""
    return any(file.startswith(os.path.dirname(m.__file__) + os.sep)
               for m in (numba, sys.modules.get("llvmlite")) if m is not None and getattr(m, "__file__", None))


def _interrupt_again_soon() -> None:
    """Signal the main thread again every 10 ms until the interrupt lands outside numba (:func:`_on_sigint`)."""
    global _retrying
    if _retrying:
        return
    _retrying = True
    import _thread
    import threading
    import time

    def retry():
        while _retrying:
            time.sleep(0.01)
            if _retrying:
                _thread.interrupt_main()

    threading.Thread(target=retry, name="cvpipe-interrupt", daemon=True).start()


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
