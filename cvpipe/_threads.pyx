# cython: language_level=3
"""The OpenMP thread count of the compiled kernels (``prange`` regions): read and set from Python.

OpenMP reads ``OMP_NUM_THREADS`` when it starts (the Dask workers of :mod:`cvpipe.compute` get 1); the default is
one thread per core. :func:`set_max_threads` changes the count for regions that the calling thread starts later.
"""

cimport openmp


def max_threads() -> int:
    """The number of threads a compiled kernel's parallel region uses when started from this thread."""
    return openmp.omp_get_max_threads()


def set_max_threads(int n) -> None:
    """Use ``n`` (>= 1) threads in the parallel regions that this thread starts from now on."""
    if n < 1:
        raise ValueError(f"`n` must be >= 1, got {n}")
    openmp.omp_set_num_threads(n)
