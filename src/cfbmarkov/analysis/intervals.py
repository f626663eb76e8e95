"""Intervals of a prediction's residence-time figures and mixing curve
(``docs/definitions.md``, Intervals).

Three sources of uncertainty are combined:

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
  approximation;
- *the flow's* (:func:`flow_variability`), for E(RT) and SD(RT): how much the figures that
  the reference shows in one window of the analysis window's length move by themselves,
  from window to window, by sampling noise and by the surges and clusters of a
  non-stationary flow, measured in the fitting window (its blocks against one another,
  every side seeing residences through the same length of window). A model that is exactly
  right still misses a window's observed E(RT) by this much: without it, the intervals are
  those of the model's own value (confidence intervals), with it, of the value the
  reference will show in the analysis window (prediction intervals).

The interval at level L is centred on the prediction's value: its lower (upper) half-width is
the distance from the fitted model's exact value to the bootstrap's (1 - L)/2 ((1 + L)/2)
quantile, and z_(1+L)/2 times the Monte Carlo and the flow's standard errors, added in
quadrature (for the RTD and the mixing curve, bin by bin and frame by frame, without a flow
term: their bands are the model's own).

References
----------
B. Efron and R. J. Tibshirani, An Introduction to the Bootstrap, Chapman & Hall (1993),
Ch. 8 (the moving-block bootstrap for dependent data) and Ch. 13 (percentile intervals).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

from cfbmarkov.analysis.mixing import _left_states, model_mixing_curve
from cfbmarkov.boundary import Boundary
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.observed.residence import (residence_times, residence_times_from_laps,
                                          rtd_histogram)
from cfbmarkov.trajectories import opened


#: blocks of the fitting window that measure the flow's variability (:func:`flow_variability`)
FLOW_BLOCKS = 4
#: ... fewer where a block would be shorter than this many of the window's mean residences
FLOW_BLOCK_RESIDENCES = 3.0


def _resampled_rtd(model, window_length: float, direction: str, entry):
    """A resampled model's RTD in the window, from the fitted model's entry distribution
    (one sparse LU per resample saved: the spread of the entry distribution is left out,
    that of the transitions kept)."""
    steps = max(2, int(round(window_length / model.lag)))
    if isinstance(model, _SplitChain):
        from cfbmarkov.markov.first_passage import rtd_of_split_chain

        up, down = (model.up, model.down) if direction == "up" else (model.down, model.up)
        return rtd_of_split_chain(up, down, model.stay, model.lag, max_steps=steps,
                                  entry=entry).in_window(window_length)
    if Boundary(model.boundary).is_open or entry is None:
        return model.rtd(window_length, direction)
    from cfbmarkov.markov.first_passage import exact_rtd

    up, down = ((model.up_fraction, model.down_fraction) if direction == "up"
                else (model.down_fraction, model.up_fraction))
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
    from cfbmarkov.markov.estimate import estimator_from_name

    totals = _bootstrap_counts(model, blocks, resamples, seed, sparse=False)
    estimator = estimator_from_name(model.estimator, model.state_space, model.lag,
                                    connected=model.connected)

    def draw():
        for total in totals:
            try:
                resampled = estimator.fit_counts(total)
            except (CfbmarkovError, ValueError):
                continue                 # counts that form no model: no figure
            yield resampled

    return draw()


def _bootstrap_counts(model, blocks: int, resamples: int, seed: int, sparse: bool):
    """The summed counts of each block-bootstrap resample of the model's fitting window
    (:func:`block_bootstrap_models`; dense, or scipy.sparse with ``sparse``). Checks and
    counts on the call; the sums are formed as the iterator is consumed."""
    from cfbmarkov.markov.discrete import discretize
    from cfbmarkov.markov.counting import count_transitions

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
                                frame_average=frame_average, sparse=sparse)
              for a, b in zip(cuts[:-1], cuts[1:])]
    rng = np.random.default_rng(seed)

    def draw():
        for _ in range(int(resamples)):
            picked = rng.integers(0, blocks, blocks)
            total = counts[picked[0]]
            for k in picked[1:]:
                total = total + counts[k]
            yield total

    return draw()


@dataclass(frozen=True)
class _SplitChain:
    """A bootstrap resample's chain without dense arrays: P split by pass direction (what
    :func:`_resampled_rtd` and :func:`~cfbmarkov.analysis.mixing.model_mixing_curve` read
    of a periodic model)."""

    up: object
    down: object
    stay: object
    state_space: object
    lag: float
    boundary: Boundary = Boundary.PERIODIC

    @property
    def transition_matrix(self):
        return (self.up + self.down + self.stay).tocsr()


def _bootstrap_chains(model, blocks: int, resamples: int, seed: int):
    """:func:`block_bootstrap_models`'s resamples (the same draws) as :class:`_SplitChain`,
    from sparse counts: for a periodic riser's model without the largest-set restriction,
    whose resamples are only asked for their RTD and mixing curve. The same chains to
    rounding (tested), without the [S, S] arrays of a model per resample."""
    from cfbmarkov.markov.estimate import estimator_from_name

    totals = _bootstrap_counts(model, blocks, resamples, seed, sparse=True)
    estimator = estimator_from_name(model.estimator, model.state_space, model.lag)
    for total in totals:
        yield _SplitChain(*estimator.split_chain(total), model.state_space, model.lag)


def flow_variability(model, window_length: float, *, direction: str = "up",
                     blocks: int = FLOW_BLOCKS):
    """How much the reference's E(RT) and SD(RT) in one window of ``window_length`` move by
    themselves from window to window, relative to their values, measured in the model's
    fitting window (the flow's own variability; module docstring).

    The fitting window is cut into B equal blocks, ``blocks`` or fewer, so that a block is at
    least ``FLOW_BLOCK_RESIDENCES`` (3) times the window's observed E(RT) long (a shorter
    block cuts off so many of its residences that the comparison measures the cut, not the
    flow); each block's residence times (from frames at the model's lag, counted in
    ``direction``, wholly inside the block) are compared with the other blocks' pooled:
    the persistence baseline inside the fitting window, every side seeing residences
    through the same length of window. The RMS
    over the blocks of the relative differences estimates sqrt(B / (B - 1)) times the
    relative SD of one block's figure (the block against the mean of B - 1 others), so one
    block's relative SD is the RMS times sqrt((B - 1) / B). That is taken as the analysis
    window's where the window is at least a block long, and scaled by sqrt(block /
    ``window_length``) (sampling noise) where it is shorter. It is not reduced for a window
    longer than a block, as independent blocks would have it (by sqrt(block / window)): a
    longer window sees longer residences, whose share carries the flow's surges and
    clusters. Measured on the paper-scale runs over 5-20 s, the relative SD of E(RT)
    between windows of 1, 1.25, 2.5 and 5 s was 8.4, 9.3, 9.4 and 5.7 % at 8 m/s and 8.6,
    11.8, 15.9 and 8.8 % at 6 m/s (5 s windows overlapping, 1 s apart), not falling as
    1 / sqrt(length) (``docs/definitions.md``, Intervals).

    Parameters
    ----------
    model : cfbmarkov.markov.MarkovModel
        The fitted model; its ``source`` (one trajectory file) and ``window`` are re-read.
    window_length : float
        Length of the analysis window (s).
    direction : {"up", "down"}, optional
        The direction residences are counted in.
    blocks : int, optional
        The most blocks B of the fitting window (at least 2).

    Returns
    -------
    (float, float) or None
        The relative standard deviations of a window's E(RT) and SD(RT) (fractions); None
        where the window is shorter than two such blocks, or fewer than two blocks hold two
        residences each (no spread can be told).

    Raises
    ------
    InputError
        For a model without one source file and a window, or fewer than 2 blocks.

    References
    ----------
    Block averaging: H. Flyvbjerg and H. G. Petersen, "Error estimates on averages of
    correlated data", J. Chem. Phys. 91, 461 (1989): where the spread of block figures does
    not fall with the block's length, the blocks are not independent, and the spread of the
    longest blocks is the honest estimate (here, one block's spread is kept for longer
    windows).
    """
    if int(blocks) < 2:
        raise InputError(f"the flow's variability needs at least 2 blocks ({blocks})")
    if not isinstance(model.source, str) or model.window is None:
        raise InputError("intervals need the model's fitting data (one source file and a window)")
    a, b = (float(v) for v in model.window)
    with opened(model.source) as traj:
        lag_frames = traj.lag_frames(model.lag)
        whole = residence_times(traj, (a, b), use_events=False, lag_frames=lag_frames,
                                direction=direction)
        # blocks at least FLOW_BLOCK_RESIDENCES mean residences long, so that a block's own
        # window cuts off few of its residences
        if whole.count < 2:
            return None
        blocks = min(int(blocks), int((b - a) / (FLOW_BLOCK_RESIDENCES * whole.mean)))
        if blocks < 2:
            return None
        cuts = a + (b - a) * np.arange(blocks + 1) / blocks
        observed = [residence_times(traj, (float(cuts[k]), float(cuts[k + 1])), use_events=False,
                                    lag_frames=lag_frames, direction=direction).samples
                    for k in range(blocks)]
    rel_mean, rel_sd = [], []
    for k, block in enumerate(observed):
        others = np.concatenate([o for j, o in enumerate(observed) if j != k])
        if block.size < 2 or others.size < 2:
            continue
        rel_mean.append(block.mean() / others.mean() - 1.0)
        spread = others.std(ddof=1)
        if spread > 0:
            rel_sd.append(block.std(ddof=1) / spread - 1.0)
    if len(rel_mean) < 2:
        return None
    block = (b - a) / blocks
    factor = np.sqrt((blocks - 1.0) / blocks) * max(1.0, np.sqrt(block / float(window_length)))
    rms = lambda values: float(np.sqrt(np.mean(np.square(values)))) if values else 0.0  # noqa: E731
    return rms(rel_mean) * factor, rms(rel_sd) * factor


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
    model_rt_mean, model_rt_sd : (float, float) or None
        The intervals without the flow's variability (s): of the model's own value
        (confidence intervals); the same as ``rt_mean`` and ``rt_sd`` where ``flow`` is
        None.
    flow : (float, float) or None
        The flow's standard deviations of a window's E(RT) and SD(RT) (s; the relative ones
        of :func:`flow_variability` times the prediction's values); None where not asked for
        or not measurable.
    """

    level: float
    rt_mean: tuple[float, float]
    rt_sd: tuple[float, float]
    rtd: np.ndarray
    resamples: int
    blocks: int
    mixing_times: np.ndarray | None = None
    mixing: np.ndarray | None = None
    model_rt_mean: tuple[float, float] | None = None
    model_rt_sd: tuple[float, float] | None = None
    flow: tuple[float, float] | None = None


#: replicate Monte Carlo runs that measure a coherent model's Monte Carlo noise
REPLICATES = 20


def _replicate_noise(model, states, left_group, n_steps: int, edges: np.ndarray,
                     window_length: float, direction: str, lags, seed: int):
    """Standard deviations over replicate Monte Carlo runs (from ``states``) of E(RT),
    SD(RT), the RTD per bin and the mixing curve at ``lags`` (None without them): the
    Monte Carlo noise of a model whose particles move coherently, which the formulas for
    independent samples underestimate."""
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
                         tracers=None, flow: bool = True) -> PredictionIntervals:
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
    flow : bool, optional
        Add the flow's own variability between windows (:func:`flow_variability`) to the
        intervals of E(RT) and SD(RT): intervals for the value the reference shows in the
        analysis window. False: intervals of the model's own value. (The RTD's and the
        mixing curve's bands are the model's own either way.)

    Returns
    -------
    PredictionIntervals
        ``mixing_times`` and ``mixing`` set where ``mixing`` and ``tracers`` are given;
        ``flow`` where ``flow`` is true and the fitting window shows the flow's spread
        (:func:`flow_variability`; where it does not, the intervals are the model's own).

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
    if not Boundary(model.boundary).is_open and not model.connected and entry is not None:
        # the resamples' RTDs and mixing curves from sparse chains (no [S, S] model each)
        drawn = _bootstrap_chains(model, blocks, resamples, seed)
    else:
        drawn = block_bootstrap_models(model, blocks=blocks, resamples=resamples, seed=seed)
    for resampled in drawn:
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

    def interval(value, boot, centre, se, se_flow=0.0):
        lo, hi = np.quantile(boot, [lo_q, hi_q], axis=0)
        noise = (z * se) ** 2 + (z * se_flow) ** 2
        down = np.sqrt(np.maximum(centre - lo, 0.0) ** 2 + noise)
        up = np.sqrt(np.maximum(hi - centre, 0.0) ** 2 + noise)
        return value - down, value + up

    relative = flow_variability(model, window_length, direction=direction) if flow else None
    model_mean = interval(mean, np.asarray(means), exact.mean, se_mean)
    model_sd = interval(sd, np.asarray(sds), exact.sd, se_sd)
    f_mean, f_sd = (0.0, 0.0) if relative is None else (relative[0] * mean, relative[1] * sd)
    m_lo, m_hi = interval(mean, np.asarray(means), exact.mean, se_mean, f_mean)
    s_lo, s_hi = interval(sd, np.asarray(sds), exact.sd, se_sd, f_sd)
    r_lo, r_hi = interval(p_mc, np.asarray(rtds), exact_hist, se_bins)
    band = None
    if curve is not None:
        with np.errstate(invalid="ignore"):     # an open riser's curve: NaN once no tracer is left
            c_lo, c_hi = interval(m_values, np.asarray(curves), m_exact[curve[0]],
                                  m_se[curve[0]])
            band = np.vstack([np.clip(c_lo, 0.0, 1.0), np.clip(c_hi, 0.0, 1.0)])
    return PredictionIntervals(     # E(RT) and SD(RT) are not negative: bounds cut at 0
        float(level), (float(max(m_lo, 0.0)), float(m_hi)), (float(max(s_lo, 0.0)), float(s_hi)),
        np.vstack([np.maximum(r_lo, 0.0), r_hi]), len(means), int(blocks),
        None if curve is None else m_times, band,
        (float(max(model_mean[0], 0.0)), float(model_mean[1])),
        (float(max(model_sd[0], 0.0)), float(model_sd[1])),
        None if relative is None else (float(f_mean), float(f_sd)))


__all__ = ["PredictionIntervals", "block_bootstrap_models", "flow_variability",
           "prediction_intervals"]
