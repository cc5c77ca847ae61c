"""The DVC stage scripts: one short function each, run by stages._runner (see its docstring).

Importing this package pins the code paths that libraries choose per CPU at run time and that change results, so
that every x86-64 machine with AVX2 writes the same bytes (``python -m stages.<name>`` imports it before anything
else, so before numpy and OpenCV read these variables; Dask workers started by a stage inherit them). Each level is
the highest one that every such machine has (AVX2 and FMA, x86-64-v3):

- ``OPENBLAS_CORETYPE=Haswell``: numpy's OpenBLAS picks its kernels per CPU, and the SVDs, eigen-decompositions and
  inverses of the estimators differ in their last bits between them (measured: SkylakeX and Haswell kernels give
  different results on the same input);
- ``OPENCV_CPU_DISABLE``: OpenCV's dispatched code stops at AVX2 (its SIFT output changes with the dispatched path);
  only the levels above AVX2 that the CPU has are named (OpenCV warns about the others on every start);
- ``OPENCV_IPP=disabled``: no Intel IPP inside OpenCV. IPP picks its code per CPU and per level (filters, resizing,
  warps, and so SIFT's pyramid): ``OPENCV_IPP`` AVX2, SSE42 and ``disabled`` give three different SIFT outputs on one
  machine, and IPP is known to take other code paths on non-Intel CPUs, so no level of it is the same on Intel and
  AMD. Off, OpenCV runs its own dispatched code, pinned by the line above (measured: SIFT, resizes and warps of ten
  sample photos 5 % slower than with IPP's AVX2 code);
- ``NPY_DISABLE_CPU_FEATURES``: numpy's AVX-512 loops are off (measured: ``np.argsort`` orders ties differently and
  ``np.arctan2`` differs in the last bit between its AVX-512 and AVX2 loops). Names a numpy build does not dispatch
  are ignored by it with an ImportWarning, hidden by default; features the machine lacks are ignored silently.

cvpipe's own kernels need no pin: they are compiled once, for x86-64-v3, without fast-math and without contraction
into FMA (meson.build), so every such CPU runs the same instructions on the same data.
"""

import os

#: OpenCV's dispatch levels above AVX2 and the /proc/cpuinfo flags each needs
_OPENCV_ABOVE_AVX2 = {
    "AVX512F": ("avx512f",),
    "AVX512-SKX": ("avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"),
    "AVX512-CLX": ("avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl", "avx512_vnni"),
    "AVX_VNNI": ("avx_vnni",),
}


def _opencv_disable() -> str:
    """The levels of ``_OPENCV_ABOVE_AVX2`` that this CPU has: OpenCV prints a warning on every start for a level
    it is asked to disable and the CPU lacks. Where /proc/cpuinfo cannot tell (not Linux), all of them."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            flags = next((set(line.split(":", 1)[1].split()) for line in f if line.startswith("flags")), None)
    except OSError:
        flags = None
    if flags is None:
        return ",".join(_OPENCV_ABOVE_AVX2)
    return ",".join(name for name, need in _OPENCV_ABOVE_AVX2.items() if flags.issuperset(need))


#: environment variables set for every stage (see the module docstring)
PINNED_ENV = {
    "OPENBLAS_CORETYPE": "Haswell",
    "OPENCV_CPU_DISABLE": _opencv_disable(),
    "OPENCV_IPP": "disabled",
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR AVX512F AVX512_SKX",
}

os.environ.update(PINNED_ENV)
# OpenCV logs a warning on every start when OPENCV_IPP turns IPP off; its errors still raise. A default only.
os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
