"""The driver of a RANSAC run: uniforms chunk by chunk to the recipe's step, until the bound is met."""

from __future__ import annotations

from typing import Callable

import numpy as np


def run(step: Callable[[np.ndarray], int], gen: np.random.Generator, sample_size: int, state: np.ndarray, *,
        max_iters: int, first_chunk: int, largest_chunk: int, min_iterations: int = 0) -> None:
    """Draw ``(rows, sample_size)`` uniforms from ``gen`` and hand them to ``step`` until the state's ``iterations``
    reach its ``bound`` (and at least ``min_iterations``) or the samples drawn reach ``10 * max_iters + 100`` (so a
    run whose samples are all degenerate ends).

    Parameters
    ----------
    step : callable
        ``step(u) -> rows used``: runs the hypotheses of the uniforms ``u`` (one sample per row), updating ``state``
        (its ``iterations``, ``bound``, the best model it keeps); it may stop before the last row once the bound is
        met.
    gen : numpy.random.Generator
        The run's generator: a seeded one reproduces the run.
    sample_size : int
        Indices per minimal sample.
    state : (1,) array of :data:`cvpipe.robust.STATE`
        The run's state (:func:`cvpipe.robust.new_state`); ``attempts`` counts the rows used.
    max_iters : int
        The cap of the bound.
    first_chunk, largest_chunk : int
        Rows of the first chunk; each next chunk is twice as many, at most ``largest_chunk``.
    min_iterations : int
        Fewest regular hypotheses, whatever the bound says.
    """
    max_attempts = 10 * int(max_iters) + 100
    chunk, attempts = int(first_chunk), 0
    iterations, bound = state["iterations"][0], state["bound"][0]
    while (iterations < bound or iterations < min_iterations) and attempts < max_attempts:
        attempts += step(gen.random((min(chunk, max_attempts - attempts), sample_size)))
        chunk = min(2 * chunk, int(largest_chunk))
        iterations, bound = state["iterations"][0], state["bound"][0]
    state["attempts"] = attempts
