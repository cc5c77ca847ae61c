"""Compile, and cache on disk, the numba kernels of every task: ``python tests/compile_kernels.py``.

The test session runs this once before its first test (``tests/conftest.py``): a command run on a cold numba cache
says "compiling the <task> kernels once" on stderr, and the tests that read stderr line by line would see that note
or not depending on which test happened to run first. The tests of the note itself use a cache folder of their own.

numba keys a cached kernel on its own file: a kernel that calls a kernel of another file keeps the callee's old
machine code after the callee's file changes. So the cached kernels of the package are dropped first whenever any of
its modules that use numba changed since they were compiled (a digest of the sources is kept beside them).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

PACKAGE = Path(__file__).resolve().parents[1] / "cvpipe"


def sources_digest() -> str:
    """sha1 of the package's modules that mention numba (those that use it, and a few that only say its name), paths
    and contents, in a fixed order: an edit elsewhere cannot change a compiled kernel."""
    h = hashlib.sha1()
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"numba" in text:
            h.update(str(path.relative_to(PACKAGE)).encode() + b"\0" + text + b"\0")
    return h.hexdigest()


def _stamp() -> Path:
    """The file beside the package's cached kernels that holds the digest they were compiled from."""
    from cvpipe.commands import kernel_cache_folder

    return Path(kernel_cache_folder(str(PACKAGE))) / "sources.sha1"


def drop_stale_kernels(digest: str) -> int:
    """Delete the package's cached kernels unless they were compiled from sources with ``digest``; the files
    deleted."""
    from cvpipe.commands import kernel_cache_folder

    folders = sorted({str(p.parent) for p in PACKAGE.rglob("*.py")})
    stamp = _stamp()
    if stamp.is_file() and stamp.read_text().strip() == digest:
        return 0
    dropped = 0
    for folder in folders:
        cache = Path(kernel_cache_folder(folder))
        if cache.is_dir():
            for f in list(cache.glob("*.nbi")) + list(cache.glob("*.nbc")):
                f.unlink()
                dropped += 1
    return dropped


def write_stamp(digest: str) -> None:
    stamp = _stamp()
    stamp.parent.mkdir(parents=True, exist_ok=True)
    stamp.write_text(digest + "\n")


def compile_all() -> None:
    """Run each kernel module once on small synthetic inputs (the results are not used)."""
    from cvpipe import hough, stereo
    from cvpipe.errors import EstimationError
    from cvpipe.homography import find_homography
    from cvpipe.linalg import solve_spd
    from cvpipe.panorama.crop import largest_rectangle

    rng = np.random.default_rng(0)
    edges = np.zeros((120, 160), np.uint8)
    edges[60, :] = 255
    edges[:, 40] = 255
    for parallel in (False, True):  # the command votes on one thread or on all, by the load average
        hough.hough_lines(edges, 1.0, np.pi / 180, 50, parallel=parallel)
    hough.hough_lines(edges, 1.0, np.pi / 180, 50, refine=True)
    hough.hough_lines_probabilistic(edges)

    src = rng.uniform(0, 500, (60, 2))
    H = np.array([[1.1, 0.02, 5.0], [-0.03, 0.95, -2.0], [1e-4, 2e-4, 1.0]])
    q = np.c_[src, np.ones(len(src))] @ H.T
    find_homography(src, q[:, :2] / q[:, 2:], rng=0)

    X = np.c_[rng.uniform(-2, 2, (80, 2)), rng.uniform(4, 8, 80)]  # points in front of two cameras 0.5 apart
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    x1, x2 = X @ K.T, (X - [0.5, 0.0, 0.0]) @ K.T
    try:
        stereo.find_fundamental(x1[:, :2] / x1[:, 2:], x2[:, :2] / x2[:, 2:], rng=0)
    except EstimationError:  # only the compiling matters
        pass
    left = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    stereo.disparity_sgm(left, np.roll(left, -4, axis=1), 16)

    largest_rectangle(np.ones((20, 30), bool))
    solve_spd(np.array([[4.0, 2.0], [2.0, 3.0]]), np.array([2.0, 1.0]))


if __name__ == "__main__":
    before = sources_digest()
    drop_stale_kernels(before)
    compile_all()
    write_stamp(before)
