"""cvpipe: reproducible classical computer-vision pipelines."""

import os as _os

__version__ = "0.1.0"

# numba's parallel kernels run on its OpenMP threading layer (GNU libgomp), whose threads sleep as soon as a parallel
# region ends (OMP_WAIT_POLICY=PASSIVE): libgomp's default spins for a while after every region, and on a 2-core machine
# that also runs other work the spinning thread competes with the one still working (and slows the OpenCV call that
# follows ours). numba's own workqueue layer also sleeps, but starts a region in 0.3-0.5 ms against OpenMP's 0.06 ms and
# splits the Hough vote of 20,000 edge pixels 1.1x faster on 2 threads where OpenMP does 1.75x (docs/notes/threads.md).
# Defaults only: NUMBA_THREADING_LAYER, NUMBA_THREADING_LAYER_PRIORITY or OMP_WAIT_POLICY set by the user win (numba
# falls back to TBB, then workqueue, where libgomp is missing), and they have no effect if numba or another OpenMP
# program was loaded before cvpipe.
_os.environ.setdefault("NUMBA_THREADING_LAYER_PRIORITY", "omp tbb workqueue")
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
# numpy's OpenBLAS on one thread: cvpipe runs its own work in parallel (numba, OpenCV, thread pools, Dask), and an
# OpenBLAS thread spins for a while after every call, taking a core from that work (in-process stitch on the
# samples' motorcycle set 132 -> 100 ms, its features 89 -> 62 ms; docs/notes/threads.md). Like the lines above, a
# default that the user's setting overrides and that has no effect if numpy was imported before cvpipe.
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
