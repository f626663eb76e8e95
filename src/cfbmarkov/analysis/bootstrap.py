"""The block bootstrap of a model's fitting window and the flow's variability between its
blocks: the parts that :func:`cfbmarkov.analysis.intervals.prediction_intervals` (a
prediction's intervals) and :func:`cfbmarkov.analysis.intervals.model_intervals` (the
model's own) share (``docs/definitions.md``, Intervals).

References
----------
B. Efron and R. J. Tibshirani, An Introduction to the Bootstrap, Chapman & Hall (1993),
Ch. 8 (the moving-block bootstrap for dependent data) and Ch. 13 (percentile intervals).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import numbers
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from typing import NamedTuple

from scipy.special import ndtri      # the normal quantile, scipy.stats.norm.ppf's (a light import)
from scipy.special import stdtrit    # Student's t quantile, scipy.stats.t.ppf's

from cfbmarkov._blas import one_blas_thread
from cfbmarkov.boundary import Boundary
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.markov.uncertainty import bootstrap_widening  # noqa: F401 (re-exported)
from cfbmarkov.observed.residence import residence_times
from cfbmarkov.trajectories import opened


#: time blocks of the fitting window that the bootstrap resamples where none are given
#: (the model's interval's and a comparison's default; the kinetics' exit-mean intervals)
BOOTSTRAP_BLOCKS = 10
#: blocks of the fitting window that measure the flow's variability (:func:`flow_variability`)
FLOW_BLOCKS = 4
#: ... fewer where a block would be shorter than this many of the window's mean residences
FLOW_BLOCK_RESIDENCES = 3.0


def fitting_runs(model) -> list[tuple[str, tuple[float, float]]]:
    """The runs a model was fitted on and the window of each: one (source, window) pair,
    or a pooled fit's pairs in its order.

    Parameters
    ----------
    model : MarkovModel

    Returns
    -------
    list of (str, (float, float))

    Raises
    ------
    InputError
        For a model without its fitting data: no window, or several sources without a
        window per run.
    """
    if isinstance(model.source, str) and model.window is not None:
        return [(model.source, tuple(model.window))]
    runs = getattr(model, "run_windows", None)
    if (isinstance(model.source, (list, tuple)) and runs is not None
            and len(runs) == len(model.source)):
        return [(str(path), tuple(w)) for path, w in zip(model.source, runs)]
    raise InputError("intervals need the model's fitting data (its source file(s) and the "
                     "window of each)")


def fitting_windows(model) -> list:
    """The model's fitting window(s) discretised in its state space at its lag, as it was
    fitted (a window at the file's start, of a space with memory: the frames with the
    history it needs, ``short_history="skip"``), one per run of :func:`fitting_runs`: what
    the bootstrap counts (``discrete`` of :func:`bootstrap_figures`, read here where not
    given).

    Returns
    -------
    list of cfbmarkov.markov.discrete.DiscreteTrajectories

    Raises
    ------
    InputError
        As :func:`fitting_runs`, or where a file cannot be read or the window lies outside
        it (:func:`cfbmarkov.markov.discrete.discretize`).
    """
    from cfbmarkov.markov.discrete import discretize

    return [discretize(source, model.state_space, model.lag, window, short_history="skip")
            for source, window in fitting_runs(model)]


def _resampled_rtd(model, window_length: float, direction: str, entry,
                   deficit_levels: int | None = None, occupancy=None):
    """A resampled model's RTD in the window, from the fitted model's entry distribution
    (one sparse LU per resample saved: the spread of the entry distribution is left out,
    that of the transitions kept), on ``deficit_levels`` lap deficits (None: as deep as
    its residences fall); a periodic riser's in a window as the window counts its records,
    its particles starting in ``occupancy`` (the fitted model's:
    :func:`~cfbmarkov.markov.first_passage.window_rtd`)."""
    from cfbmarkov.markov.first_passage import exact_rtd, rtd_of_split_chain, window_rtd

    if isinstance(model, _SplitChain):
        up, down = (model.up, model.down) if direction == "up" else (model.down, model.up)
        if window_length is not None:
            return window_rtd(up, down, model.stay, model.lag, window_length, occupancy,
                              deficit_levels)
        return rtd_of_split_chain(up, down, model.stay, model.lag, deficit_levels,
                                  max_steps=200_000, entry=entry)
    if Boundary(model.boundary).is_open or entry is None:
        return model.rtd(window_length, direction, occupancy)
    up, down = ((model.up_fraction, model.down_fraction) if direction == "up"
                else (model.down_fraction, model.up_fraction))
    if window_length is not None:
        from cfbmarkov.markov.first_passage import split_by_pass

        return window_rtd(*split_by_pass(model.transition_matrix, up, down), model.lag,
                          window_length, occupancy, deficit_levels)
    return exact_rtd(model.transition_matrix, up, down, model.lag, deficit_levels,
                     max_steps=200_000, entry=entry)


def _resampled_intrinsic(chain, direction: str, entry, deficit_levels: int):
    """A resampled chain's intrinsic E(RT) and SD(RT), solved for
    (:func:`~cfbmarkov.markov.first_passage.rtd_moments`), its resolved mass, and its start
    on the levels, from which its RTD is propagated beside the other resamples' only as
    far as the last bin (:func:`_intrinsic_bins`; a long tail's lags beyond it are not
    needed: the bins' probabilities are of the whole mass). The figures of
    :func:`_resampled_rtd`, but for the tail of 1e-10 of the mass that its propagation
    leaves."""
    from cfbmarkov.markov.first_passage import rtd_moments_and_start

    up, down = (chain.up, chain.down) if direction == "up" else (chain.down, chain.up)
    total, mean, sd, start = rtd_moments_and_start(up, down, chain.stay, chain.lag,
                                                   deficit_levels, entry)
    return mean, sd, total, start


def _intrinsic_bins(solved: list, lag: float, edges: np.ndarray) -> list[np.ndarray]:
    """The RTD per bin of ``edges`` of each of :func:`_resampled_intrinsic`'s resamples,
    their heads propagated side by side (:func:`~cfbmarkov.markov.first_passage.heads`),
    each as a share of its resolved mass."""
    from cfbmarkov.markov.first_passage import heads

    if not solved:
        return []
    probabilities = heads([start for _, _, _, start in solved], _reach(edges, lag))
    return [_binned_lags(f, lag, edges, total)
            for f, (_, _, total, _) in zip(probabilities, solved)]


def _reach(edges: np.ndarray, lag: float) -> int:
    """The lags an RTD must hold for its probabilities in every bin of ``edges``."""
    return int(round(float(edges[-1]) / lag)) + 1


#: a resample's moments are solved for, and its RTD propagated only as far as the bins
#: reach, where the fitted model's RTD runs this many times longer than the bins (else the
#: propagation of the whole RTD costs less than the solves)
SOLVED_TAIL = 4
#: and where its chain on the levels has at most this many (state, level) pairs: the LU of
#: a larger one fills in (a 1596-state memory on 9 levels: 0.07 s a resample, against
#: 0.02 s for the propagation it would save; 228 states: a few ms against 0.14 s)
SOLVED_PAIRS = 4000


def _binned(rtd, edges: np.ndarray, total: float | None = None) -> np.ndarray:
    """An exact RTD's probability per bin of ``edges``, with the sample histogram's rule
    for times on an edge (whole lags on bins of one lag fall in the bin they start), as a
    share of ``total`` (default: the RTD's resolved mass)."""
    return _binned_lags(rtd.probability, rtd.lag, edges,
                        rtd.probability.sum() if total is None else total)


def _binned_lags(probability: np.ndarray, lag: float, edges: np.ndarray,
                 total: float) -> np.ndarray:
    """:func:`_binned` of the probabilities of residences of 1, 2, ... lags."""
    width = float(edges[1] - edges[0])
    times = lag * np.arange(1, probability.size + 1)
    hist, _ = np.histogram(times + 1e-6 * width, bins=edges, weights=probability / total)
    return hist


def block_bootstrap_models(model, *, blocks: int = BOOTSTRAP_BLOCKS, resamples: int = 100,
                           seed: int = 0, discrete=None):
    """Models fitted on block-bootstrap resamples of a model's fitting window.

    The fitting window (re-read from the model's source file) is cut into ``blocks``
    contiguous time blocks and the transitions of each counted (with the model's
    estimator's rule); the frame pairs (t, t + lag) are split by their first frame, so
    that every pair of the window is counted in exactly one block. Each resample draws
    ``blocks`` blocks with replacement, sums their counts and forms a model with the same
    estimator, state space and lag. The data are read and counted once; each resample costs
    one estimate. A model fitted on several runs (:func:`fitting_runs`) has ``blocks``
    blocks in each run's window, and a resample draws ``blocks`` of each run's own blocks
    (a stratified block bootstrap: every run keeps its weight in every resample).

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
    discrete : list of DiscreteTrajectories, optional
        The fitting windows already discretised (:func:`fitting_windows`, one per run);
        read from the files where not given.

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

    totals = _bootstrap_counts(model, blocks, resamples, seed, sparse=False,
                               discrete=discrete)
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


def _bootstrap_counts(model, blocks: int, resamples: int, seed: int, sparse: bool,
                      discrete=None):
    """The summed counts of each block-bootstrap resample of the model's fitting window
    (:func:`block_bootstrap_models`; dense, or scipy.sparse with ``sparse``). Checks and
    counts on the call; the sums are formed as the iterator is consumed. ``discrete``: the
    fitting windows already discretised (:func:`fitting_windows`), one per run."""
    from cfbmarkov.markov.counting import block_face_counts, count_transitions

    if int(blocks) < 2 or int(resamples) < 1:
        raise InputError(f"a block bootstrap needs at least 2 blocks and 1 resample ({blocks}, "
                         f"{resamples})")
    blocks = int(blocks)
    frame_average = model.estimator == "paper"
    counts = []           # blocks of run r at counts[r * blocks: (r + 1) * blocks]
    runs = fitting_runs(model)
    discrete = fitting_windows(model) if discrete is None else _checked_windows(
        model, runs, discrete)
    for (source, window), frames in zip(runs, discrete):
        # the frame pairs (t, t + lag) are split, by their first frame, into contiguous
        # blocks: each pair is counted in exactly one block, none across a block's edge lost
        lag_frames = int(frames.lag_frames)
        pairs = frames.times.size - lag_frames
        if pairs < blocks:
            raise InputError(f"the fitting window {window[0]:g}-{window[1]:g} s of {source} "
                             f"holds {max(pairs, 0)} frame pairs one lag apart, fewer than the "
                             f"{blocks} bootstrap blocks")
        cuts = np.rint(np.linspace(0, pairs, blocks + 1)).astype(np.int64)
        times = frames.times
        block_counts = [count_transitions(frames.block(float(times[a]),
                                                       float(times[b - 1 + lag_frames])),
                                          frame_average=frame_average, sparse=sparse)
                        for a, b in zip(cuts[:-1], cuts[1:])]
        if block_counts[0].faces is not None:
            # an open riser's entries and returns read with the frames before each block:
            # a fall back out through the inlet across a block's edge stays a return
            block_counts = [dataclasses.replace(c, faces=f) for c, f in
                            zip(block_counts, block_face_counts(frames, cuts))]
        counts += block_counts
    runs = len(counts) // blocks
    rng = np.random.default_rng(seed)
    stacked = _StackedCounts(counts) if sparse and counts[0].faces is None else None

    def draw():
        for _ in range(int(resamples)):
            # blocks of each run drawn from that run's own (one run: as before)
            picked = np.concatenate([r * blocks + rng.integers(0, blocks, blocks)
                                     for r in range(runs)])
            if stacked is not None:
                # the sums formed where the resample's figures are (a worker thread)
                yield _Resample(stacked, np.bincount(picked, minlength=len(counts)))
                continue
            total = counts[picked[0]]
            for k in picked[1:]:
                total = total + counts[k]
            yield total

    return draw()


def _checked_windows(model, runs, discrete) -> list:
    """``discrete`` as a list, refused in one line unless it holds each of ``runs``' fitting
    window in the model's state space and lag, read from that run's file: the interval is
    of the model's own fitting data or none."""
    import os

    from cfbmarkov.markov.discrete import DiscreteTrajectories

    discrete = list(discrete)
    if len(discrete) != len(runs):
        raise InputError(f"{len(discrete)} discretised windows for a model fitted on "
                         f"{len(runs)} run(s): give one per run, or none")
    from cfbmarkov.markov.discrete import held_window

    fix = "give those of bootstrap.fitting_windows(model), or none"
    for k, (frames, (source, window)) in enumerate(zip(discrete, runs)):
        if not isinstance(frames, DiscreteTrajectories):
            raise InputError(f"discretised window {k + 1} is a {type(frames).__name__}, not "
                             f"a DiscreteTrajectories: {fix}")
        lag = frames.lag_frames * frames.frame_interval
        if (frames.state_space != model.state_space
                or not math.isclose(lag, model.lag, rel_tol=1e-6)
                or frames.window is None
                or not all(math.isclose(a, b, abs_tol=1e-9)
                           for a, b in zip(frames.window, held_window(source, window)))
                or os.path.realpath(str(frames.source)) != os.path.realpath(str(source))):
            raise InputError(f"discretised window {k + 1} is not the model's fitting window "
                             f"(its file, state space, lag or window differs): {fix}")
    return discrete


@dataclass(frozen=True)
class _Resample:
    """One resample of :class:`_StackedCounts`: block b taken ``times[b]`` times; its
    counts (:meth:`counts`) or its chain (:meth:`_StackedCounts.split_chain`) formed where
    it is used."""

    stacked: "_StackedCounts"
    times: np.ndarray

    def counts(self):
        return self.stacked.total(self.times)


class _StackedCounts:
    """The sparse counts of B blocks on the union of their non-zeros, stacked [B, nnz] per
    field, so that a resample's total (each block times the number of times it was drawn)
    is one product per field instead of B - 1 sparse sums."""

    FIELDS = ("counts", "counts_up", "counts_down", "frame_average_sum")

    def __init__(self, counts):
        import scipy.sparse as sp

        s = counts[0].counts.shape[0]
        self.s = s
        coos = {name: [None if getattr(c, name) is None else sp.coo_array(getattr(c, name))
                       for c in counts] for name in self.FIELDS}
        keys = np.unique(np.concatenate(
            [np.asarray(m.row, np.int64) * s + m.col for ms in coos.values() for m in ms
             if m is not None] + [np.zeros(0, np.int64)]))
        self.indices = (keys % s).astype(np.int64)
        self.indptr = np.searchsorted(keys // s, np.arange(s + 1)).astype(np.int64)
        self.stacks = {}
        for name, ms in coos.items():
            if any(m is None for m in ms):
                self.stacks[name] = None
                continue
            stack = np.zeros((len(ms), keys.size))
            for b, m in enumerate(ms):
                np.add.at(stack[b], np.searchsorted(keys, np.asarray(m.row, np.int64) * s + m.col),
                          m.data)
            self.stacks[name] = stack
        self.occupied = np.stack([np.asarray(c.occupied_frames) for c in counts])
        self.frame_pairs = np.array([int(c.frame_pairs) for c in counts], np.int64)
        self.integer = {name: np.issubdtype(getattr(counts[0], name).dtype, np.integer)
                        for name in self.FIELDS if self.stacks[name] is not None}

    def total(self, times: np.ndarray):
        """The summed counts with block b taken ``times[b]`` times."""
        import scipy.sparse as sp

        from cfbmarkov.markov.counting import TransitionCounts

        weights = times.astype(np.float64)
        fields = {}
        for name, stack in self.stacks.items():
            if stack is None:
                fields[name] = None
                continue
            data = weights @ stack
            if self.integer[name]:
                data = np.rint(data).astype(np.int64)
            matrix = sp.csr_array((data, self.indices.copy(), self.indptr.copy()),
                                  shape=(self.s, self.s))
            matrix.eliminate_zeros()
            fields[name] = matrix
        occupied = (times @ self.occupied).astype(self.occupied.dtype)
        return TransitionCounts(fields["counts"], fields["counts_up"], fields["counts_down"],
                                fields["frame_average_sum"], occupied,
                                int(times @ self.frame_pairs))

    def split_chain(self, times: np.ndarray, weights: str):
        """The resample's chain split by pass direction, (P_up, P_down, P_stay) as
        :meth:`~cfbmarkov.markov.estimate.TransitionEstimator.split_chain` forms it from
        :meth:`total`'s counts: the same operations on each non-zero (row sums by the same
        numpy reduction), so the same bits, in a few numpy operations on the stacked
        non-zeros instead of a dozen scipy.sparse ones, whose Python overhead holds the
        GIL that the threads computing the resamples' figures share. ``weights``: the
        field whose rows are normalised (``counts``: maximum likelihood;
        ``frame_average_sum``: the paper's). None where a state is never left in the
        resample (the estimator fills its row from its cell, or keeps it in place:
        :meth:`total`'s counts and the estimator then)."""
        import scipy.sparse as sp

        names = ("counts", "counts_up", "counts_down", weights)
        if any(self.stacks.get(name) is None for name in names):
            return None
        fields = {}
        for name in names:
            data = times.astype(np.float64) @ self.stacks[name]
            if self.integer[name]:      # as total(): whole counts, then float64
                data = np.rint(data).astype(np.int64).astype(np.float64)
            fields[name] = data
        c, w = fields["counts"], fields[weights]
        lengths = np.diff(self.indptr)
        rows = np.repeat(np.arange(self.s), lengths)
        counted = c != 0.0
        if np.bincount(rows[counted], minlength=self.s).min() == 0:
            return None                # a state never left: the estimator's fill
        # the weights' row sums as scipy sums a CSR matrix's rows (np.add.reduceat over
        # the non-zeros of each non-empty row): the same bits
        nonzero = w != 0.0
        ends = np.concatenate([[0], np.cumsum(nonzero)])[self.indptr]
        filled = np.flatnonzero(ends[1:] > ends[:-1])
        totals = np.zeros(self.s)
        totals[filled] = np.add.reduceat(w[nonzero], ends[:-1][filled])
        scale = np.divide(1.0, totals, out=np.zeros_like(totals), where=totals > 0)
        inverse = np.divide(1.0, c, out=np.zeros_like(c), where=counted)
        share = (scale[rows] * w) * inverse        # P_ij / C_ij on the counted pairs
        up, down = fields["counts_up"], fields["counts_down"]
        parts = []
        for values in (up, down, (c - up) - down):
            part = share * values
            keep = part != 0.0
            indptr = np.concatenate([[0], np.cumsum(keep)])[self.indptr]
            parts.append(sp.csr_matrix((part[keep], self.indices[keep], indptr),
                                       shape=(self.s, self.s)))
        return tuple(parts)


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
    chain_of = _split_chain_former(model)
    for total in _bootstrap_counts(model, blocks, resamples, seed, sparse=True):
        yield chain_of(total)


def _split_chain_former(model):
    """The function that turns a resample's sparse counts into its :class:`_SplitChain`
    (:func:`_bootstrap_chains`), for the threads that compute the resamples' figures."""
    from cfbmarkov.markov.estimate import estimator_from_name

    estimator = estimator_from_name(model.estimator, model.state_space, model.lag)

    weights = "frame_average_sum" if model.estimator == "paper" else "counts"

    def chain_of(total) -> _SplitChain:
        if isinstance(total, _Resample):
            parts = total.stacked.split_chain(total.times, weights)
            if parts is not None:
                return _SplitChain(*parts, model.state_space, model.lag)
            total = total.counts()
        return _SplitChain(*estimator.split_chain(total), model.state_space, model.lag)

    return chain_of


def check_interval_options(level: float, resamples: int, blocks: int = 2,
                           fix: str = "more resamples, or a lower level") -> None:
    """Refuse an interval's options that cannot give it: a level outside (0, 1), fewer than
    2 blocks or 10 resamples, too few resamples to reach the level's tails, or a level so
    low that its bounds lie within two resamples of each other.

    A percentile interval's bounds are the bootstrap's (1 - level)/2 and (1 + level)/2
    quantiles; with fewer than 1 / (1 - level) resamples each tail holds less than half a
    resample, so both bounds are the extreme resamples whatever the level, and a 99.9999 %
    interval from 10 resamples comes out narrower than the 90 % one (Efron & Tibshirani
    1993, Ch. 13 and 19: some thousand resamples for 95 % bounds).

    Parameters
    ----------
    level : float
        The interval's coverage.
    resamples, blocks : int
        Of the block bootstrap.
    fix : str, optional
        What the message names as the cure for too few resamples.

    Raises
    ------
    InputError
        Naming the problem and what to change (also a level that is not a number, blocks
        or resamples that are not whole numbers).
    """
    if isinstance(level, (bool, str, bytes)) or not isinstance(level, numbers.Real) \
            or not 0.0 < float(level) < 1.0:
        raise InputError(f"interval level {level!r} must be a number strictly between 0 "
                         "and 1")
    for name, value in (("blocks", blocks), ("resamples", resamples)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise InputError(f"{name} {value!r} must be a whole number")
    if int(blocks) < 2 or int(resamples) < 10:
        raise InputError(f"intervals need at least 2 blocks and 10 resamples ({blocks}, "
                         f"{resamples})")
    if float(level) * int(resamples) < 2.0:
        # the bounds' quantiles lie within two resamples of each other: the interval is the
        # gap between neighbouring resamples, whatever the level (a "1e-10 %" interval came
        # out as wide as the 1 % one)
        raise InputError(f"a {100 * float(level):.3g} % interval spans fewer than 2 of the "
                         f"{int(resamples)} bootstrap resamples, so its bounds are a gap "
                         "between neighbouring resamples whatever the level: give a level "
                         f"of at least {2.0 / int(resamples):.3g} (e.g. 0.9)")
    needed = int(math.ceil(1.0 / (1.0 - float(level)) - 1e-9))
    if int(resamples) < needed:
        raise InputError(f"a {100 * float(level):g} % interval needs at least {needed} "
                         f"bootstrap resamples (each of its tails holds "
                         f"{50 * (1 - float(level)):.3g} % of them; from {int(resamples)} its "
                         f"bounds would be the extreme resamples, narrower than the level "
                         f"says): {fix}")


class FlowVariability(NamedTuple):
    """The flow's variability between windows (:func:`flow_variability`)."""

    #: relative standard deviation of a window's E(RT) (fraction)
    mean: float
    #: relative standard deviation of a window's SD(RT) (fraction)
    sd: float
    #: degrees of freedom of the two estimates: the blocks compared, less one per group
    #: of blocks compared among themselves (one group, or one per run with ``within_runs``)
    degrees_of_freedom: int


def flow_quantile(level: float, degrees_of_freedom: int | None = None) -> float:
    """The multiplier of the flow's standard deviation in an interval at ``level``: Student's
    t quantile at (1 + level) / 2 with the estimate's degrees of freedom, the normal one
    where they are not known (None: intervals stored without them).

    A standard deviation estimated from B blocks carries B - 1 degrees of freedom; a
    prediction interval for one more window's value built on it takes Student's t, not the
    normal quantile, which would cover less than stated (90 % intervals from two blocks:
    t = 6.31 against z = 1.64).

    References
    ----------
    G. J. Hahn and W. Q. Meeker, Statistical Intervals, Wiley (1991), Ch. 4 (prediction
    intervals for a normal distribution with estimated variance).
    """
    p = 0.5 * (1.0 + float(level))
    if degrees_of_freedom is None:
        return float(ndtri(p))
    if int(degrees_of_freedom) < 1:
        raise InputError(f"the flow's variability needs at least 1 degree of freedom "
                         f"({degrees_of_freedom})")
    return float(stdtrit(int(degrees_of_freedom), p))


def flow_variability(model, window_length: float, *, direction: str | None = None,
                     blocks: int = FLOW_BLOCKS, within_runs: bool = False,
                     sampling: bool = False) -> FlowVariability | None:
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

    A model fitted on several runs (:func:`fitting_runs`) has the blocks of every run's
    window (as many as fit in each, by the same rule, from the E(RT) of all the runs'
    residences), each compared with all the others pooled: the spread then holds the
    differences between the runs too. With ``within_runs`` each block is compared with the
    other blocks of its own run only (runs with fewer than two blocks left out): the flow's
    variability within the runs, without their differences.

    Parameters
    ----------
    model : cfbmarkov.markov.MarkovModel
        The fitted model; its fitting windows are re-read from its source file(s).
    window_length : float
        Length of the analysis window (s).
    direction : {"up", "down"}, optional
        The direction residences are counted in; default the model's ``flow_direction``.
    blocks : int, optional
        The most blocks B of the fitting window (at least 2).
    within_runs : bool, optional
        Compare each block with the other blocks of its own run only (a pooled fit's
        within-run variability; default False: with all the other blocks).
    sampling : bool, optional
        Keep the blocks' own sampling in the spread (how much one window's *observed*
        figure moves: `compare`'s prediction intervals, whose other terms carry the fitting
        window's and the prediction's sampling but not the reference window's); default
        False: the spread beyond it (the model's own interval, whose block bootstrap
        carries that sampling already).

    Returns
    -------
    FlowVariability or None
        The relative standard deviations of a window's E(RT) and SD(RT) (fractions) and
        their degrees of freedom (the blocks compared less one per group: an interval takes
        Student's t with them, :func:`flow_quantile`); None where the window is shorter
        than two such blocks, or fewer than two blocks hold two residences each (no spread
        can be told).

    Raises
    ------
    InputError
        For a model without its fitting data (:func:`fitting_runs`), or fewer than 2 blocks.

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
    direction = model.flow_direction if direction is None else direction
    runs = fitting_runs(model)
    with contextlib.ExitStack() as stack:
        # each file opened once: its frames' checks and reads serve the whole window and
        # its blocks
        files = [stack.enter_context(opened(source)) for source, _ in runs]

        def samples(traj, window):
            return residence_times(traj, window, use_events=False,
                                   lag_frames=traj.lag_frames(model.lag), direction=direction,
                                   split_at_absences=True,
                                   face_band=traj.height / model.state_space.rows).samples

        pooled = np.concatenate([samples(traj, window)
                                 for traj, (_, window) in zip(files, runs)])
        if pooled.size < 2:
            return None
        observed, lengths, group = [], [], []
        for r, (traj, (_, (a, b))) in enumerate(zip(files, runs)):
            # blocks at least FLOW_BLOCK_RESIDENCES mean residences long, so that a block's
            # own window cuts off few of its residences
            n = min(int(blocks), int((b - a) / (FLOW_BLOCK_RESIDENCES * pooled.mean())))
            if n < 1 or (n < 2 and (len(runs) == 1 or within_runs)):
                continue
            cuts = a + (b - a) * np.arange(n + 1) / n
            observed += [samples(traj, (float(cuts[k]), float(cuts[k + 1])))
                         for k in range(n)]
            lengths += [(b - a) / n] * n
            group += [r if within_runs else 0] * n
    if len(observed) < 2:
        return None
    rel_mean, rel_sd, noise_mean, noise_sd, compared = [], [], [], [], set()
    for k, block in enumerate(observed):
        others = np.concatenate([o for j, o in enumerate(observed)
                                 if j != k and group[j] == group[k]])
        if block.size < 2 or others.size < 2:
            continue
        ratio = block.mean() / others.mean()
        rel_mean.append(ratio - 1.0)
        noise_mean.append(ratio * ratio * (_mean_noise(block) + _mean_noise(others)))
        compared.add(group[k])
        spread = others.std(ddof=1)
        if spread > 0:
            ratio = block.std(ddof=1) / spread
            rel_sd.append(ratio - 1.0)
            noise_sd.append(ratio * ratio * (_sd_noise(block) + _sd_noise(others)))
    if len(rel_mean) < 2:
        return None
    # blocks in each comparison (their mean over the blocks, within_runs: per run)
    count = float(np.mean([group.count(g) for g in group]))
    block = float(np.mean(lengths))
    factor = np.sqrt((count - 1.0) / count) * max(1.0, np.sqrt(block / float(window_length)))
    if sampling:
        noise_mean, noise_sd = [0.0] * len(rel_mean), [0.0] * len(rel_sd)
    return FlowVariability(_beyond_noise(rel_mean, noise_mean) * factor,
                           _beyond_noise(rel_sd, noise_sd) * factor,
                           max(len(rel_mean) - len(compared), 1))


def _mean_noise(samples: np.ndarray) -> float:
    """The squared relative standard error of a sample's mean, CV^2 / n."""
    return float(samples.var(ddof=1) / samples.mean() ** 2 / samples.size)


def _sd_noise(samples: np.ndarray) -> float:
    """The squared relative standard error of a sample's SD, (kurtosis - 1) / (4 n) (the
    delta method on the variance's sampling variance; Kendall & Stuart, Vol. 1, 10.7)."""
    centred = samples - samples.mean()
    variance = float(np.mean(centred ** 2))
    kurtosis = float(np.mean(centred ** 4)) / variance ** 2 if variance > 0 else 3.0
    return max(kurtosis - 1.0, 0.0) / (4.0 * samples.size)


def _beyond_noise(relative: list[float], noise: list[float]) -> float:
    """The RMS of the blocks' relative differences with their sampling part taken out:
    sqrt(max(mean(d^2) - mean(noise), 0)), noise each difference's squared standard error
    from its two samples (the method of moments of a one-way random-effects model: the
    spread between blocks less what their own residences' scatter gives; Searle, Casella
    and McCulloch, Variance Components, Wiley 1992, Ch. 3). The block bootstrap carries
    that sampling already; left in, a window of few residences per block (tracks of a
    second, a tracer or three) counted it twice, its interval 3 to 10 times too wide."""
    if not relative:
        return 0.0
    excess = float(np.mean(np.square(relative)) - np.mean(noise))
    return float(np.sqrt(max(excess, 0.0)))


def bootstrap_figures(model, window_length: float | None, direction: str, entry, edges,
                      blocks: int, resamples: int, seed: int, curve=None,
                      deficit_levels: int | None = None, occupancy=None, discrete=None):
    """E(RT), SD(RT) and the RTD per bin of ``edges`` of each block-bootstrap resample of
    the model's fitting window (and, with ``curve`` = (lags, states, left), its expected
    mixing curve at those lags): the model's spread, shared by both kinds of interval.

    Parameters
    ----------
    model : MarkovModel
        The fitted model (its fitting window is re-read and counted once per block).
    window_length : float or None
        The analysis window (s): each resample's RTD as seen in it; None: the intrinsic RTD.
    direction : {"up", "down"}
        The direction residences are counted in.
    entry : ndarray of float64, shape (S,), or None
        The fitted model's entry distribution, each resample's RTD started from it (None:
        each resample's own).
    edges : ndarray, shape (B + 1,)
        RTD bin edges (s).
    blocks, resamples, seed : int
        Of the bootstrap (:func:`block_bootstrap_models`).
    curve : (ndarray of int, ndarray of int, ndarray of bool), optional
        Lags, tracers' states and left group of a mixing curve.
    deficit_levels : int, optional
        The lap deficits each resample's exact RTD keeps (a periodic riser's; None: as
        deep as its residences fall, :func:`~cfbmarkov.markov.first_passage.exact_rtd`).
    occupancy : ndarray of float64, shape (S,), optional
        With ``window_length``, where the window's particles start (default the fitted
        model's :func:`~cfbmarkov.markov.model_rtd.window_start_occupancy`).
    discrete : list of DiscreteTrajectories, optional
        The fitting windows already discretised (:func:`fitting_windows`); read where not
        given.

    Returns
    -------
    means, sds : list of float
        Of the resamples with residences (s).
    rtds : list of ndarray, shape (B,)
        Their probability per bin.
    curves : list of ndarray
        Their mixing curves at the lags (every resample; empty without ``curve``).
    """
    from cfbmarkov.analysis.mixing import model_mixing_curve

    if window_length is not None and occupancy is None and not Boundary(model.boundary).is_open:
        from cfbmarkov.markov.model_rtd import window_start_occupancy

        occupancy = window_start_occupancy(model, direction)
    chain_of = None
    if (not Boundary(model.boundary).is_open and not model.connected and entry is not None
            and direction in ("up", "down")):
        # the resamples' RTDs and mixing curves from sparse chains (no [S, S] model each),
        # each formed from its counts in the thread that computes its figures
        drawn = _bootstrap_counts(model, blocks, resamples, seed, sparse=True,
                                  discrete=discrete)
        chain_of = _split_chain_former(model)
    else:
        drawn = block_bootstrap_models(model, blocks=blocks, resamples=resamples, seed=seed,
                                       discrete=discrete)
    # a long tail beyond the bins, a small chain: the resamples' moments solved for
    # (_resampled_intrinsic)
    solve = (window_length is None and deficit_levels is not None and entry is not None
             and direction in ("up", "down")
             and model.n_states * (deficit_levels + 1) <= SOLVED_PAIRS
             and model.rtd(None, direction).probability.size
             > SOLVED_TAIL * _reach(edges, model.lag))

    def figures(resampled):
        if chain_of is not None:
            resampled = chain_of(resampled)
        mixing = None
        if curve is not None:      # the transitions' spread; defined with or without residences
            mixing = model_mixing_curve(resampled, curve[1], curve[2],
                                        int(curve[0].max()))[0][curve[0]]
        try:
            if solve and isinstance(resampled, _SplitChain):
                # the moments solved; the head propagated below, beside the others'
                return mixing, _resampled_intrinsic(resampled, direction, entry,
                                                    deficit_levels)
            rtd = _resampled_rtd(resampled, window_length, direction, entry, deficit_levels,
                                 occupancy)
        except (CfbmarkovError, ValueError):
            return mixing, None      # a resample without residences: no figure
        return mixing, (rtd.mean, rtd.sd, _binned(rtd, edges))

    means, sds, rtds, curves, solved = [], [], [], [], []
    for mixing, figure in _in_threads(figures, drawn):
        if mixing is not None:
            curves.append(mixing)
        if figure is not None:
            means.append(figure[0])
            sds.append(figure[1])
            if len(figure) == 4:
                solved.append(figure)
            else:
                rtds.append(figure[2])
    if solved:
        rtds = _intrinsic_bins(solved, model.lag, edges)
    return means, sds, rtds, curves


def _in_threads(function, items):
    """``function`` of each of ``items``, in their order, computed by as many threads as
    Numba's thread count (each running its kernels on one thread: the exact RTD's
    propagation releases the GIL), a few items ahead at most, so that the resampled models
    are not all held at once. Each result depends on its item alone: the same results for
    any thread count."""
    import numba

    workers = numba.get_num_threads()
    if workers <= 1:
        yield from map(function, items)
        return
    pool = ThreadPoolExecutor(max_workers=workers, initializer=numba.set_num_threads,
                              initargs=(1,))
    pending: deque = deque()
    # one BLAS thread (a process-wide limit) held for the whole pool: the resamples' small
    # LU factorisations on the process's default BLAS threads would change their last bits
    with one_blas_thread():
        try:
            # each item submitted as it is formed, so that forming the next ones (the
            # bootstrap counts' sums, under the GIL) overlaps the threads' work on the
            # earlier ones
            for item in items:
                pending.append(pool.submit(function, item))
                if len(pending) >= 2 * workers:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        finally:    # on Ctrl-C: the items not started are dropped, the running ones finish
            pool.shutdown(wait=True, cancel_futures=True)


def interval_bounds(value, boot, centre, level: float, se=0.0, se_flow=0.0,
                    flow_degrees_of_freedom: int | None = None, *, blocks: int,
                    runs: int = 1):
    """An interval at ``level`` centred on ``value``: each half-width is the distance from
    ``centre`` (the fitted model's exact value) to the bootstrap's (1 - level)/2 or
    (1 + level)/2 quantile of ``boot`` (along axis 0) times :func:`bootstrap_widening`
    (the bootstrap drew ``blocks`` blocks of each of ``runs`` runs), z times the standard
    error ``se`` (Monte Carlo) and :func:`flow_quantile` (Student's t with
    ``flow_degrees_of_freedom``) times ``se_flow`` (the flow's), added in quadrature.

    Returns
    -------
    (lower, upper)
        Floats or arrays as ``value``.
    """
    lo_q, hi_q = 0.5 * (1 - level), 0.5 * (1 + level)
    z = float(ndtri(hi_q))
    widening = bootstrap_widening(level, blocks, runs)
    lo, hi = np.quantile(boot, [lo_q, hi_q], axis=0)
    noise = (z * se) ** 2 + (flow_quantile(level, flow_degrees_of_freedom) * se_flow) ** 2
    down = np.sqrt((widening * np.maximum(centre - lo, 0.0)) ** 2 + noise)
    up = np.sqrt((widening * np.maximum(hi - centre, 0.0)) ** 2 + noise)
    return value - down, value + up
