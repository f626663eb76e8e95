"""Intervals of a prediction's residence-time figures and mixing curve
(``docs/definitions.md``, Intervals).

Two sources of uncertainty are combined:

- *the model's*: a block bootstrap over time blocks of the fitting window
  (:func:`block_bootstrap_models`). The window's transitions are counted in B contiguous
  blocks; a resample draws B blocks with replacement, sums their counts and forms a model
  (the same estimator and state space), whose exact RTD in the analysis window gives
  E(RT), SD(RT) and the probability per RTD bin, and whose expected mixing curve from the
  tracers' states at the window start (:func:`cfbmarkov.analysis.mixing.model_mixing_curve`)
  gives the mixing curve's. Resampling whole blocks keeps the correlation between
  consecutive transitions and carries the window's non-stationarity (a surge in one block)
  into the spread, which a multinomial (Bayesian counts) model of independent transitions
  would not;
- *the Monte Carlo's*: the prediction's own sampling noise, the standard error of its
  mean (SD / sqrt(n)), of its SD (SD / sqrt(2 (n - 1))), of a bin probability
  (sqrt(p (1 - p) / n)) and of the mixing curve (exact for the fitted model and the
  tracers' states, :func:`~cfbmarkov.analysis.mixing.model_mixing_curve`), normal
  approximation.

The interval at level L is centred on the prediction's value: its lower (upper) half-width is
the distance from the fitted model's exact value to the bootstrap's (1 - L)/2 ((1 + L)/2)
quantile and z_(1+L)/2 times the Monte Carlo standard error, added in quadrature (for the
mixing curve, frame by frame).

References
----------
B. Efron and R. J. Tibshirani, An Introduction to the Bootstrap, Chapman & Hall (1993),
Ch. 8 (the moving-block bootstrap for dependent data) and Ch. 13 (percentile intervals).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

from cfbmarkov.analysis.mixing import model_mixing_curve
from cfbmarkov.analysis.rtd import rtd_histogram
from cfbmarkov.errors import CfbmarkovError, InputError


def _resampled_rtd(model, window_length: float, direction: str, entry):
    """A resampled model's RTD in the window, from the fitted model's entry distribution
    (one sparse LU per resample saved: the spread of the entry distribution is left out,
    that of the transitions kept)."""
    if model.boundary == "open" or entry is None:
        return model.rtd(window_length, direction)
    from cfbmarkov.markov.rtd import exact_rtd

    up, down = ((model.up_fraction, model.down_fraction) if direction == "up"
                else (model.down_fraction, model.up_fraction))
    steps = max(2, int(round(window_length / model.lag)))
    return exact_rtd(model.transition_matrix, up, down, model.lag, max_steps=steps,
                     entry=entry).in_window(window_length)


def _binned(rtd, edges: np.ndarray) -> np.ndarray:
    """An exact RTD's probability per bin of ``edges``, with the sample histogram's rule
    for times on an edge (whole lags on bins of one lag fall in the bin they start)."""
    width = float(edges[1] - edges[0])
    hist, _ = np.histogram(rtd.times + 1e-6 * width, bins=edges,
                           weights=rtd.probability / rtd.probability.sum())
    return hist


def block_bootstrap_models(model, *, blocks: int = 10, resamples: int = 100, seed: int = 0):
    """Models fitted on block-bootstrap resamples of a model's fitting window.

    The fitting window (re-read from the model's source file) is cut into ``blocks``
    contiguous time blocks and the transitions of each counted (with the model's
    estimator's rule); the frame pairs (t, t + lag) are split by their first frame, so
    that every pair of the window is counted in exactly one block. Each resample draws
    ``blocks`` blocks with replacement, sums their counts and forms a model with the same
    estimator, state space and lag. The data are read and counted once; each resample costs
    one estimate.

    Parameters
    ----------
    model : cfbmarkov.markov.MarkovModel
        The fitted model; its ``source`` (one trajectory file) and ``window`` are re-read.
    blocks : int, optional
        Time blocks B of the fitting window (at least 2).
    resamples : int, optional
        Resamples drawn (at least 1).
    seed : int, optional
        Seed of the resampling.

    Returns
    -------
    iterator of cfbmarkov.markov.MarkovModel
        One model per resample whose counts form a model (a resample that does not, e.g. an
        open riser's without any entry, is skipped), formed as the iterator is consumed, in
        the order drawn; fewer than ``resamples`` where some were skipped.

    Raises
    ------
    InputError
        On the call (not on iteration): for too few blocks or resamples, a model without
        one source file and a window, or a fitting window with fewer frame pairs one lag
        apart than blocks.

    References
    ----------
    B. Efron and R. J. Tibshirani, An Introduction to the Bootstrap, Chapman & Hall (1993),
    Ch. 8.6 (the moving-block bootstrap; here non-overlapping blocks).
    """
    from cfbmarkov.markov.discrete import discretize
    from cfbmarkov.markov.estimate import count_transitions, estimator_from_name

    if int(blocks) < 2 or int(resamples) < 1:
        raise InputError(f"a block bootstrap needs at least 2 blocks and 1 resample ({blocks}, "
                         f"{resamples})")
    if not isinstance(model.source, str) or model.window is None:
        raise InputError("intervals need the model's fitting data (one source file and a window)")
    blocks = int(blocks)
    discrete = discretize(model.source, model.state_space, model.lag, model.window)
    # the frame pairs (t, t + lag) are split, by their first frame, into contiguous blocks:
    # each pair is counted in exactly one block, none across a block's edge is lost
    lag_frames = int(discrete.lag_frames)
    pairs = discrete.times.size - lag_frames
    if pairs < blocks:
        raise InputError(f"the fitting window holds {max(pairs, 0)} frame pairs one lag apart, "
                         f"fewer than the {blocks} bootstrap blocks")
    cuts = np.rint(np.linspace(0, pairs, blocks + 1)).astype(np.int64)
    times = discrete.times
    frame_average = model.estimator == "paper"
    counts = [count_transitions(discrete.block(float(times[a]), float(times[b - 1 + lag_frames])),
                                frame_average=frame_average)
              for a, b in zip(cuts[:-1], cuts[1:])]
    estimator = estimator_from_name(model.estimator, model.state_space, model.lag,
                                    connected=model.connected)
    rng = np.random.default_rng(seed)

    def draw():
        for _ in range(int(resamples)):
            picked = rng.integers(0, blocks, blocks)
            total = counts[picked[0]]
            for k in picked[1:]:
                total = total + counts[k]
            try:
                resampled = estimator.fit_counts(total)
            except (CfbmarkovError, ValueError):
                continue                 # counts that form no model: no figure
            yield resampled

    return draw()


@dataclass(frozen=True)
class PredictionIntervals:
    """Intervals of E(RT), SD(RT), the RTD per bin and the mixing curve at ``level``.

    Attributes
    ----------
    level : float
        Coverage of the intervals (e.g. 0.9).
    rt_mean, rt_sd : (float, float)
        Intervals (s).
    rtd : ndarray of float64, shape (2, B)
        Lower and upper probability per bin.
    resamples : int
        Bootstrap resamples that gave a model with residences.
    blocks : int
        Time blocks of the fitting window.
    mixing_times : ndarray of float64, shape (T,), or None
        Frame times of the prediction's mixing curve (s); None where the tracers' states
        were not given.
    mixing : ndarray of float64, shape (2, T), or None
        Lower and upper bound of the mixing curve at each of those frames (fraction of all
        particles; of the tracers present in an open riser), NaN where the curve is
        undefined.
    """

    level: float
    rt_mean: tuple[float, float]
    rt_sd: tuple[float, float]
    rtd: np.ndarray
    resamples: int
    blocks: int
    mixing_times: np.ndarray | None = None
    mixing: np.ndarray | None = None


#: replicate Monte Carlo runs that measure a coherent model's Monte Carlo noise
REPLICATES = 20


def _replicate_noise(model, states, left_group, n_steps: int, edges: np.ndarray,
                     window_length: float, direction: str, lags, seed: int):
    """Standard deviations over replicate Monte Carlo runs (from ``states``) of E(RT),
    SD(RT), the RTD per bin and the mixing curve at ``lags`` (None without them): the
    Monte Carlo noise of a model whose particles move coherently, which the formulas for
    independent samples underestimate."""
    from cfbmarkov.analysis.mixing import _left_states
    from cfbmarkov.analysis.rtd import residence_times_from_laps

    sign = 1 if direction == "up" else -1
    times = model.lag * np.arange(n_steps + 1)
    in_left = _left_states(model.state_space) > 0 if lags is not None else None
    left = np.asarray(left_group, dtype=bool) if left_group is not None else None
    figures, curves = [], []
    for r in range(REPLICATES):
        run_states, laps = model.monte_carlo(states, n_steps, seed=seed + 7919 * (r + 1))
        samples = residence_times_from_laps(times, sign * laps.astype(np.int64))
        if samples.size < 2:
            continue
        _, hist = rtd_histogram(samples, float(edges[1] - edges[0]), window_length=float(edges[-1]))
        figures.append(np.concatenate([[samples.mean(), samples.std(ddof=1)], hist]))
        if lags is not None:
            curves.append((in_left[run_states[lags]] & left).sum(axis=1) / states.size)
    if len(figures) < REPLICATES // 2:
        raise InputError("intervals: too few replicate Monte Carlo runs of the coherent model "
                         "had residences")
    spread = np.std(np.asarray(figures), axis=0, ddof=1)
    curve = np.std(np.asarray(curves), axis=0, ddof=1) if curves else None
    return spread[0], spread[1], spread[2:], curve


def prediction_intervals(model, samples: np.ndarray, edges: np.ndarray, window_length: float, *,
                         level: float = 0.9, blocks: int = 10, resamples: int = 100,
                         seed: int = 0, direction: str = "up", mixing=None,
                         tracers=None) -> PredictionIntervals:
    """Intervals of a prediction's E(RT), SD(RT), RTD and mixing curve (module docstring).

    Parameters
    ----------
    model : MarkovModel
        The fitted model behind the prediction; its fitting window is re-read from its
        source file.
    samples : ndarray of float64, shape (K,)
        The prediction's residence-time samples in the analysis window (s).
    edges : ndarray, shape (B + 1,)
        The comparison's RTD bin edges (s).
    window_length : float
        Length of the analysis window (s).
    level : float, optional
        Coverage, in (0, 1).
    blocks : int, optional
        Time blocks of the fitting window (at least 2).
    resamples : int, optional
        Bootstrap resamples (at least 10).
    seed : int, optional
        Seed of the resampling.
    direction : {"up", "down"}, optional
        The direction residences are counted in (:meth:`MarkovModel.rtd`).
    mixing : (ndarray, ndarray), each of shape (T,), optional
        The prediction's mixing curve: its frame times (s), one lag apart from the window
        start, and its values (:func:`cfbmarkov.analysis.mixing.mixing_curve_of`).
    tracers : (ndarray of int, ndarray of bool), each of shape (N,), optional
        The particles' states at the window start in the model's state space (-1: absent)
        and the left tracer group; with ``mixing``, the mixing curve gets its band.

    Returns
    -------
    PredictionIntervals
        ``mixing_times`` and ``mixing`` set where ``mixing`` and ``tracers`` are given.

    Raises
    ------
    InputError
        For a level outside (0, 1), too few blocks or resamples, a model without a source
        file and window, a fitting window too short for the blocks, fewer than 2 samples,
        fewer than 10 resamples with residences, only one of ``mixing`` and ``tracers``, a
        mixing curve not on whole lags from its first frame, or tracers that do not fit the
        model (:func:`~cfbmarkov.analysis.mixing.model_mixing_curve`).

    References
    ----------
    ``docs/definitions.md`` (Intervals); B. Efron and R. J. Tibshirani, An Introduction to
    the Bootstrap, Chapman & Hall (1993), Ch. 8 and 13.
    """
    if not 0.0 < float(level) < 1.0:
        raise InputError(f"interval level {level!r} must lie between 0 and 1")
    if int(blocks) < 2 or int(resamples) < 10:
        raise InputError(f"intervals need at least 2 blocks and 10 resamples ({blocks}, "
                         f"{resamples})")
    samples = np.asarray(samples, dtype=np.float64)
    if samples.size < 2:
        raise InputError("intervals need at least 2 residence-time samples in the window")
    if (mixing is None) != (tracers is None):
        raise InputError("the mixing band needs both the prediction's curve and the tracers")
    exact = model.rtd(window_length, direction)
    entry = exact.entry_distribution
    curve = None
    if mixing is not None:
        m_times = np.asarray(mixing[0], dtype=np.float64)
        m_values = np.asarray(mixing[1], dtype=np.float64)
        if m_times.ndim != 1 or m_times.shape != m_values.shape or m_times.size == 0:
            raise InputError("the prediction's mixing curve must be two arrays of shape (T,)")
        steps = (m_times - m_times[0]) / model.lag
        lags = np.rint(steps).astype(np.int64)
        if np.abs(steps - lags).max() > 1e-3 or lags.min() < 0:
            raise InputError("the prediction's mixing curve is not on whole lags of its model "
                             f"({model.lag:g} s) from its first frame")
        states, left = tracers
        m_exact, m_se = model_mixing_curve(model, states, left, int(lags.max()))
        curve = (lags, states, left)
    means, sds, rtds, curves = [], [], [], []
    for resampled in block_bootstrap_models(model, blocks=blocks, resamples=resamples,
                                            seed=seed):
        if curve is not None:      # the transitions' spread; defined with or without residences
            curves.append(model_mixing_curve(resampled, curve[1], curve[2],
                                             int(curve[0].max()))[0][curve[0]])
        try:
            rtd = _resampled_rtd(resampled, window_length, direction, entry)
        except (CfbmarkovError, ValueError):
            continue                 # a resample without residences: no figure
        means.append(rtd.mean)
        sds.append(rtd.sd)
        rtds.append(_binned(rtd, edges))
    if len(means) < 10:
        raise InputError("intervals: fewer than 10 bootstrap resamples had residences")
    exact_hist = _binned(exact, edges)
    lo_q, hi_q = 0.5 * (1 - level), 0.5 * (1 + level)
    z = float(norm.ppf(hi_q))
    n = samples.size
    mean, sd = float(samples.mean()), float(samples.std(ddof=1))
    _, p_mc = rtd_histogram(samples, float(edges[1] - edges[0]),
                            window_length=float(edges[-1]))
    se_mean, se_sd = sd / np.sqrt(n), sd / np.sqrt(2 * (n - 1))
    se_bins = np.sqrt(p_mc * (1 - p_mc) / n)
    if getattr(model, "coherence", 0.0) > 0.0:
        # coherent moves: the particles' residences are correlated; the Monte Carlo noise
        # comes from replicate runs instead of the formulas for independent samples
        if tracers is None:
            raise InputError("intervals of a model with coherent moves need the particles' "
                             "states at the window start (its Monte Carlo noise is measured "
                             "on replicate runs from them)")
        states0 = np.asarray(tracers[0])
        se_mean, se_sd, se_bins, se_curve = _replicate_noise(
            model, states0, tracers[1], max(2, int(round(window_length / model.lag))), edges,
            window_length, direction, None if curve is None else curve[0], seed)
        if curve is not None:
            m_se = np.zeros(int(curve[0].max()) + 1)
            m_se[curve[0]] = se_curve

    def interval(value, boot, centre, se):
        lo, hi = np.quantile(boot, [lo_q, hi_q], axis=0)
        down = np.sqrt(np.maximum(centre - lo, 0.0) ** 2 + (z * se) ** 2)
        up = np.sqrt(np.maximum(hi - centre, 0.0) ** 2 + (z * se) ** 2)
        return value - down, value + up

    m_lo, m_hi = interval(mean, np.asarray(means), exact.mean, se_mean)
    s_lo, s_hi = interval(sd, np.asarray(sds), exact.sd, se_sd)
    r_lo, r_hi = interval(p_mc, np.asarray(rtds), exact_hist, se_bins)
    band = None
    if curve is not None:
        with np.errstate(invalid="ignore"):     # an open riser's curve: NaN once no tracer is left
            c_lo, c_hi = interval(m_values, np.asarray(curves), m_exact[curve[0]],
                                  m_se[curve[0]])
            band = np.vstack([np.clip(c_lo, 0.0, 1.0), np.clip(c_hi, 0.0, 1.0)])
    return PredictionIntervals(float(level), (float(m_lo), float(m_hi)),
                               (float(max(s_lo, 0.0)), float(s_hi)),
                               np.vstack([np.maximum(r_lo, 0.0), r_hi]), len(means), int(blocks),
                               None if curve is None else m_times, band)


__all__ = ["PredictionIntervals", "block_bootstrap_models", "prediction_intervals"]
