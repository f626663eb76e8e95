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
  mean (SD / sqrt(n)), of its SD (SD sqrt((kurtosis - 1) / (4 n)), the delta method,
  Kendall & Stuart, Vol. 1, 10.7: a riser's RTD is skewed and long-tailed, where
  SD / sqrt(2 (n - 1)) would hold for normal samples alone), of a bin probability
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
quantile, z_(1+L)/2 times the Monte Carlo's standard error and t_(1+L)/2 times the flow's
(Student's t with the flow estimate's degrees of freedom, the blocks compared less one:
an SD from a few blocks is itself uncertain), added in quadrature (for the RTD and the
mixing curve, bin by bin and frame by frame, without a flow term: their bands are the
model's own).

References
----------
B. Efron and R. J. Tibshirani, An Introduction to the Bootstrap, Chapman & Hall (1993),
Ch. 8 (the moving-block bootstrap for dependent data) and Ch. 13 (percentile intervals).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfbmarkov.analysis.bootstrap import (BOOTSTRAP_BLOCKS, FLOW_BLOCK_RESIDENCES,  # noqa: F401
                                          FLOW_BLOCKS,
                                          _binned, _bootstrap_chains, _reach, _sd_noise,
                                          _resampled_rtd,
                                          block_bootstrap_models, bootstrap_figures,
                                          check_interval_options,
                                          fitting_runs, flow_variability, interval_bounds,
                                          bootstrap_widening)
from cfbmarkov.analysis.mixing import _left_states, model_mixing_curve
from cfbmarkov.errors import InputError
from cfbmarkov.observed.residence import residence_times_from_laps, rtd_histogram


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
    flow_degrees_of_freedom : int or None
        Their degrees of freedom: the interval takes Student's t with them
        (:func:`~cfbmarkov.analysis.bootstrap.flow_quantile`); None with ``flow``.
    bootstrap_widening : float or None
        The factor the bootstrap's distances to its quantiles were multiplied by for its
        blocks (:func:`~cfbmarkov.markov.uncertainty.bootstrap_widening`).
    flow_relative : (float, float) or None
        ``flow`` relative to the prediction's E(RT) and SD(RT) (fractions: what
        :func:`flow_variability` measured); None with ``flow``.
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
    flow_degrees_of_freedom: int | None = None
    bootstrap_widening: float | None = None
    flow_relative: tuple[float, float] | None = None


class SourceChanged(InputError):
    """The file a model names as its source no longer holds the data it was fitted on."""


class SourceMissing(InputError):
    """The file a model names as its source cannot be found (from the current folder, beside
    the model file or among the files a verb was given)."""


def _check_sources_exist(model) -> None:
    """Refuse a model without a recorded identity whose fitting file is not where its
    ``source`` says (no other file can be checked to be it)."""
    import os

    sources = model.source if isinstance(model.source, (list, tuple)) else [model.source]
    if not sources or not all(sources):
        raise SourceMissing("the model names no trajectory file it was fitted on: intervals "
                            "need its fitting data (fit it with cfbmarkov fit), or "
                            "--resamples 0 to leave them out")
    for source in sources:
        if not os.path.isfile(str(source)):
            raise SourceMissing(
                f"{source} (the model's fitting file, named from the folder it was fitted "
                "in): no such file from this folder, and the model records no identity of "
                "its fitting data by which another copy could be taken; run from that "
                "folder, or --resamples 0 to leave the intervals out")


def resolve_source(model, candidates=()):
    """The model with its fitting file(s) found: its ``source`` is a path as given at fit
    time, relative to the folder it was fitted in, which need not be the current one.

    Tried in turn, each kept only where its fitting window's content identity
    (:func:`cfbmarkov.trajectory_identity.window_identity`) is the one recorded at fit
    time: the path as recorded (from the current folder), the same path beside the model
    file and the file's name alone beside it (a model loaded from a file, saved where it
    was fitted, or in the folder of its fitting file: ``synth/model.h5`` fitted on
    ``synth/reference.h5`` finds ``reference.h5`` beside it from any folder), and
    ``candidates`` (the files a verb was given, e.g. `compare`'s reference when it is the
    fitting file).

    Parameters
    ----------
    model : MarkovModel
    candidates : iterable of str or os.PathLike, optional
        Further files that may be the fitting file.

    Returns
    -------
    MarkovModel
        ``model``, or a copy whose ``source`` names the files found. A model without a
        recorded identity is returned as it is (its source taken on trust), where its
        source files exist.

    Raises
    ------
    SourceChanged
        Where a file of that name exists but none tried holds the fitting window's data.
    SourceMissing
        Where no file tried exists (for a model without a recorded identity: where its
        source names no file, or a file missing from the current folder).
    """
    import os
    from pathlib import Path

    from cfbmarkov.trajectories import Trajectories
    from cfbmarkov.trajectory_identity import same_window

    if not model.source_identity:
        _check_sources_exist(model)
        return model
    pooled = not isinstance(model.source, str)
    sources = [str(p) for p in model.source] if pooled else [model.source]
    identities = model.source_identity.split(";")
    windows = ([tuple(w) for w in model.run_windows] if pooled and model.run_windows
               else [model.window] * len(sources))
    if len(identities) != len(sources) or len(windows) != len(sources):
        return model
    home = model._cache.get("file")
    found = []
    for source, identity, window in zip(sources, identities, windows):
        tried = [Path(source)]
        if home is not None:
            if not Path(source).is_absolute():
                tried.append(Path(home).parent / source)
            tried.append(Path(home).parent / Path(source).name)
        named = {os.path.abspath(p) for p in tried}     # files found by the source's name
        tried += [Path(c) for c in candidates]
        existing, match = [], None
        for path in dict.fromkeys(os.path.abspath(p) for p in tried):
            if not Path(path).is_file():
                continue
            if path in named:   # (a candidate that is not the fitting file says nothing
                existing.append(path)     # of whether the fitting file was replaced)
            try:
                with Trajectories(path) as traj:
                    if same_window(traj, window, identity):
                        match = path
                        break
            except InputError:
                continue
        if match is None:
            where = (f"the files of that name tried ({', '.join(existing)}) are not the data "
                     "the model was fitted on (its fitting window's content differs: another "
                     "file of that name, or the file replaced since the fit)" if existing
                     else "no file of that name was found from this folder or beside the "
                     "model file")
            fix = ("run from that folder (in it, the file was replaced since the fit: fit "
                   "again)" if existing else "run from that folder, or put the file beside "
                   "the model file")
            error = SourceChanged if existing else SourceMissing
            raise error(f"{source} (the model's fitting file, named from the folder it was "
                        f"fitted in): {where}; {fix}, or --resamples 0 to leave the "
                        "intervals out")
        found.append(source if os.path.abspath(source) == match else match)
    if found == sources:
        return model
    return model._derived(source=found if pooled else found[0])


def check_source_identity(model) -> None:
    """Refuse a model whose source file's fitting window is not the one it was fitted on.

    Parameters
    ----------
    model : MarkovModel
        A model with one source file; one without a recorded ``source_identity`` passes.

    Raises
    ------
    SourceChanged
        Where the window's content identity
        (:func:`cfbmarkov.trajectory_identity.window_identity`) differs from the one
        recorded at fit time: another file of the same name, or the file replaced.
    InputError
        Where the source cannot be read or the window holds no frame of it.
    """
    from cfbmarkov.trajectories import Trajectories
    from cfbmarkov.trajectory_identity import same_window

    if not model.source_identity or not isinstance(model.source, str):
        return
    with Trajectories(model.source) as traj:
        if same_window(traj, model.window, model.source_identity):
            return
    raise SourceChanged(
        f"{model.source} is not the data the model was fitted on (its fitting window's "
        "content differs: another file of that name, or the file replaced since the fit); "
        "run from the folder the model was fitted in with its own trajectory file, or fit "
        "again (--resamples 0 compares without intervals)")


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
                         level: float = 0.9, blocks: int = BOOTSTRAP_BLOCKS,
                         resamples: int = 100,
                         seed: int = 0, direction: str | None = None, mixing=None,
                         tracers=None, flow: bool = True,
                         candidates=(), occupancy=None) -> PredictionIntervals:
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
        The direction residences are counted in (:meth:`MarkovModel.rtd`); default the
        model's ``flow_direction``, the direction of its fitting window's net solids flow.
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
    candidates : iterable of str or os.PathLike, optional
        Files that may be the model's fitting file where its recorded path does not lead
        to it (:func:`resolve_source`; e.g. `compare`'s reference).
    occupancy : array_like of float, shape (S,), optional
        A periodic riser's: where the window's particles start (the prediction's states
        in its first frame of the window), for the exact RTD as the window sees it and its
        resamples' (:meth:`MarkovModel.rtd <cfbmarkov.markov.model.MarkovModel.rtd>`);
        default the fitting window's occupancy.

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
    from cfbmarkov.limits import check_seed

    check_interval_options(level, resamples, blocks)
    seed = check_seed(seed)
    samples = np.asarray(samples, dtype=np.float64)
    if samples.size < 2:
        raise InputError("intervals need at least 2 residence-time samples in the window")
    if (mixing is None) != (tracers is None):
        raise InputError("the mixing band needs both the prediction's curve and the tracers")
    direction = model.flow_direction if direction is None else direction
    exact = model.rtd(window_length, direction, occupancy)
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
    model = resolve_source(model, candidates)       # the fitting data, for the bootstrap
    means, sds, rtds, curves = bootstrap_figures(model, window_length, direction, entry,
                                                 edges, blocks, resamples, seed, curve,
                                                 exact.deficit_levels, occupancy)
    if len(means) < 10:
        raise InputError("intervals: fewer than 10 bootstrap resamples had residences")
    exact_hist = _binned(exact, edges)
    n = samples.size
    mean, sd = float(samples.mean()), float(samples.std(ddof=1))
    _, p_mc = rtd_histogram(samples, float(edges[1] - edges[0]),
                            window_length=float(edges[-1]))
    # the SD's standard error by the delta method (kurtosis - 1) / (4 n), which holds for
    # a riser's skewed RTD, where SD / sqrt(2 (n - 1)) holds for normal samples alone
    se_mean, se_sd = sd / np.sqrt(n), sd * np.sqrt(_sd_noise(samples))
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

    # a window's observed figure moves by its own sampling too, which no other term holds
    relative = (flow_variability(model, window_length, direction=direction, sampling=True)
                if flow else None)
    dof = None if relative is None else relative.degrees_of_freedom

    runs = len(fitting_runs(model))

    def interval(value, boot, centre, se, se_flow=0.0):
        return interval_bounds(value, boot, centre, level, se, se_flow, dof, blocks=blocks,
                               runs=runs)

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
        None if relative is None else (float(f_mean), float(f_sd)), dof,
        bootstrap_widening(level, int(blocks), runs),
        None if relative is None else (float(relative[0]), float(relative[1])))


#: most bins of a model's RTD interval (:func:`model_rtd_edges`)
MODEL_RTD_BINS = 40


def model_rtd_edges(rtd) -> np.ndarray:
    """The bins of a model's RTD interval: whole lags wide, at most ``MODEL_RTD_BINS`` (40)
    of them, from 0 to past the exact RTD's 99th percentile (the bin that holds it
    included), rounded up to a bin.

    Parameters
    ----------
    rtd : ResidenceTimeDistribution
        The model's exact intrinsic RTD.

    Returns
    -------
    ndarray of float64, shape (B + 1,)
        Bin edges (s), whole multiples of the lag written as the RTD's times are
        (:func:`~cfbmarkov.markov.first_passage.lag_multiples`: 0.3, not
        0.30000000000000004), so that a residence of a whole number of lags falls, with
        ``numpy.histogram``'s rule, in the bin whose lower edge it equals.
    """
    from cfbmarkov.markov.first_passage import lag_multiples

    cumulative = np.cumsum(rtd.probability) / rtd.probability.sum()
    # the residence of k + 1 lags at which the cumulative mass reaches 99 % falls in the
    # bin it starts, [k + 1, k + 2) lags: the edges reach k + 2 lags
    upper = int(np.searchsorted(cumulative, 0.99)) + 2            # lags
    width = max(1, -(-upper // MODEL_RTD_BINS))
    bins = -(-upper // width)
    return lag_multiples(rtd.lag, width * np.arange(bins + 1)).astype(np.float64)


#: the deepest lap deficit a model interval's resamples keep (the fewest an exact RTD keeps,
#: MIN_DEFICIT_LEVELS); a model whose exact RTD keeps more has its resamples' figures scaled
#: by its own full-depth / shallow ratio (:func:`model_intervals`): the bootstrap costs what
#: it costs on a shallow chain
BOOTSTRAP_DEFICIT_LEVELS = 8


@dataclass(frozen=True)
class _Shallow:
    """The fitted model's figures on :data:`BOOTSTRAP_DEFICIT_LEVELS` lap deficits."""

    mean: float                 # E(RT), s
    sd: float                   # SD(RT), s
    binned: np.ndarray          # probability per bin of the interval's edges
    deficit_levels: int


def _shallow_rtd(model, exact, direction: str, edges: np.ndarray) -> _Shallow | None:
    """The fitted model's intrinsic E(RT), SD(RT) and RTD per bin of ``edges`` on
    :data:`BOOTSTRAP_DEFICIT_LEVELS` lap deficits from its exact entry distribution, where
    its exact RTD keeps more (None otherwise): the depth of the bootstrap resamples, whose
    figures are scaled by the model's ratio of the two (``docs/definitions.md``, The model's
    interval). The moments solved for and the RTD propagated only as far as the bins, as
    the resamples' (:func:`~cfbmarkov.analysis.bootstrap._resampled_intrinsic`)."""
    if exact.deficit_levels is None or exact.deficit_levels <= BOOTSTRAP_DEFICIT_LEVELS:
        return None
    from cfbmarkov.markov.first_passage import rtd_moments_and_head, split_by_pass

    up, down = ((model.up_fraction, model.down_fraction) if direction == "up"
                else (model.down_fraction, model.up_fraction))
    p_up, p_down, p_stay = split_by_pass(model.transition_matrix, up, down)
    total, mean, sd, head = rtd_moments_and_head(p_up, p_down, p_stay, model.lag,
                                                 BOOTSTRAP_DEFICIT_LEVELS,
                                                 exact.entry_distribution,
                                                 _reach(edges, model.lag))
    if not (mean > 0 and sd > 0):
        return None
    return _Shallow(mean, sd, _binned(head, edges, total), BOOTSTRAP_DEFICIT_LEVELS)


def model_intervals(model, *, level: float = 0.9, blocks: int = BOOTSTRAP_BLOCKS,
                    resamples: int = 100, seed: int = 0, direction: str | None = None,
                    discrete=None):
    """Intervals of a fitted model's exact E(RT), SD(RT) and RTD per bin, from its fitting
    window alone (``docs/definitions.md``, The model's interval).

    The same definitions as a prediction's intervals (:func:`prediction_intervals`), for
    the model's intrinsic RTD and without a Monte Carlo term: the block bootstrap of the
    fitting window (``blocks`` time blocks counted once, ``resamples`` draws of their
    counts, each a chain whose exact RTD from the fitted model's entry distribution gives
    E(RT), SD(RT) and the RTD per bin) and, for E(RT) and SD(RT), the flow's variability
    between blocks of the window (:func:`flow_variability` for an analysis window as long
    as the fitting window), added in quadrature. The interval is centred on the model's
    exact value.

    A model fitted on several runs (a pooled fit) resamples ``blocks`` blocks of each run's
    window within that run (:func:`block_bootstrap_models`), and its flow term is the
    variability between the blocks of all the runs' windows (:func:`flow_variability`)
    divided by sqrt(runs): the runs are independent samples of one flow, and the pooled
    model sees their mean.

    Each resample's exact RTD keeps :data:`BOOTSTRAP_DEFICIT_LEVELS` lap deficits; where the
    model's exact RTD keeps more (residences that fall many laps, as in a velocity memory's
    falling states), the resamples' E(RT), SD(RT) and RTD per bin are scaled by the fitted
    model's ratio of its full-depth value to its 8-deficit one (a resample's deep tail taken
    to change with it as the model's does).

    Parameters
    ----------
    model : MarkovModel
        The fitted model; its fitting window is re-read from its source file.
    level : float, optional
        Coverage, in (0, 1).
    blocks : int, optional
        Time blocks of the fitting window (at least 2).
    resamples : int, optional
        Bootstrap resamples (at least 10).
    seed : int, optional
        Seed of the resampling.
    direction : {"up", "down"}, optional
        The direction residences are counted in (:meth:`MarkovModel.rtd`); default the
        model's ``flow_direction``, the direction of its fitting window's net solids flow.
    discrete : list of DiscreteTrajectories, optional
        The fitting window(s) already discretised, one per run
        (:func:`cfbmarkov.analysis.bootstrap.fitting_windows`: what ``fit`` reads once for
        the interval and the verdict); read from the file(s) where not given.

    Returns
    -------
    cfbmarkov.markov.uncertainty.ModelUncertainty
        Bins from :func:`model_rtd_edges`; ``flow_sd`` None where the window is too short
        for the flow's term (the intervals are then the bootstrap's alone); the flow's term
        takes Student's t with its degrees of freedom (``flow_degrees_of_freedom``).

    Raises
    ------
    InputError
        For a model that is not a MarkovModel, a level that is not a number in (0, 1),
        blocks or resamples that are not whole numbers (at least 2 and 10), a seed that is
        not one of 0 .. 2^64 - 1, a model without its fitting data (:func:`fitting_runs`),
        a fitting window too short for the blocks, or fewer than 10 resamples with
        residences.
    CfbmarkovError
        If the model has no residence time (:meth:`MarkovModel.rtd`).

    References
    ----------
    B. Efron and R. J. Tibshirani, An Introduction to the Bootstrap, Chapman & Hall (1993),
    Ch. 8 and 13; H. Flyvbjerg and H. G. Petersen, J. Chem. Phys. 91, 461 (1989).
    """
    from cfbmarkov.limits import check_seed
    from cfbmarkov.markov.model import MarkovModel
    from cfbmarkov.markov.uncertainty import ModelUncertainty

    if not isinstance(model, MarkovModel):
        raise InputError(f"model_intervals({model!r}): give a fitted MarkovModel "
                         "(MarkovModel.load(path) for a model file)")
    check_interval_options(level, resamples, blocks)
    seed = check_seed(seed)
    model = resolve_source(model)
    runs = fitting_runs(model)
    direction = model.flow_direction if direction is None else direction
    exact = model.rtd(None, direction)
    edges = model_rtd_edges(exact)
    shallow = _shallow_rtd(model, exact, direction, edges)
    means, sds, rtds, _ = bootstrap_figures(
        model, None, direction, exact.entry_distribution, edges, int(blocks), int(resamples),
        seed, deficit_levels=(exact if shallow is None else shallow).deficit_levels,
        discrete=discrete)
    if len(means) < 10:
        raise InputError("intervals: fewer than 10 bootstrap resamples had residences")
    if shallow is not None:     # each resample's spread, scaled to the full depth
        means = [value * exact.mean / shallow.mean for value in means]
        sds = [value * exact.sd / shallow.sd for value in sds]
        full, part = _binned(exact, edges), shallow.binned
        scale = np.divide(full, part, out=np.ones_like(full), where=part > 0)
        rtds = [values * scale for values in rtds]
    length = float(np.mean([b - a for _, (a, b) in runs]))
    variability = flow_variability(model, length, direction=direction)
    dof = None if variability is None else variability.degrees_of_freedom
    relative = None
    if variability is not None:     # several independent runs: their mean's variability
        relative = tuple(v / np.sqrt(len(runs)) for v in variability[:2])
    f_mean, f_sd = (0.0, 0.0) if relative is None else (relative[0] * exact.mean,
                                                        relative[1] * exact.sd)
    drawn = {"blocks": int(blocks), "runs": len(runs)}
    m_lo, m_hi = interval_bounds(exact.mean, np.asarray(means), exact.mean, level, 0.0, f_mean,
                                 dof, **drawn)
    s_lo, s_hi = interval_bounds(exact.sd, np.asarray(sds), exact.sd, level, 0.0, f_sd, dof,
                                 **drawn)
    hist = _binned(exact, edges)
    r_lo, r_hi = interval_bounds(hist, np.asarray(rtds), hist, level, **drawn)
    return ModelUncertainty(float(level), (max(float(m_lo), 0.0), float(m_hi)),
                            (max(float(s_lo), 0.0), float(s_hi)), edges,
                            np.vstack([np.maximum(r_lo, 0.0), r_hi]), len(means),
                            int(blocks) * len(runs), length / int(blocks), relative,
                            int(resamples), dof,
                            bootstrap_widening(level, int(blocks), len(runs)))


__all__ = ["PredictionIntervals", "SourceChanged", "SourceMissing", "block_bootstrap_models",
           "check_source_identity", "flow_variability", "resolve_source",
           "model_intervals", "model_rtd_edges", "prediction_intervals"]
