"""The shared stage runner: what every stage script would otherwise repeat.

A stage script is one function of its own logic plus one call::

    def hough_edges(st: Stage) -> None:
        for f in st.progress(io.list_images(st.args.images), "edges"):
            ...
        st.made(f"{n} edge maps")

    if __name__ == "__main__":
        run(hough_edges, section="hough.edges", args={"images": "input folder", "out": "output folder"})

The runner builds the command line from the declared paths (every path is a required ``--name`` option; the values
live in ``dvc.yaml``'s ``cmd``, except a user's data folder, which ``cmd`` names by its parameter, ``--images-param
hough.data``, so that no value of ``params.yaml`` ever reaches the shell), loads and validates the stage's
``params.yaml`` section(s), shows progress on stderr when it is a terminal, turns a bad input or parameter into one
line ``<stage>: error: ...`` naming the file or key (exit 2; 1 when the algorithm could not produce a result; 130 on
Ctrl-C, 143 on SIGTERM) with no traceback, prints one summary line (what the stage made, what it dropped and why)
and writes the stage's timings to ``outputs/timings/<stage>.json``. Timings are never part of a cached output: a
rerun that gives the same results leaves every DVC hash unchanged, so the stages after it stay up to date.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence, TypeVar

from cvpipe import interrupt, io
from cvpipe.errors import BudgetError, CvpipeError, EstimationError, InputError
from cvpipe.metrics import headline, rounded
from cvpipe.params import SECTIONS, load_section

T = TypeVar("T")

#: the path arguments every report stage takes (its summary for the page, its dvc plots folder, its metrics file)
REPORT_ARGS = {"summary": "summary JSON for the report page", "plots": "folder for dvc plots data",
               "metrics": "metrics JSON (git-tracked)"}

#: where the uncached timing files go (relative to the repository root, where DVC runs every stage)
TIMINGS_DIR = Path("outputs/timings")
#: ``--<name>-param KEY``: the alternative of every single-path argument ``--<name>``, its value read from the params
#: file (:func:`path_param`)
PARAM_SUFFIX = "-param"
#: overrides ``compute.scheduler`` of the params file for the stages that fan out (:meth:`Stage.map`)
SCHEDULER_ENV = "CVPIPE_COMPUTE_SCHEDULER"


def details_path(metrics_path: str | os.PathLike) -> Path:
    """Where a stage's full metrics go beside its headline metrics file: ``metrics_sgm.json`` -> ``details_sgm.json``
    (a cached DVC output, while the metrics file is tracked by git)."""
    p = Path(metrics_path)
    return p.with_name(p.name.replace("metrics", "details", 1) if "metrics" in p.name else f"details_{p.name}")


@dataclass
class Stage:
    """What a stage function gets: its arguments, its parameters, and the means to report what it did."""

    name: str
    args: argparse.Namespace
    params: Any = None
    sections: dict[str, Any] = field(default_factory=dict)
    dropped: list[dict] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    _made: list[str] = field(default_factory=list)

    def progress(self, items: Iterable[T], desc: str | None = None, total: int | None = None) -> Iterable[T]:
        """``items`` with a progress bar on stderr (only when stderr is a terminal, so DVC logs stay clean)."""
        return io.progress(items, desc or self.name, total=total)

    def map(self, fn: Callable[[Any, Any], Any], items: Iterable, shared: Any = None, desc: str | None = None, *,
            names: Sequence[str] | None = None, total: int | None = None) -> Iterator[tuple[str, Any]]:
        """Run ``fn(item, shared)`` over ``items`` where ``compute`` in the params file says, in input order.

        ``compute`` (:class:`cvpipe.params.ComputeParams`; absent = in process; the environment variable
        ``CVPIPE_COMPUTE_SCHEDULER``, when set, overrides ``compute.scheduler``) is read here, never declared as a
        stage parameter: it changes where the items run, never what they give, so the stage's outputs are the
        same bytes whatever runs them (the caller writes them in the order yielded).

        Parameters
        ----------
        fn : callable
            A module-level function of the library (workers import it by reference) taking the item's data, not
            a path: a worker need not see this working directory.
        items : iterable
            The items' data, consumed lazily (only a window of them is in memory on a cluster). An item that is
            an exception instance (its data could not be read) is not run: it is dropped with its message.
        shared : object, optional
            Data every item needs (a reference and its features): sent once per worker.
        desc : str, optional
            The progress bar's label (default: the stage name).
        names : sequence of str, optional
            The items' names for :meth:`drop` (default: their positions).
        total : int, optional
            The number of items for the progress (default ``len(names)`` or ``len(items)``).

        Yields
        ------
        (name, value)
            For every item that succeeded, in input order. A failed item (a :class:`~cvpipe.errors.CvpipeError`)
            becomes ``drop(name, reason)``, in input order too; any other exception ends the stage as it would in
            a plain loop.
        """
        from cvpipe.compute import map_items, raise_unexpected

        if total is None:
            total = len(names) if names is not None else (len(items) if hasattr(items, "__len__") else None)
        c = load_section(SECTIONS["compute"], "compute", self.args.params) if _has_compute(self.args.params) \
            else SECTIONS["compute"]()
        scheduler = c.scheduler
        if os.environ.get(SCHEDULER_ENV, "").strip():
            # one run on a cluster without editing params.yaml (`CVPIPE_COMPUTE_SCHEDULER=tcp://head:8786 dvc repro`)
            from cvpipe.compute import check_scheduler

            scheduler = check_scheduler(os.environ[SCHEDULER_ENV], SCHEDULER_ENV)
        kept: list[int] = []  # input position of each item submitted
        unread: dict[int, str] = {}  # input position -> why its data could not be read

        def feed() -> Iterator[Any]:
            for pos, data in enumerate(items):
                if isinstance(data, BaseException):
                    unread[pos] = str(data)
                    continue
                kept.append(pos)
                yield data

        def name(pos: int) -> str:
            return str(names[pos]) if names is not None else str(pos)

        flushed = 0  # the drops are recorded in input order, whatever the mode, so the outputs match byte for byte

        def flush(upto: int) -> None:
            nonlocal flushed
            for pos in range(flushed, upto):
                if pos in unread:
                    self.drop(name(pos), unread.pop(pos))
            flushed = max(flushed, upto)

        over_budget: list[str] = []  # the reasons of the items the memory budget refused
        succeeded = 0
        for res in map_items(fn, feed(), scheduler=scheduler, workers=c.workers or None,
                             window=c.window or None, shared=shared, progress=desc or self.name, total=total):
            pos = kept[res.index]
            flush(pos)
            flushed = pos + 1
            if res.ok:
                succeeded += 1
                yield name(pos), res.value
            else:
                raise_unexpected(res)
                self.drop(name(pos), res.error)
                if res.error_type == BudgetError.__name__:
                    over_budget.append(f"{name(pos)}: {res.error}")
        flush(max(unread, default=-1) + 1)
        if over_budget and not succeeded and len(over_budget) == len(kept):
            # nothing made, and only because of the budget: a failure, not "0 results" with exit 0
            raise BudgetError(f"every item ({len(kept)}) was refused by the memory budget; the first: "
                              f"{over_budget[0]}")

    def map_sets(self, sets: Sequence[tuple[str, dict]], fn: Callable, data: Callable[[str, dict], Any],
                 shared: Any, desc: str) -> Iterator[tuple[str, dict | None, Any]]:
        """:meth:`map` over a chain of per-set records: run ``fn`` on every set that has not failed in an earlier
        stage and yield ``(name, failure record or None, fn's value or None)`` for every set, in order.

        ``sets`` are ``(name, record of the earlier step)``; a record without ``ok`` counts as ok. ``data(name,
        prev)`` reads a set's item (lazily, here). A set that failed earlier is carried (:meth:`step_record`); one
        whose ``fn`` raised is this stage's failure, already dropped with its reason by :meth:`map`.
        """
        todo = [(n, prev) for n, prev in sets if prev.get("ok", True)]
        results = self.map(fn, (data(n, prev) for n, prev in todo), shared=shared, desc=desc,
                           names=[n for n, _ in todo])
        pending = None
        for name, prev in sets:
            if not prev.get("ok", True):
                yield name, self.step_record(prev, name, dict), None
                continue
            if pending is None:
                pending = next(results, None)
            if pending is not None and pending[0] == name:
                yield name, None, pending[1]
                pending = None
            else:
                reason = next(d["reason"] for d in reversed(self.dropped) if d["item"] == name)
                yield name, {"ok": False, "error": reason, "failed_in": self.name}, None

    def step_record(self, prev: dict, name: str, step: Callable[[], dict]) -> dict:
        """One set's record in a chain of per-set records (each stage writes one per set): the earlier failure
        carried on, else ``step()``'s record, else (``step`` raised :class:`~cvpipe.errors.EstimationError`) this
        stage's failure, also dropped (:meth:`drop`) so that the summary line names it.

        Returns
        -------
        dict
            ``{"ok": True, ...}`` or ``{"ok": False, "error", "failed_in"}`` (the stage that failed), so that a
            report can say which set failed, where and why.
        """
        if not prev.get("ok"):
            return {"ok": False, "error": prev.get("error"), "failed_in": prev.get("failed_in")}
        try:
            return step()
        except EstimationError as exc:
            self.drop(name, str(exc))
            return {"ok": False, "error": str(exc), "failed_in": self.name}

    def step_summary(self, records: Sequence[dict], what: str) -> str:
        """``"2 sets warped ... (1 failed in an earlier stage)"``: the summary phrase of a chain of per-set records
        (this stage's own failures are in the line's dropped list)."""
        ok = sum(1 for r in records if r["ok"])
        earlier = sum(1 for r in records if not r["ok"] and r.get("failed_in") != self.name)
        return f"{ok} {what}" + (f" ({earlier} failed in an earlier stage)" if earlier else "")

    def drop(self, item: str, reason: str) -> None:
        """Record that ``item`` (a file, pair, set or probe name) was not processed, and why."""
        self.dropped.append({"item": str(item), "reason": str(reason)})

    def finish(self, out: str | Path, count: int, what: str, nothing: str) -> None:
        """Record ``dropped.json`` in the output folder ``out`` and the summary phrase ``"<count> <what>"``; with
        nothing made at all, fail with the one line ``nothing`` (InputError: the inputs were unusable)."""
        io.save_json(Path(out) / "dropped.json", self.dropped)
        if not count:
            raise InputError(nothing)
        self.made(f"{count} {what}")

    def write_report(self, summary: dict, metrics: dict | None = None, plots: dict[str, list] | None = None,
                     dropped: Iterable[dict] = ()) -> None:
        """A report stage's standard outputs: the page summary (``--summary``), the git-tracked metrics
        (``--metrics``), the ``dvc plots`` rows (``--plots``/<name>.json); what earlier stages dropped is carried."""
        io.save_json(self.args.summary, summary)
        if metrics is not None:
            self.save_metrics(self.args.metrics, metrics)
        for name, rows in (plots or {}).items():
            self.save_plot(Path(self.args.plots) / f"{name}.json", rows)
        self.carry(dropped)

    def save_metrics(self, path: str | os.PathLike, metrics: dict) -> None:
        """The git-tracked metrics file ``path`` gets the headline of ``metrics`` (:func:`cvpipe.metrics.headline`:
        the few figures experiments are compared by, at the precision they carry); all of ``metrics``, per item,
        goes to the cached details file beside it (:func:`details_path`)."""
        io.save_json(path, headline(metrics))
        io.save_json(details_path(path), metrics)

    def save_plot(self, path: str | os.PathLike, rows: Any) -> None:
        """A ``dvc plots`` file: ``rows`` with their floats rounded as the metrics are (:func:`cvpipe.metrics.rounded`)."""
        io.save_json(path, rounded(rows))

    def carry(self, dropped: Iterable[dict]) -> None:
        """Repeat what an earlier stage dropped (``{"item", "reason"}`` records) in this stage's summary line."""
        for d in dropped:
            self.drop(d["item"], d["reason"])

    def made(self, what: str) -> None:
        """Add a phrase to the stage's summary line (``"12 edge maps"``)."""
        self._made.append(what)

    @contextmanager
    def timer(self, key: str) -> Iterator[None]:
        """Time the block into the stage's timings under ``key`` (accumulated when the key repeats)."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.timings[key] = self.timings.get(key, 0.0) + time.perf_counter() - t0

    def summary_line(self) -> str:
        made = "; ".join(self._made) or "done"
        line = f"{self.name}: {made}"
        if self.dropped:
            items = ", ".join(f"{d['item']} ({d['reason']})" for d in self.dropped)
            line += f"; dropped {len(self.dropped)}: {items}"
        return line


def path_param(path: str | os.PathLike, key: str) -> str:
    """The value of the dotted parameter ``key`` (``"hough.data"``) of the params file ``path``: a path.

    A stage is told the parameter's name rather than its value so that no value of ``params.yaml`` (a folder named
    by a user: spaces, quotes, ``;``, ``$``) is ever pasted into the shell command that DVC runs.

    Raises
    ------
    InputError
        The parameter is missing, or is not a non-empty string without NUL.
    """
    from cvpipe.params import read_params_file

    node: Any = read_params_file(path)
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise InputError(f"{path}: parameter `{key}` is missing")
        node = node[part]
    if not isinstance(node, str) or not node.strip() or "\0" in node:
        hint = ""
        if isinstance(node, (int, float)) and not isinstance(node, bool):  # `-S t.data=123`: YAML reads a number
            hint = f"; a folder named like a number is given quoted: -S '{key}=\"{node}\"'"
        raise InputError(f"`{key}` must be a folder path (a non-empty string), got {node!r} "
                         f"({type(node).__name__}) in {path}{hint}", file=str(path))
    return node


#: what a path of DVC's temporary copy for a queued experiment (``dvc exp run --queue``, ``--temp``) contains
EXPERIMENT_COPY = f"{os.sep}.dvc{os.sep}tmp{os.sep}exps{os.sep}"


def check_data_folder(folder: str, key: str, cwd: str | os.PathLike | None = None) -> None:
    """Refuse a data folder ``folder`` (the parameter ``key``) that does not exist, in one line; in DVC's copy of
    the repository for a queued experiment, say why it is missing and how to make experiments see it.

    A queued experiment runs in a copy made from git and DVC's cache: a folder that neither tracks is not in it.
    """
    if Path(folder).is_dir():
        return
    here = os.path.abspath(cwd or os.getcwd())
    if EXPERIMENT_COPY in here + os.sep:
        raise InputError(f"`{key}`: {folder} is not in this experiment's copy of the repository (a queued "
                         f"experiment sees only what git or DVC tracks): run `dvc add {folder}` and commit "
                         f"{folder}.dvc (or commit the folder to git), or queue with `--copy-paths {folder}`",
                         file=folder)
    raise InputError(f"`{key}`: no such folder: {folder}", file=folder)


def _resolve_path_params(ns: argparse.Namespace, args: dict[str, str]) -> None:
    """Replace each ``--<name>-param KEY`` given by ``--<name> <value of KEY>`` (see :func:`path_param`), and
    check that a data folder given so exists (:func:`check_data_folder`)."""
    for name in args:
        dest = name.replace("-", "_")
        key = getattr(ns, f"{dest}{PARAM_SUFFIX.replace('-', '_')}", None)
        if key is not None:
            value = path_param(ns.params, key)
            check_data_folder(value, key)
            setattr(ns, dest, value)


def check_version(params_path: str | os.PathLike, installed: str | None = None) -> None:
    """Refuse to run when the params file records another cvpipe version (``cvpipe.version``, written by ``cvpipe
    init``) than the one installed: a stage's cached results would otherwise mix two versions' output. Without the
    key (this repository, where stages depend on the source files instead) or the file, nothing to check."""
    from cvpipe import __version__
    from cvpipe.params import read_params_file

    installed = installed or __version__
    if not Path(params_path).is_file():  # a stage that reads no parameters needs no params file
        return
    section = read_params_file(params_path).get("cvpipe")
    recorded = section.get("version") if isinstance(section, dict) else None
    if recorded is not None and str(recorded) != installed:
        raise InputError(f"{params_path}: `cvpipe.version` is {recorded} but cvpipe {installed} is installed: "
                         f"install cvpipe=={recorded}, or run `cvpipe init --upgrade .` to record {installed} "
                         "(every stage then reruns once)", file=str(params_path))


def _has_compute(path: str) -> bool:
    """Whether the params file has a ``compute`` section (without one, items run in process)."""
    from cvpipe.params import read_params_file

    node = read_params_file(path)
    return isinstance(node, dict) and "compute" in node


def _parser(doc: str, args: dict[str, str], options: dict[str, dict]) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    for name, help_text in args.items():
        if help_text.startswith("+"):
            ap.add_argument(f"--{name}", required=True, nargs="+", help=help_text.lstrip("+"))
            continue
        group = ap.add_mutually_exclusive_group(required=True)
        group.add_argument(f"--{name}", help=help_text)
        group.add_argument(f"--{name}{PARAM_SUFFIX}", metavar="KEY",
                           help=f"the parameter of the params file whose value is --{name} (e.g. hough.data)")
    for name, spec in options.items():
        ap.add_argument(f"--{name}", **spec)
    ap.add_argument("--params", default="params.yaml", help="the parameter file (default: params.yaml)")
    return ap


def run(fn: Callable[[Stage], Any], *, section: str | Sequence[str] | None = None, args: dict[str, str],
        options: dict[str, dict] | None = None, name: str | None = None, item: str | None = None,
        argv: list[str] | None = None) -> int:
    """Run the stage function ``fn`` as a command and exit with its status.

    Parameters
    ----------
    fn : callable
        The stage's own logic; it gets a :class:`Stage`.
    section : str or list of str, optional
        The ``params.yaml`` section(s) the stage reads (``"hough.edges"``). The first one's model is ``st.params``;
        all of them are in ``st.sections`` by name.
    args : dict
        Path arguments, name -> help text; each becomes a required ``--name``, or its alternative
        ``--name-param KEY`` which reads the path from the parameter ``KEY`` of the params file (how ``dvc.yaml``
        passes ``<task>.data``). A help text starting with ``+`` makes the argument take one or more values (and
        has no ``-param`` form).
    options : dict, optional
        Further arguments, name -> ``argparse.add_argument`` keywords (``{"method": {"required": True}}``).
    name : str, optional
        The stage name in messages; defaults to the function's name.
    item : str, optional
        For a matrix stage, the option whose value completes the name (``hough_lines@ours``).
    argv : list of str, optional
        The arguments (default ``sys.argv[1:]``). Without them the stage is the program, and takes over Ctrl-C and
        SIGTERM (:mod:`cvpipe.interrupt`): the first one ends the stage between items and steps with exit 130 and
        the one line ``<stage>: error: interrupted`` (143 and ``terminated`` for a SIGTERM), a second one at once.
    """
    stage_name = name or fn.__name__
    program = argv is None  # run as `python -m stages.<name>`: this process's Ctrl-C is the stage's
    if program:
        interrupt.install(name=stage_name)
    doc = sys.modules[fn.__module__].__doc__ or ""
    ns = _parser(doc, args, options or {}).parse_args(argv)
    if item is not None:
        stage_name = f"{stage_name}@{getattr(ns, item)}"
        if program:
            interrupt.install(name=stage_name)
    st = Stage(name=stage_name, args=ns)
    status = 0
    t0 = time.perf_counter()
    try:
        interrupt.check()
        check_version(ns.params)
        _resolve_path_params(ns, args)
        names = [section] if isinstance(section, str) else list(section or [])
        for sec in names:
            st.sections[sec] = load_section(SECTIONS[sec], sec, ns.params)
        st.params = st.sections[names[0]] if names else None
        fn(st)
        interrupt.check()
    except EstimationError as exc:
        status = 1
        print(f"{stage_name}: error: {exc}", file=sys.stderr)
    except (CvpipeError, ValueError, OSError) as exc:
        status = 2
        print(f"{stage_name}: error: {exc}", file=sys.stderr)
    except KeyboardInterrupt:
        interrupt.ignore()  # ending now: a further signal must not add a second line
        status = interrupt.status()  # 130, or 143 after a SIGTERM
        print(f"{stage_name}: error: {interrupt.reason()}", file=sys.stderr)
    if status == 0:
        st.timings["total"] = time.perf_counter() - t0
        _write_timings(st)
        print(st.summary_line())
    sys.exit(interrupt.finish(status))


def _write_timings(st: Stage) -> None:
    """Write the stage's timings to the uncached ``outputs/timings/<stage>.json`` (never fails the stage)."""
    try:
        io.save_json(TIMINGS_DIR / f"{st.name}.json",
                     {"stage": st.name, "seconds": st.timings, "load_average": _load_average()})
    except OSError as exc:  # a timing file is a convenience; the results are already written
        print(f"{st.name}: warning: timings not written ({exc})", file=sys.stderr)


def _load_average() -> float | None:
    try:
        return os.getloadavg()[0]
    except OSError:
        return None
