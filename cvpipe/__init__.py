"""cvpipe: reproducible classical computer-vision pipelines."""

import os as _os

__version__ = "0.1.0"

# The compiled kernels' parallel loops run on OpenMP (GNU libgomp), whose threads sleep as soon as a parallel region
# ends (OMP_WAIT_POLICY=PASSIVE): libgomp's default spins for a while after every region, and on a 2-core machine that
# also runs other work the spinning thread competes with the one still working (and slows the OpenCV call that follows
# ours; docs/notes/threads.md). A default only: OMP_WAIT_POLICY set by the user wins, and it has no effect if another
# OpenMP program was loaded before cvpipe.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
# numpy's OpenBLAS on one thread: cvpipe runs its own work in parallel (OpenMP, OpenCV, thread pools, Dask), and an
# OpenBLAS thread spins for a while after every call, taking a core from that work (in-process stitch on the
# samples' motorcycle set 132 -> 100 ms, its features 89 -> 62 ms; docs/notes/threads.md). Like the lines above, a
# default that the user's setting overrides and that has no effect if numpy was imported before cvpipe.
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
