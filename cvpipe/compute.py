"""The execution layer: map a per-item function over many items, in process or on a Dask cluster.

``compute.scheduler`` chooses where the work runs and never what it computes:

- ``""`` (the default): a loop in this process, the items one at a time on a thread of its own; Dask is not even
  imported.
- ``"local"``: a ``distributed.LocalCluster`` of ``workers`` single-threaded worker processes (default: one per
  core), with OpenCV and our OpenMP kernels limited to one thread each so that the workers do not fight over the
  cores.
- ``"tcp://host:port"`` (port 1..65535): a running cluster, e.g. ``dask scheduler`` and ``dask worker``, or any
  other Dask deployment (Kubernetes, Slurm through dask-jobqueue). Before a client connects, the address is checked
  to greet like a Dask scheduler within ``timeout`` seconds (:func:`probe_scheduler`); a scheduler lost mid-run ends
  the run with one :class:`ComputeError` naming it, after the items that had finished were yielded.

Items travel with their data: ``fn(item, shared)`` receives arrays or bytes, never a path in the caller's working
directory, because a worker need not see that directory. Each item's data is scattered straight to a worker, in
batches, never through the scheduler; ``shared`` (a reference image, a gallery) is sent once per worker. Results
come back in the input order whatever finished first, so a caller that writes them sequentially produces the same
bytes in every mode. At most ``window`` items are submitted and not yet yielded at any time, so the
memory of a run over 10^4 items does not grow with the number of items, provided ``items`` is a lazy iterable.

An item whose function raises is reported as a failed :class:`ItemResult` with the exception's message and never
stops the others; an item lost with its worker is rerun on another one (Dask reschedules it; if the scheduler gives
up on it, it is resubmitted up to ``retries`` times). This module never touches the disk.
"""

from __future__ import annotations

import contextlib
import contextvars
import itertools
import logging
import os
import sys
import uuid
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

from . import interrupt
from .errors import EstimationError, InputError, check_int

#: the worker environment of a ``local`` cluster: one thread per worker for every threaded library we use
WORKER_ENV = {"OPENCV_FOR_THREADS_NUM": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "OPENBLAS_NUM_THREADS": "1"}

#: seconds to wait for a remote scheduler (the connection, its greeting and the client's registration) before giving
#: up; the default of every ``timeout`` parameter of this module
CONNECT_TIMEOUT = 10.0
#: the address schemes accepted: plain TCP only (``tls://`` would need certificates that no option passes, ``ucx://``
#: an extra package)
SCHEMES = ("tcp",)
#: the most bytes a scheduler's first message (its greeting, about 60 bytes) may announce; a peer announcing more
#: is not a Dask scheduler and is refused before anything is allocated for it
MAX_GREETING_BYTES = 64 * 1024


class ComputeError(EstimationError):
    """The cluster could not run the work (unreachable scheduler): nothing was computed, the CLI exits 1."""


@dataclass(frozen=True)
class ItemResult:
    """The outcome of one item.

    Attributes
    ----------
    index : int
        Position of the item in the input (results are yielded in this order).
    value : object
        What ``fn`` returned; None when the item failed.
    error : str or None
        The message of the exception the item raised (or why it was lost); None on success.
    error_type : str or None
        The exception's class name (``"InputError"``, ``"EstimationError"``, ...).
    attempts : int
        How many times the item was submitted (more than 1 only when a worker was lost under it).
    exception : BaseException or None
        The exception itself, in process only (None from a cluster, where only its message and class travel):
        a caller can re-raise it with its chain (a Ctrl-C wrapped in a SystemError) intact.
    """

    index: int
    value: Any = None
    error: str | None = None
    error_type: str | None = None
    attempts: int = 1
    exception: BaseException | None = field(default=None, compare=False, repr=False)

    @property
    def ok(self) -> bool:
        return self.error is None


def _cvpipe_classes() -> dict[str, type]:
    from .errors import CvpipeError

    classes: dict[str, type] = {}
    todo = [CvpipeError]
    while todo:
        cls = todo.pop()
        classes[cls.__name__] = cls
        todo.extend(cls.__subclasses__())
    return classes


def raise_unexpected(result: ItemResult) -> None:
    """Re-raise an item's failure that is not a cvpipe error (a bug, an interrupt): it ends the command, as it did
    before items were mapped, rather than becoming one listed item.

    In process the original exception is raised (its chain intact, so a Ctrl-C wrapped in a SystemError stays exit
    130); from a cluster, an :class:`InputError` for a ``ValueError`` and an :class:`EstimationError` otherwise,
    naming the exception's class.
    """
    if result.ok or result.error_type in _cvpipe_classes():
        return
    if result.exception is not None:
        raise result.exception
    cls = InputError if result.error_type == "ValueError" else EstimationError
    raise cls(f"internal error on a worker ({result.error_type}: {result.error})")


def item_error(result: ItemResult, file: str | None = None) -> EstimationError | InputError:
    """The cvpipe error ``result`` failed with, rebuilt from its class name so that its exit status survives.

    An item's exception crosses the cluster as its message and class name (:func:`_run_one`); this maps the name
    back: any :class:`~cvpipe.errors.CvpipeError` subclass by name (``InputError``, ``BudgetError`` -> exit 2,
    ``EstimationError`` -> exit 1), a ``ValueError`` (a bad value) to :class:`InputError`, anything else (a lost
    item, an unexpected failure) to :class:`EstimationError`.
    """
    from .errors import CvpipeError

    cls = _cvpipe_classes().get(result.error_type or "")
    if cls is None or cls is CvpipeError:
        cls = InputError if result.error_type == "ValueError" else EstimationError
    try:
        return cls(result.error, file=file)
    except TypeError:  # a subclass with its own constructor: keep the exit status, not the class
        return (InputError if issubclass(cls, InputError) else EstimationError)(result.error, file=file)


def scheduler_problem(scheduler: str) -> str | None:
    """Why ``scheduler`` (stripped) is not ``""``, ``"local"`` or ``tcp://host:port`` with a port in 1..65535, as the
    end of a sentence; None when it is one of them. Parses only: nothing is contacted."""
    from urllib.parse import urlsplit

    s = scheduler.strip()
    forms = "must be '' (in process), 'local' or a scheduler address tcp://host:port (port 1..65535)"
    if s in ("", "local"):
        return None
    if "://" not in s:
        return forms
    scheme = s.split("://", 1)[0].lower()
    if scheme not in SCHEMES:
        return f"{forms}; scheme {scheme}:// is not supported (only {', '.join(f'{x}://' for x in SCHEMES)})"
    try:
        parts = urlsplit(s)
        port = parts.port
    except ValueError:  # a port that is not a number in 0..65535
        return f"{forms}; the port is not a number in 1..65535"
    if not parts.hostname:
        return f"{forms}; the host is empty"
    if port is None:
        return f"{forms}; the port is missing"
    if not 1 <= port <= 65535:
        return f"{forms}; port {port} is outside 1..65535"
    if parts.path not in ("", "/") or parts.query or parts.fragment or parts.username or parts.password:
        return f"{forms}; nothing may follow host:port"
    return None


def check_scheduler(scheduler: str, name: str = "compute.scheduler") -> str:
    """``scheduler`` stripped if it is ``""``, ``"local"`` or ``tcp://host:port``; else raise naming ``name``.

    Raises
    ------
    InputError
        Not a string, another scheme (``tls://``, ``ucx://``), an empty host, or a port outside 1..65535.
    """
    if not isinstance(scheduler, str):
        raise InputError(f"`{name}` must be a string, got {scheduler!r}")
    problem = scheduler_problem(scheduler)
    if problem is not None:
        raise InputError(f"`{name}` {problem}, got {scheduler!r}")
    return scheduler.strip()


def check_timeout(timeout: float, name: str = "timeout") -> float:
    """``timeout`` as a float if it is a finite number of seconds > 0; else raise naming ``name``."""
    import math

    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not (math.isfinite(timeout)
                                                                                 and timeout > 0):
        raise InputError(f"`{name}` must be a finite number of seconds > 0, got {timeout!r}")
    return float(timeout)


def probe_scheduler(address: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """Check that a Dask scheduler answers at ``address`` within ``timeout`` seconds, before a client connects.

    A Dask scheduler greets every new connection at once with a short message: an 8-byte little-endian length
    and that many bytes (:data:`MAX_GREETING_BYTES` at most). A peer that accepts and says nothing (a plain HTTP
    server waits for a request), closes, answers in HTTP or announces a larger first message is not one; the Dask
    client would wait on it for ever or allocate what it announces, so it is refused here. Only the first 8 bytes
    are read; the connection is then closed.

    Parameters
    ----------
    address : str
        ``tcp://host:port`` (see :func:`check_scheduler`).
    timeout : float
        Seconds for the connection and the greeting together.

    Raises
    ------
    ComputeError
        Nothing listens, the peer does not greet within ``timeout``, or its greeting is not a Dask one; the
        message names the address.
    """
    import socket
    import struct
    import time
    from urllib.parse import urlsplit

    parts = urlsplit(address)
    deadline = time.monotonic() + timeout
    why = f"cannot reach the Dask scheduler at {address} within {timeout:g} s"
    try:
        with socket.create_connection((parts.hostname, parts.port), timeout=timeout) as sock:
            head = b""
            while len(head) < 8:
                sock.settimeout(max(deadline - time.monotonic(), 1e-3))
                chunk = sock.recv(8 - len(head))
                if not chunk:
                    raise ComputeError(f"{address} closed the connection without a Dask greeting: not a Dask "
                                       "scheduler")
                head += chunk
    except socket.timeout:
        raise ComputeError(f"{address} accepted the connection but sent no Dask greeting within {timeout:g} s: "
                           "not a Dask scheduler (or it is overloaded)") from None
    except OSError as exc:
        raise ComputeError(f"{why}: {exc.strerror or exc}") from None
    if head[:5] in (b"HTTP/", b"<!DOC", b"<html"):
        raise ComputeError(f"{address} answers HTTP, not the Dask protocol: not a Dask scheduler (its dashboard?)")
    (size,) = struct.unpack("<Q", head)
    if not 0 < size <= MAX_GREETING_BYTES:
        raise ComputeError(f"{address} announced a first message of {size} bytes (a Dask scheduler's greeting is "
                           f"at most {MAX_GREETING_BYTES}): not a Dask scheduler")


def _run_one(fn: Callable, item: Any, shared: Any, with_shared: bool, keep: bool = False) -> tuple:
    """Run ``fn`` on one item where it lands; the item's own exception becomes a value, not a task failure.

    A task failure would make Dask retry a bad item (it cannot tell a corrupt image from a lost worker); catching it
    here leaves Dask's retries for what they are for.
    """
    try:
        return True, (fn(item, shared) if with_shared else fn(item)), None
    except Exception as exc:  # noqa: BLE001 - every item failure is reported, none stops the run
        return False, str(exc) or type(exc).__name__, type(exc).__name__, *((exc,) if keep else ())


def _progress_callback(progress: Any, total: int | None) -> tuple[Callable[[int], None], Callable[[], None]]:
    """``(update(done), close())`` for ``progress``: None, a tqdm description (str) or ``callable(done, total)``."""
    if progress is None:
        return (lambda done: None), (lambda: None)
    if isinstance(progress, str):
        from tqdm import tqdm

        # disable=None: silent when stderr is not a terminal; the bar shows done/total and the rate
        bar = tqdm(total=total, desc=progress, unit="item", disable=None, file=sys.stderr)

        def update(done: int) -> None:
            bar.update(done - bar.n)

        return update, bar.close
    return (lambda done: progress(done, total)), (lambda: None)


def _serial(fn, items, shared, with_shared, update) -> Iterator[ItemResult]:
    """The in-process loop: one item at a time, each on the same thread of the run's own, as on a Dask worker.

    With glibc, memory that the main thread frees goes back to the system and each item's arrays are faulted in
    again, while another thread's allocator keeps it for the next item (`cvpipe logo` on the 52 sample scenes, SIFT:
    10.9-11.9 s on the main thread, 9.2-9.4 s on a thread of its own, the same answers). Each item runs with the
    caller's context variables; OpenMP's thread count there is the process's (``OMP_NUM_THREADS``), as on a Dask
    worker. Ctrl-C is seen between items.
    """
    with ThreadPoolExecutor(1, thread_name_prefix="cvpipe-items") as thread:
        for i, item in enumerate(interrupt.checked(items)):
            ok, value, etype, *exc = thread.submit(contextvars.copy_context().run, _run_one, fn, item, shared,
                                                   with_shared, True).result()
            yield ItemResult(i, value, None, None) if ok else ItemResult(i, None, value, etype, exception=exc[0])
            update(i + 1)


@contextlib.contextmanager
def cluster(scheduler: str, workers: int | None = None, *, timeout: float = CONNECT_TIMEOUT,
            name: str = "compute.scheduler"):
    """Open the Dask client for ``scheduler`` (None for ``""``) and close it, and a local cluster, on exit.

    Parameters
    ----------
    scheduler : str
        ``""``, ``"local"`` or a scheduler address (see the module docstring).
    workers : int, optional
        Worker processes of a ``local`` cluster; None or 0 = ``os.cpu_count()``. Ignored otherwise.
    timeout : float
        Seconds to wait for a remote scheduler: its greeting (:func:`probe_scheduler`), then the client's
        connection and registration (default :data:`CONNECT_TIMEOUT`).
    name : str
        The parameter or option that named ``scheduler``, for error messages.

    Raises
    ------
    InputError
        ``scheduler`` is not one of the accepted forms, ``timeout`` is not a positive number or ``workers`` is
        negative.
    ComputeError
        The scheduler at the address could not be reached, or did not answer as a Dask scheduler, within
        ``timeout``.
    """
    s = check_scheduler(scheduler, name)
    timeout = check_timeout(timeout)
    if workers is not None:
        workers = check_int("compute.workers", workers, 0, note="0 = one per core")
    if s == "":
        yield None
        return
    from .errors import require_extra

    require_extra("distributed", "dask", "a Dask scheduler (`compute.scheduler`, `--scheduler`)")
    import dask
    from distributed import Client, LocalCluster

    if s == "local":
        # the nanny's `env` is set inside each worker process, before it imports OpenCV or starts OpenMP;
        # `pre-spawn-environ` would be written into this process's own os.environ too, and OpenCV or OpenMP started
        # here later would then run this process's own work on one thread
        # no dashboard, and the scheduler's HTTP endpoints on a free port rather than 8787 (may be taken)
        local = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                             silence_logs=logging.ERROR, dashboard_address=None, env=dict(WORKER_ENV),
                             scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"})
        try:
            with Client(local) as client:
                yield client
        finally:
            local.close()
        return
    probe_scheduler(s, timeout)
    quiet = _quiet_client_logs()
    try:
        with dask.config.set({"distributed.comm.timeouts.connect": f"{timeout}s"}):
            client = Client(s, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as exc:
        quiet.close()
        raise ComputeError(f"cannot reach the Dask scheduler at {s} within {timeout:g} s: "
                           f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    try:
        yield client
    finally:
        with contextlib.suppress(*_lost_scheduler()):
            client.close(timeout=timeout)
        quiet.close()


def _lost_scheduler() -> tuple[type[BaseException], ...]:
    """What a client call raises when its scheduler went away: an ``OSError`` (a closed or reset connection, a
    timed-out reconnect; Dask's ``CommClosedError`` is one), a ``TimeoutError``, the futures cancelled with it."""
    from concurrent.futures import CancelledError

    return OSError, TimeoutError, CancelledError


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


class _quiet_client_logs:
    """Silence the ``distributed`` loggers (their reconnect attempts and tracebacks) until :meth:`close`: on a remote
    scheduler, what went wrong is the one :class:`ComputeError` line."""

    #: the family's root and the loggers that Dask's logging configuration gives a level of their own
    LOGGERS = ("distributed", "distributed.client", "distributed.comm", "distributed.core", "distributed.batched")

    def __init__(self):
        self._levels = {name: logging.getLogger(name).level for name in self.LOGGERS}
        for name in self.LOGGERS:
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)

    def close(self) -> None:
        for name, level in self._levels.items():
            logging.getLogger(name).setLevel(level)


def map_items(fn: Callable, items: Iterable, *, scheduler: str = "", workers: int | None = None,
              shared: Any = None, window: int | None = None, retries: int = 2, progress: Any = None,
              total: int | None = None, client: Any = None,
              timeout: float = CONNECT_TIMEOUT) -> Iterator[ItemResult]:
    """Apply ``fn`` to every item and yield an :class:`ItemResult` per item, in the input order.

    Parameters
    ----------
    fn : callable
        ``fn(item)``, or ``fn(item, shared)`` when ``shared`` is given. Must be picklable (a module-level function)
        for a cluster, and take the item's data, not a path only this process can read.
    items : iterable
        Consumed lazily: only ``window`` items are held at a time on a cluster.
    scheduler : str
        ``""`` (in process), ``"local"`` or a scheduler address; ignored when ``client`` is given.
    workers : int, optional
        Size of a ``local`` cluster (None or 0 = one worker per core).
    shared : object, optional
        Data every item needs; sent once to each worker (``scatter(broadcast=True)``), not once per item.
    window : int, optional
        Most items submitted but not yet yielded (in flight or waiting for an earlier item); default 4 x the
        cluster's threads. Bounds the memory whatever the number of items.
    retries : int
        Resubmissions of an item whose worker was lost after Dask itself gave up (``KilledWorker``).
    progress : None, str or callable
        A tqdm description (bar on stderr, silent when it is not a terminal) or ``progress(done, total)``.
    total : int, optional
        Number of items for the progress (default ``len(items)`` when it has one).
    client : distributed.Client, optional
        An open client to use instead of ``scheduler`` (kept open).
    timeout : float
        Seconds to wait for a remote scheduler (see :func:`cluster`; default :data:`CONNECT_TIMEOUT`).

    Yields
    ------
    ItemResult
        One per item, ``index`` 0, 1, 2, ... An item's exception is its ``error``; it never stops the others.

    Raises
    ------
    InputError
        Bad ``scheduler``, ``workers``, ``window``, ``retries`` or ``timeout``.
    ComputeError
        The scheduler cannot be reached or is not a Dask scheduler (raised at the first ``next()``, before any item
        runs), or it was lost mid-run (raised after the items that had finished were yielded; the message names
        the address and their number).
    """
    if window is not None:
        window = check_int("compute.window", window, 1)
    retries = check_int("retries", retries, 0)
    if total is None and hasattr(items, "__len__"):
        total = len(items)
    with_shared = shared is not None
    if client is None and check_scheduler(scheduler) == "":
        return _serial_gen(fn, items, shared, with_shared, progress, total)
    return _cluster_gen(fn, items, scheduler, workers, shared, with_shared, window, retries, progress, total,
                        client, timeout)


def _serial_gen(fn, items, shared, with_shared, progress, total):
    update, close = _progress_callback(progress, total)
    try:
        yield from _serial(fn, items, shared, with_shared, update)
    finally:
        close()


def _cluster_gen(fn, items, scheduler, workers, shared, with_shared, window, retries, progress, total, client,
                 timeout):
    ctx = contextlib.nullcontext(client) if client is not None else cluster(scheduler, workers, timeout=timeout)
    finished = 0
    with ctx as c:
        try:
            for res in _windowed(c, fn, items, shared, with_shared, window, retries, progress, total):
                yield res
                finished += 1
        except (ComputeError, *_lost_scheduler()) as exc:
            # the items already yielded are the caller's to keep; the rest never ran
            where = scheduler if client is None else getattr(getattr(c, "scheduler", None), "address", "?")
            raise ComputeError(f"lost the Dask scheduler at {where} after {finished} items had finished "
                               f"({_first_line(exc)})") from None


def _windowed(client, fn, items, shared, with_shared, window, retries, progress, total) -> Iterator[ItemResult]:
    """Keep at most ``window`` items between submission and yield; yield in input order.

    Completion is polled with ``distributed.wait(..., return_when="FIRST_COMPLETED")`` in short rounds rather than
    through ``as_completed``: the latter's background coroutine can die inside the client's event loop (seen as a
    tornado ``AssertionError`` under load) and leave the iteration waiting for ever. Each round also checks that the
    client is still connected, so a scheduler that goes away ends the run with :class:`ComputeError`, not a hang.
    """
    if window is None:
        nthreads = sum(client.nthreads().values()) or 1
        window = 4 * nthreads
    shared_arg = client.scatter([shared], broadcast=True, hash=False)[0] if with_shared else None
    run_id = f"{getattr(fn, '__name__', 'item')}-{uuid.uuid4().hex}"
    update, close = _progress_callback(progress, total)
    source = enumerate(items)
    pending: dict[Any, tuple] = {}  # future -> (index, item, attempt, future of the item's data)
    done: dict[int, ItemResult] = {}
    next_yield = 0
    next_submit = 0
    exhausted = False

    def submit(batch: list[tuple[int, Any, int]]) -> None:
        # the items' data goes straight to the workers (one scatter per batch). Embedded in the tasks, it went
        # through the scheduler and was freed late: the driver's peak memory grew ~4x from 10^2 to 10^3 items.
        datas = client.scatter([item for _, item, _ in batch], hash=False)
        for (index, item, attempt), data in zip(batch, datas):
            fut = client.submit(_run_one, fn, data, shared_arg, with_shared, key=f"{run_id}-{index}-{attempt}",
                                pure=False)
            pending[fut] = (index, item, attempt, data)

    refill = max(1, window // 4)  # scatter in batches: fewer round trips, the window stays nearly full
    try:
        while True:
            interrupt.check()  # a Ctrl-C ends the run between rounds; the finally below cancels what is pending
            free = window - (next_submit - next_yield)
            if not exhausted and free > 0 and (free >= refill or not pending):
                batch = []
                for index, item in itertools.islice(source, free):
                    batch.append((index, item, 1))
                exhausted = len(batch) < free
                if batch:
                    submit(batch)
                    next_submit += len(batch)
            if not pending and next_yield == next_submit:
                break
            finished = _wait_some(client, list(pending))
            # one round trip for all the results of this round; a failed task's future gives its exception
            ok_futs = [f for f in finished if f.status == "finished"]
            values = dict(zip(ok_futs, client.gather(ok_futs))) if ok_futs else {}
            for fut in finished:
                index, item, attempt, data = pending.pop(fut)
                data.release()
                if fut in values:
                    ok, value, etype = values[fut]
                    done[index] = (ItemResult(index, value, None, None, attempt) if ok
                                   else ItemResult(index, None, value, etype, attempt))
                else:
                    # the task itself failed (its worker died and the scheduler gave up on it, or it was cancelled)
                    outcome = _task_failure(fut)
                    if attempt <= retries:
                        fut.release()
                        submit([(index, item, attempt + 1)])
                        continue
                    done[index] = ItemResult(index, None, f"lost after {attempt} attempts: {outcome}",
                                             type(outcome).__name__, attempt)
                fut.release()
            while next_yield in done:
                yield done.pop(next_yield)
                next_yield += 1
                update(next_yield)
    finally:
        for fut, (_, _, _, data) in pending.items():
            fut.cancel()
            data.release()
        if shared_arg is not None:
            shared_arg.release()
        close()


#: seconds of one completion poll; between polls the client's connection is checked
POLL = 5.0


def _wait_some(client, futures: list) -> list:
    """The futures of ``futures`` that have finished (at least one), waiting in rounds of :data:`POLL` seconds.

    Raises
    ------
    ComputeError
        The client lost its scheduler while waiting.
    """
    from concurrent.futures import CancelledError

    from distributed import wait

    while True:
        # a timeout means nothing finished in this round; recent versions raise a CancelledError subclass when a
        # future was cancelled (its data was lost with a worker): that future counts as finished, and the caller
        # resubmits it
        with contextlib.suppress(TimeoutError, CancelledError):
            wait(futures, timeout=POLL, return_when="FIRST_COMPLETED")
        finished = [f for f in futures if f.status != "pending"]
        if finished:
            return finished
        if client.status not in ("running", "connecting"):
            raise ComputeError(f"the client is {client.status} while waiting for results")


def _task_failure(fut) -> BaseException:
    """The exception a failed or cancelled task ended with (never raises itself)."""
    try:
        exc = fut.exception(timeout=POLL)
    except BaseException as err:  # noqa: BLE001 - a cancelled future raises CancelledError here
        return err
    return exc if exc is not None else RuntimeError(f"task {fut.status}")
