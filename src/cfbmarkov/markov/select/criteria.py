"""The criteria that judge a candidate on the judged blocks, behind one interface.

:class:`Criterion` is what the choice asks of a criterion: the counts a candidate is fitted
on for each judged block, one row of numbers per block, the candidate's score from its rows,
the units of the bias terms, and the words of the record. Its three implementations:

:class:`WindowRTD` (``criterion="window"``)
    The candidate's exact RTD over the whole fitting window against the one observed there;
    score MD / MD(cells).
:class:`CrossValidatedRTD` (``criterion="rtd"``)
    Blocked cross-validation of the RTD: fitted on the other blocks, judged on the held-out
    block's RTD; score |mean PD E(RT)| / u_E + |mean PD SD(RT)| / u_SD + mean MD / mean
    MD(cells).
:class:`HeldOutCK` (``criterion="ck"``)
    Blocked cross-validation of the Chapman-Kolmogorov test on coarse groups; score the mean
    absolute error relative to that of the paper's cells.
"""

from __future__ import annotations

import functools
import math
import operator
from abc import ABC, abstractmethod
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from cfbmarkov.markov.discrete import DiscreteTrajectories
from cfbmarkov.markov.first_passage import window_rtd
from cfbmarkov.markov.groups import core_annulus, group_labels, height_bands, product_groups
from cfbmarkov.markov.select.blocks import MIN_RESIDENCES, JudgedBlocks
from cfbmarkov.markov.select.record import CandidateScore
from cfbmarkov.observed.metrics import minkowski_distance, percentage_difference
from cfbmarkov.observed.residence import rtd_histogram

#: the goals for a model's bias (%): the units of the score's PD terms on a steady flow
GOAL_PD_MEAN, GOAL_PD_SD = 2.0, 10.0
#: the CK criterion's times, in base lags
CK_LAG_MULTIPLES = np.arange(2, 21, 2)


class Criterion(ABC):
    """How candidates are judged on the judged blocks of the fitting window.

    A candidate is judged block by block: for judged block k it is fitted on the counts
    :meth:`training` gives, and :meth:`judge` returns one row of numbers; :meth:`score`
    turns the rows into its :class:`~cfbmarkov.markov.select.record.CandidateScore`.

    Parameters
    ----------
    fitting : JudgedBlocks
        The judged blocks and what was observed there.
    lag : float
        The base lag, s.
    """

    #: the name (``criterion`` of :func:`~cfbmarkov.markov.select.choice.select_model`)
    name = ""
    #: the column of a candidate's rows that must be finite for it to be scored; its mean
    #: over the blocks for the paper's cells is the reference of the score
    column = 2

    def __init__(self, fitting: JudgedBlocks, lag: float):
        self.fitting = fitting
        self.lag = lag

    def training(self, parts: list, k: int):
        """The counts a candidate is fitted on to be judged on judged block ``k``: those of
        the other blocks.

        Parameters
        ----------
        parts : list of TransitionCounts
            The candidate's counts in each block of ``fitting.blocks``.
        k : int
            The judged block.

        Returns
        -------
        TransitionCounts
        """
        return functools.reduce(operator.add, parts[:k] + parts[k + 1:])

    @abstractmethod
    def judge(self, discrete: DiscreteTrajectories, k: int, estimator, training,
              lag: float) -> tuple[float, ...]:
        """One candidate's numbers on judged block ``k``.

        Parameters
        ----------
        discrete : DiscreteTrajectories
            The candidate's states over the fitting window.
        k : int
            The judged block.
        estimator : TransitionEstimator
            The candidate's estimator.
        training : TransitionCounts
            The counts it is fitted on (:meth:`training`).
        lag : float
            The candidate's lag, s.

        Returns
        -------
        tuple of float
            One row of the candidate's table.

        Raises
        ------
        CfbmarkovError
            Where the candidate cannot be fitted or judged.
        """

    @cached_property
    def units(self) -> tuple[float, float]:
        """The units of the score's |PD E(RT)| and |PD SD(RT)| terms, %: the goals."""
        return GOAL_PD_MEAN, GOAL_PD_SD

    @abstractmethod
    def score(self, states: str, lag: float, n_states: int, table: np.ndarray,
              reference: float) -> CandidateScore:
        """A judged candidate's score.

        Parameters
        ----------
        states : str
            The state space's name.
        lag : float
            The candidate's lag, s.
        n_states : int
            Its number of states.
        table : ndarray of float64, shape (K, C)
            Its rows (:meth:`judge`) over the K judged blocks.
        reference : float
            The paper's cells' mean of :attr:`column` (1 where it is not positive).

        Returns
        -------
        CandidateScore
        """

    @abstractmethod
    def method(self) -> str:
        """The method as the selection record names it."""

    @abstractmethod
    def reason(self, best: CandidateScore, cells: CandidateScore | None) -> str:
        """Why ``best`` was chosen, in words (``cells``: the paper's cells, None if not judged);
        the numbers of every candidate are in the record's table
        (:func:`~cfbmarkov.markov.selection_table.candidate_columns`)."""


class _RTDCriterion(Criterion):
    """A criterion by the exact RTD of the candidate against the observed one; its rows are
    (PD E(RT) %, PD SD(RT) %, MD, E(RT) s, SD(RT) s)."""

    def __init__(self, fitting: JudgedBlocks, lag: float):
        super().__init__(fitting, lag)
        #: the observed RTD histogram of each judged block (bins one base lag wide)
        self.histograms = [rtd_histogram(o.samples, lag, window_length=blk[1] - blk[0])[1]
                           for o, blk in zip(fitting.observed, fitting.judged)]

    def judge(self, discrete, k, estimator, training, lag):
        # its RTD from where particles entered in the counts it was fitted on
        block, direction = self.fitting.judged[k], self.fitting.direction
        up, down, stay = estimator.split_chain(training)
        if direction == "down":     # the mirror image: in at the top, out below
            up, down = down, up
        # as the block's samples count them: records from its first frame, the particles
        # starting where the block's are
        rtd = window_rtd(up, down, stay, lag, block[1] - block[0],
                         _block_start_occupancy(discrete, block[0], up.shape[0]))
        observed, histogram = self.fitting.observed[k], self.histograms[k]
        return (percentage_difference(rtd.mean, observed.mean),
                percentage_difference(rtd.sd, observed.sd, scale=observed.mean),
                minkowski_distance(histogram, _exact_histogram(rtd, self.lag, histogram.size),
                                   2.0),
                rtd.mean, rtd.sd)

    @abstractmethod
    def _value(self, table: np.ndarray, reference: float) -> float:
        """The score from the table."""

    def score(self, states, lag, n_states, table, reference):
        return CandidateScore(states, lag, n_states, float(table[:, 3].mean()),
                              float(table[:, 4].mean()), float(table[:, 0].mean()),
                              float(table[:, 1].mean()), float(table[:, 2].mean()),
                              float(self._value(table, reference)))

    def reason(self, best, cells):
        reason = self._reason(best, cells)
        if self.fitting.direction == "down":
            reason += ("; residences counted downward, as the solids' net flow over the "
                       "fitting window runs")
        return reason

    @abstractmethod
    def _reason(self, best: CandidateScore, cells: CandidateScore | None) -> str:
        """:meth:`reason` before the direction is said."""


class WindowRTD(_RTDCriterion):
    """The RTD over the whole fitting window: fitted and judged on the window, score
    MD / MD(cells); the bias terms are recorded but do not judge (units NaN)."""

    name = "window"

    def training(self, parts, k):
        """All the counts of the window, whatever ``k``."""
        return functools.reduce(operator.add, parts)

    @cached_property
    def units(self) -> tuple[float, float]:
        """NaN: on the window itself only the shape judges."""
        return math.nan, math.nan

    def _value(self, table, reference):
        return table[:, 2].mean() / reference

    def method(self) -> str:
        return "the RTD over the fitting window"

    def _reason(self, best, cells):
        a, b = self.fitting.window
        observed = self.fitting.whole
        judged = self.fitting.judged
        if len(judged) > 1:         # pooled runs: each run's window judged
            where = (f"the fitting windows of {len(judged)} runs ("
                     + ", ".join(f"{lo:g}-{hi:g} s" for lo, hi in judged) + ")")
            seen, held = "each run's window", "the windows hold"
        else:
            where, seen, held = (f"the fitting window {a:g}-{b:g} s", f"a {b - a:g} s window",
                                 "the window holds")
        # what the table's percentages are against: the chain's RTD as a window of that
        # length sees it, against the window's observed one (not the intrinsic E(RT))
        return (f"{best.states} at lag {best.lag:g} s had the exact RTD closest to the one "
                f"observed over {where}; the percentages set the chain's RTD as seen in "
                f"{seen} (E(RT) {best.rt_mean:.3g} s) against the residences {held} whole, "
                f"E(RT) {observed.mean:.3g} s, SD(RT) {observed.sd:.3g} s")


class CrossValidatedRTD(_RTDCriterion):
    """Blocked cross-validation of the RTD: fitted on the other blocks, judged on the
    held-out block by bias (in :attr:`units`) and shape."""

    name = "rtd"

    @cached_property
    def units(self) -> tuple[float, float]:
        """The goals, or the blocks' own variability where larger (:func:`_natural_tolerances`)."""
        return _natural_tolerances(self.fitting.observed)

    def _value(self, table, reference):
        # the bias over the blocks: how the blocks' RTDs differ from one another (a
        # riser's clusters come and go) is noise no stationary model can predict
        unit_mean, unit_sd = self.units
        return (abs(table[:, 0].mean()) / unit_mean
                + abs(table[:, 1].mean()) / unit_sd + table[:, 2].mean() / reference)

    def method(self) -> str:
        return f"{self.fitting.folds}-fold blocked cross-validation of the RTD"

    def _reason(self, best, cells):
        a, b = self.fitting.window
        return (f"{best.states} at lag {best.lag:g} s had the lowest score in "
                f"{self.fitting.folds}-fold blocked cross-validation over {a:g}-{b:g} s")


class HeldOutCK(Criterion):
    """Blocked cross-validation of the Chapman-Kolmogorov test: fitted on the other blocks,
    judged by the held-out CK error (:func:`_held_out_ck_error`) at :attr:`times`; its rows
    are (CK error,)."""

    name = "ck"
    column = 0

    def __init__(self, fitting: JudgedBlocks, lag: float):
        super().__init__(fitting, lag)
        #: the CK test's times, s
        self.times = CK_LAG_MULTIPLES * lag

    def judge(self, discrete, k, estimator, training, lag):
        up, down, stay = estimator.split_chain(training)
        return (_held_out_ck_error(discrete.block(*self.fitting.judged[k]), up + down + stay,
                                   self.times),)

    def score(self, states, lag, n_states, table, reference):
        ck = float(table[:, 0].mean())
        return CandidateScore(states, lag, n_states, math.nan, math.nan, math.nan, math.nan,
                              math.nan, ck / reference, ck_error=ck)

    def method(self) -> str:
        return f"{self.fitting.folds}-fold blocked cross-validation of the Chapman-Kolmogorov test"

    def reason(self, best, cells):
        count = self.fitting.whole.count
        a, b = self.fitting.window
        why = (f"the fitting window holds only {count} complete residences (fewer "
               f"than {MIN_RESIDENCES}), so the RTD could not judge; "
               if count < MIN_RESIDENCES else "")
        return (f"{why}{best.states} at lag {best.lag:g} s had the lowest held-out "
                f"Chapman-Kolmogorov error in {self.fitting.folds}-fold blocked "
                f"cross-validation over {a:g}-{b:g} s")


#: the criteria by name
CRITERIA: dict[str, type[Criterion]] = {c.name: c for c in (WindowRTD, CrossValidatedRTD,
                                                            HeldOutCK)}


def criterion_for(fitting: JudgedBlocks, lag: float) -> Criterion:
    """The criterion ``fitting.criterion`` on the judged blocks ``fitting``.

    Parameters
    ----------
    fitting : JudgedBlocks
        The judged blocks (``criterion`` one of ``window``, ``rtd``, ``ck``).
    lag : float
        The base lag, s.

    Returns
    -------
    Criterion
    """
    return CRITERIA[fitting.criterion](fitting, lag)


def _exact_histogram(rtd, bin_width: float, n_bins: int) -> np.ndarray:
    index = np.floor(rtd.times / bin_width + 1e-6).astype(np.int64)
    keep = (index >= 0) & (index < n_bins)
    counts = np.bincount(index[keep], weights=rtd.probability[keep], minlength=n_bins)
    total = counts.sum()
    return counts / total if total > 0 else counts


def _natural_tolerances(observed) -> tuple[float, float]:
    """The units of the score's two bias terms (%): the goal, or the flow's own variability.

    Each block's observed E(RT) and SD(RT) are compared with those of the other blocks'
    residence times pooled (the persistence baseline inside the cross-validation); the RMS
    of those percentage differences over the blocks is how much the riser itself varies
    from one stretch of the window to the next. A candidate's bias smaller than that is not
    evidence for it, so the unit is the larger of the goal (2 % for E, 10 % for SD) and this
    natural variability.

    Parameters
    ----------
    observed : sequence of ResidenceTimes
        The held-out blocks' residence times, in block order.

    Returns
    -------
    (float, float)
        The units of |PD E(RT)| and |PD SD(RT)|, in %.
    """
    pd_mean, pd_sd = [], []
    for k, held_out in enumerate(observed):
        others = np.concatenate([o.samples for j, o in enumerate(observed) if j != k])
        if others.size < 2 or held_out.count < 2:
            continue
        pd_mean.append(percentage_difference(float(others.mean()), held_out.mean))
        pd_sd.append(percentage_difference(float(others.std(ddof=1)), held_out.sd,
                                           scale=held_out.mean))
    if not pd_mean:
        return GOAL_PD_MEAN, GOAL_PD_SD
    rms = lambda values: float(np.sqrt(np.mean(np.square(values))))  # noqa: E731
    return max(GOAL_PD_MEAN, rms(pd_mean)), max(GOAL_PD_SD, rms(pd_sd))


def _block_start_occupancy(discrete: DiscreteTrajectories, start: float, n_states: int
                           ) -> np.ndarray:
    """The particles per state in the first frame of ``discrete`` at or after ``start`` (s)
    that holds a particle in a state (a space with memory skips its first frames)."""
    times = np.asarray(discrete.times)
    for i in range(int(np.searchsorted(times, start - 1e-9 * max(1.0, abs(start)))),
                   times.size):
        states = np.asarray(discrete.states[i])
        states = states[(states >= 0) & (states < n_states)]
        if states.size:
            return np.bincount(states, minlength=n_states).astype(np.float64)
    return np.ones(n_states)


def _held_out_ck_error(block: DiscreteTrajectories, matrix: np.ndarray, times: np.ndarray
                       ) -> float:
    """Mean |P_model(A -> B, t) - P_observed(A -> B, t)| over the coarse groups (height
    thirds x core/annulus) and ``times`` (s) in the held-out ``block``. Every time uses the
    same start frames (those at least the longest time before the block's end), and the
    model starts from the occupancy of its states in each group there (as
    :func:`~cfbmarkov.markov.diagnostics.ck_test`); NaN when the block is shorter than the
    longest time."""
    space, lag, lag_frames = block.state_space, block.lag, block.lag_frames
    block_states = block.states
    steps = np.rint(np.asarray(times, dtype=np.float64) / lag).astype(np.int64)
    if steps.min() < 1 or np.any(np.abs(steps * lag - times) > 1e-9):
        return math.nan                     # the times are not whole multiples of this lag
    n_start = block_states.shape[0] - int(steps.max()) * lag_frames
    if n_start <= 0:
        return math.nan
    _, cell_label = group_labels(space, product_groups(height_bands(space, 3),
                                                       core_annulus(space)))
    state_group = cell_label[space.cell_of_state]
    g, s = int(state_group.max()) + 1, space.n_states
    # absent particles (an open riser's, ABSENT = -1) have no group; one present at a start
    # frame and gone k lags on counts in its start group's total, not in any pair
    labels = np.where(block_states >= 0, state_group[np.maximum(block_states, 0)], -1)
    member = np.zeros((s, g))
    member[np.arange(s), state_group] = 1.0
    start_states = block_states[:n_start]
    occupancy = np.bincount(start_states[start_states >= 0], minlength=s).astype(np.float64)
    start_labels = labels[:n_start]
    n_a = np.bincount(start_labels[start_labels >= 0], minlength=g).astype(np.float64)
    start_distribution = occupancy[:, None] * member                       # [S, G]
    mass = start_distribution.sum(axis=0, keepdims=True)
    x = np.divide(start_distribution, mass, out=np.zeros_like(start_distribution),
                  where=mass > 0)
    transposed = sp.csr_matrix(matrix.T)
    errors, done = [], 0
    for k in np.sort(steps):
        for _ in range(int(k) - done):
            x = transposed @ x                         # each group's distribution, k lags on
        done = int(k)
        shift = int(k) * lag_frames
        later = labels[shift:shift + n_start]
        both = (start_labels >= 0) & (later >= 0)
        pairs = np.bincount(start_labels[both] * g + later[both],
                            minlength=g * g).reshape(g, g).astype(np.float64)
        ok = n_a > 0
        predicted = (member.T @ x).T                   # [G from, G to]
        errors.append(np.abs(predicted[ok] - pairs[ok] / n_a[ok, None]).mean())
    return float(np.mean(errors))
