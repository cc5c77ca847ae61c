"""Run one benchmark and write its result, stamped, to ``<dir>/<name>.json``: ``python -m cvpipe.bench.record NAME``.

``make benchmarks`` calls this once per benchmark of :data:`RECORDED`, then ``cvpipe bench report``. The benchmark
runs in this process exactly as ``cvpipe bench <task> <arguments> --json`` would (its JSON, printed on stdout, is
captured); the file written is that JSON plus these top-level keys:

- ``stamp``: cvpipe's version and the SHA-256 of the code of every cvpipe source file the run measured (see
  :func:`measured_files` and :func:`file_digest`: a Python file's docstrings, comments and layout do not count),
  with a digest over all of them, so that :func:`stale_files` tells whether the committed result is older than
  the code it measures;
- ``command`` (the equivalent ``cvpipe bench`` command line), ``wall_seconds``, ``cpus``, ``cpu_model``,
  ``load_average_1min`` (before and after the run) and ``versions`` (Python and the libraries the run imported).

The result is written only when the benchmark printed its JSON (with ``exit_status`` when it exited non-zero, as
the guard does for a row over its limit), atomically, so a failed or interrupted run leaves the previous file in
place.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import hashlib
import importlib
import io as _stdio
import json
import os
import platform
import sys
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

#: the repository (or installed tree) root: the parent of the ``cvpipe`` package
ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Recipe:
    """How one benchmark is recorded.

    Attributes
    ----------
    bench : str
        The ``cvpipe bench`` subcommand (a module of ``cvpipe.bench``).
    arguments : tuple of str
        Its arguments besides ``--data`` and ``--json``.
    measures : tuple of str
        cvpipe modules the benchmark runs outside this process (fresh interpreters, Dask workers, ``cvpipe``
        subprocesses): imported before the stamp is taken, so that their sources are stamped too.
    """

    bench: str
    arguments: tuple[str, ...] = ()
    measures: tuple[str, ...] = ()


#: benchmark name (the JSON file's stem) -> how it is run, in the order `make benchmarks` runs them
RECORDED: dict[str, Recipe] = {
    "hough": Recipe("hough"),
    "homography": Recipe("homography"),
    "defect": Recipe("defect"),
    "stereo": Recipe("stereo"),
    "stereo_rectify": Recipe("stereo", ("--rectify", "--seeds", "12")),
    # 100 and 500 probes: the idle-machine figures of docs/notes/scale-out.md; 10^4 probes take an hour here
    "scale": Recipe("scale", ("--sizes", "100,500"), ("cvpipe.defect", "cvpipe.compute")),
    "logo": Recipe("logo"),
    "logo_loo": Recipe("logo", ("--protocol", "loo")),
    "panorama": Recipe("panorama", (), ("cvpipe.commands.stitch",)),
    "guard": Recipe("guard", ("--samples", "data/samples"),
                    ("cvpipe.cli", "cvpipe.commands.stitch", "cvpipe.commands.hough")),
}

#: modules that run a benchmark or render its result but are not measured by it
PLUMBING = ("cvpipe.bench.record", "cvpipe.bench.report", "cvpipe.bench.plots", "cvpipe.bench.peers")
#: distribution names of the libraries whose versions are recorded, by the top-level module they provide
LIBRARIES = {"numpy": ("numpy",), "cv2": ("opencv-contrib-python-headless", "opencv-contrib-python",
                                          "opencv-python-headless", "opencv-python"),
             "scipy": ("scipy",), "skimage": ("scikit-image",), "dask": ("dask",), "distributed": ("distributed",)}
#: extensions of a compiled module's sources and of the headers beside them
KERNEL_SOURCES = (".pyx", ".cpp", ".c")
KERNEL_HEADERS = (".pxd", ".hpp", ".h")


def command_line(name: str, extra: tuple[str, ...] = ()) -> str:
    """The ``cvpipe bench`` command that gives ``name``'s result (printed as JSON)."""
    recipe = RECORDED[name]
    return " ".join(["cvpipe", "bench", recipe.bench, "--data", "$CVPIPE_DATA", *recipe.arguments, *extra, "--json"])


def _source_of(module_name: str, file: str, root: Path) -> list[Path]:
    """The source files of one imported cvpipe module: its ``.py``, or a compiled module's ``.pyx``/``.cpp`` beside
    the Python modules of its package (an editable install keeps the built library elsewhere) and the headers there."""
    path = Path(file)
    if path.suffix == ".py":
        return [path.resolve()]
    parts = module_name.split(".")
    folder = root.joinpath(*parts[:-1])
    found = [folder / (parts[-1] + ext) for ext in KERNEL_SOURCES if (folder / (parts[-1] + ext)).is_file()]
    if found:
        found += sorted(p for p in folder.iterdir() if p.suffix in KERNEL_HEADERS)
    return found


def measured_files(modules: dict | None = None, root: Path = ROOT) -> list[str]:
    """The cvpipe source files (paths relative to ``root``, sorted) of the imported modules: what a run measured.

    Every imported ``cvpipe`` module counts except :data:`PLUMBING`; a compiled module counts by its sources and the
    headers beside them. Build settings (``meson.build``) and third-party libraries are not included (their versions
    are recorded apart).
    """
    modules = sys.modules if modules is None else modules
    files: set[Path] = set()
    for name, module in list(modules.items()):
        if not (name == "cvpipe" or name.startswith("cvpipe.")) or name in PLUMBING:
            continue
        file = getattr(module, "__file__", None)
        if file:
            files.update(_source_of(name, file, root))
    rel = []
    for f in files:
        try:
            rel.append(f.relative_to(root).as_posix())
        except ValueError:  # a module loaded from outside the tree (not ours): nothing of this tree to stamp
            continue
    return sorted(rel)


def _canonical(node: ast.AST) -> str:
    """``node`` as text: its class and fields, without positions, and without fields that are None or empty (so
    that a field added by a newer Python, such as ``type_params``, does not change the text)."""
    if isinstance(node, ast.AST):
        fields = [f"{k}={_canonical(v)}" for k, v in ast.iter_fields(node) if v is not None and v != []]
        return f"{type(node).__name__}({','.join(fields)})"
    if isinstance(node, list):
        return "[" + ",".join(_canonical(v) for v in node) + "]"
    return repr(node)


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and body
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return tree


def file_digest(path: Path) -> str:
    """SHA-256 of a source file's code: of a Python file's syntax tree without docstrings (comments, docstrings and
    layout do not change what a benchmark measures), of any other file's bytes."""
    data = path.read_bytes()
    if path.suffix == ".py":
        try:
            data = _canonical(_strip_docstrings(ast.parse(data, str(path)))).encode()
        except SyntaxError:  # hashed as bytes: the benchmark could not have run it anyway
            pass
    return hashlib.sha256(data).hexdigest()


def make_stamp(files: list[str], root: Path = ROOT) -> dict:
    """``{"cvpipe": version, "files": {path: sha256}, "digest": sha256 of the sorted (path, sha256) list}``."""
    from .. import __version__

    hashes = {f: file_digest(root / f) for f in files}
    whole = hashlib.sha256("\n".join(f"{f} {h}" for f, h in sorted(hashes.items())).encode()).hexdigest()
    return {"cvpipe": __version__, "digest": whole, "files": hashes}


def stale_files(stamp: dict, root: Path = ROOT) -> list[str]:
    """What differs between ``stamp`` and the code in ``root`` now: changed or missing files (by path), and
    ``"cvpipe version X -> Y"`` when the version changed. Empty when the stamped result is current."""
    from .. import __version__

    out = [] if stamp.get("cvpipe") == __version__ else [f"cvpipe version {stamp.get('cvpipe')} -> {__version__}"]
    for f, h in sorted(stamp.get("files", {}).items()):
        path = root / f
        if not path.is_file():
            out.append(f"{f} (missing)")
        elif file_digest(path) != h:
            out.append(f)
    return out


def library_versions(modules: dict | None = None) -> dict[str, str]:
    """Python's version and the installed version of each library of :data:`LIBRARIES` that was imported."""
    modules = sys.modules if modules is None else modules
    out = {"python": platform.python_version()}
    for top, dists in LIBRARIES.items():
        if top not in modules:
            continue
        for dist in dists:
            with contextlib.suppress(metadata.PackageNotFoundError):
                out[dist] = metadata.version(dist)
                break
    return out


def record(name: str, data: str, folder: str | os.PathLike = "benchmarks", extra: tuple[str, ...] = ()) -> dict:
    """Run benchmark ``name`` on the data root ``data`` and write ``folder/<name>.json``; return what was written.

    ``extra`` arguments go to the benchmark after those of its recipe (a smoke run's ``--limit 3``) and into the
    recorded command."""
    from .. import io
    from ..errors import InputError
    from .report import cpu_model

    recipe = RECORDED[name]
    module = importlib.import_module(f"cvpipe.bench.{recipe.bench}")
    parser = argparse.ArgumentParser(prog=f"cvpipe bench {recipe.bench}")
    module.add_arguments(parser)
    args = parser.parse_args(["--data", data, *recipe.arguments, *extra, "--json"])
    out = Path(folder) / f"{name}.json"
    io.check_output_path(out, "--dir", (".json",))
    load_before = os.getloadavg()[0]
    t0 = time.perf_counter()
    captured = _stdio.StringIO()
    with contextlib.redirect_stdout(captured):
        status = module.run(args)
    wall = time.perf_counter() - t0
    load_after = os.getloadavg()[0]
    try:
        result = json.loads(captured.getvalue())
    except json.JSONDecodeError as exc:
        raise InputError(f"`{command_line(name, extra)}` exited with status {status} and printed no JSON document "
                         f"on stdout ({exc}); {out} left as it was") from exc
    if not isinstance(result, dict):
        result = {"result": result}
    if status:  # a result all the same (the guard's exit 1: a row over its limit), kept with the status
        result["exit_status"] = status
    for measured in recipe.measures:
        importlib.import_module(measured)
    result.update({
        "stamp": make_stamp(measured_files()),
        "command": command_line(name, extra),
        "wall_seconds": round(wall, 1),
        "cpus": os.cpu_count(),
        "cpu_model": cpu_model(),
        "load_average_1min": [round(load_before, 2), round(load_after, 2)],
        "versions": library_versions(),
    })
    io.save_json(out, result)
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m cvpipe.bench.record", description=__doc__.splitlines()[0])
    parser.add_argument("name", nargs="?", choices=list(RECORDED), help="the benchmark (the JSON file's stem)")
    parser.add_argument("--list", action="store_true",
                        help="print the benchmarks' names, one a line, in the order `make benchmarks` runs them")
    parser.add_argument("--data", default=os.environ.get("CVPIPE_DATA"),
                        help="root of the shared data sets (default: $CVPIPE_DATA)")
    parser.add_argument("--dir", default="benchmarks", help="folder of the result files (default: benchmarks)")
    parser.epilog = "Any other argument goes to the benchmark (e.g. `--limit 3` for a smoke run) and into its command."
    args, extra = parser.parse_known_args(argv)
    from ..errors import CvpipeError

    if args.list:
        print("\n".join(RECORDED))
        return 0
    if args.name is None:
        parser.error("name a benchmark (or --list)")
    if not args.data:
        parser.error("no data root: pass --data DIR or set CVPIPE_DATA")
    try:
        res = record(args.name, args.data, args.dir, tuple(extra))
    except CvpipeError as exc:
        print(f"cvpipe: error: {exc}", file=sys.stderr)
        return 2
    print(f"{args.name}: {res['wall_seconds']} s wall, 1-min load {res['load_average_1min'][0]} before, "
          f"{res['load_average_1min'][1]} after -> {Path(args.dir) / (args.name + '.json')}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
