"""Intervals of a prediction's residence-time figures (``docs/definitions.md``, Intervals).

Two sources of uncertainty are combined:

- *the model's*: a block bootstrap over time blocks of the fitting window. The window's
  transitions are counted in B contiguous blocks; a resample draws B blocks with
  replacement, sums their counts and forms a model (the same estimator and state space),
  whose exact RTD in the analysis window gives E(RT), SD(RT) and the probability per RTD
  bin. Resampling whole blocks keeps the correlation between consecutive transitions and
  carries the window's non-stationarity (a surge in one block) into the spread, which a
  multinomial (Bayesian counts) model of independent transitions would not;
- *the Monte Carlo's*: the prediction's own sampling noise, the standard error of its
  mean (SD / sqrt(n)), of its SD (SD / sqrt(2 (n - 1))) and of a bin probability
  (sqrt(p (1 - p) / n)), normal approximation.

The interval at level L is centred on the prediction's value: its lower (upper) half-width is
the distance from the fitted model's exact value to the bootstrap's (1 - L)/2 ((1 + L)/2)
quantile and z_(1+L)/2 times the Monte Carlo standard error, added in quadrature.

References
----------
B. Efron and R. J. Tibshirani, An Introduction to the Bootstrap, Chapman & Hall (1993),
Ch. 8 (the moving-block bootstrap for dependent data) and Ch. 13 (percentile intervals).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

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


@dataclass(frozen=True)
class PredictionIntervals:
    """Intervals of E(RT), SD(RT) and the RTD per bin at ``level``.

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
    """

    level: float
    rt_mean: tuple[float, float]
    rt_sd: tuple[float, float]
    rtd: np.ndarray
    resamples: int
    blocks: int


def prediction_intervals(model, samples: np.ndarray, edges: np.ndarray, window_length: float, *,
                         level: float = 0.9, blocks: int = 10, resamples: int = 100,
                         seed: int = 0, direction: str = "up") -> PredictionIntervals:
    """Intervals of a prediction's E(RT), SD(RT) and RTD (module docstring).

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

    Returns
    -------
    PredictionIntervals

    Raises
    ------
    InputError
        For a level outside (0, 1), too few blocks or resamples, a model without a source
        file and window, a fitting window too short for the blocks, or fewer than 2 samples.
    """
    from cfbmarkov.markov.discrete import discretize
    from cfbmarkov.markov.estimate import count_transitions, estimator_from_name

    if not 0.0 < float(level) < 1.0:
        raise InputError(f"interval level {level!r} must lie between 0 and 1")
    if int(blocks) < 2 or int(resamples) < 10:
        raise InputError(f"intervals need at least 2 blocks and 10 resamples ({blocks}, "
                         f"{resamples})")
    samples = np.asarray(samples, dtype=np.float64)
    if samples.size < 2:
        raise InputError("intervals need at least 2 residence-time samples in the window")
    if not isinstance(model.source, str) or model.window is None:
        raise InputError("intervals need the model's fitting data (one source file and a window)")
    discrete = discretize(model.source, model.state_space, model.lag, model.window)
    t0, t1 = float(discrete.times[0]), float(discrete.times[-1])
    cuts = np.linspace(t0, t1, int(blocks) + 1)
    step = discrete.frame_interval
    frame_average = model.estimator == "paper"
    counts = [count_transitions(discrete.block(a, b - (0 if k == blocks - 1 else step)),
                                frame_average=frame_average)
              for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:]))]
    estimator = estimator_from_name(model.estimator, model.state_space, model.lag,
                                    connected=model.connected)
    rng = np.random.default_rng(seed)
    means, sds, rtds = [], [], []
    exact = model.rtd(window_length, direction)
    entry = exact.entry_distribution
    for _ in range(int(resamples)):
        picked = rng.integers(0, len(counts), len(counts))
        total = counts[picked[0]]
        for k in picked[1:]:
            total = total + counts[k]
        try:
            rtd = _resampled_rtd(estimator.fit_counts(total), window_length, direction, entry)
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

    def interval(value, boot, centre, se):
        lo, hi = np.quantile(boot, [lo_q, hi_q], axis=0)
        down = np.sqrt(np.maximum(centre - lo, 0.0) ** 2 + (z * se) ** 2)
        up = np.sqrt(np.maximum(hi - centre, 0.0) ** 2 + (z * se) ** 2)
        return value - down, value + up

    m_lo, m_hi = interval(mean, np.asarray(means), exact.mean, sd / np.sqrt(n))
    s_lo, s_hi = interval(sd, np.asarray(sds), exact.sd, sd / np.sqrt(2 * (n - 1)))
    r_lo, r_hi = interval(p_mc, np.asarray(rtds), exact_hist, np.sqrt(p_mc * (1 - p_mc) / n))
    return PredictionIntervals(float(level), (float(m_lo), float(m_hi)),
                               (float(max(s_lo, 0.0)), float(s_hi)),
                               np.vstack([np.maximum(r_lo, 0.0), r_hi]), len(means), int(blocks))
