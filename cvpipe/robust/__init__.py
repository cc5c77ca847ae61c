"""The robust-estimation core: what every RANSAC estimator of cvpipe shares, written once.

A robust estimator here is a *recipe*: a model (its minimal solver, its residual and its refit) over these parts:

- :mod:`~cvpipe.robust.state`: the search state of one run, a record with named fields (:data:`STATE`,
  :func:`new_state`) that the driver creates and the kernels update in place;
- :mod:`~cvpipe.robust.sampling`: minimal samples of distinct indices from uniforms (:func:`sample_distinct`,
  :func:`sample4`, :func:`draw_samples`), exact sampling without replacement, so a seeded generator reproduces a run;
- :mod:`~cvpipe.robust.stopping`: the adaptive iteration bound (:func:`iterations_needed`) and Wald's sequential
  probability ratio test that drops a bad hypothesis after a few dozen points (:func:`sprt_threshold`, and the
  updates of its parameters from the rejected and the accepted models, :func:`on_rejected`, :func:`on_new_best`);
- :mod:`~cvpipe.robust.loop`: the driver (:func:`run`) that draws uniforms chunk by chunk and hands them to the
  recipe's step until the bound is met or the attempts are spent;
- :mod:`~cvpipe.robust.significance`: the a-contrario test against chance (:func:`log10_nfa`).

The recipes: :func:`cvpipe.homography.find_homography` (4-point samples, SPRT, local optimization),
:func:`cvpipe.stereo.find_fundamental` (7-point samples in batches) and :func:`cvpipe.logo.affine_ransac`
(3-point samples scored all at once). The steps are inline C in ``_core.pxd`` (the ``State`` struct, the samplers,
the stopping rules) that the recipes' compiled kernels cimport, and ``_search`` exposes to Python; each recipe writes
its short per-hypothesis loop itself, out of these steps, so that its own solver and residual inline into it.
"""

from .loop import run
from .sampling import draw_samples, sample4, sample_distinct
from .significance import log10_nfa
from .state import STATE, new_state
from .stopping import iterations_needed, on_new_best, on_rejected, sprt_threshold

__all__ = ["STATE", "draw_samples", "iterations_needed", "log10_nfa", "new_state", "on_new_best", "on_rejected", "run",
           "sample4", "sample_distinct", "sprt_threshold"]
