"""cvpipe: reproducible classical computer-vision pipelines."""

import os as _os

__version__ = "0.1.0"

# numba's OpenMP threading layer busy-waits at the end of every parallel region. Our kernels are many short parallel
# regions, and on a 2-core machine that also runs other work the waiting thread competes with the one still working:
# stereo on tsukuba took 89 ms with OpenMP and 58 ms with numba's own workqueue layer (which sleeps instead) in the
# same conditions. A default only: NUMBA_THREADING_LAYER set by the user wins, and it has no effect if numba was
# imported before cvpipe.
_os.environ.setdefault("NUMBA_THREADING_LAYER", "workqueue")
