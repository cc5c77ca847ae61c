"""cvpipe.compute: the same results in process, on a LocalCluster and on a real external Dask cluster; items come
back in input order, failures are listed without stopping the others, a killed worker loses no item, an unreachable
scheduler is one line and exit 1, and the window bounds what is held at once."""

from __future__ import annotations

import contextvars
import json
import os
import signal
import subprocess
import sys
import threading
import time

import cv2
import numpy as np
import pytest

from cvpipe import cli
from cvpipe.compute import ComputeError, ItemResult, check_scheduler, cluster, map_items
from cvpipe.errors import EstimationError, InputError
from cvpipe.params import ComputeParams, from_mapping

from test_defects import board, make_probe, motion
from test_logos import PERSP, _scene, _view, gallery, gallery_dir, marks  # noqa: F401 - fixtures used below
from conftest import default_params_path

pytestmark = pytest.mark.timeout(600)  # a cluster run that stalls fails here, not after the suite-wide 1500 s


# ----------------------------------------------------------------------------- item functions (module level: picklable)


def square_or_fail(x: int, shared: dict) -> int:
    """x^2 + offset; item 3 fails the way a bad image does (its own exception, not the worker's)."""
    if x == 3:
        raise InputError("item 3: not a readable image")
    time.sleep(0.002 * ((x * 7) % 5))  # uneven durations, so completion order differs from input order
    return x * x + shared["offset"]


def slow_square(x: int) -> tuple[int, int]:
    time.sleep(0.15)
    return x * x, os.getpid()


_KEEP: list = []


def where_and_what(x: int, shared: np.ndarray) -> tuple[int, int, float]:
    """(process id, id of the shared object, a checksum of it); keeping the object alive makes its id unique."""
    _KEEP.append(shared)
    return os.getpid(), id(shared), float(shared.sum())


def first_is_slow(x: int) -> int:
    time.sleep(0.5 if x == 0 else 0.01)
    return x


# ----------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def external():
    """A real ``dask scheduler`` and two ``dask worker --nthreads 1`` processes on 127.0.0.1 (torn down always)."""
    from cvpipe.bench.scale import external_cluster, worker_environment

    env = worker_environment()
    # the workers unpickle this module's functions by reference: make tests/ importable there too
    env["PYTHONPATH"] = os.pathsep.join([os.path.dirname(__file__), env["PYTHONPATH"]])
    with external_cluster(2, env=env) as ext:
        yield ext


@pytest.fixture(scope="module")
def local_client():
    """A LocalCluster of two single-threaded worker processes, shared by the tests that need one."""
    with cluster("local", 2) as client:
        yield client


@pytest.fixture(scope="module")
def probes(tmp_path_factory):
    """A synthetic board, five probes of it (two with inserted defects) and one file that is not an image."""
    d = tmp_path_factory.mktemp("probes")
    ref = board(11)
    cv2.imwrite(str(d / "reference.png"), ref)
    paths = []
    for k in range(5):
        part = ref.copy()
        if k in (1, 3):
            cv2.circle(part, (100 + 30 * k, 150), 8, (25, 25, 35), -1, cv2.LINE_AA)
        H = motion(1.5 * k - 3, 1.0 + 0.01 * k, (4.0 - k, 2.0 * k - 5))
        p = d / f"probe_{k}.png"
        cv2.imwrite(str(p), make_probe(part, H, seed=k))
        paths.append(str(p))
    broken = d / "probe_broken.png"
    broken.write_bytes(b"not an image")
    paths.insert(2, str(broken))
    return str(d / "reference.png"), paths


# ----------------------------------------------------------------------------- the layer itself


def test_serial_path_never_imports_dask(repo_root):
    code = ("import sys; from cvpipe.compute import map_items; "
            "r = list(map_items(abs, [-1, 2])); assert [x.value for x in r] == [1, 2]; "
            "assert not any(m == 'dask' or m.startswith(('dask.', 'distributed')) for m in sys.modules), 'imported'")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(repo_root), os.environ.get("PYTHONPATH", "")]))
    subprocess.run([sys.executable, "-c", code], check=True, env=env)


def test_serial_results_in_order_with_the_bad_item_listed():
    got = list(map_items(square_or_fail, range(8), shared={"offset": 1}))
    assert [r.index for r in got] == list(range(8))
    assert [r.value for r in got] == [x * x + 1 if x != 3 else None for x in range(8)]
    assert got[3] == ItemResult(3, None, "item 3: not a readable image", "InputError")
    assert all(r.ok for i, r in enumerate(got) if i != 3)


def _where_it_ran(item, shared):
    return threading.get_ident(), shared["var"].get()


def test_serial_items_run_on_one_thread_of_their_own_with_the_callers_context():
    var = contextvars.ContextVar("var", default="unset")
    before_threads = threading.active_count()
    token = var.set("the caller's")
    try:
        got = [r.value for r in map_items(_where_it_ran, range(4), shared={"var": var})]
    finally:
        var.reset(token)
    idents = {g[0] for g in got}
    assert len(idents) == 1 and threading.get_ident() not in idents  # one thread, not the caller's
    assert all(g[1] == "the caller's" for g in got)  # the caller's context variables
    assert threading.active_count() == before_threads  # the thread ends with the run
    # a run left after its first item ends its thread too
    run = map_items(_where_it_ran, range(4), shared={"var": var})
    next(run)
    run.close()
    assert threading.active_count() == before_threads


@pytest.mark.slow
def test_local_cluster_gives_the_serial_results(local_client):
    serial = list(map_items(square_or_fail, range(30), shared={"offset": 5}))
    dist = list(map_items(square_or_fail, range(30), shared={"offset": 5}, client=local_client, window=4))
    assert dist == serial


@pytest.mark.slow
def test_shared_data_is_one_object_per_worker(local_client):
    shared = np.arange(1000, dtype=np.float64)
    got = [r.value for r in map_items(where_and_what, range(40), shared=shared, client=local_client)]
    assert os.getpid() not in {pid for pid, _, _ in got}, "the items ran in the driver, not on the workers"
    ids_by_pid: dict[int, set[int]] = {}
    for pid, oid, total in got:
        ids_by_pid.setdefault(pid, set()).add(oid)
        assert total == shared.sum()
    # deserialised once per worker, not once per item (~20 items per worker). At most 2: on a loaded machine a
    # worker can be handed its first task before the scheduler has recorded its broadcast copy, and then fetches
    # one more copy from its peer; it never fetches one per item.
    assert all(len(ids) <= 2 for ids in ids_by_pid.values()), ids_by_pid
    assert len(got) >= 10 * len(ids_by_pid)


@pytest.mark.slow
@pytest.mark.parametrize("window", [1, 3, 8])
def test_window_bounds_the_items_held(local_client, window):
    """Items are pulled lazily: pulled - yielded never exceeds the window, even when the first item is the slowest
    (its 49 successors finish first and must wait in the reorder buffer, which counts against the window)."""
    pulled = 0

    def source():
        nonlocal pulled
        for x in range(50):
            pulled += 1
            yield x

    yielded, worst = 0, 0
    for r in map_items(first_is_slow, source(), client=local_client, window=window):
        assert r.index == yielded and r.value == yielded
        yielded += 1
        worst = max(worst, pulled - yielded + 1)  # +1: the item just yielded was held until now
    assert yielded == 50
    assert worst <= window, f"held {worst} items with a window of {window}"


def test_bad_arguments_name_the_parameter():
    with pytest.raises(InputError, match="`compute.scheduler` must be '' .*got 'cluster'"):
        check_scheduler("cluster")
    with pytest.raises(InputError, match="`--scheduler` must be"):
        check_scheduler("tcp://", "--scheduler")
    with pytest.raises(InputError, match="`compute.window` must be an integer >= 1, got 0"):
        map_items(abs, [1], window=0)
    with pytest.raises(InputError, match="`retries` must be an integer >= 0"):
        map_items(abs, [1], retries=-1)
    with pytest.raises(InputError, match="`compute.workers` must be an integer >= 0"):
        with cluster("local", -1):
            pass
    assert check_scheduler(" tcp://10.0.0.5:8786 ") == "tcp://10.0.0.5:8786"


def test_compute_params_validate():
    assert (from_mapping(ComputeParams, {"scheduler": "local", "workers": 2}, "compute")
            == ComputeParams(scheduler="local", workers=2))
    # one line naming the dotted key and what it accepts (the params module's message form)
    with pytest.raises(InputError, match=r"`compute.scheduler`: must be '' \(in process\), 'local' or"):
        from_mapping(ComputeParams, {"scheduler": "fast"}, "compute")
    with pytest.raises(InputError, match=r"`compute.workers` must be in \[0, 4096\], got -1"):
        from_mapping(ComputeParams, {"workers": -1}, "compute")
    with pytest.raises(InputError, match="`compute.window` must be an integer"):
        from_mapping(ComputeParams, {"window": 2.5}, "compute")


def test_progress_reports_done_and_total():
    seen = []
    list(map_items(abs, range(4), progress=lambda done, total: seen.append((done, total))))
    assert seen == [(1, 4), (2, 4), (3, 4), (4, 4)]


# ----------------------------------------------------------------------------- faults


def test_unreachable_scheduler_is_one_line_exit_1_nothing_written(probes, tmp_path, capsys):
    from cvpipe.bench.scale import free_port

    ref, paths = probes
    address = f"tcp://127.0.0.1:{free_port()}"  # nothing listens there
    out = tmp_path / "out"
    # -q: without notes (the kernel-compile note of a cold cache), the error must be the only line
    code = cli.main(["-q", "inspect", ref, *paths, "--scheduler", address, "--out", str(out), "--json"])
    captured = capsys.readouterr()
    assert code == 1
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and address in lines[0] and lines[0].startswith("cvpipe: error: "), captured.err
    # --json: stdout is the one JSON error record of the contract, naming the address
    assert address in captured.out and captured.out.count("\n") == 1 and '"exit": 1' in captured.out
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("address, match", [
    ("tcp://127.0.0.1:0", r"port 0 is outside 1\.\.65535, got 'tcp://127\.0\.0\.1:0'"),
    ("tcp://127.0.0.1:99999", r"the port is not a number in 1\.\.65535"),
    ("tcp://127.0.0.1:-5", r"the port is not a number in 1\.\.65535"),
    ("tcp://127.0.0.1", r"the port is missing"),
    ("tcp://:8786", r"the host is empty"),
    ("tls://127.0.0.1:8786", r"scheme tls:// is not supported \(only tcp://\)"),
    ("ucx://127.0.0.1:8786", r"scheme ucx:// is not supported"),
    ("tcp://127.0.0.1:8786/x", r"nothing may follow host:port"),
])
def test_bad_addresses_are_refused_before_any_connection(address, match):
    with pytest.raises(InputError, match=r"`--scheduler` must be '' \(in process\), 'local' or a scheduler address "
                                         r"tcp://host:port \(port 1\.\.65535\); " + match):
        check_scheduler(address, "--scheduler")
    with pytest.raises(InputError, match=r"`compute.scheduler`: must be .*; " + match):
        from_mapping(ComputeParams, {"scheduler": address}, "compute")


def test_a_bad_address_is_exit_2_one_line(tmp_path, capsys):
    img = tmp_path / "a.png"
    cv2.imwrite(str(img), np.full((40, 40), 90, np.uint8))
    code, out, err = _cli(["hough", str(img), "--scheduler", "tls://127.0.0.1:8786", "--json"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "scheme tls:// is not supported" in err
    assert json.loads(out)["exit"] == 2


@pytest.mark.parametrize("timeout", [0, -1.0, float("nan"), float("inf"), "5"])
def test_timeout_must_be_positive_seconds(timeout):
    with pytest.raises(InputError, match=r"`timeout` must be a finite number of seconds > 0"):
        list(map_items(abs, [1], scheduler="tcp://127.0.0.1:8786", timeout=timeout))


@pytest.fixture
def fake_server():
    """``start(greet)`` listens on 127.0.0.1 in a thread and returns its ``tcp://`` address; ``greet`` is what it
    sends each connection it accepts (None: nothing, ``"http"``: a plain ``http.server``). Stopped at the end."""
    import socket
    import threading
    from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

    stops = []

    def start(greet):
        if greet == "http":
            server = ThreadingHTTPServer(("127.0.0.1", 0), SimpleHTTPRequestHandler)
            threading.Thread(target=server.serve_forever, daemon=True).start()
            stops.append(server.shutdown)
            stops.append(server.server_close)
            return f"tcp://127.0.0.1:{server.server_address[1]}"
        sock = socket.socket()
        sock.bind(("127.0.0.1", 0))
        sock.listen(8)
        held = []

        def serve():
            while True:
                try:
                    conn, _ = sock.accept()
                except OSError:
                    return
                held.append(conn)  # kept open, so the client sees silence rather than a closed connection
                if greet:
                    conn.sendall(greet)

        threading.Thread(target=serve, daemon=True).start()
        stops.append(lambda: [c.close() for c in held + [sock]])
        return f"tcp://127.0.0.1:{sock.getsockname()[1]}"

    yield start
    for stop in stops:
        stop()


@pytest.mark.parametrize("greet, match", [
    (None, "accepted the connection but sent no Dask greeting within 1 s: not a Dask scheduler"),
    ("http", "accepted the connection but sent no Dask greeting within 1 s: not a Dask scheduler"),
    (b"HTTP/1.0 400 Bad request\r\n", "answers HTTP, not the Dask protocol"),
    (int(6e9).to_bytes(8, "little") + bytes(64), "announced a first message of 6000000000 bytes"),
])
def test_a_peer_that_does_not_speak_dask_fails_within_the_timeout(fake_server, greet, match):
    address = fake_server(greet)
    t0 = time.monotonic()
    with pytest.raises(ComputeError, match=f"{address} {match}"):
        list(map_items(abs, [1, 2], scheduler=address, timeout=1))
    # no hang: the timeout bounds the wait (the margin covers importing Dask on a loaded machine)
    assert time.monotonic() - t0 < 1 + 20


@pytest.mark.slow
def test_a_scheduler_killed_mid_run_is_one_error_naming_it_after_the_finished_items():
    from cvpipe.bench.scale import external_cluster, worker_environment

    env = worker_environment()
    env["PYTHONPATH"] = os.pathsep.join([os.path.dirname(__file__), env["PYTHONPATH"]])
    with external_cluster(1, env=env) as ext:
        got = []
        with pytest.raises(ComputeError, match=rf"lost the Dask scheduler at {ext.address} after \d+ items had "
                                               r"finished \(.+\)$") as err:
            for r in map_items(slow_square, range(40), scheduler=ext.address, window=4):
                got.append(r)
                if r.index == 3:
                    ext.scheduler.send_signal(signal.SIGKILL)
                    ext.scheduler.wait(timeout=10)
    assert [r.index for r in got] == list(range(len(got))) and len(got) >= 4  # the finished items were yielded
    assert f"after {len(got)} items had finished" in str(err.value)
    assert "\n" not in str(err.value)


def test_unreachable_scheduler_raises_compute_error():
    from cvpipe.bench.scale import free_port

    address = f"tcp://127.0.0.1:{free_port()}"
    with pytest.raises(ComputeError, match=f"cannot reach the Dask scheduler at {address}"):
        list(map_items(abs, [1, 2], scheduler=address, timeout=2))


@pytest.mark.slow
def test_killed_worker_loses_no_item(tmp_path):
    """Kill one of two workers while items are running: every item still comes back, right and in order."""
    from cvpipe.bench.scale import external_cluster, worker_environment

    env = worker_environment()
    env["PYTHONPATH"] = os.pathsep.join([os.path.dirname(__file__), env["PYTHONPATH"]])
    with external_cluster(2, env=env) as ext:
        victim = ext.workers[0]
        got = []
        for r in map_items(slow_square, range(40), scheduler=ext.address, window=6):
            got.append(r)
            if r.index == 8:
                # mid-run: 9 items done, up to 6 submitted (some running on the victim), 25 not yet submitted
                victim.send_signal(signal.SIGKILL)
                victim.wait(timeout=10)
    assert [r.index for r in got] == list(range(40))
    assert all(r.ok for r in got), [r.error for r in got if not r.ok]
    assert [r.value[0] for r in got] == [x * x for x in range(40)]
    pids = [r.value[1] for r in got]
    assert victim.pid in pids[:9], "the killed worker had done no work before it was killed"
    assert victim.pid not in pids[9 + 6:], "items submitted after the kill ran on the dead worker"


# ----------------------------------------------------------------------------- CLI batches, byte for byte


def _cli(argv: list[str], capsys) -> tuple[int, str, str]:
    code = cli.main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.slow
def test_inspect_batch_identical_serial_local_external(probes, external, capsys):
    ref, paths = probes
    base = ["inspect", ref, *paths, "--json"]
    serial = _cli(base, capsys)
    local = _cli(base + ["--scheduler", "local"], capsys)
    remote = _cli(base + ["--scheduler", external.address], capsys)
    # exit 2 (bad input, main's contract: the worst item's status): the broken probe is listed as an error and the
    # five good ones are judged
    assert serial[0] == 2 and '"verdict": "faulty"' in serial[1] and "probe_broken.png" in serial[2]
    assert local == serial
    assert remote == serial


@pytest.mark.slow
def test_hough_batch_identical_serial_local_external(tmp_path, external, capsys):
    paths = []
    for k in range(4):
        img = np.full((160, 200), 30, np.uint8)
        cv2.line(img, (10, 20 + 30 * k), (190, 140 - 10 * k), 230, 2)
        cv2.line(img, (40 + 25 * k, 5), (60 + 20 * k, 155), 230, 2)
        p = tmp_path / f"lines_{k}.png"
        cv2.imwrite(str(p), img)
        paths.append(str(p))
    (tmp_path / "bad.png").write_bytes(b"")
    paths.append(str(tmp_path / "bad.png"))
    base = ["hough", *paths, "--threshold", "60", "--json"]
    serial = _cli(base, capsys)
    assert serial[0] == 2 and "bad.png: file is empty" in serial[2]
    assert _cli(base + ["--scheduler", "local"], capsys) == serial
    assert _cli(base + ["--scheduler", external.address], capsys) == serial



@pytest.mark.slow
def test_logo_batch_identical_serial_local_external(tmp_path, gallery_dir, marks, external, capsys):
    scenes = []
    for k, brand in enumerate(["brand1", None, "brand0", "brand1"]):
        p = tmp_path / f"scene_{k}.jpg"
        cv2.imwrite(str(p), _scene(marks[brand] if brand else None, _view((300 + 10 * k, 240), 0.8, 8 * k, PERSP)))
        scenes.append(str(p))
    (tmp_path / "broken.jpg").write_bytes(b"not an image at all")
    scenes.insert(1, str(tmp_path / "broken.jpg"))
    base = ["logo", *scenes, "--gallery", str(gallery_dir), "--json"]
    serial = _cli(base, capsys)
    assert serial[0] == 2 and '"brand": "brand1"' in serial[1] and "broken.jpg" in serial[2]
    assert _cli(base + ["--scheduler", "local"], capsys) == serial
    assert _cli(base + ["--scheduler", external.address], capsys) == serial


# ----------------------------------------------------------------------------- sharing results through a DVC remote


def _dvc(cwd, *args, env=None) -> str:
    proc = subprocess.run([sys.executable, "-m", "dvc", *args], cwd=cwd, capture_output=True, text=True, env=env)
    assert proc.returncode == 0, f"dvc {' '.join(args)}: {proc.stdout}{proc.stderr}"
    return proc.stdout + proc.stderr


@pytest.mark.slow
def test_a_teammate_restores_a_stage_from_the_shared_run_cache(tmp_path, repo_root):
    """The README recipe: run a stage, ``dvc push --run-cache`` to a local-directory remote; a fresh checkout that
    never ran it (no dvc.lock) runs ``dvc repro --pull``: the output is restored from the shared run cache and the
    stage does not run."""
    remote = tmp_path / "remote"
    img = np.full((120, 160), 30, np.uint8)
    cv2.line(img, (5, 10), (150, 110), 230, 2)
    stage = ("stages:\n  lines:\n    cmd: python -m cvpipe.cli hough a.png --threshold 40 --json > lines.json\n"
             "    deps: [a.png]\n    outs: [lines.json]\n")
    # the stage's command must run this checkout's cvpipe
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(repo_root), os.environ.get("PYTHONPATH", "")]))
    outputs = {}
    for who in ("me", "teammate"):
        d = tmp_path / who
        d.mkdir()
        cv2.imwrite(str(d / "a.png"), img)
        (d / "dvc.yaml").write_text(stage)
        _dvc(d, "init", "--no-scm", "-q")
        _dvc(d, "remote", "add", "-d", "shared", str(remote))
        if who == "me":
            _dvc(d, "repro", env=env)
            _dvc(d, "push", "--run-cache")
        else:
            log = _dvc(d, "repro", "--pull", env=env)
            # DVC's words for "found in the run cache, outputs checked out, command not run"
            assert "skipping run" in log, log
        outputs[who] = (d / "lines.json").read_bytes()
    assert outputs["teammate"] == outputs["me"] and b'"lines"' in outputs["me"]


def test_bench_scale_rejects_bad_options(tmp_path, capsys):
    assert cli.main(["bench", "scale", "--data", str(tmp_path), "--sizes", "ten"]) == 2
    assert "`--sizes` must be comma-separated integers" in capsys.readouterr().err
    assert cli.main(["bench", "scale", "--data", str(tmp_path), "--modes", "serial,cloud"]) == 2
    assert "`--modes` must be a subset of" in capsys.readouterr().err
    assert cli.main(["bench", "scale", "--data", str(tmp_path)]) == 2
    assert "pairs.txt: not found" in capsys.readouterr().err


# ----------------------------------------------------------------------------- a pipeline stage, byte for byte


@pytest.mark.slow
def test_defect_register_stage_identical_serial_local_external(tmp_path, repo_root, external):
    """The ``defect_register`` stage (``st.map``) gives the same output bytes in process, on a LocalCluster of 2
    workers and on an external scheduler with 2 workers; ``compute`` is read from the params file only."""
    import yaml

    from cvpipe import io

    folder = tmp_path / "data"
    ref = board(11)
    io.save_image(folder / "reference.png", ref)
    for k in range(5):
        part = ref.copy()
        if k in (1, 3):
            cv2.circle(part, (100 + 30 * k, 150), 8, (25, 25, 35), -1, cv2.LINE_AA)
        io.save_image(folder / "probes" / f"probe_{k}.png",
                      make_probe(part, motion(1.5 * k - 3, 1.0 + 0.01 * k, (4.0 - k, 2.0 * k - 5)), seed=k))
    io.save_image(folder / "probes" / "blank.png", np.full(ref.shape, 90, np.uint8))  # cannot be registered
    env = dict(os.environ, PYTHONPATH=str(repo_root))
    base = yaml.safe_load(default_params_path().read_text())

    def stage(module: str, *args, compute: dict | None = None, cwd=tmp_path) -> subprocess.CompletedProcess:
        params = dict(base)
        if compute is not None:
            params["compute"] = compute
        else:
            params.pop("compute", None)  # absent section: in process
        pfile = cwd / "params.yaml"
        pfile.write_text(yaml.safe_dump(params))
        proc = subprocess.run([sys.executable, "-m", module, *map(str, args), "--params", str(pfile)], cwd=cwd,
                              env=env, capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
        return proc

    o = tmp_path / "o"
    stage("stages.features", "--images", folder, "--out", o / "features", "--section", "defect.features")
    stage("stages.defect_match", "--images", folder, "--features", o / "features", "--out", o / "matches")
    outputs = {}
    for mode, compute in {"absent": None, "serial": {"scheduler": "", "workers": 0, "window": 0},
                          "local": {"scheduler": "local", "workers": 2, "window": 0},
                          "external": {"scheduler": external.address, "workers": 0, "window": 3}}.items():
        out = tmp_path / f"register_{mode}"
        proc = stage("stages.defect_register", "--images", folder, "--features", o / "features", "--matches",
                     o / "matches", "--out", out, compute=compute)
        outputs[mode] = ({p.name: p.read_bytes() for p in sorted(out.iterdir())}, proc.stdout.replace(str(out), ""))
    files, summary = outputs["absent"]
    # every good probe registered, the blank one dropped (by match or register) and never lost in any mode
    assert {f"probe_{k}.npz" for k in range(5)} <= set(files) and "registration.json" in files
    doc = json.loads(files["registration.json"])
    assert sorted(doc["probes"]) == [f"probe_{k}" for k in range(5)]
    assert any(d["item"].startswith("blank") for d in doc["dropped"])
    for mode in ("serial", "local", "external"):
        assert outputs[mode] == (files, summary), mode  # byte for byte, and the same summary line


def half_of_even(x: int) -> int:
    """x // 2; an odd x is the item's own failure (InputError), a negative one a bug (ZeroDivisionError)."""
    if x < 0:
        return 1 // 0
    if x % 2:
        raise InputError(f"{x} is odd")
    return x // 2


@pytest.mark.parametrize("scheduler", ["", pytest.param("local", marks=pytest.mark.slow)])
def test_stage_map_yields_in_order_and_drops_in_input_order(tmp_path, repo_root, scheduler):
    import argparse

    sys.path.insert(0, str(repo_root))
    from stages._runner import Stage

    (tmp_path / "params.yaml").write_text(f"compute:\n  scheduler: '{scheduler}'\n  workers: 2\n  window: 2\n")
    st = Stage("t", argparse.Namespace(params=str(tmp_path / "params.yaml")))
    items = [0, InputError("b.png: cannot read"), 2, 3, 4, 6, InputError("g.png: empty"), 8]
    got = list(st.map(half_of_even, items, names=list("abcdefgh")))
    # the successes in input order, each named; the unread item and the failed one dropped in input order
    assert got == [("a", 0), ("c", 1), ("e", 2), ("f", 3), ("h", 4)]
    assert st.dropped == [{"item": "b", "reason": "b.png: cannot read"}, {"item": "d", "reason": "3 is odd"},
                          {"item": "g", "reason": "g.png: empty"}]
    # a bug is not an item's failure: it ends the stage (the runner turns it into the exit status)
    with pytest.raises((ZeroDivisionError, EstimationError)):
        list(Stage("t", argparse.Namespace(params=str(tmp_path / "params.yaml"))).map(half_of_even, [2, -1]))


def test_stage_map_without_compute_section_runs_in_process(tmp_path, repo_root):
    import argparse

    sys.path.insert(0, str(repo_root))
    from stages._runner import Stage

    (tmp_path / "params.yaml").write_text("other: {}\n")
    st = Stage("t", argparse.Namespace(params=str(tmp_path / "params.yaml")))
    assert list(st.map(half_of_even, [4, 5], names=["x", "y"])) == [("x", 2)]
    assert st.dropped == [{"item": "y", "reason": "5 is odd"}]


# ------------------------------------------------------------------- every stage that fans out, byte for byte


def test_gallery_travels_to_a_worker_and_matches_the_same(gallery, marks):
    """A logo gallery crosses to a worker the way Dask ships it (pickle): the trained FLANN matcher cannot travel,
    so the copy re-indexes its references; it must give the very same matches, or logo_match would differ."""
    import pickle

    from cvpipe import logo
    from cvpipe.features import detect

    cv2.randu(np.empty(64), 0, 1)  # a worker's OpenCV generator is wherever its earlier tasks left it
    copy = pickle.loads(pickle.dumps(gallery))
    assert copy.matcher is not gallery.matcher and copy.dropped == gallery.dropped
    assert [r.name for r in copy.references] == [r.name for r in gallery.references]
    scene = detect(_scene(marks["brand1"], _view((420, 300), 0.6, -35, PERSP)), "sift")
    here, there = logo.match_scene(gallery, scene).to_arrays(), logo.match_scene(copy, scene).to_arrays()
    assert len(here["scene_idx"]) > 10  # a real match set, not two empty ones
    assert here.keys() == there.keys() and all(np.array_equal(here[k], there[k]) for k in here)

#: each stage that maps its items with ``st.map`` but ``defect_register`` (tested above), one matrix item where the
#: stage is a matrix (the code path is the same for every method; the cheapest method keeps the test short)
FANNED_OUT = ["homography_features", "homography_estimate@ours", "hough_lines@opencv", "logo_match@orb",
              "logo_verify@orb", "defect_diff", "defect_regions", "stereo_rectify", "stereo_disparity@opencv_sgbm",
              "panorama_match", "panorama_homographies", "panorama_warp", "panorama_blend"]


def _dvc_stages(stages: dict, params: dict) -> dict[str, dict]:
    """Every dvc.yaml stage (one per matrix item, ``base@value``) with its ``argv``, ``outs`` (outs and metrics)
    and ``deps``, the ``${...}`` templates filled from ``params``."""
    import re
    import shlex

    def fill(text: str, item: dict) -> str:
        def one(m: re.Match) -> str:
            key = m.group(1)
            if key.startswith("item."):
                return item[key[5:]]
            node = params
            for part in key.split("."):
                node = node[part]
            return str(node)

        return re.sub(r"\$\{([^}]+)\}", one, text)

    def paths(entries: list, item: dict) -> list[str]:
        return [fill(e if isinstance(e, str) else next(iter(e)), item) for e in entries]

    out = {}
    for base, spec in stages.items():
        matrix = spec.get("matrix", {})
        key = next(iter(matrix), None)
        for value in matrix.get(key, [None]):
            item = {} if key is None else {key: value}
            out[base if key is None else f"{base}@{value}"] = {
                "argv": shlex.split(fill(spec["cmd"], item)), "deps": paths(spec.get("deps", []), item),
                "outs": paths(spec.get("outs", []) + spec.get("metrics", []), item)}
    return out


@pytest.fixture(scope="module")
def sample_pipeline(tmp_path_factory, repo_root):
    """A scratch copy of the pipeline's layout on the samples (fewer logo scenes), with ``run(stage, scheduler)``
    that runs one dvc.yaml stage there (the stages whose outputs it depends on first, once, in process) and returns
    its output files' bytes."""
    import shutil

    import yaml

    root = tmp_path_factory.mktemp("pipeline")
    params = yaml.safe_load(default_params_path().read_text())
    params.pop("compute", None)  # in process unless CVPIPE_COMPUTE_SCHEDULER says otherwise
    params["samples"].update(logo_scenes=3, logo_negatives=1)  # the few scenes the test needs
    (root / "params.yaml").write_text(yaml.safe_dump(params))
    stages = _dvc_stages(yaml.safe_load((repo_root / "dvc.yaml").read_text())["stages"], params)
    done: set[str] = set()

    def call(name: str, scheduler: str) -> dict[str, bytes]:
        for out in stages[name]["outs"]:  # nothing left from another run can stand in for a missing output
            p = root / out
            shutil.rmtree(p) if p.is_dir() else p.unlink(missing_ok=True)
        env = dict(os.environ, PYTHONPATH=str(repo_root), CVPIPE_COMPUTE_SCHEDULER=scheduler)
        argv = stages[name]["argv"]
        proc = subprocess.run([sys.executable, *argv[1:]] if argv[0] == "python" else argv, cwd=root, env=env,
                              capture_output=True, text=True)
        assert proc.returncode == 0, f"{name} ({scheduler or 'in process'}): {proc.stderr}"
        files = {}
        for out in stages[name]["outs"]:
            p = root / out
            for f in sorted(p.rglob("*")) if p.is_dir() else [p]:
                if f.is_file():
                    files[f.relative_to(root).as_posix()] = f.read_bytes()
        return files

    def run(name: str, scheduler: str = "") -> dict[str, bytes]:
        for pre, spec in stages.items():
            if pre not in done and pre != name and any(
                    d == o or d.startswith(o + "/") for d in stages[name]["deps"] for o in spec["outs"]):
                run(pre)
        done.add(name)
        return call(name, scheduler)

    return run


@pytest.mark.slow
@pytest.mark.parametrize("stage", FANNED_OUT)
def test_fanned_out_stage_identical_serial_and_local(sample_pipeline, stage):
    """Every stage that fans its items out writes the same bytes in process and on a LocalCluster (through
    ``CVPIPE_COMPUTE_SCHEDULER``, as a user would run ``dvc repro`` on a cluster)."""
    serial = sample_pipeline(stage)
    local = sample_pipeline(stage, "local")
    assert serial, f"{stage} wrote nothing"
    assert sorted(local) == sorted(serial)
    for path in serial:
        assert local[path] == serial[path], path  # byte for byte
