"""The command and stage contract on hostile input and interrupts: each test runs the command or the stage and
checks the exit status, the one stderr line, the JSON record and the files left behind."""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from cvpipe import cli, errors, homography, hough, io
from cvpipe.params import StereoSgmParams

sys.path.insert(0, str(Path(__file__).parent))
from sweep_inputs import texture  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, PYTHONPATH=str(ROOT))


def run_main(capsys, argv):
    """(exit status, stderr lines, stdout JSON) of an in-process run."""
    code = cli.main([str(a) for a in argv])
    cap = capsys.readouterr()
    lines = [ln for ln in cap.err.splitlines() if ln.strip()]
    return code, lines, json.loads(cap.out) if cap.out.strip() else None


def only_error_line(lines):
    assert len(lines) == 1 and lines[0].startswith("cvpipe: error:"), lines
    return lines[0]


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    root = tmp_path_factory.mktemp("views")
    t = texture(240, 440, seed=1)
    paths = {}
    for name, img in {"a": t[:, :320], "b": t[:, 100:420], "r": t[:, 8:328]}.items():
        paths[name] = root / f"{name}.png"
        cv2.imwrite(str(paths[name]), img)
    return paths


def no_temporaries(folder: Path) -> bool:
    return not [p for p in folder.rglob("*") if ".cvpipe-tmp-" in p.name or ".tmp" in p.name]


# ------------------------------------------------------------------------------ item 6: JSON and error lines


def test_inspect_missing_probe_exit_2_path_once(capsys, views, tmp_path):
    code, lines, doc = run_main(capsys, ["inspect", views["a"], tmp_path / "nope.png", "--json"])
    line = only_error_line(lines)
    assert code == 2 and line.count("nope.png") == 1 and "no such file" in line
    assert doc["exit"] == 2 and doc["file"].endswith("nope.png") and doc["error"].count("nope.png") == 1


def test_inspect_missing_probe_without_json_is_one_line(capsys, views, tmp_path):
    code, lines, doc = run_main(capsys, ["inspect", views["a"], tmp_path / "nope.png"])
    assert code == 2 and doc is None
    only_error_line(lines)


def test_inspect_blank_reference_is_blamed_on_the_reference(capsys, views, tmp_path):
    blank = tmp_path / "blank_ref.png"
    cv2.imwrite(str(blank), np.full((240, 320), 128, np.uint8))
    code, lines, doc = run_main(capsys, ["inspect", blank, views["a"], "--json"])
    line = only_error_line(lines)
    assert code == 2 and "blank_ref.png" in line and "reference is blank" in line
    assert doc == {"error": doc["error"], "file": str(blank), "exit": 2}


def test_inspect_missing_reference_still_prints_a_json_record(capsys, views, tmp_path):
    code, lines, doc = run_main(capsys, ["inspect", tmp_path / "ref.png", views["a"], "--json"])
    only_error_line(lines)
    assert code == 2 and set(doc) == {"error", "file", "exit"} and doc["file"].endswith("ref.png")


def test_inspect_equal_file_names_from_different_folders_get_distinct_pictures(capsys, views, tmp_path):
    for sub in ("x", "y"):
        (tmp_path / sub).mkdir()
        cv2.imwrite(str(tmp_path / sub / "probe.png"), cv2.imread(str(views["a"])))
    out = tmp_path / "ov"
    code, lines, doc = run_main(capsys, ["inspect", views["a"], tmp_path / "x" / "probe.png",
                                         tmp_path / "y" / "probe.png", "--out", out, "--json"])
    assert code == 0 and not [ln for ln in lines if ln.startswith("cvpipe: error:")] and len(doc) == 2
    # two records, two sets of pictures: nothing overwritten
    assert sorted(p.name for p in out.glob("*.png")) == ["x_probe_diff.png", "x_probe_regions.png",
                                                         "y_probe_diff.png", "y_probe_regions.png"]


@pytest.mark.parametrize("argv", [
    ["hough", "{missing}", "--json"],
    ["homography", "{missing}", "{a}", "--json"],
    ["stereo", "{missing}", "{a}", "--max-disp", "16", "-o", "{tmp}/d.npy", "--json"],
    ["stitch", "{missing}", "{a}", "-o", "{tmp}/p.png", "--json"],
    ["hough", "{a}", "--theta-deg", "-1", "--json"],
    ["hough", "{a}", "--no-such-option", "--json"],
])
def test_every_failure_prints_one_json_record(capsys, views, tmp_path, argv):
    argv = [a.format(missing=tmp_path / "missing.png", a=views["a"], tmp=tmp_path) for a in argv]
    code, lines, doc = run_main(capsys, argv)
    only_error_line(lines)
    assert code == 2 and set(doc) == {"error", "file", "exit"} and doc["exit"] == 2
    assert doc["error"] == lines[0].removeprefix("cvpipe: error: ")


def test_output_path_that_is_a_folder_names_no_temporary(capsys, views, tmp_path):
    folder = tmp_path / "d.npy"
    folder.mkdir()
    code, lines, doc = run_main(capsys, ["stereo", views["a"], views["r"], "--max-disp", "16", "-o", folder, "--json"])
    line = only_error_line(lines)
    assert code == 2 and "is a folder" in line and "tmp" not in line.replace(str(tmp_path), "")
    assert doc["file"] == str(folder) and list(folder.iterdir()) == []


def test_unexpected_exception_is_one_line_exit_1(capsys, monkeypatch, views):
    monkeypatch.setattr(hough, "edges_of", lambda *a, **k: 1 / 0)
    code, lines, doc = run_main(capsys, ["hough", views["a"], "--json"])
    assert code == 1 and "ZeroDivisionError" in only_error_line(lines) and doc["exit"] == 1


def test_terminal_colour_codes_of_a_library_message_are_dropped(capsys, monkeypatch, views):
    """A library error coloured for a terminal (ANSI codes in its text) is plain text in the line and the record."""
    def coloured(*a, **k):
        raise TypeError("\x1b[1m\x1b[1mNo implementation of function\x1b[0m\n\x1b[0m\x1b[1m(int64)\x1b[0m")

    monkeypatch.setattr(hough, "edges_of", coloured)
    code, lines, doc = run_main(capsys, ["hough", views["a"], "--json"])
    line = only_error_line(lines)
    assert code == 1 and "\x1b" not in line and "No implementation of function (int64)" in line, line
    assert doc["error"] == line.removeprefix("cvpipe: error: ")


# ------------------------------------------------------------------------------------------------------ Ctrl-C


def test_keyboard_interrupt_wrapped_by_an_extension_is_exit_130(capsys, monkeypatch, views):
    def parallel_kernel(*a, **k):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:  # what a C extension that returns with the exception set turns it into
            raise SystemError("<built-in function ...> returned a result with an exception set") from exc

    monkeypatch.setattr(hough, "edges_of", parallel_kernel)
    code, lines, doc = run_main(capsys, ["hough", views["a"], "--json"])
    assert code == 130 and only_error_line(lines) == "cvpipe: error: interrupted"
    assert doc == {"error": "interrupted", "file": None, "exit": 130}


def run_program(code: str, *argv, timeout: float = 120) -> subprocess.CompletedProcess:
    """Run the ``cvpipe`` program (its entry point, as the console script does) after ``code`` in a subprocess."""
    script = f"import sys\nsys.argv = ['cvpipe', *sys.argv[1:]]\n{code}\nfrom cvpipe._entry import main\nsys.exit(main())"
    return subprocess.run([sys.executable, "-c", script, *map(str, argv)], capture_output=True, text=True, env=ENV,
                          timeout=timeout)


def assert_interrupted(proc: subprocess.CompletedProcess) -> None:
    """Exit 130, the one stderr line, and the interrupt's JSON record as the only document on stdout."""
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.strip() == "cvpipe: error: interrupted"
    assert json.loads(proc.stdout) == {"error": "interrupted", "file": None, "exit": 130}


#: a stand-in for the edge detector of `cvpipe hough` in which a Ctrl-C is swallowed before it can propagate
SWALLOWED = {
    # Python code run from C (a __del__, a library's callback) cannot pass a KeyboardInterrupt on: it reaches only
    # sys.unraisablehook, which records it; the work goes on to the end of its step, which ends the command
    "in a C callback": """
class CCallback:
    def __del__(self):
        raise KeyboardInterrupt  # unraisable, as inside a callback run from C

def edges_of(gray, *a, **k):
    CCallback()
    t0 = time.monotonic()
    while time.monotonic() - t0 < 0.5:  # the rest of the step's ordinary Python work
        sum(range(1000))
    return np.zeros_like(gray)
""",
    # a real SIGINT during a step whose code catches everything: the handler only records it (nothing is raised
    # for the library to eat), so the step ends the command before anything is printed from it
    "by a library": """
def edges_of(gray, *a, **k):
    try:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.5)
    except BaseException:
        raise SystemExit("the handler raised into the library's code")
    return np.zeros_like(gray)
"""}


@pytest.mark.parametrize("how", SWALLOWED)
def test_swallowed_ctrl_c_still_ends_with_130(views, how):
    code = ("import os, signal, time\nimport numpy as np\nfrom cvpipe import hough\n" + SWALLOWED[how]
            + "\nhough.edges_of = edges_of\n")
    assert_interrupted(run_program(code, "hough", views["a"], "--json"))


def test_ctrl_c_during_the_import_of_the_cli_is_exit_130():
    """The console script imports the entry point, which takes over Ctrl-C before importing cvpipe.cli: a SIGINT
    during that import (or any later one) is one line and 130, not a traceback or death by SIGINT (-2)."""
    code = """
import os, signal, importlib.abc

class SlowImport(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "cvpipe.cli":  # Ctrl-C lands while cvpipe.cli is being imported
            os.kill(os.getpid(), signal.SIGINT)
        return None

sys.meta_path.insert(0, SlowImport())
"""
    assert_interrupted(run_program(code, "--json", "--version"))


def test_entry_point_is_light_and_is_the_console_script():
    """[project.scripts] runs cvpipe._entry:main, whose import pulls in nothing before it handles Ctrl-C."""
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"cvpipe": "cvpipe._entry:main"}
    new = "import sys; before = set(sys.modules); import {}; print(sorted(set(sys.modules) - before))"
    loaded = [json.loads(subprocess.run([sys.executable, "-c", new.format(m)], capture_output=True, text=True,
                                        env=ENV, check=True).stdout.replace("'", '"'))
              for m in ("cvpipe._entry", "__future__, signal")]
    # the entry point adds only itself, its package and the interrupt layer (with ``atexit``, built into the
    # interpreter) to what `import signal` loads anyway
    assert sorted(set(loaded[0]) - set(loaded[1])) == ["atexit", "cvpipe", "cvpipe._entry", "cvpipe.interrupt"]


def _stereo_command(left, right, out) -> list:
    # `-m cvpipe`: the program's entry point, as the console script runs it
    return [sys.executable, "-m", "cvpipe", "-q", "stereo", str(left), str(right), "--max-disp", "128", "-o",
            str(out / "d.npy"), "--json"]


def _threads(pid: int) -> int | None:
    try:
        return len(os.listdir(f"/proc/{pid}/task"))
    except FileNotFoundError:  # it has just ended
        return None


def _peak_threads(cmd) -> int:
    """The most threads a run of ``cmd`` has at once: the OpenMP team starts with the first parallel kernel and is
    the last to appear, so reaching this count means the kernels run."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=dict(ENV, OMP_NUM_THREADS="2"))
    peak = 1
    while proc.poll() is None:
        peak = max(peak, _threads(proc.pid) or 0)
        time.sleep(0.002)
    return peak


def _loaded(pid: int, library: str) -> bool:
    """Whether process ``pid`` has mapped a shared library whose path contains ``library``."""
    try:
        with open(f"/proc/{pid}/maps", encoding="utf-8") as fh:
            return library in fh.read()
    except (FileNotFoundError, ProcessLookupError):  # it has just ended
        return False


#: a library the stereo command maps only while it imports its modules, after its entry point took over Ctrl-C
#: (``cvpipe._entry`` imports the standard library and ``cvpipe.interrupt`` alone first): pydantic's core, which the
#: parameter models load (a signal before that lands in Python's own start-up, which no program handles)
START_UP_LIBRARY = "_pydantic_core"


def _interrupt_stereo(cmd, out, delay, peak=None, second=None, after=None):
    """Run ``cmd`` and send SIGINT ``delay`` seconds after its start (``peak`` None), after it mapped the library
    ``after`` (the imports), or after it reached ``peak`` threads (the parallel kernels), and a second one ``second``
    seconds after the first (None: one only).

    Returns ``(proc, stdout, stderr)`` for a run that ended as interrupted before its results went out; None for
    one whose results went out whole (checked here): exit 0 when the signal came after the process ended, or 130
    and the one line when it came while they went out or during the shutdown."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(ENV, OMP_NUM_THREADS="2"))
    t0 = time.monotonic()
    while proc.poll() is None and time.monotonic() - t0 < 300:
        n = _threads(proc.pid)
        if after is not None:
            if n is None or _loaded(proc.pid, after):
                time.sleep(delay)
                break
            time.sleep(0.002)
            continue
        if n is None or (peak is None and time.monotonic() - t0 > delay):
            break
        if peak is not None and n >= peak:
            time.sleep(delay)
            break
        time.sleep(0.002)
    proc.send_signal(signal.SIGINT)  # nothing when the process has already ended
    if second is not None:
        time.sleep(second)
        proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=300)
    # never a signal: not a crash (-11), not death by SIGINT (-2)
    assert proc.returncode in (0, 130), (delay, second, proc.returncode, stderr)
    if proc.returncode == 0 or (proc.returncode == 130 and "valid_fraction" in stdout):
        assert stderr == ("" if proc.returncode == 0 else "cvpipe: error: interrupted\n"), stderr
        assert "valid_fraction" in json.loads(stdout) and (out / "d.npy").exists(), stdout
        (out / "d.npy").unlink()
        return None
    return proc, stdout, stderr


def _assert_interrupted_run(done, out) -> None:
    proc, stdout, stderr = done
    assert proc.returncode == 130, stderr
    assert stderr.strip() == "cvpipe: error: interrupted"
    assert json.loads(stdout) == {"error": "interrupted", "file": None, "exit": 130}
    # interrupted before its results went out: nothing written, no temporary left
    assert not out.exists() or list(out.iterdir()) == []


def _stereo_pair(tmp_path):
    t = texture(600, 1100, seed=3)
    left, right = tmp_path / "l.png", tmp_path / "r.png"
    cv2.imwrite(str(left), t[:, :1000])
    cv2.imwrite(str(right), t[:, 20:1020])
    # a first run warms the file system cache and measures the run's length
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-m", "cvpipe", "-q", "stereo", str(left), str(right), "--max-disp", "128",
                    "-o", str(tmp_path / "warm.npy")], env=dict(ENV, OMP_NUM_THREADS="2"), check=True,
                   capture_output=True, timeout=600)
    return left, right, time.monotonic() - t0


@pytest.mark.slow
@pytest.mark.parametrize("when", ["start-up", "parallel kernels"])
def test_ctrl_c_during_parallel_stereo(tmp_path, when):
    """A real SIGINT during start-up (imports) or while the parallel SGM kernels run: exit 130,
    one line, no traceback, nothing written."""
    left, right, _ = _stereo_pair(tmp_path)
    out = tmp_path / "out"
    cmd = _stereo_command(left, right, out)
    peak = None if when == "start-up" else _peak_threads(cmd)
    if (out / "d.npy").exists():
        (out / "d.npy").unlink()
    # the kernels take a few tenths of a run: up to 5 runs, the signal sent 0-150 ms after the OpenMP threads
    # appeared, until one lands before the work is done
    # start-up: the imports take a few tenths of a second after the parameter models' library is mapped
    for delay in ([0.0, 0.05, 0.1] if when == "start-up" else [0.0, 0.03, 0.06, 0.1, 0.15]):
        done = _interrupt_stereo(cmd, out, delay, peak, after=START_UP_LIBRARY if when == "start-up" else None)
        if done is not None:
            break
    else:
        pytest.skip("every run had finished when the signal arrived")
    _assert_interrupted_run(done, out)


@pytest.mark.slow
def test_ctrl_c_at_any_moment_of_parallel_stereo(tmp_path):
    """SIGINT at 40 moments spread over whole runs of the parallel stereo command (imports, the parallel kernels,
    the writing of the results, the shutdown), one alone or two 5 ms apart: every run ends
    either interrupted (exit 130, the one line and the record, nothing written) or with its complete result (exit
    0), never by a signal."""
    left, right, seconds = _stereo_pair(tmp_path)
    out = tmp_path / "out"
    cmd = _stereo_command(left, right, out)
    runs = 40
    interrupted = 0
    for k in range(runs):
        # from 0.3 s (the interpreter runs the entry point, which holds Ctrl-C: before, a SIGINT is Python's own
        # default) to 1.2 x the length of a warm run, so that the last moments fall after the work
        delay = 0.3 + (1.2 * seconds - 0.3) * k / (runs - 1)
        done = _interrupt_stereo(cmd, out, delay, second=0.005 if k % 2 else None)
        if done is not None:
            _assert_interrupted_run(done, out)
            interrupted += 1
    # most moments fall inside a run (the exact share depends on the machine's load)
    assert interrupted >= runs // 4, interrupted


@pytest.mark.parametrize("first, second, word, code", [
    ("SIGINT", "SIGINT", "interrupted", 130), ("SIGTERM", "SIGTERM", "terminated", 143),
    ("SIGTERM", "SIGINT", "terminated", 143)])  # the first signal sets the words and the status
def test_first_ctrl_c_is_recorded_and_the_second_ends_the_process_at_once(tmp_path, first, second, word, code):
    """The handler never raises: after the first SIGINT (or SIGTERM) the work goes on until it checks, and check()
    raises there; a second signal prints the one line (and the record) and ends the process at once, with 130 after
    a SIGINT and 143 after a SIGTERM."""
    script = tmp_path / "twice.py"
    script.write_text(textwrap.dedent(f"""
        import os, signal, sys, time
        from cvpipe import interrupt
        assert interrupt.install(record=True)
        os.kill(os.getpid(), signal.{first})
        t0 = time.monotonic()
        while time.monotonic() - t0 < 0.3:  # ordinary work: nothing is raised into it
            sum(range(100))
        assert interrupt.seen()
        try:
            interrupt.check()
            sys.exit("check() did not raise")
        except KeyboardInterrupt:
            pass
        os.kill(os.getpid(), signal.{second})
        time.sleep(5)
        sys.exit("the second signal did not end the process")
    """))
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=ENV, timeout=120)
    assert proc.returncode == code, proc.stderr
    assert proc.stderr == f"cvpipe: error: {word}\n"
    assert proc.stdout == f'{{"error": "{word}", "exit": {code}, "file": null}}\n'
    # "at once": the script would sleep 5 s after the second signal; start-up takes well under a second
    assert time.monotonic() - t0 < 5


def test_ctrl_c_while_the_results_go_out_leaves_them_whole_and_ends_with_130(tmp_path):
    """A Ctrl-C after the work is done no longer cuts the results short: check() stops raising, the results go out
    whole, then the program ends with 130 and the line on stderr (no failure record after the results on stdout)."""
    script = tmp_path / "results.py"
    script.write_text(textwrap.dedent("""
        import os, signal, sys
        from cvpipe import interrupt
        from cvpipe.commands import final_output
        assert interrupt.install(record=True)
        final_output()
        os.kill(os.getpid(), signal.SIGINT)
        interrupt.check()  # does not raise: the results are going out
        print('{"lines": 3}')
        sys.exit(interrupt.finish(0))
    """))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=ENV, timeout=120)
    assert (proc.returncode, proc.stdout, proc.stderr) == (130, '{"lines": 3}\n', "cvpipe: error: interrupted\n")


@pytest.mark.parametrize("moment", ["after finish", "during the shutdown"])
def test_ctrl_c_after_the_work_up_to_the_process_end_is_not_lost(tmp_path, moment):
    """A SIGINT after finish() decided the exit status, up to the end of the interpreter's shutdown (here from an
    ``atexit`` function, which runs before the handler's own last one), still ends the program with 130 and the
    one line: never exit 0 as if no Ctrl-C came, never death by SIGINT (-2)."""
    script = tmp_path / "late.py"
    script.write_text(textwrap.dedent(f"""
        import atexit, os, signal, sys
        from cvpipe import interrupt
        assert interrupt.install()
        print("done")
        code = interrupt.finish(0)
        if {moment!r} == "after finish":
            os.kill(os.getpid(), signal.SIGINT)
        else:
            atexit.register(os.kill, os.getpid(), signal.SIGINT)
        sys.exit(code)
    """))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=ENV, timeout=120)
    assert (proc.returncode, proc.stdout, proc.stderr) == (130, "done\n", "cvpipe: error: interrupted\n")


def test_exit_status_and_message_pass_through_the_handlers_last_step(tmp_path):
    """Without a Ctrl-C the program's own status leaves unchanged: a number as it is, a message as 1 (printed)."""
    for code, expected in (("0", 0), ("3", 3), ("'a message'", 1), ("None", 0)):
        proc = subprocess.run([sys.executable, "-c", "import sys\nfrom cvpipe import interrupt\n"
                               f"interrupt.install()\nsys.exit(interrupt.finish({code}))"],
                              capture_output=True, text=True, env=ENV, timeout=120)
        assert proc.returncode == expected, (code, proc.stderr)
        assert proc.stderr == ("a message\n" if expected == 1 else "")


def test_ctrl_c_when_sigint_is_ignored_changes_nothing(tmp_path):
    """A program started with SIGINT ignored (nohup, a background job) stays deaf to it."""
    code = "import signal\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\nfrom cvpipe import interrupt\n" \
           "print(interrupt.install(), signal.getsignal(signal.SIGINT) is signal.SIG_IGN)"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=120)
    assert proc.stdout.split() == ["False", "True"], proc.stderr


@pytest.mark.parametrize("sig, word, code", [("SIGINT", "interrupted", 130), ("SIGTERM", "terminated", 143)])
def test_stage_interrupted_between_items_is_one_line_exit_130(tmp_path, sig, word, code):
    """A stage run as a program (the shared runner): a Ctrl-C (or SIGTERM) during an item ends the stage before the
    next one, with exit 130 and the line `<stage>: error: interrupted` (143, `terminated`), and writes no summary
    or timings."""
    script = tmp_path / "stage.py"
    script.write_text(textwrap.dedent(f"""
        import os, signal, sys
        from stages._runner import Stage, run

        def demo(st: Stage) -> None:
            for k in st.progress(range(5), "items"):
                print("item", k, flush=True)
                if k == 1:
                    os.kill(os.getpid(), signal.{sig})

        run(demo, args={{}})
    """))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=ENV, timeout=120,
                          cwd=tmp_path)
    assert proc.returncode == code, proc.stderr
    assert proc.stderr.strip() == f"demo: error: {word}"
    assert proc.stdout.split("\n")[:2] == ["item 0", "item 1"] and "item 2" not in proc.stdout
    assert not (tmp_path / "outputs").exists()


# ------------------------------------------------------------------------------- items 7, 8: io temporaries


def test_outputs_honour_the_umask(tmp_path, capsys, views):
    img = np.zeros((16, 16, 3), np.uint8)
    for mask, mode in ((0o022, 0o644), (0o077, 0o600), (0o002, 0o664)):
        old = os.umask(mask)
        try:
            io.save_image(tmp_path / f"m{mask:o}.png", img)
            io.save_json(tmp_path / f"m{mask:o}.json", {"a": 1})
        finally:
            os.umask(old)
        assert stat.S_IMODE((tmp_path / f"m{mask:o}.png").stat().st_mode) == mode
        assert stat.S_IMODE((tmp_path / f"m{mask:o}.json").stat().st_mode) == mode
    old = os.umask(0o022)
    try:
        code, _, _ = run_main(capsys, ["stereo", views["a"], views["r"], "--max-disp", "16", "-o",
                                       tmp_path / "o" / "d.npy", "--json"])
    finally:
        os.umask(old)
    assert code == 0 and stat.S_IMODE((tmp_path / "o" / "d.npy").stat().st_mode) == 0o644


def test_temporary_removed_on_keyboard_interrupt(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        with io.atomic_path(tmp_path / "out.npy") as tmp:
            assert ".cvpipe-tmp-" in tmp.name and tmp.name.startswith(".out")
            tmp.write_bytes(b"half")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_stale_temporary_of_a_dead_process_is_removed_at_the_next_write(tmp_path, capsys, views):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # a pid that no longer runs
    out = tmp_path / "o"
    out.mkdir()
    stale = out / f".d{io.TMP_MARKER}{dead.pid}-0123abcd.npy"
    alive = out / f".d{io.TMP_MARKER}{os.getpid()}-0123abcd.npy"  # a concurrent writer's: must stay
    foreign = out / ".d.abc.tmp.npy"  # not ours: must stay
    for p in (stale, alive, foreign):
        p.write_bytes(b"x" * 100)
    io._SWEPT.discard(out.resolve())
    code, _, _ = run_main(capsys, ["stereo", views["a"], views["r"], "--max-disp", "16", "-o", out / "d.npy"])
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(["d.npy", alive.name, foreign.name])


# ------------------------------------------------------------------------------------------ item 4: names


@pytest.mark.parametrize("name", ["../../../../../tmp/x", "/etc/passwd", "a/b", "a\\b", "..", ".", "", "x\0y"])
def test_safe_name_refuses_paths(name):
    with pytest.raises(errors.InputError, match="pair name"):
        io.safe_name(name, "pair name")


def test_safe_name_keeps_plain_names():
    assert io.safe_name("0_astronaut", "pair name") == "0_astronaut"
    assert io.safe_name("probe_01.png", "probe") == "probe_01.png"


def test_pair_names_come_from_file_names_so_truth_cannot_redirect_outputs(tmp_path):
    """A truth.json ``name`` of ``../../x`` names no pair: the pairs are named after files and folders
    (cvpipe.datasets), and a truth entry only adds ground truth to a pair of that name."""
    from cvpipe import datasets

    t = texture(120, 200, seed=4)
    for name in ("p_a.png", "p_b.png"):
        cv2.imwrite(str(tmp_path / name), t[:, :160])
    (tmp_path / "truth.json").write_text(json.dumps({"pairs": [
        {"name": "../../../../../tmp/x", "a": "p_a.png", "b": "p_b.png", "H": np.eye(3).tolist()}]}))
    pairs, dropped = datasets.find_homography(tmp_path)
    # the one pair is still found, named after its files, and the truth entry of another name gives it no H
    assert [(p.name, p.a, p.b, p.H) for p in pairs] == [("p", tmp_path / "p_a.png", tmp_path / "p_b.png", None)]
    assert dropped == [] and io.safe_name(pairs[0].name, "pair name") == "p"
    # a truth entry named after the pair does give it its H: the entry above was read and matched no pair
    H = np.diag([2.0, 2.0, 1.0])
    (tmp_path / "truth.json").write_text(json.dumps({"pairs": [{"name": "p", "H": H.tolist()}]}))
    (pair,), _ = datasets.find_homography(tmp_path)
    assert pair.name == "p" and np.array_equal(pair.H, H)


# --------------------------------------------------------------------------------- item 5: output suffixes


@pytest.mark.parametrize("out", ["p.txt", "pano"])
def test_stitch_checks_the_output_before_stitching(capsys, monkeypatch, views, tmp_path, out):
    import cvpipe.panorama

    monkeypatch.setattr(cvpipe.panorama, "stitch", lambda *a, **k: pytest.fail("stitched before checking -o"))
    code, lines, doc = run_main(capsys, ["stitch", views["a"], views["b"], "-o", tmp_path / out, "--json"])
    line = only_error_line(lines)
    assert code == 2 and "`-o` must end in one of .png" in line and doc["exit"] == 2
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------- items 1, 7, 9: memory etc.


@pytest.mark.parametrize("option", [["--theta-deg", "0.0001"], ["--rho", "0.0001"]])
def test_hough_tiny_steps_refused_before_allocating(capsys, monkeypatch, views, option):
    monkeypatch.setattr(hough.transform, "hough_accumulator", lambda *a, **k: pytest.fail("accumulator allocated"))
    monkeypatch.setattr(hough.transform, "_grid", lambda *a, **k: pytest.fail("tables allocated"))
    code, lines, doc = run_main(capsys, ["hough", views["a"], *option, "--json"])
    line = only_error_line(lines)
    assert code == 2 and "--theta-deg" in line and "--rho" in line and "memory budget" in line
    assert doc["exit"] == 2


def test_stereo_over_budget_names_max_disp(capsys, monkeypatch, views, tmp_path):
    # 320 x 240 x 16 disparities x 5 bytes = 6.1 MB of volumes > a 1 MB budget
    monkeypatch.setenv("CVPIPE_MEMORY_BUDGET_GB", "0.001")
    code, lines, doc = run_main(capsys, ["-q", "stereo", views["a"], views["r"], "--max-disp", "16", "-o",
                                         tmp_path / "d.npy", "--json"])
    line = only_error_line(lines)
    assert code == 2 and "`--max-disp`" in line and "downscale" in line and not (tmp_path / "d.npy").exists()


def test_bad_memory_budget_variable_is_refused(capsys, monkeypatch, views):
    monkeypatch.setenv("CVPIPE_MEMORY_BUDGET_GB", "lots")
    code, lines, _ = run_main(capsys, ["hough", views["a"]])
    assert code == 2 and "CVPIPE_MEMORY_BUDGET_GB" in only_error_line(lines)


def test_huge_image_detection_is_downscaled_and_says_so(monkeypatch, textured_image):
    from cvpipe import features

    full = features.detect(textured_image, "sift", 500)
    monkeypatch.setenv("CVPIPE_MEMORY_BUDGET_GB", str(640 * 480 * 250 / 4 / 1e9))  # a quarter of what SIFT needs
    with pytest.warns(errors.BudgetWarning, match=r"detected at 0\.\d+x size"):
        small = features.detect(textured_image, "sift", 500)
    # positions stay in the original pixels: the strongest keypoints of both runs lie in the same image area
    assert len(small) > 50
    assert small.xy[:, 0].max() > 0.8 * textured_image.shape[1] and small.xy[:, 1].max() > 0.8 * full.xy[:, 1].max()


def test_budget_note_is_one_line_and_silenced_by_quiet(capsys, monkeypatch, views):
    # a budget of a tenth of what SIFT needs on the 320x240 views: the command scales detection down and says so
    monkeypatch.setenv("CVPIPE_MEMORY_BUDGET_GB", str(320 * 240 * 250 / 10 / 1e9))
    argv = ["homography", views["a"], views["b"], "--detector", "sift", "--json"]
    code, lines, _ = run_main(capsys, argv)
    notes = [ln for ln in lines if ln.startswith("cvpipe: note: ")]
    assert notes and all("memory budget" in ln for ln in notes), lines
    code_quiet, lines_quiet, _ = run_main(capsys, ["-q", *argv])
    assert code_quiet == code and lines_quiet == []


def test_stereo_paths_6_refused_by_the_parameters():
    with pytest.raises(ValueError, match=r"`paths` must be one of \[4, 8\], got 6"):
        StereoSgmParams(paths=6)
    assert StereoSgmParams(paths=4).paths == 4


def test_stereo_reads_16_bit_like_8_bit(capsys, views, tmp_path):
    for k in ("a", "r"):
        cv2.imwrite(str(tmp_path / f"{k}16.png"), cv2.imread(str(views[k])).astype(np.uint16) * 257)
    outs = {}
    for tag, (l, r) in {"8": (views["a"], views["r"]), "16": (tmp_path / "a16.png", tmp_path / "r16.png")}.items():
        code, lines, _ = run_main(capsys, ["stereo", l, r, "--max-disp", "16", "-o", tmp_path / f"d{tag}.npy"])
        assert code == 0 and not [ln for ln in lines if ln.startswith("cvpipe: error:")]
        outs[tag] = np.load(tmp_path / f"d{tag}.npy", allow_pickle=False)
    # x * 257 / 257 restores every 8-bit value exactly, so the disparities are identical
    assert np.array_equal(outs["8"], outs["16"], equal_nan=True)


# ------------------------------------------------------------------------------- item 2: chance-level models


def test_uniformly_random_matches_give_no_model():
    rng = np.random.default_rng(7)
    refused = 0
    for trial in range(20):
        src = rng.uniform(0, [640, 480], (60, 2))
        dst = rng.uniform(0, [640, 480], (60, 2))
        for method in homography.METHODS:
            try:
                homography.estimate(method, src, dst, threshold=3.0, rng=trial)
            except errors.EstimationError as exc:
                assert "chance level" in str(exc) or "no homography" in str(exc)
                refused += 1
    assert refused == 20 * len(homography.METHODS)  # no model from pure chance, whatever the method


def test_real_model_with_outliers_is_kept_and_significant():
    rng = np.random.default_rng(3)
    H = np.array([[1.1, 0.05, 12.0], [-0.03, 0.95, 7.0], [1e-4, -5e-5, 1.0]])
    src = rng.uniform(0, [640, 480], (80, 2))
    dst = homography.transform_points(H, src) + rng.normal(0, 0.5, (80, 2))
    dst[:60] = rng.uniform(0, [640, 480], (60, 2))  # 75 % outliers, 20 true matches
    for method in homography.METHODS:
        fit = homography.estimate(method, src, dst, threshold=3.0, rng=0)
        assert fit.num_inliers >= 18 and fit.log10_nfa < -5  # 20 true matches are far beyond chance


def test_four_matches_cannot_be_told_from_chance_on_the_cli_path():
    src = np.array([[0, 0], [100, 0], [100, 100], [0, 100]], float)
    with pytest.raises(errors.EstimationError, match="fits any 4 exactly"):
        homography.estimate("ours", src, src + 5)
    assert homography.find_homography(src, src + 5).num_inliers == 4  # the function keeps cv2's semantics


def test_homography_command_on_unrelated_images_is_exit_1_with_counts(capsys, tmp_path):
    for seed in (11, 12):
        cv2.imwrite(str(tmp_path / f"{seed}.png"), texture(480, 640, seed=seed))
    for method in ("ours", "opencv-ransac", "opencv-magsac"):
        code, lines, doc = run_main(capsys, ["homography", tmp_path / "11.png", tmp_path / "12.png", "--method",
                                             method, "--json"])
        line = only_error_line(lines)
        assert code == 1 and doc["exit"] == 1 and ("chance level" in line or "matches" in line), line


# ------------------------------------------------------------------- flags: checked by their parameters' bounds


@pytest.mark.parametrize("argv, expected", [
    # beyond int64 and beyond a C int: the flag's own range, whatever the library underneath would have said
    (["hough", "{a}", "--threshold", "1180591620717411303424"],
     "hough: `--threshold` must be in [1, 2147483647], got 1180591620717411303424"),
    (["hough", "{a}", "--method", "opencv", "--threshold", "4294967297"],
     "hough: `--threshold` must be in [1, 2147483647], got 4294967297"),
    (["hough", "{a}", "--rho", "nan"], "hough: `--rho` must be a finite number, got nan"),
    (["hough", "{a}", "--canny", "-5", "100"], "hough: `--canny` must be in [0.0, inf), got -5.0"),
    (["homography", "{a}", "{b}", "--method", "opencv_ransac", "--threshold", "1e308"],
     "homography: `--threshold` must be in (0.0, 100.0], got 1e+308"),
    (["homography", "{a}", "{b}", "--max-features", "1099511627776"],
     "homography: `--max-features` must be in [1, 1000000], got 1099511627776"),
    (["homography", "{a}", "{b}", "--ratio", "inf"], "homography: `--ratio` must be a finite number, got inf"),
    (["homography", "{a}", "{b}", "--seed", "-1"], "homography: `--seed` must be in [0, 2147483647], got -1"),
    (["stitch", "{a}", "{b}", "-o", "{tmp}/p.png", "--seed", "-1"],
     "stitch: `--seed` must be in [0, 2147483647], got -1"),
    (["stereo", "{a}", "{r}", "--max-disp", "16", "-o", "{tmp}/d.npy", "--rectify", "--seed", "-1"],
     "stereo: `--seed` must be in [0, 2147483647], got -1"),
    (["logo", "{a}", "--gallery", "{tmp}", "--seed", "-1"], "logo: `--seed` must be in [0, 2147483647], got -1"),
    (["stitch", "{a}", "{b}", "-o", "{tmp}/p.png", "--compose-megapix", "1e-9"],
     "stitch: `--compose-megapix` must be <= 0 (full resolution) or in [0.01, 1000.0], got 1e-09"),
    (["stitch", "{a}", "{b}", "-o", "{tmp}/p.png", "--work-megapix", "1e-9"],
     "stitch: `--work-megapix` must be <= 0 (full resolution) or in [0.01, 1000.0], got 1e-09"),
    (["stitch", "{a}", "{b}", "-o", "{tmp}/p.png", "--min-confidence", "inf"],
     "stitch: `--min-confidence` must be a finite number, got inf"),
])
def test_flags_are_checked_by_their_parameters_bounds(capsys, views, tmp_path, argv, expected):
    """A flag takes what its params.yaml key takes: one line naming the flag and the range, exit 2, nothing written
    (the values reached the compiled kernels, OpenCV or numpy before, with their own words or an internal error)."""
    argv = [a.format(a=views["a"], b=views["b"], r=views["r"], tmp=tmp_path) for a in argv]
    code, lines, doc = run_main(capsys, [*argv, "--json"])
    line = only_error_line(lines)
    cmd = argv[0]
    assert line == f"cvpipe: error: {expected} (see cvpipe {cmd} --help)", line
    assert code == 2 and doc == {"error": line.removeprefix("cvpipe: error: "), "file": None, "exit": 2}
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("spelling", ["dotted", "symlink"])
def test_stitch_refuses_one_file_given_twice(capsys, views, tmp_path, spelling):
    """The same photo twice is one photo: refused with the file named, not stitched as "3 images"."""
    a = views["a"]
    if spelling == "dotted":
        again = a.parent / "." / a.name
    else:
        again = tmp_path / "link.png"
        again.symlink_to(a)
    out = tmp_path / "p.png"
    code, lines, doc = run_main(capsys, ["stitch", a, views["b"], again, "-o", out, "--json"])
    line = only_error_line(lines)
    assert code == 2 and line == (f"cvpipe: error: IMAGE 3 ({again}) is the same file as IMAGE 1 ({a}); "
                                  "give each photo once"), line
    assert doc == {"error": line.removeprefix("cvpipe: error: "), "file": str(again), "exit": 2}
    assert not out.exists()


# ----------------------------------------------------------------------------------------------------- SIGTERM


#: a stand-in for the edge detector of `cvpipe hough` during which the test sends the signal: it says it runs (a
#: file), then works on for 2 s
SLOW_EDGES = """
import pathlib, time
import numpy as np
from cvpipe import hough

def edges_of(gray, *a, **k):
    pathlib.Path({ready!r}).write_text("running")
    t0 = time.monotonic()
    while time.monotonic() - t0 < 2:
        sum(range(1000))
    return np.zeros_like(gray)

hough.edges_of = edges_of
"""


@pytest.mark.parametrize("json_flag", [True, False], ids=["json", "text"])
def test_sigterm_is_one_line_exit_143_and_the_json_record(views, tmp_path, json_flag):
    """A real SIGTERM from another process while a step runs: the step ends the command as a Ctrl-C would, with its
    own status 143, the line `cvpipe: error: terminated` and, with --json, the failure record; nothing else."""
    ready = tmp_path / "ready"
    script = (f"import sys\nsys.argv = ['cvpipe', *sys.argv[1:]]\n{SLOW_EDGES.format(ready=str(ready))}\n"
              "from cvpipe._entry import main\nsys.exit(main())")
    overlay = tmp_path / "o.png"
    proc = subprocess.Popen([sys.executable, "-c", script, "hough", str(views["a"]), "--overlay", str(overlay),
                             *(["--json"] if json_flag else [])],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    t0 = time.monotonic()
    while not ready.exists():
        assert proc.poll() is None and time.monotonic() - t0 < 60, "the command never reached its step"
        time.sleep(0.01)
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=60)
    assert (proc.returncode, stderr) == (143, "cvpipe: error: terminated\n")
    if json_flag:
        assert json.loads(stdout) == {"error": "terminated", "file": None, "exit": 143}
    else:
        assert stdout == ""
    assert not overlay.exists() and no_temporaries(tmp_path)
