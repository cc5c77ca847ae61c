"""A user's pipeline: the ``dvc.yaml`` and ``params.yaml`` that ``cvpipe init`` writes into a DVC repository.

The one pipeline is this project's own ``dvc.yaml`` (shipped with the package as the template, ``cvpipe/pipeline/``);
the parameters are the defaults of their models (:func:`default_params`). A user's pipeline differs from this
project's in three ways, and only these:

- each stage runs ``cvpipe stage NAME`` (the stage scripts that ship with the package) instead of
  ``python -m stages.NAME`` (this repository's ``stages/``, the same files);
- a stage depends on its data folder, the outputs of the stages before it and its parameters, not on cvpipe's source
  files (a user's repository has none); instead every stage lists the parameter ``cvpipe.version``, the installed
  version the results were made with. A stage refuses to run under another version (it names both), and
  ``cvpipe init --upgrade`` records the installed one, so that every stage reruns once after an upgrade and never
  silently mixes results of two versions;
- only the chosen tasks, each reading its own ``<task>.data`` folder (the bundled samples' stage only when a task
  still reads ``data/samples``).

Pure functions on the parsed YAML (mappings from ``ruamel.yaml``'s round-trip loader keep their comments); the
command (:mod:`cvpipe.commands.init`) reads and writes the files.
"""

from __future__ import annotations

import copy
import re
from typing import Any, Iterable, MutableMapping

#: the tasks, in the order of the pipeline
TASKS = ("homography", "hough", "defect", "panorama", "logo", "stereo")
#: the params.yaml section that records the cvpipe version of the results (``cvpipe.version``)
VERSION_SECTION = "cvpipe"
#: the bundled samples' folder: a task whose data is under it needs the ``samples`` stage
SAMPLES_DIR = "data/samples"
#: how this repository runs a stage, and how a user's repository does
SOURCE_CMD, PACKAGE_CMD = "python -m stages.", "cvpipe stage "
#: lines ``cvpipe init`` makes sure the repository's .gitignore has (uncached timings, ``dvc plots show`` output)
GITIGNORE_LINES = ("/outputs/timings/", "/outputs/plots/", "/dvc_plots/")
#: params.yaml sections that are not a task's and that every user's pipeline keeps
COMMON_SECTIONS = ("compute",)

#: the first lines of the dvc.yaml and params.yaml that ``cvpipe init`` writes
PIPELINE_HEADER = """\
# cvpipe's pipeline (written by `cvpipe init`; yours to edit: running it again only adds what is missing).
# Each stage runs `cvpipe stage NAME` (`cvpipe stage NAME --help`) and reruns when its data folder (`<task>.data`
# in params.yaml), an earlier stage's output, its parameters or `cvpipe.version` change.
"""
PARAMS_HEADER = """\
# cvpipe's parameters, by task and stage (`<task>.<stage>`); `<task>.data` is the task's input folder. Change one
# with `dvc exp run -S hough.lines.threshold=120`; every value's meaning and range: `cvpipe <command> --help`.
# `cvpipe.version` is the cvpipe that made the results (`cvpipe init --upgrade` records the installed one).
"""

_CODE_DEP = re.compile(r"^(cvpipe|stages)/")


def stage_task(name: str) -> str | None:
    """The task a stage of the pipeline belongs to (``"hough_lines"`` -> ``"hough"``), or None for the stages that
    serve every task (``samples``, ``report``)."""
    return next((t for t in TASKS if name == t or name.startswith(f"{t}_")), None)


def parse_data(pairs: Iterable[str]) -> dict[str, str]:
    """``["panorama=data/mine/trip", ...]`` -> ``{"panorama": "data/mine/trip"}``, validated.

    Raises
    ------
    ValueError
        A pair is not ``TASK=FOLDER``, names an unknown task, or gives a task twice.
    """
    out: dict[str, str] = {}
    for pair in pairs:
        task, sep, folder = pair.partition("=")
        if not sep or not folder.strip():
            raise ValueError(f"`--data {pair}`: expected TASK=FOLDER (e.g. panorama=data/mine/trip)")
        if task not in TASKS:
            raise ValueError(f"`--data {pair}`: unknown task `{task}`; choose from: {', '.join(TASKS)}")
        if task in out:
            raise ValueError(f"`--data`: task `{task}` is given twice")
        out[task] = folder.strip().rstrip("/") or "/"
    return out


def parse_tasks(text: str | None) -> tuple[str, ...]:
    """``"hough,panorama"`` -> ``("hough", "panorama")`` in pipeline order; None or empty: every task.

    Raises
    ------
    ValueError
        An unknown task.
    """
    if not text:
        return TASKS
    names = {t.strip() for t in text.split(",") if t.strip()}
    unknown = sorted(names - set(TASKS))
    if unknown:
        raise ValueError(f"`--tasks`: unknown task(s) {', '.join(unknown)}; choose from: {', '.join(TASKS)}")
    return tuple(t for t in TASKS if t in names)


def needs_samples(params: MutableMapping, tasks: Iterable[str]) -> bool:
    """Whether any of ``tasks`` reads its ``<task>.data`` under the bundled samples' folder."""
    return any(str(params[t]["data"]).rstrip("/").startswith(SAMPLES_DIR) for t in tasks)


def default_data(task: str) -> str:
    """A task's default input folder: its part of the bundled samples."""
    return f"{SAMPLES_DIR}/{task}"


def default_params() -> dict:
    """Every parameter at its default, as params.yaml nests them: each section of :data:`cvpipe.params.SECTIONS`
    from its model (where every default is declared), and each task's ``data`` folder (:func:`default_data`)."""
    from .params import SECTIONS

    out: dict = {}
    for section, cls in SECTIONS.items():
        *parents, last = section.split(".")
        node = out
        for p in parents:
            node = node.setdefault(p, {})
        node[last] = cls().model_dump(mode="json")
    for t in TASKS:
        out[t] = {"data": default_data(t), **out.get(t, {})}
    return out


def user_params(defaults: MutableMapping, tasks: Iterable[str], data: dict[str, str], version: str) -> Any:
    """The user's params.yaml: the sections of ``tasks`` of ``defaults`` (:func:`default_params`), each ``data``
    replaced where ``data`` names one, the common ones, ``samples`` when a task still reads the samples, and
    ``cvpipe.version``."""
    tasks = tuple(tasks)
    out = copy.deepcopy(defaults)
    for t in data:
        out[t]["data"] = data[t]
    keep = set(tasks) | set(COMMON_SECTIONS) | ({"samples"} if needs_samples(out, tasks) else set())
    for key in [k for k in out if k not in keep]:
        del out[key]
    out[VERSION_SECTION] = {"version": version}
    return out


def user_stage(stage: MutableMapping) -> Any:
    """One stage of the template as a user's repository runs it (see the module docstring)."""
    out = copy.deepcopy(stage)
    out["cmd"] = str(out["cmd"]).replace(SOURCE_CMD, PACKAGE_CMD)
    if "deps" in out:
        deps = [d for d in out["deps"] if not _CODE_DEP.match(str(d))]
        if deps:
            out["deps"] = type(out["deps"])(deps) if not isinstance(out["deps"], list) else deps
        else:
            del out["deps"]
    params = list(out.get("params") or [])
    out["params"] = [VERSION_SECTION, *params]
    return out


def user_pipeline(template: MutableMapping, tasks: Iterable[str], samples: bool) -> Any:
    """The user's dvc.yaml: the stages of ``tasks`` (plus ``samples`` when ``samples``, and the report over the
    chosen tasks), each as :func:`user_stage` makes it, and the top-level plots of those tasks."""
    tasks = tuple(tasks)
    out = copy.deepcopy(template)
    stages = out["stages"]
    for name in list(stages):
        task = stage_task(name)
        keep = task in tasks if task else (name != "samples" or samples)
        if not keep:
            del stages[name]
            continue
        stages[name] = user_stage(stages[name])
        if name == "report":
            stages[name]["deps"] = [d for d in stages[name].get("deps", [])
                                    if not str(d).startswith("outputs/") or str(d).split("/")[1] in tasks]
    if "plots" in out:
        kept = [p for p in out["plots"] if _plot_task(p) in (None, *tasks)]
        del out["plots"][:]
        out["plots"].extend(kept)
    return out


def _plot_task(entry: Any) -> str | None:
    """The task a top-level ``plots`` entry of dvc.yaml belongs to (by the outputs/<task>/ files it names, or the
    ``<task>_`` prefix of its id), None for one of every task (the timings)."""
    key = next(iter(entry)) if isinstance(entry, MutableMapping) else str(entry)
    text = " ".join([str(key), *_strings(entry)])
    for t in TASKS:
        if str(key).startswith(f"{t}_") or f"outputs/{t}/" in text:
            return t
    return None


def _strings(node: Any) -> list[str]:
    if isinstance(node, MutableMapping):
        return [s for k, v in node.items() for s in [str(k), *_strings(v)]]
    if isinstance(node, list):
        return [s for v in node for s in _strings(v)]
    return [str(node)]


def merge_missing(existing: MutableMapping, new: MutableMapping, prefix: str = "") -> list[str]:
    """Add to ``existing``, in place, every key of ``new`` it lacks (recursively into mappings); never changes a
    value ``existing`` has. Returns the dotted names of what was added."""
    added = []
    for key, value in new.items():
        name = f"{prefix}{key}"
        if key not in existing:
            existing[key] = copy.deepcopy(value)
            added.append(name)
        elif isinstance(existing[key], MutableMapping) and isinstance(value, MutableMapping):
            added += merge_missing(existing[key], value, f"{name}.")
    return added


def merge_pipeline(existing: MutableMapping, new: MutableMapping) -> list[str]:
    """Add to a user's dvc.yaml, in place, the stages and plots of ``new`` it lacks; a stage or plot it has is kept
    as the user left it. Returns what was added (``stages.<name>``, ``plots.<id>``)."""
    added = [f"stages.{n}" for n in merge_missing(existing.setdefault("stages", {}), new.get("stages", {}))]
    if new.get("plots"):
        plots = existing.setdefault("plots", [])
        have = {_plot_id(p) for p in plots}
        for p in new["plots"]:
            if _plot_id(p) not in have:
                plots.append(copy.deepcopy(p))
                added.append(f"plots.{_plot_id(p)}")
    return added


def _plot_id(entry: Any) -> str:
    return str(next(iter(entry))) if isinstance(entry, MutableMapping) else str(entry)


def missing_lines(text: str, lines: Iterable[str]) -> list[str]:
    """The ``lines`` that the file content ``text`` (a .gitignore) does not have as a line."""
    have = {line.strip() for line in text.splitlines()}
    return [line for line in lines if line not in have]
