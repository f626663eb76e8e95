"""Comparison metrics: percentage difference, Minkowski distance (Eq. 9), mixing RMS."""

from __future__ import annotations

import numpy as np

from cfbmarkov.errors import InputError


#: a reference within this fraction of its scale is zero to round-off: its PD is undefined
ROUNDOFF = 1e-9


def percentage_difference(model, reference, scale=None):
    """Percentage difference PD = 100 (model - reference) / reference, in %.

    Parameters
    ----------
    model : float or array_like
        The model's value(s), e.g. E(RT) or SD(RT) of a prediction, in any unit (s for
        residence times).
    reference : float or array_like
        The reference value(s) (e.g. the CFD-DEM), in the same unit; broadcast against
        ``model``.
    scale : float or array_like, optional
        The magnitude against which a reference counts as zero: where |reference| <=
        ``ROUNDOFF`` x |scale| the reference is zero to round-off and the PD is undefined
        (NaN). For SD(RT) pass E(RT): residence times that are all equal give an SD of
        about 1e-16 s, whose PD would be a number made of round-off. Default: only an exact
        zero is undefined.

    Returns
    -------
    float or numpy.ndarray
        PD in %; a float for scalar inputs, an array of the broadcast shape otherwise. NaN
        where the reference is zero (to round-off) or NaN; ``summary.json`` writes it as
        null and the report's tables as "n/d".

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Table 3;
    ``docs/definitions.md`` (Metrics, Percentage difference).
    """
    m = np.asarray(model, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    limit = 0.0 if scale is None else ROUNDOFF * np.abs(np.asarray(scale, dtype=np.float64))
    defined = np.abs(r) > limit
    with np.errstate(divide="ignore", invalid="ignore"):
        pd = np.where(defined, 100.0 * (m - r) / np.where(defined, r, 1.0), np.nan)
    return float(pd) if pd.ndim == 0 else pd


def percentage_text(value, spec: str = "+.2f") -> str:
    """A PD as text: formatted with ``spec``, or "n/d" where it is undefined (None or NaN).

    Parameters
    ----------
    value : float or None
        The PD (%).
    spec : str
        A format spec.

    Returns
    -------
    str
    """
    if value is None or not np.isfinite(value):
        return "n/d"
    return f"{value:{spec}}"


def minkowski_distance(e, f, order: float = 2.0) -> float:
    """Minkowski distance MD = (sum_j |e_j - f_j|^k)^(1/k) of two equally long arrays (Eq. 9).

    Parameters
    ----------
    e, f : array_like
        The two arrays, flattened; of equal size. For RTDs: probability per bin on shared
        bins, shape (B,).
    order : float, optional
        The order k >= 1 (below 1 the sum is not a distance); ``numpy.inf`` gives the
        largest absolute difference.

    Returns
    -------
    float
        The distance, in the unit of ``e`` and ``f`` (0 for empty arrays).

    Raises
    ------
    InputError
        When ``e`` and ``f`` differ in size, or ``order`` is below 1 (or NaN).

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Eq. 9;
    ``docs/definitions.md`` (Metrics, Minkowski distance).
    """
    e = np.asarray(e, dtype=np.float64).reshape(-1)
    f = np.asarray(f, dtype=np.float64).reshape(-1)
    if e.shape != f.shape:
        raise InputError(f"Minkowski distance of arrays of different lengths ({e.size} and {f.size})")
    if not order >= 1:   # NaN fails too; inf is the largest difference
        raise InputError(f"Minkowski order {order:g} must be a finite number >= 1 (or inf, "
                         "the largest difference): below 1 the sum is not a distance")
    d = np.abs(e - f)
    if d.size == 0:
        return 0.0
    scale = float(d.max())
    if np.isinf(order) or scale == 0.0 or not np.isfinite(scale):
        return scale
    # scaled by the largest difference before powering, so that a large order (1000) does
    # not underflow every term to 0: MD = max|d| (sum (|d| / max|d|)^k)^(1/k)
    return scale * float(np.sum((d / scale) ** order) ** (1.0 / order))


def mixing_rms(ref_times, ref_fraction, model_times, model_fraction, weights=None,
               frames: bool = False):
    """RMS difference of two mixing curves on the model's frames (a fraction).

    The reference is evaluated at the model's frame times by linear interpolation; the
    model's times must lie inside the reference's range (to round-off). With ``weights``
    each frame's squared difference is weighted (an open riser's: the tracers still
    present, whose sampling noise in the curve falls as one over their count).

    Parameters
    ----------
    ref_times : array_like, shape (T_ref,)
        Frame times of the reference curve, s, strictly increasing.
    ref_fraction : array_like, shape (T_ref,)
        The reference mixing curve (fraction of all particles, -).
    model_times : array_like, shape (T,)
        Frame times of the model curve, s.
    model_fraction : array_like, shape (T,)
        The model mixing curve (fraction of all particles, -).
    weights : array_like, shape (T,), optional
        Non-negative weight of each of the model's frames (default equal weights).
    frames : bool, optional
        Also return how many of the model's frames were compared.

    Returns
    -------
    float
        sqrt(mean((model - reference)^2)) over the model's frames, weighted where
        ``weights`` are given (sum w d^2 / sum w), a fraction of all particles; frames
        where a curve is NaN (an open riser whose tracers have all left) or whose weight
        is 0 are skipped, and NaN is returned when none is left to compare.
    int
        With ``frames``: the frames compared.

    Raises
    ------
    InputError
        When times and fractions of a curve differ in length, a curve is empty, the
        reference times do not increase, or the model's times leave the reference's range.

    References
    ----------
    ``docs/definitions.md`` (Metrics, Mixing RMS); the paper's Fig. 11.
    """
    rt = np.asarray(ref_times, dtype=np.float64).reshape(-1)
    rf = np.asarray(ref_fraction, dtype=np.float64).reshape(-1)
    mt = np.asarray(model_times, dtype=np.float64).reshape(-1)
    mf = np.asarray(model_fraction, dtype=np.float64).reshape(-1)
    if rt.size != rf.size or mt.size != mf.size:
        raise InputError("mixing curve times and fractions differ in length")
    if rt.size == 0 or mt.size == 0:
        raise InputError("mixing RMS of an empty curve")
    w = (np.ones(mt.size) if weights is None
         else np.asarray(weights, dtype=np.float64).reshape(-1))
    if w.size != mt.size or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InputError("mixing RMS weights must be finite, non-negative, one per model frame")
    if np.any(np.diff(rt) <= 0):
        raise InputError("reference mixing curve times do not increase")
    span = max(rt[-1] - rt[0], abs(rt[-1]), 1.0)
    tol = 1e-9 * span
    if rt.size > 1:
        tol = max(tol, 1e-6 * float(np.min(np.diff(rt))))
    if mt.min() < rt[0] - tol or mt.max() > rt[-1] + tol:
        raise InputError(f"model frames {mt.min():g} to {mt.max():g} s leave the reference's "
                         f"{rt[0]:g} to {rt[-1]:g} s")
    at = np.clip(mt, rt[0], rt[-1])
    # a model time within round-off of a reference frame is that frame (2.2800000000000002
    # for 2.28): interpolated beside the frame where a curve's tracers are last seen, an
    # open riser's frame was dropped
    above = np.clip(np.searchsorted(rt, at), 0, rt.size - 1)
    below = np.clip(above - 1, 0, rt.size - 1)
    nearest = np.where(np.abs(rt[above] - at) < np.abs(rt[below] - at), above, below)
    at = np.where(np.abs(rt[nearest] - at) <= tol, rt[nearest], at)
    finite = np.isfinite(rf)
    if weights is None and finite.all() and np.isfinite(mf).all():
        rms = float(np.sqrt(np.mean((mf - np.interp(at, rt, rf)) ** 2)))
        return (rms, int(mt.size)) if frames else rms
    # an open riser: a curve is NaN where none of its tracers is left; only frames where
    # both are defined (the reference on both sides of the time) are compared
    ok = np.isfinite(mf) & (np.interp(at, rt, finite.astype(np.float64)) == 1.0) & (w > 0)
    if not ok.any():
        return (float("nan"), 0) if frames else float("nan")
    ref_at_model = np.interp(at[ok], rt[finite], rf[finite])
    rms = float(np.sqrt(np.average((mf[ok] - ref_at_model) ** 2, weights=w[ok])))
    return (rms, int(ok.sum())) if frames else rms


def rtd_span(probability, tail: float = 0.01) -> int:
    """How many bins an RTD spans: from the bin holding its ``tail`` quantile to the bin
    holding its 1 - ``tail`` quantile, both included (a stray residence in a far bin does
    not widen it).

    Parameters
    ----------
    probability : array_like, shape (B,)
        Probability per bin (:func:`cfbmarkov.observed.residence.rtd_histogram`).
    tail : float, optional
        The share of residences left out at each end.

    Returns
    -------
    int
        Bins spanned; 0 when the RTD holds no residence.
    """
    p = np.asarray(probability, dtype=np.float64).reshape(-1)
    total = p.sum()
    if not total > 0:
        return 0
    cumulative = np.cumsum(p) / total
    first = int(np.searchsorted(cumulative, tail - 1e-12, side="left"))
    last = int(np.searchsorted(cumulative, 1.0 - tail - 1e-12, side="left"))
    return max(1, min(last, p.size - 1) - first + 1)


__all__ = ["ROUNDOFF", "minkowski_distance", "mixing_rms", "percentage_difference",
           "percentage_text", "rtd_span"]
