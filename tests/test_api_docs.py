"""The "Python API" sections of ``docs/*.md`` run as written, and ``help(cvpipe)`` names entry points that exist.

Each ```` ```python ```` block of a doc's "Python API" section runs from the repository root on the bundled samples
(``data/samples``, built by ``dvc repro samples``), the blocks of one doc in order in one namespace, as a reader who
pastes them one after the other would. The entry points are the indented ``cvpipe.<module>.<name>(...)`` lines of
the "Entry points" section of the :mod:`cvpipe` docstring, under one heading line per task.
"""

from __future__ import annotations

import importlib
import pydoc
import re

import pytest

import cvpipe
from conftest import ROOT

DOCS = ROOT / "docs"
SAMPLES = ROOT / "data" / "samples"
TASKS = ("hough", "homography", "defect", "logo", "stereo", "panorama")
HEADING = "## Python API"

#: a heading line of the cvpipe docstring's entry point list: ``task: what it answers (docs/task.md...)``
_TASK_LINE = re.compile(r"^(?P<task>\w+)(?::.*\((?P<doc>docs/\w+\.md)[;)].*)?$")
#: an entry point line under it: four spaces, then the dotted name and its arguments
_ENTRY_LINE = re.compile(r"^    (?P<name>cvpipe(?:\.\w+)+)\(")


def api_section(path) -> tuple[str, list[tuple[int, str]]]:
    """The "Python API" section of a Markdown file: its text and its ``python`` blocks.

    Returns
    -------
    text : str
        From the heading to the next heading of the same or a higher level ("" when there is no such section).
    blocks : list of (int, str)
        ``(line number of the block's first code line, code)``, 1-based as in the file.
    """
    lines = path.read_text(encoding="utf-8").splitlines()
    inside, fence, section, blocks, code, start = False, None, [], [], [], 0
    for number, line in enumerate(lines, 1):
        if fence is None and re.match(r"#{1,2} ", line):  # a heading outside code: the section starts or ends
            inside = line.strip() == HEADING
        if inside:
            section.append(line)
        if line.startswith("```"):
            if fence is None:
                fence, code, start = line[3:].strip(), [], number + 1
            else:
                if inside and fence == "python":
                    blocks.append((start, "\n".join(code) + "\n"))
                fence = None
        elif fence is not None:
            code.append(line)
    return "\n".join(section), blocks


def entry_points() -> dict[str, list[str]]:
    """Task (or ``shared``) -> the dotted names that the ``Entry points`` section of ``cvpipe.__doc__`` lists."""
    lines = cvpipe.__doc__.splitlines()
    start = lines.index("Entry points") + 2  # past the underline
    found: dict[str, list[str]] = {}
    task = None
    for line in lines[start:]:
        if not line.strip():
            break
        if (m := _ENTRY_LINE.match(line)) is not None:
            found[task].append(m["name"])
        elif (m := _TASK_LINE.match(line)) is not None:
            task = m["task"]
            found[task] = []
        else:
            raise AssertionError(f"unexpected line in cvpipe's entry point list: {line!r}")
    return found


def test_api_section_reads_only_the_python_blocks_of_its_own_section(tmp_path):
    doc = tmp_path / "x.md"
    doc.write_text("# x\n```python\nbefore = 1\n```\n## Python API\ntext\n```python\n# a comment, not a heading\n"
                   "a = 1\n```\n```\nshell\n```\n### detail\n```python\nb = 2\n```\n"
                   "## Pipeline\n```python\nc = 3\n```\n")
    text, blocks = api_section(doc)
    assert blocks == [(8, "# a comment, not a heading\na = 1\n"), (16, "b = 2\n")]
    assert text.startswith("## Python API") and "Pipeline" not in text


@pytest.mark.parametrize("task", TASKS)
def test_every_task_doc_has_a_python_api_section_with_an_example(task):
    text, blocks = api_section(DOCS / f"{task}.md")
    assert text, f"docs/{task}.md has no '{HEADING}' section"
    assert blocks, f"the '{HEADING}' section of docs/{task}.md has no ```python block"


@pytest.mark.parametrize("path", sorted(p for p in DOCS.glob("*.md") if api_section(p)[1]), ids=lambda p: p.name)
def test_python_api_examples_run_from_the_repository_root(path, monkeypatch, capsys):
    if not SAMPLES.is_dir():
        pytest.skip("data/samples is absent (build it with `dvc repro samples`)")
    monkeypatch.chdir(ROOT)
    namespace = {"__name__": "__main__"}
    for start, code in api_section(path)[1]:
        # padded so that a traceback gives the line number in the Markdown file
        exec(compile("\n" * (start - 1) + code, str(path), "exec"), namespace)
    assert capsys.readouterr().out, f"the examples of {path.name} print nothing"


def test_help_lists_the_entry_points_of_every_task():
    listed = entry_points()
    assert set(listed) == {*TASKS, "shared"}
    assert all(listed.values()), "a task with no entry point listed"
    text = pydoc.render_doc(cvpipe, renderer=pydoc.plaintext)
    for name in sum(listed.values(), []):
        assert name in text, f"help(cvpipe) does not show {name}"


def test_help_points_at_each_task_doc():
    for line in cvpipe.__doc__.splitlines():
        if (m := _TASK_LINE.match(line)) is not None and m["task"] in TASKS:
            assert m["doc"] == f"docs/{m['task']}.md"
            assert (ROOT / m["doc"]).is_file()


@pytest.mark.parametrize("name", sum(entry_points().values(), []))
def test_entry_point_resolves_to_a_callable(name):
    module, attribute = name.rsplit(".", 1)
    assert callable(getattr(importlib.import_module(module), attribute))


@pytest.mark.parametrize("task", TASKS)
def test_the_task_doc_names_its_entry_points(task):
    text, _ = api_section(DOCS / f"{task}.md")
    for name in entry_points()[task]:
        assert f"`{name}(" in text, f"docs/{task}.md's '{HEADING}' section does not describe {name}"
