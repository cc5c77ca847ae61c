"""The photometric fit (gain and bias) and the misregistration-tolerant difference, in the reference frame."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import EstimationError, InputError
from ..params import DefectDiffParams
from ._util import check_gray, disc

#: the ``defect.diff`` defaults: the one declaration of :func:`fit_gain_bias`'s ``trim``
_DIFF = DefectDiffParams()


@dataclass(frozen=True)
class Difference:
    """Result of :func:`difference`.

    Attributes
    ----------
    diff : (H, W) float32
        Tolerant absolute difference in grey levels of the reference, 0 outside ``valid``.
    valid : (H, W) bool
        Reference pixels that the probe covers (minus a border margin).
    gain, bias : float
        Photometric model ``probe ~= gain * reference + bias`` fitted on the overlap.
    noise : float
        Robust standard deviation of the corrected residual, grey levels.
    contrast : float
        Dynamic range of the reference (99th - 1st percentile), grey levels.
    """

    diff: np.ndarray
    valid: np.ndarray
    gain: float
    bias: float
    noise: float
    contrast: float

    #: the arrays of :meth:`to_arrays` (before their prefix), the keys a cached ``.npz`` must hold for
    #: :meth:`from_arrays`
    ARRAYS = ("diff", "valid", "gain", "bias", "noise", "contrast")

    def to_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Named arrays for ``io.save_npz``, each name prefixed by ``prefix``."""
        return {prefix + k: np.asarray(getattr(self, k)) for k in self.ARRAYS}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], prefix: str = "") -> "Difference":
        """Inverse of :meth:`to_arrays`."""
        return cls(np.asarray(arrays[prefix + "diff"], np.float32), np.asarray(arrays[prefix + "valid"], bool),
                   *(float(arrays[prefix + k]) for k in ("gain", "bias", "noise", "contrast")))

    def photometry(self) -> dict[str, float]:
        """The scalar fields (photometric fit, noise, contrast), for a JSON record."""
        return {k: getattr(self, k) for k in ("gain", "bias", "noise", "contrast")}


def fit_gain_bias(reference: np.ndarray, warped: np.ndarray, valid: np.ndarray, trim: float = _DIFF.fit_trim,
                  iterations: int = 4, max_samples: int = 40_000) -> tuple[float, float, float]:
    """Robust fit of ``warped ~= gain * reference + bias`` over ``valid`` pixels.

    Least squares repeated on the pixels whose residual lies within ``trim`` robust standard deviations (MAD), so
    defects and misregistered edges do not pull the fit. At most about ``max_samples`` pixels on a regular grid
    are used.

    Parameters
    ----------
    reference, warped : (H, W) array
        Grey levels.
    valid : (H, W) bool

    Returns
    -------
    gain, bias, sigma : float
        ``sigma`` is the robust residual standard deviation in grey levels (plus 0.5 for quantisation).

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.tile(np.arange(0, 200, 2, dtype=np.float32), (100, 1))
    >>> gain, bias, sigma = fit_gain_bias(ref, 0.8 * ref + 20, np.ones(ref.shape, bool))
    >>> round(gain, 3), round(bias, 3)
    (0.8, 20.0)
    """
    step = max(1, int(np.sqrt(valid.size / max_samples)))
    v = valid[::step, ::step]
    r = reference[::step, ::step][v].astype(np.float64)
    w = warped[::step, ::step][v].astype(np.float64)
    if len(r) < 100:
        raise EstimationError(f"registration failed: only {int(valid.sum())} overlapping pixels to compare")
    keep = np.ones(len(r), bool)
    gain, bias, sigma = 1.0, 0.0, 0.0
    for _ in range(iterations):
        rk, wk = r[keep], w[keep]
        var = rk.var()
        if var < 1e-6:
            raise EstimationError("the reference is flat over the overlap: nothing to compare")
        gain = float(((rk - rk.mean()) * (wk - wk.mean())).mean() / var)
        bias = float(wk.mean() - gain * rk.mean())
        res = w - (gain * r + bias)
        sigma = float(1.4826 * np.median(np.abs(res - np.median(res)))) + 0.5
        keep = np.abs(res) <= trim * sigma
        if keep.sum() < 100:
            break
    if gain < 0.2:
        raise EstimationError(f"registration failed: the aligned probe has gain {gain:.2f} against the reference "
                              f"(inverted or washed-out image?)")
    return gain, bias, sigma


def difference(reference: np.ndarray, warped: np.ndarray, valid: np.ndarray,
               params: DefectDiffParams | None = None) -> Difference:
    """Misregistration-tolerant difference between the reference and the probe warped onto it.

    The probe is first corrected by the fitted gain and bias. A pixel differs by how far the probe lies outside
    the [min, max] of the reference over a disc of ``tolerance_radius``, or the reference outside the probe's
    [min, max] over that disc, whichever is larger: a shift of up to the radius produces no difference, while
    extra or missing material of any width does.

    Parameters
    ----------
    reference : (H, W) uint8
    warped : (H, W) uint8
        Probe resampled on the reference grid (:func:`warp_to_reference`).
    valid : (H, W) bool
        Reference pixels covered by the probe.
    params : DefectDiffParams, optional

    Examples
    --------
    >>> import cv2, numpy as np
    >>> rng = np.random.default_rng(0)
    >>> ref = cv2.resize((rng.random((16, 16)) > 0.5).astype(np.uint8) * 160 + 50, (160, 160),
    ...                  interpolation=cv2.INTER_NEAREST)
    >>> warped = np.roll(ref, 1, axis=1)  # misregistered by one pixel
    >>> warped[60:70, 60:70] = 0  # and a defect, darker than any reference pixel (50 or 210)
    >>> d = difference(ref, warped, np.ones(ref.shape, bool))
    >>> bool(d.diff[62:68, 62:68].min() > 40), bool(d.diff[:, :50].max() < 1)  # the shift alone leaves ~nothing
    (True, True)
    """
    p = params or DefectDiffParams()
    reference, warped = check_gray("reference", reference), check_gray("warped", warped)
    valid = np.asarray(valid, bool)
    if reference.shape != warped.shape or valid.shape != reference.shape:
        raise InputError(f"`reference`, `warped` and `valid` must have one shape, got {reference.shape}, "
                         f"{warped.shape}, {valid.shape}")
    if p.border_margin > 0:  # also away from the reference's own frame: scans are often ragged at their edges
        valid = cv2.erode(valid.astype(np.uint8), disc(p.border_margin), borderType=cv2.BORDER_CONSTANT,
                          borderValue=0).astype(bool)
    ref = reference.astype(np.float32)
    prb = warped.astype(np.float32)
    if p.smooth_sigma > 0:
        ref = cv2.GaussianBlur(ref, (0, 0), p.smooth_sigma)
        prb = cv2.GaussianBlur(prb, (0, 0), p.smooth_sigma)
    gain, bias, sigma = fit_gain_bias(ref, prb, valid, p.fit_trim)
    prb = (prb - bias) / gain
    if p.tolerance_radius > 0:
        k = disc(p.tolerance_radius)
        ref_lo, ref_hi = cv2.erode(ref, k), cv2.dilate(ref, k)
        prb_lo, prb_hi = cv2.erode(prb, k), cv2.dilate(prb, k)
        d = np.maximum(np.maximum(prb - ref_hi, ref_lo - prb), np.maximum(ref - prb_hi, prb_lo - ref))
    else:
        d = np.abs(prb - ref)
    d = np.maximum(d, 0.0)
    d[~valid] = 0.0
    lo, hi = np.percentile(ref[valid][::7], [1, 99])
    return Difference(d.astype(np.float32), valid, gain, bias, sigma / gain, float(hi - lo))


def difference_item(item: tuple, shared: tuple) -> tuple[dict, dict, float]:
    """The difference map(s) of one registered probe: the per-probe work of the ``defect_diff`` stage, an item of
    :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    item : tuple
        ``(warped, valid, alternative)``: the probe warped onto the reference and its valid mask, and the same
        pair for the direct alternative registration, or None.
    shared : tuple
        ``(reference gray image, DefectDiffParams)``, sent once per worker.

    Returns
    -------
    (arrays, fit, seconds)
        The arrays of the ``<probe>.npz`` (:meth:`Difference.to_arrays`, ``alt_``-prefixed for the alternative),
        the photometric fit record (``primary`` and ``alternative``, or ``alternative_error`` when only the
        alternative could not be compared) and the seconds the differences took.

    Raises
    ------
    EstimationError, InputError
        As :func:`difference`, for the primary registration (the stage drops the probe with the reason).

    Examples
    --------
    >>> import cv2
    >>> from cvpipe.params import DefectDiffParams
    >>> ref = cv2.GaussianBlur(np.random.default_rng(0).integers(0, 255, (96, 96)).astype(np.uint8), (0, 0), 2)
    >>> probe = ref.copy(); probe[40:52, 40:52] = 255   # a bright square where the reference has texture
    >>> arrays, fit, _ = difference_item((probe, np.ones(ref.shape, bool), None), (ref, DefectDiffParams()))
    >>> sorted(arrays), sorted(fit)
    (['bias', 'contrast', 'diff', 'gain', 'noise', 'valid'], ['primary'])
    """
    import time

    warped, valid, alternative = item
    reference, p = shared
    t0 = time.perf_counter()
    d = difference(reference, warped, valid, p)
    arrays, fit = d.to_arrays(), {"primary": d.photometry()}
    if alternative is not None:
        try:
            alt = difference(reference, *alternative, p)
        except EstimationError as exc:  # only a second opinion: the probe goes on without it
            fit["alternative_error"] = str(exc)
        else:
            arrays.update(alt.to_arrays("alt_"))
            fit["alternative"] = alt.photometry()
    return arrays, fit, time.perf_counter() - t0
