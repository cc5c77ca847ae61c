"""The DVC stage scripts: one short function each, run by stages._runner (see its docstring).

Importing this package pins the code paths that libraries choose per CPU at run time and that change results, so
that every x86-64 machine with AVX2 writes the same bytes (``python -m stages.<name>`` imports it before anything
else, so before numpy and OpenCV read these variables; Dask workers started by a stage inherit them):

- ``OPENBLAS_CORETYPE=Haswell``: numpy's OpenBLAS picks its kernels per CPU, and the SVDs, eigen-decompositions and
  inverses of the estimators differ in their last bits between them (measured: SkylakeX and Haswell kernels give
  different results on the same input);
- ``OPENCV_CPU_DISABLE=AVX512F,AVX512-SKX``: OpenCV's dispatched code stops at AVX2, which every such machine has
  (its SIFT output changes with the dispatched path).

numba's kernels are compiled for the host CPU but without fast-math, so their results do not depend on it (measured
with ``NUMBA_CPU_NAME`` haswell, skylake-avx512 and the host: the same bytes); they are not pinned.
"""

import os

#: environment variables set for every stage (see the module docstring)
PINNED_ENV = {"OPENBLAS_CORETYPE": "Haswell", "OPENCV_CPU_DISABLE": "AVX512F,AVX512-SKX"}

os.environ.update(PINNED_ENV)
