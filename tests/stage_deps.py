"""The cvpipe/stages modules each DVC stage imports, directly or not (static: every import statement counts,
also those inside functions). Run ``python tests/stage_deps.py`` to print what each stage of dvc.yaml lacks, and
``python tests/stage_deps.py --fix`` to rewrite every stage's code deps to exactly what it imports."""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("cvpipe", "stages")


def module_file(name: str) -> Path | None:
    """The file of a module of this repository (``cvpipe.io`` -> cvpipe/io.py; a compiled kernel's Cython source,
    ``cvpipe.hough._vote`` -> cvpipe/hough/_vote.pyx, or its declarations, .pxd), or None for third-party ones."""
    if name.split(".")[0] not in PACKAGES:
        return None
    base = ROOT.joinpath(*name.split("."))
    for cand in (base.with_suffix(".py"), base / "__init__.py", base.with_suffix(".pyx"), base.with_suffix(".pxd")):
        if cand.is_file():
            return cand
    return None


#: ``from X cimport ...``, ``from X import ...``, ``cimport X`` and ``import X`` lines of a Cython source
_CYTHON_IMPORT = re.compile(r"^\s*(?:from\s+(\.*[\w.]*)\s+c?import\b|c?import\s+([\w.]+))", re.M)


def _cython_imports(path: Path, pkg: str) -> set[str]:
    """The modules a .pyx/.pxd file imports or cimports (relative names resolved against ``pkg``)."""
    found = set()
    for rel, plain in _CYTHON_IMPORT.findall(path.read_text(encoding="utf-8")):
        name = rel or plain
        level = len(name) - len(name.lstrip("."))
        if level:
            parts = pkg.split(".")
            name = ".".join(parts[: len(parts) - level + 1] + ([name.lstrip(".")] if name.lstrip(".") else []))
        found.add(name)
    return found


def _imports(path: Path) -> set[str]:
    pkg = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    if path.name == "__init__.py":
        pkg = ".".join(path.relative_to(ROOT).parts[:-1])
    if path.suffix in (".pyx", ".pxd"):
        return _cython_imports(path, pkg)
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = pkg.split(".")
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join(parts + ([node.module] if node.module else []))
            found.add(base)
            found.update(f"{base}.{a.name}" for a in node.names)
    return found


def closure(module: str) -> set[Path]:
    """Every repository file that importing ``module`` may load (with the parent packages' ``__init__``)."""
    todo, seen = [module], set()
    while todo:
        name = todo.pop()
        parts = name.split(".")
        for i in range(1, len(parts) + 1):
            f = module_file(".".join(parts[:i]))
            for g in (f, f.with_suffix(".pxd") if f is not None and f.suffix == ".pyx" else None):
                if g is not None and g.is_file() and g not in seen:  # a .pyx's own .pxd counts with it
                    seen.add(g)
                    todo.extend(_imports(g))
    return seen


def stage_modules(dvc_yaml: Path = ROOT / "dvc.yaml") -> dict[str, str]:
    """Stage name -> the ``stages.<x>`` module its cmd runs."""
    stages = yaml.safe_load(dvc_yaml.read_text(encoding="utf-8"))["stages"]
    out = {}
    for name, st in stages.items():
        m = re.search(r"python -m (stages\.\w+)", st["cmd"])
        if m:
            out[name] = m.group(1)
    return out


def missing_deps(dvc_yaml: Path = ROOT / "dvc.yaml") -> dict[str, list[str]]:
    """Stage name -> repository files it imports that its ``deps`` do not cover (a listed folder covers its files)."""
    stages = yaml.safe_load(dvc_yaml.read_text(encoding="utf-8"))["stages"]
    result = {}
    for name, module in stage_modules(dvc_yaml).items():
        deps = [str(d).rstrip("/") for d in stages[name].get("deps", [])]
        need = sorted(f.relative_to(ROOT).as_posix() for f in closure(module))
        lacking = [f for f in need if not any(f == d or f.startswith(d + "/") for d in deps)]
        if lacking:
            result[name] = lacking
    return result


def code_unit(path: Path) -> str:
    """The dvc.yaml dependency that covers the repository file ``path``: its task package (or any other package of
    cvpipe: ``cvpipe/hough/transform.py`` -> ``cvpipe/hough``), or the file itself for a top-level module of cvpipe
    and for a stage script or the runner (``cvpipe/io.py``, ``stages/_runner.py``)."""
    parts = path.relative_to(ROOT).parts
    if parts[0] == "cvpipe" and len(parts) > 2:
        return "/".join(parts[:2])
    return "/".join(parts)


def code_deps(module: str) -> list[str]:
    """The code dependencies of the stage that runs ``module``: the units (:func:`code_unit`) of everything it
    imports, sorted."""
    return sorted({code_unit(f) for f in closure(module)})


def _flow(items: list[str], indent: int, width: int = 118) -> list[str]:
    """``deps: [a, b, ...]`` as YAML lines of at most ``width`` columns (a value with ``$``, ``{`` or ``,`` quoted)."""
    words = [f'"{i}"' if any(c in i for c in "${},[]#") else i for i in items]
    lines, line = [], " " * indent + "deps: ["
    for k, w in enumerate(words):
        piece = w + ("]" if k == len(words) - 1 else ",")
        if len(line) + 1 + len(piece) > width and not line.endswith("["):
            lines.append(line + "\n")
            line = " " * (indent + 7) + piece
        else:
            line += ("" if line.endswith("[") else " ") + piece
    lines.append(line + "\n")
    return lines


def fix_deps(dvc_yaml: Path = ROOT / "dvc.yaml") -> int:
    """Rewrite each stage's deps in ``dvc_yaml`` as one flow list: its other deps (data, earlier outputs) as they
    were, then its code deps (:func:`code_deps`); comments and everything else kept.

    Returns the number of stages whose deps changed."""
    modules = stage_modules(dvc_yaml)
    stages = yaml.safe_load(dvc_yaml.read_text(encoding="utf-8"))["stages"]
    lines = dvc_yaml.read_text(encoding="utf-8").splitlines(keepends=True)
    out, stage, changed, i = [], None, 0, 0
    while i < len(lines):
        line = lines[i]
        m = re.match(r"^  (\w+):\s*$", line)
        if m:
            stage = m.group(1)
        if stage in modules and line.strip().startswith("deps:"):
            start = i
            if line.strip() == "deps:":  # block style: the `- ` lines that follow
                i += 1
                while i < len(lines) and lines[i].startswith("      - "):
                    i += 1
            else:  # flow style: up to the closing bracket
                while not lines[i].rstrip().endswith("]"):
                    i += 1
                i += 1
            old = [str(d) for d in stages[stage].get("deps", [])]
            keep = [d for d in old if not d.startswith(("cvpipe/", "stages/"))]
            new = _flow(keep + code_deps(modules[stage]), indent=4)
            if new != lines[start:i]:
                changed += 1
            out.extend(new)
            continue
        out.append(line)
        i += 1
    dvc_yaml.write_text("".join(out), encoding="utf-8")
    return changed


if __name__ == "__main__":
    if "--fix" in sys.argv[1:]:
        print(f"deps rewritten in {fix_deps()} stages")
    for stage, files in missing_deps().items():
        print(f"{stage}:")
        for f in files:
            print(f"      - {f}")
    sys.exit(0)
