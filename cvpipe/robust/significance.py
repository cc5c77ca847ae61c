"""The a-contrario test of a model against chance (Moisan & Stival's ORSA)."""

from __future__ import annotations

import math


def log10_nfa(inliers: int, matches: int, p: float, sample_size: int = 4) -> float:
    """``log10`` of the number of false alarms of a model with ``inliers`` among ``matches``.

    A model is fixed by ``s = sample_size`` matches and there are ``C(n, s)`` of them; under the null hypothesis each
    of the other ``n - s`` matches agrees with it by chance with probability ``p``, so (ORSA, Moisan & Stival 2004,
    with the binomial tail instead of its bound) ``NFA = C(n, s) P[Binomial(n - s, p) >= k - s]``.

    Parameters
    ----------
    inliers, matches : int
        Inlier count ``k`` and number of putative matches ``n``.
    p : float
        Chance that an unrelated match is an inlier.
    sample_size : int
        Matches that fix a model (4 for a homography).

    Returns
    -------
    float
        ``log10 NFA``; a model is significant when it is below ``log10`` of the accepted number of false alarms
        (0 for one). ``inf`` for fewer than ``sample_size`` of either; ``-inf`` for more inliers than matches.

    Examples
    --------
    >>> from cvpipe.robust import log10_nfa
    >>> log10_nfa(40, 100, 0.01) < 0 < log10_nfa(6, 100, 0.01)  # 40 of 100 agree: no chance; 6: chance
    True
    """
    from scipy.special import bdtrc  # imported here: most commands never test significance

    # math.lgamma: on Python ints several times faster than scipy's gammaln ufunc, to the same few ulps
    n, k, s = int(matches), int(inliers), int(sample_size)
    if n < s or k < s:
        return float("inf")
    p = min(max(float(p), 0.0), 1.0)
    log_models = (math.lgamma(n + 1) - math.lgamma(s + 1) - math.lgamma(n - s + 1)) / math.log(10)
    if k == s or p >= 1.0:
        return float(log_models)
    j = k - s
    if p <= 0.0 or k > n:  # no chance model agrees with more matches than there are
        return float("-inf")
    tail = float(bdtrc(j - 1, n - s, p))  # P[X > j - 1] = P[X >= j]
    if tail <= 0.0:  # underflow: the first term of the tail bounds it from below and stays finite in logs
        tail_log = (math.lgamma(n - s + 1) - math.lgamma(j + 1) - math.lgamma(n - s + 1 - j) + j * math.log(p)
                    + (n - s - j) * math.log1p(-p)) / math.log(10)
        return float(log_models + tail_log)
    return float(log_models + math.log10(tail))
