"""``cvpipe init DIR``: cvpipe's pipeline in your own git + DVC repository (dvc.yaml, params.yaml, .gitignore).

What it writes and why is in :mod:`cvpipe.init`. Run again, it only adds what is missing (the stages and parameters
of a task added with ``--tasks``, a .gitignore line): a stage, parameter or line that is there is never changed,
and a ``--data`` that contradicts the folder params.yaml already names is refused, naming the file.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

HELP = "set up cvpipe's pipeline in your own git + DVC repository (writes dvc.yaml, params.yaml, .gitignore)"
EXAMPLE = "cvpipe init ../my-project --tasks hough"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", metavar="DIR", help="the repository's root (created, with `git init` and "
                                                   "`dvc init`, where it is not one yet)")
    parser.add_argument("--tasks", metavar="LIST", default=None,
                        help="comma-separated tasks to set up (default: all six: homography, hough, defect, "
                             "panorama, logo, stereo)")
    parser.add_argument("--data", metavar="TASK=FOLDER", action="append", default=[],
                        help="a task's input folder, relative to DIR (repeat per task; default: the bundled "
                             "samples, data/samples/<task>, built by the pipeline's `samples` stage, which needs "
                             "cvpipe[samples])")
    parser.add_argument("--upgrade", action="store_true",
                        help="record the installed cvpipe version in params.yaml (cvpipe.version): after an "
                             "upgrade, every stage reruns once with it")


#: the templates `cvpipe init` writes from, as this repository holds them (installed: all in cvpipe/pipeline/)
TEMPLATES = {"dvc.yaml": "dvc.yaml", "offline.html": ".dvc/plots/offline.html"}
#: where a repository's `dvc plots show/diff` page template goes (DVC's config names it relative to .dvc/)
PLOTS_PAGE = "plots/offline.html"


def template_file(name: str = "dvc.yaml") -> Path:
    """A template of ``cvpipe init`` (:data:`TEMPLATES`): shipped in the package (``cvpipe/pipeline/``), or, for a
    checkout of this project installed in editable mode, the repository's own file."""
    import cvpipe

    package = Path(cvpipe.__file__).resolve().parent
    installed, checkout = package / "pipeline" / name, package.parent / TEMPLATES[name]
    if installed.is_file():
        return installed
    if checkout.is_file() and (package.parent / "stages" / "_runner.py").is_file():
        return checkout
    raise FileNotFoundError(f"cvpipe's template {name} is missing from {package}: reinstall cvpipe")


def _offline_plots(root: Path) -> list[str]:
    """The page template that keeps `dvc plots show/diff` offline, and DVC's setting that uses it, where missing."""
    import shutil

    done = []
    page = root / ".dvc" / PLOTS_PAGE
    if not page.exists():
        page.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(template_file("offline.html"), page)
        done.append(f".dvc/{PLOTS_PAGE}: written")
    got = subprocess.run([sys.executable, "-m", "dvc", "config", "plots.html_template"], cwd=root,
                         capture_output=True, text=True)
    if got.returncode != 0 or not got.stdout.strip():
        _run([sys.executable, "-m", "dvc", "config", "plots.html_template", PLOTS_PAGE], root)
        done.append(f"dvc config plots.html_template {PLOTS_PAGE}")
    return done


def _yaml():
    from ..errors import require_extra

    ruamel = require_extra("ruamel.yaml", "pipeline", "cvpipe init")
    y = ruamel.YAML(typ="rt")
    y.width = 118
    y.indent(mapping=2, sequence=4, offset=2)
    return y


def _load(y, path: Path):
    from ..io import read_text

    return y.load(read_text(path, "YAML file"))


def _template(path: Path) -> dict:
    """A template file as plain data (``yaml.safe_load``: its comments are this repository's)."""
    import yaml

    from ..io import read_text

    return yaml.safe_load(read_text(path, "YAML file"))


def _dump(y, data, path: Path, header: str = "") -> None:
    """Write ``data`` as YAML to ``path`` all at once (a temporary beside it, then renamed), after ``header``."""
    import io as _io

    from ..io import atomic_path

    buf = _io.StringIO()
    buf.write(header)
    y.dump(data, buf)
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue(), encoding="utf-8")


def _run(cmd: list[str], cwd: Path) -> None:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if proc.returncode != 0:
        last = (proc.stderr or proc.stdout).strip().splitlines()
        raise OSError(f"`{' '.join(cmd)}` failed in {cwd}: {last[-1] if last else f'exit {proc.returncode}'}")


def _ensure_repository(root: Path) -> list[str]:
    """``git init`` and ``dvc init`` where ``root`` is not yet a git / DVC repository's root; what it ran."""
    from ..errors import InputError

    ran = []
    if not (root / ".git").exists():
        inside = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=root, capture_output=True, text=True)
        if inside.returncode == 0:
            raise InputError(f"{root} is inside the git repository {inside.stdout.strip()}: run `cvpipe init` at "
                             "its root", file=str(root))
        _run(["git", "init", "-q"], root)
        ran.append("git init")
    if not (root / ".dvc").is_dir():
        from ..errors import require_extra

        require_extra("dvc", "pipeline", "cvpipe init")
        _run([sys.executable, "-m", "dvc", "init", "-q"], root)
        ran.append("dvc init")
    return ran


def _data_folders(root: Path, data: dict[str, str]) -> dict[str, str]:
    """Each ``--data`` folder as a path relative to ``root``, checked to be a folder inside it."""
    from ..errors import InputError

    out = {}
    for task, folder in data.items():
        p = Path(folder)
        full = (p if p.is_absolute() else root / p).resolve()
        try:
            rel = full.relative_to(root.resolve())
        except ValueError:
            raise InputError(f"`--data {task}={folder}`: the folder must be inside the repository {root} "
                             "(DVC tracks what is in it)", file=folder) from None
        if not full.is_dir():
            raise InputError(f"`--data {task}={folder}`: no such folder in {root}", file=str(full))
        if rel == Path("."):
            raise InputError(f"`--data {task}={folder}`: a folder inside the repository, not its root, is "
                             "expected", file=folder)
        out[task] = rel.as_posix()
    return out


def run(args: argparse.Namespace) -> int:
    from .. import __version__
    from .. import init as pipeline
    from ..errors import InputError
    from ..io import read_text

    tasks = pipeline.parse_tasks(args.tasks)
    data = pipeline.parse_data(args.data)
    extra = sorted(set(data) - set(tasks))
    if extra:
        raise ValueError(f"`--data` names task(s) not in --tasks: {', '.join(extra)}")
    y = _yaml()
    root = Path(args.dir)
    data = _data_folders(root, data)  # checked before anything is written
    root.mkdir(parents=True, exist_ok=True)
    ran = _ensure_repository(root)
    params = pipeline.user_params(pipeline.default_params(), tasks, data, __version__)
    # the template's comments speak of this project's repository: a user's dvc.yaml gets a header of its own
    dvc = pipeline.user_pipeline(_template(template_file()), tasks, pipeline.needs_samples(params, tasks))

    done = []
    params_path, dvc_path, ignore_path = root / "params.yaml", root / "dvc.yaml", root / ".gitignore"
    if params_path.exists():
        have = _load(y, params_path) or {}
        for task, folder in data.items():
            old = have.get(task, {}).get("data") if isinstance(have.get(task), dict) else None
            if old is not None and str(old).rstrip("/") != folder:
                raise InputError(f"{params_path}: `{task}.data` is already {old!r}, not {folder!r}; cvpipe init "
                                 "never changes a value you set: edit it there or run `dvc exp run -S "
                                 f"{task}.data={folder}`", file=str(params_path))
        added = pipeline.merge_missing(have, params)
        recorded = have.get(pipeline.VERSION_SECTION, {}).get("version")
        if args.upgrade and recorded != __version__:
            have[pipeline.VERSION_SECTION]["version"] = __version__
            added.append(f"{pipeline.VERSION_SECTION}.version={__version__} (was {recorded})")
        elif recorded != __version__:
            print(f"cvpipe init: note: {params_path} records cvpipe {recorded}, {__version__} is installed: the "
                  "stages refuse to run until `cvpipe init --upgrade` records it", file=sys.stderr)
        if added:
            _dump(y, have, params_path)
            done.append(f"params.yaml: added {', '.join(added)}")
    else:
        _dump(y, params, params_path, pipeline.PARAMS_HEADER)
        done.append("params.yaml: written")
    if dvc_path.exists():
        have = _load(y, dvc_path) or {}
        added = pipeline.merge_pipeline(have, dvc)
        if added:
            _dump(y, have, dvc_path)
            done.append(f"dvc.yaml: added {', '.join(added)}")
    else:
        _dump(y, dvc, dvc_path, pipeline.PIPELINE_HEADER)
        done.append(f"dvc.yaml: written ({len(dvc['stages'])} stages)")
    done += _offline_plots(root)
    text = read_text(ignore_path, ".gitignore") if ignore_path.exists() else ""
    lines = pipeline.missing_lines(text, pipeline.GITIGNORE_LINES)
    if lines:
        sep = "" if not text or text.endswith("\n") else "\n"
        with open(ignore_path, "a", encoding="utf-8") as f:
            f.write(sep + "\n".join(lines) + "\n")
        done.append(f".gitignore: added {' '.join(lines)}")

    print(f"cvpipe init: {root}: " + ("; ".join(ran + done) if ran or done else "up to date, nothing to add"))
    folders = sorted(set(data.values()))
    steps = [f"dvc add {f}" for f in folders]
    # `dvc add X` writes X.dvc and lists X in the .gitignore beside it
    tracked = [p for f in folders for p in (f"{f}.dvc", (Path(f).parent / ".gitignore").as_posix())]
    steps.append(" ".join(["git add dvc.yaml params.yaml .gitignore", *dict.fromkeys(tracked)])
                 + " && git commit -m 'cvpipe pipeline'")
    steps.append("dvc repro")
    print("next (in " + os.fspath(root) + "):\n  " + "\n  ".join(steps))
    return 0
