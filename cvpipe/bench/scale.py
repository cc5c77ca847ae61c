"""``cvpipe bench scale --data DIR``: defect inspection throughput in process, on a LocalCluster and on a cluster.

The stream: probe ``k`` comes from DeepPCB pair ``(k // 2) mod pairs``, its test image (faulty) for even ``k`` and
its template (perfect) for odd ``k``, warped by its own seeded homography with lighting, blur and noise (the same
generator as ``cvpipe bench defect``); the first 200 probes are the DeepPCB probes, longer streams reuse the pairs
with new warps. Probes are made lazily in the stage process and travel to the workers as arrays; the references and
their keypoints are scattered once per worker.

Every configuration runs in a fresh interpreter, so that its peak memory (``ru_maxrss``) is its own: serial in
process (OpenMP and OpenCV with their own threads), ``LocalCluster`` with 1 and with 2 single-threaded workers, and an
external ``dask scheduler`` with 2 ``dask worker --nthreads 1`` processes on 127.0.0.1, and ``kill2``: its own
external cluster of 2 workers of which one is killed (SIGKILL) when half of the probes are done, so that the time a
lost worker costs shows against ``external2`` (the rates before and after the kill, and the whole run's time).
The results of every mode are hashed and must agree. The scheduler's per-item overhead is the latency of an empty
task, submitted one at a time (median and p95), and the rate of empty tasks through
:func:`cvpipe.compute.map_items`.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import resource
import socket
import statistics
import subprocess
import sys
import time
import typing
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

if typing.TYPE_CHECKING:  # annotations only: the modules are imported inside the functions that use them,
    # so that `cvpipe bench scale --help` imports neither numpy nor cv2
    import numpy as np

    from .. import defect as defects


HELP = "inspection throughput serial vs a Dask LocalCluster vs an external Dask cluster (probes/s, overhead, memory)"
EXAMPLE = "cvpipe bench scale --data ../shared/data --max-items 200"

MODES = ("serial", "local1", "local2", "external2", "kill2")
ROOT = Path(__file__).resolve().parents[2]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", default=os.environ.get("CVPIPE_DATA"),
                        help="data root holding deeppcb/ (default: $CVPIPE_DATA)")
    parser.add_argument("--sizes", default="100,1000,10000",
                        help="stream lengths in probes, comma-separated (default 100,1000,10000)")
    parser.add_argument("--max-items", type=int, default=0, help="skip stream lengths above this (0 = none)")
    parser.add_argument("--modes", default=",".join(MODES), help=f"comma-separated subset of {', '.join(MODES)}")
    parser.add_argument("--seed", type=int, default=20261122, help="seed of the random warps")
    parser.add_argument("--overhead-tasks", type=int, default=200, help="empty tasks timed one by one (default 200)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument("--out", help="write results JSON here as well")


# --------------------------------------------------------------------------------------------------- the stream


class References:
    """DeepPCB templates by pair index with their keypoints, detected lazily once per process that uses them.

    Only the images travel (pickled once per worker); the keypoints are recomputed where they are needed, because
    each worker would otherwise receive every reference's keypoints whether it inspects that part or not.
    """

    def __init__(self, images: list[np.ndarray], params: defects.InspectParams):
        self.images, self.params, self._features = images, params, {}

    def __getstate__(self) -> dict:
        return {"images": self.images, "params": self.params}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["images"], state["params"])

    def features(self, i: int):
        from ..features import detect

        if i not in self._features:
            f = self.params.features
            self._features[i] = detect(self.images[i], f.detector, f.max_features)
        return self._features[i]


def inspect_item(item: tuple, refs: References) -> list:
    """One probe of the stream: ``item`` = (pair index, probe gray); returns [verdict, score, regions]."""
    import numpy as np
    from .. import defect as defects

    i, probe = item
    r = defects.inspect(refs.images[i], probe, refs.params, reference_features=refs.features(i))
    return [r.verdict, round(float(r.score), 6), np.round(r.probe_regions, 3).tolist()]


def stream(pairs: list[dict], templates: list[np.ndarray], tests: list[np.ndarray], n: int, seed: int):
    """The lazily generated probes ``(pair index, probe)`` (see the module docstring)."""
    import numpy as np
    from .defect import make_probe

    for k in range(n):
        i = (k // 2) % len(pairs)
        src, boxes = (tests[i], pairs[i]["boxes"]) if k % 2 == 0 else (templates[i], np.zeros((0, 4)))
        probe, _, _ = make_probe(src, boxes, np.random.default_rng([seed, k]))
        yield i, probe


def _noop(x):
    return x


# --------------------------------------------------------------------------------------------------- clusters


def free_port() -> int:
    """A TCP port that was free on 127.0.0.1 a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class ExternalCluster:
    """A ``dask scheduler`` and ``dask worker`` processes started by :func:`external_cluster`."""

    address: str
    scheduler: subprocess.Popen
    workers: list[subprocess.Popen]


def worker_environment() -> dict:
    """This environment with cvpipe (this checkout) importable and one thread per library."""
    from ..compute import WORKER_ENV

    env = dict(os.environ, **WORKER_ENV)
    env["PYTHONPATH"] = os.pathsep.join(p for p in [str(ROOT), env.get("PYTHONPATH", "")] if p)
    return env


@contextlib.contextmanager
def external_cluster(n_workers: int = 2, *, env: dict | None = None, timeout: float = 60.0):
    """Start ``dask scheduler`` and ``n_workers`` single-threaded ``dask worker`` processes on 127.0.0.1.

    Workers run without a nanny, so that killing one (a test does) kills the worker itself. Every process is
    terminated, and killed if it does not stop, on exit, whatever happened.

    Yields
    ------
    ExternalCluster
    """
    from distributed import Client

    env = env or worker_environment()
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env}
    procs: list[subprocess.Popen] = []
    try:
        procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host",
                                       "127.0.0.1", "--port", str(port), "--no-dashboard"], **quiet))
        for _ in range(n_workers):
            procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                           "--nthreads", "1", "--no-nanny", "--no-dashboard"], **quiet))
        with Client(address, timeout=timeout) as client:
            client.wait_for_workers(n_workers, timeout=timeout)
        yield ExternalCluster(address, procs[0], procs[1:])
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


# --------------------------------------------------------------------------------------------------- measuring


def _load(data: str) -> tuple[list, list, list]:
    """Every DeepPCB pair, its template and its test image (gray); the same shared data at every stream length."""
    from .. import io
    from .defect import load_pairs

    pairs = load_pairs(Path(data))
    templates = [io.read_image(p["template"], "gray") for p in pairs]
    tests = [io.read_image(p["test"], "gray") for p in pairs]
    return pairs, templates, tests


def measure(mode: str, n: int, data: str, seed: int, address: str = "", overhead_tasks: int = 200) -> dict:
    """Run one configuration in this process; return throughput, overhead, memory and the results' digest."""
    from .. import defect as defects
    from ..compute import map_items

    pairs, templates, tests = _load(data)
    refs = References(templates, defects.InspectParams())
    t0 = time.perf_counter()
    victim = None
    if mode == "serial":
        ctx = contextlib.nullcontext(None)
    elif mode == "kill2":
        from distributed import Client

        stack = contextlib.ExitStack()
        ext = stack.enter_context(external_cluster(2))
        victim = ext.workers[0]
        ctx = _kill_context(stack, Client(ext.address))
    else:
        from ..compute import cluster

        ctx = cluster({"local1": "local", "local2": "local", "external2": address}[mode],
                      {"local1": 1, "local2": 2}.get(mode))
    out = {"mode": mode, "probes": n}
    with ctx as client:
        out["startup_s"] = time.perf_counter() - t0
        # warm-up: lazy initialisation (first imports, OpenCV's and OpenMP's thread pools) on every worker is not
        # throughput
        warm = list(stream(pairs, templates, tests, 2, seed + 1))
        list(map_items(inspect_item, warm, shared=refs, client=client) if client else
             map_items(inspect_item, warm, shared=refs))
        digest, errors = hashlib.sha256(), 0
        t0 = time.perf_counter()
        results = map_items(inspect_item, stream(pairs, templates, tests, n, seed), shared=refs, client=client,
                            total=n, progress=f"scale {mode}")
        for r in results:
            if victim is not None and r.index + 1 == n // 2:
                victim.kill()  # SIGKILL: no goodbye to the scheduler, its items in flight are lost
                victim.wait(timeout=10)
                out["killed_after_s"] = time.perf_counter() - t0
            errors += not r.ok
            digest.update(json.dumps([r.index, r.value, r.error]).encode())
        wall = time.perf_counter() - t0
        out.update(wall_s=wall, probes_per_s=n / wall, errors=errors, digest=digest.hexdigest()[:16])
        if client is not None:
            lat = []
            for i in range(overhead_tasks):
                t = time.perf_counter()
                client.submit(_noop, i, pure=False).result()
                lat.append(time.perf_counter() - t)
            lat.sort()
            out["empty_task_median_ms"] = 1e3 * statistics.median(lat)
            out["empty_task_p95_ms"] = 1e3 * lat[int(0.95 * (len(lat) - 1))]
            t = time.perf_counter()
            m = 10 * overhead_tasks
            for _ in map_items(_noop, range(m), client=client):
                pass
            out["empty_tasks_per_s"] = m / (time.perf_counter() - t)
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


@contextlib.contextmanager
def _kill_context(stack: contextlib.ExitStack, client):
    """Yield ``client``, then close it and the cluster that ``stack`` holds."""
    with stack:
        try:
            yield client
        finally:
            client.close()


def _child(argv_json: str) -> None:
    """Entry point of the fresh interpreter that :func:`run_fresh` starts."""
    print(json.dumps(measure(**json.loads(argv_json))))


def run_fresh(**kwargs) -> dict:
    """:func:`measure` in a fresh interpreter (its own peak memory); stderr passes through for the progress."""
    from ..compute import WORKER_ENV

    snippet = f"from cvpipe.bench.scale import _child; _child({json.dumps(json.dumps(kwargs))})"
    env = worker_environment()
    if kwargs["mode"] == "serial":
        # serial keeps the libraries' own threads: that is the in-process default users get
        env = {k: v for k, v in env.items() if k not in WORKER_ENV or k in os.environ}
    proc = subprocess.run([sys.executable, "-c", snippet], env=env, stdout=subprocess.PIPE, text=True, check=False)
    if proc.returncode != 0:
        return {"mode": kwargs["mode"], "probes": kwargs["n"], "error": f"exit {proc.returncode}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run(args: argparse.Namespace) -> int:
    from .. import io

    if not args.data:
        raise InputError("no data root: pass --data DIR or set CVPIPE_DATA")
    try:
        sizes = sorted({int(s) for s in args.sizes.split(",") if s.strip()})
    except ValueError as exc:
        raise InputError(f"`--sizes` must be comma-separated integers, got {args.sizes!r}") from exc
    if not sizes or sizes[0] < 1:
        raise InputError(f"`--sizes` must be positive integers, got {args.sizes!r}")
    if args.max_items < 0:
        raise InputError(f"`--max-items` must be >= 0, got {args.max_items}")
    if args.max_items:
        sizes = [s for s in sizes if s <= args.max_items] or [args.max_items]
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    bad = [m for m in modes if m not in MODES]
    if bad or not modes:
        raise InputError(f"`--modes` must be a subset of {', '.join(MODES)}, got {args.modes!r}")
    _load(args.data)  # a missing data root is one line before anything starts
    rows = []
    with (external_cluster(2) if "external2" in modes else contextlib.nullcontext()) as ext:
        for n in sizes:
            for mode in modes:
                rows.append(run_fresh(mode=mode, n=n, data=args.data, seed=args.seed,
                                      address=ext.address if ext else "", overhead_tasks=args.overhead_tasks))
                print(f"  {mode:9} {n:6d} probes done", file=sys.stderr)
    for n in sizes:
        base = next((r for r in rows if r["probes"] == n and r["mode"] == "serial" and "error" not in r), None)
        one = next((r for r in rows if r["probes"] == n and r["mode"] == "local1" and "error" not in r), None)
        digests = {r["digest"] for r in rows if r["probes"] == n and "digest" in r}
        for r in rows:
            if r["probes"] == n and "error" not in r:
                r["speedup_vs_serial"] = r["probes_per_s"] / base["probes_per_s"] if base else None
                r["speedup_vs_local1"] = r["probes_per_s"] / one["probes_per_s"] if one else None
                r["identical_results"] = len(digests) == 1
        ext2 = next((r for r in rows if r["probes"] == n and r["mode"] == "external2" and "error" not in r), None)
        for r in rows:
            if r["probes"] == n and r["mode"] == "kill2" and "error" not in r and "killed_after_s" in r:
                # the rates before and after the kill, and the whole run against the same cluster undisturbed
                r["rate_before_kill"] = (n // 2) / r["killed_after_s"]
                r["rate_after_kill"] = (n - n // 2) / max(r["wall_s"] - r["killed_after_s"], 1e-9)
                r["slowdown_vs_external2"] = r["wall_s"] / ext2["wall_s"] if ext2 else None
    res = {"sizes": sizes, "modes": modes, "cpu_count": os.cpu_count(), "load_average": list(os.getloadavg()),
           "rows": rows}
    if args.out:
        io.save_json(args.out, res)
    if args.json:
        print(io.dumps_json(res))
        return 0
    la = ", ".join(f"{x:.2f}" for x in res["load_average"])
    print(f"defect inspection stream on DeepPCB, {os.cpu_count()} cores, load average after the runs {la}")
    print(f"{'mode':10} {'probes':>6} {'probes/s':>9} {'x serial':>8} {'x local1':>8} {'empty med':>9} "
          f"{'p95 ms':>7} {'empty/s':>8} {'peak MB':>8} {'same':>5} {'err':>4}")
    for r in rows:
        if "error" in r:
            print(f"{r['mode']:10} {r['probes']:6d} failed: {r['error']}")
            continue
        f = lambda k, fmt: format(r[k], fmt) if r.get(k) is not None else "-"  # noqa: E731
        print(f"{r['mode']:10} {r['probes']:6d} {f('probes_per_s', '9.2f')} {f('speedup_vs_serial', '8.2f')} "
              f"{f('speedup_vs_local1', '8.2f')} {f('empty_task_median_ms', '9.2f')} "
              f"{f('empty_task_p95_ms', '7.2f')} {f('empty_tasks_per_s', '8.0f')} {r['peak_rss_mb']:8.0f} "
              f"{'yes' if r['identical_results'] else 'NO':>5} {r['errors']:4d}")
    for r in rows:
        if r.get("rate_before_kill") is not None:
            vs = (f", {r['slowdown_vs_external2']:.2f}x external2's undisturbed run"
                  if r.get("slowdown_vs_external2") else "")
            print(f"kill2 {r['probes']}: one of 2 workers killed after {r['killed_after_s']:.1f} s (half the probes "
                  f"done); {r['rate_before_kill']:.2f} probes/s before, {r['rate_after_kill']:.2f} after; whole run "
                  f"{r['wall_s']:.1f} s{vs}; {r['errors']} failed items (the stream's own), results "
                  f"{'identical' if r['identical_results'] else 'DIFFERENT'}")
    return 0
