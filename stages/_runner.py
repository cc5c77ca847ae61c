"""The shared stage runner: what every stage script would otherwise repeat.

A stage script is one function of its own logic plus one call::

    def hough_edges(st: Stage) -> None:
        for f in st.progress(io.list_images(st.args.images), "edges"):
            ...
        st.made(f"{n} edge maps")

    if __name__ == "__main__":
        run(hough_edges, section="hough.edges", args={"images": "input folder", "out": "output folder"})

The runner builds the command line from the declared paths (every path is a required ``--name`` option; the values
live in ``dvc.yaml``'s ``cmd``), loads and validates the stage's ``params.yaml`` section(s), shows progress on
stderr when it is a terminal, turns a bad input or parameter into one line ``<stage>: error: ...`` naming the file
or key (exit 2; 1 when the algorithm could not produce a result; 130 on Ctrl-C) with no traceback, prints one
summary line (what the stage made, what it dropped and why) and writes the stage's timings to
``outputs/timings/<stage>.json``. Timings are never part of a cached output: a rerun that gives the same results
leaves every DVC hash unchanged, so the stages after it stay up to date.
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

from cvpipe import io
from cvpipe.errors import CvpipeError, EstimationError, InputError
from cvpipe.params import SECTIONS, load_section

T = TypeVar("T")

#: where the uncached timing files go (relative to the repository root, where DVC runs every stage)
TIMINGS_DIR = Path("outputs/timings")


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
            io.save_json(self.args.metrics, metrics)
        for name, rows in (plots or {}).items():
            io.save_json(Path(self.args.plots) / f"{name}.json", rows)
        self.carry(dropped)

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


def _parser(doc: str, args: dict[str, str], options: dict[str, dict]) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    for name, help_text in args.items():
        nargs = "+" if help_text.startswith("+") else None
        ap.add_argument(f"--{name}", required=True, nargs=nargs, help=help_text.lstrip("+"))
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
        Path arguments, name -> help text; each becomes a required ``--name``. A help text starting with ``+``
        makes the argument take one or more values.
    options : dict, optional
        Further arguments, name -> ``argparse.add_argument`` keywords (``{"method": {"required": True}}``).
    name : str, optional
        The stage name in messages; defaults to the function's name.
    item : str, optional
        For a matrix stage, the option whose value completes the name (``hough_lines@ours``).
    """
    doc = sys.modules[fn.__module__].__doc__ or ""
    ns = _parser(doc, args, options or {}).parse_args(argv)
    stage_name = name or fn.__name__
    if item is not None:
        stage_name = f"{stage_name}@{getattr(ns, item)}"
    st = Stage(name=stage_name, args=ns)
    status = 0
    t0 = time.perf_counter()
    try:
        names = [section] if isinstance(section, str) else list(section or [])
        for sec in names:
            st.sections[sec] = load_section(SECTIONS[sec], sec, ns.params)
        st.params = st.sections[names[0]] if names else None
        fn(st)
    except EstimationError as exc:
        status = 1
        print(f"{stage_name}: error: {exc}", file=sys.stderr)
    except (CvpipeError, ValueError, OSError) as exc:
        status = 2
        print(f"{stage_name}: error: {exc}", file=sys.stderr)
    except KeyboardInterrupt:
        status = 130
        print(f"{stage_name}: interrupted", file=sys.stderr)
    if status == 0:
        st.timings["total"] = time.perf_counter() - t0
        _write_timings(st)
        print(st.summary_line())
    sys.exit(status)


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
