"""Exact residence-time distribution of a Markov model (no Monte Carlo noise).

``docs/definitions.md`` (Residence time) defines a residence as the time between two
consecutive upward passes that lift the lap counter L to a value it has not had before. In
the chain this is a first-passage problem on the states augmented with the lap deficit
l = L - L_entry in {0, -1, ..., -K}:

- a transition i -> j without a pass keeps l; a pass down through the bottom lowers it;
- a pass up through the top raises it, and from l = 0 it ends the residence (absorption),
  the landing state j being the entry state of the next residence.

Entry states are distributed as the stationary distribution nu of the embedded chain of
landing states (entry -> next entry), found from the absorption probabilities B = (I-Q)^-1 R
by block elimination over the lap-deficit levels (:mod:`cfbmarkov.markov.entry_chain`). The
residence-time probabilities f(k) = P(RT = k lag) follow by propagating nu through Q, the
tail of a long RTD from a Krylov projection whose error is bounded
(:mod:`cfbmarkov.markov.tail_closure`). The result is exact up to the lap-deficit
truncation K, the tail cut-off and that bound, all reported as ``unresolved`` mass.

A residence can only be observed inside an analysis window of length W if it starts and ends
in it, and the window counts the lap counter's records from its first frame: the RTD it sees
(:func:`window_rtd`) is a renewal of those records from where its particles start, then the
backward equations; where no particle falls through the bottom it is f(k)(n_W - k)+
renormalised (:meth:`ResidenceTimeDistribution.in_window`). This is what a sample-based RTD
on a window (CFD-DEM or Monte Carlo) estimates.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numba as nb
import numpy as np
import scipy.sparse as sp

from cfbmarkov._blas import one_blas_thread
from cfbmarkov._repr import compact_repr
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.limits import MAX_BINS, MAX_STEPS, check_finite
from cfbmarkov.markov.connectivity import closed_classes
from cfbmarkov.markov.entry_chain import (DepthElimination, embedded_stationary,
                                          entry_matrix)
from cfbmarkov.markov.model_arrays import check_pass_fractions, check_stochastic
from cfbmarkov.markov.tail_closure import (EARLY_MASS, EARLY_STEP, FIRST_TRY, MAX_TRIES,
                                           krylov_dimension, next_try, try_closure)
from cfbmarkov.markov.tail_closure import level_row as _level_row
from cfbmarkov.markov.shift_invert import factor_levels, level_inverse


def lag_multiples(lag: float, steps: np.ndarray) -> np.ndarray:
    """The times ``steps * lag`` (s) as their decimal values where the lag has a short one.

    ``3 * 0.025`` is 0.07500000000000001 in floating point; rounded to the lag's own
    decimals (as :func:`repr` writes it, at most 12) it is the float nearest 0.075, which
    prints and compares as such. A lag without such a decimal form (1/30 s) is left as the
    product.

    Parameters
    ----------
    lag : float
        The lag (s).
    steps : ndarray of int, shape (K,)
        The multiples.

    Returns
    -------
    ndarray of float64, shape (K,)
        The times (s), within one unit of round-off of ``steps * lag``.
    """
    times = lag * np.asarray(steps, dtype=np.float64)
    text = repr(float(lag))
    if "e" in text or "." not in text:
        return times
    decimals = len(text.split(".")[1])
    return np.round(times, decimals) if decimals <= 12 else times


class TrappedResidences(CfbmarkovError):
    """Every residence of the chain is trapped: no particle that enters can reach the top
    again (the states it enters lead only to states that are never left)."""


@dataclass(frozen=True, eq=False)     # == is identity, as for a MarkovModel (array fields)
class ResidenceTimeDistribution:
    """f(k) = probability that a residence lasts k lags (k = 1, 2, ...).

    Attributes
    ----------
    lag : float
        The lag (s).
    probability : ndarray of float64, shape (K,)
        f(k); index 0 is k = 1. The intrinsic RTD's sums with ``unresolved`` to 1; an RTD
        as a window sees it (``window`` set) is the distribution of the residences the
        window holds whole, summing to 1 by itself.
    unresolved : float
        The intrinsic RTD's mass not resolved (lap-deficit truncation, traps, tail
        cut-off); for an RTD as a window sees it, the share of the residences begun in the
        window that do not end in it (:func:`window_rtd`), not part of the sum of
        ``probability``.
    entry_distribution : ndarray of float64, shape (S,)
        The distribution of the states residences start in.
    window : float or None
        Length of the observation window (s); None for the intrinsic RTD.
    closed_classes : int
        Closed classes of the chain that residences run in.
    uncertainty : ModelUncertainty or None
        The intervals of a fitted model's E(RT), SD(RT) and RTD per bin
        (:class:`cfbmarkov.markov.uncertainty.ModelUncertainty`), on the intrinsic RTD of a
        model that has them; None otherwise.
    deficit_levels : int or None
        K, the deepest lap deficit the computation kept (a periodic riser's; None for an
        open riser's).
    deficit_unresolved : float
        The part of ``unresolved`` that fell below deficit -K.
    drift_mean : float or None
        Where more than :data:`DEFICIT_TOL` fell below the deepest deficit kept
        (:data:`MAX_DEFICIT_LEVELS`), the chain's E(RT) from its lap drift
        (:func:`drift_residence_time`, s), which counts those residences too; else None.
    times : ndarray of float64, shape (K,)
        The residence times k lag (s) of ``probability`` (a property).
    mean, sd : float
        E(RT) and SD(RT) (s) of the resolved mass, renormalised (properties).

    Notes
    -----
    See ``docs/definitions.md`` (Residence time; Exact RTD of a model).
    """

    def __repr__(self) -> str:
        text = compact_repr(self)
        head, _, rest = text.partition("(")
        try:
            moments = f"mean={self.mean:.6g} s, sd={self.sd:.6g} s, "
        except (ValueError, ZeroDivisionError, FloatingPointError):
            moments = ""
        return f"{head}({moments}{rest}"

    lag: float
    probability: np.ndarray   # [K]: index 0 is k = 1
    unresolved: float         # mass not resolved (lap-deficit truncation, traps, tail cut;
    # for an RTD computed only as far as a window: the rest too)
    entry_distribution: np.ndarray  # [S] stationary distribution of entry states
    window: float | None = None     # observation window length, s (None: intrinsic RTD)
    closed_classes: int = 1         # closed classes of the chain that residences run in
    # the fitted model's intervals (markov.uncertainty.ModelUncertainty), or None
    uncertainty: object = None
    deficit_levels: int | None = None   # K, the lap deficits kept (None: an open riser's)
    deficit_unresolved: float = 0.0     # of ``unresolved``: fallen below deficit -K
    drift_mean: float | None = None     # E(RT) from the lap drift, where deficits were lost

    def __post_init__(self):
        # immutable as the model that caches it: its arrays are read-only copies (the
        # caller's arrays are left as they are)
        for name in ("probability", "entry_distribution"):
            value = getattr(self, name)
            if isinstance(value, np.ndarray) and value.flags.writeable:
                value = value.copy()
                value.setflags(write=False)
                object.__setattr__(self, name, value)

    @property
    def times(self) -> np.ndarray:
        """Residence times k*lag (s) of :attr:`probability`."""
        return lag_multiples(self.lag, np.arange(1, self.probability.size + 1))

    @property
    def mean(self) -> float:
        """E(RT) (s), of the resolved mass renormalised."""
        w = self.probability / self.probability.sum()
        return float(np.sum(w * self.times))

    @property
    def sd(self) -> float:
        """SD(RT), s (of the distribution; samples use ddof = 1)."""
        w = self.probability / self.probability.sum()
        m = np.sum(w * self.times)
        return float(np.sqrt(max(np.sum(w * (self.times - m) ** 2), 0.0)))

    def in_window(self, window: float) -> "ResidenceTimeDistribution":
        """The RTD as observed in an analysis window of ``window`` s.

        A residence of k lags fits in n_W - k of the n_W = window / lag frame positions, so
        the observed RTD is f(k) (n_W - k)+ renormalised (see the module docstring): where
        every record the window counts is a true one (an open riser's entries; a periodic
        riser whose particles never pass down through the bottom). A periodic riser's window
        with falls sees :func:`window_rtd`, which :meth:`MarkovModel.rtd
        <cfbmarkov.markov.model.MarkovModel.rtd>` returns.

        Parameters
        ----------
        window : float
            Length of the analysis window (s).

        Returns
        -------
        ResidenceTimeDistribution
            With ``window`` set and residences longer than the window left out; its
            ``unresolved`` is, as :func:`window_rtd`'s, the share of the residences begun
            inside the window that do not end in it: 1 - sum_k f(k) (n_W - k)+ / n_W (a
            residence begins at any of the n_W frame positions alike; those that never end,
            the intrinsic ``unresolved``, included).

        Raises
        ------
        InputError
            If ``window`` is not a positive finite length (s) of at most
            :data:`~cfbmarkov.limits.MAX_STEPS` lags, or this RTD is already one a window
            sees (its ``window`` set: weighting it again would count the window twice; ask
            the model, :meth:`MarkovModel.rtd(window=...)
            <cfbmarkov.markov.model.MarkovModel.rtd>`).
        CfbmarkovError
            If no residence fits in the window.
        """
        if self.window is not None:
            raise InputError(f"in_window(): this RTD is already the one a {self.window:g} s "
                             "window sees, and weighting it again would count the window "
                             "twice; ask the model for the window: model.rtd(window=...)")
        if isinstance(window, (tuple, list, np.ndarray)) and np.ndim(window) >= 1:
            raise InputError(f"in_window(): window {window!r} is not a length (s): give one "
                             "number, the window's stop - start")
        window = check_finite(window, "window length", "s", positive=True)
        if window / self.lag > MAX_STEPS:
            raise InputError(f"window length {window:g} s is {window / self.lag:.3g} lags of "
                             f"{self.lag:g} s, more than {MAX_STEPS}; give a window length of "
                             f"at most {MAX_STEPS * self.lag:g} s")
        n_window = int(round(window / self.lag))
        k = np.arange(1, self.probability.size + 1)
        weights = np.clip(n_window - k, 0, None).astype(np.float64)
        observed = self.probability * weights
        if observed.sum() <= 0:
            held = np.flatnonzero(self.probability > 0)
            shortest = ("" if held.size == 0 else
                        f": its shortest residence lasts {(held[0] + 1) * self.lag:g} s; give a "
                        f"window of at least {(held[0] + 2) * self.lag:g} s")
            raise CfbmarkovError(f"no residence of this model fits in a window of {window:g} s"
                                 + shortest)
        resolved = (1.0 - self.unresolved) * float(observed.sum()) / (
            float(self.probability.sum()) * n_window)
        observed = observed[: max(n_window - 1, 1)]
        return ResidenceTimeDistribution(self.lag, observed / observed.sum(),
                                         min(1.0, max(0.0, 1.0 - resolved)),
                                         self.entry_distribution, float(window),
                                         self.closed_classes, deficit_levels=self.deficit_levels,
                                         deficit_unresolved=self.deficit_unresolved)

    def histogram(self, bin_width: float, upper: float) -> tuple[np.ndarray, np.ndarray]:
        """Probability per bin on edges 0, bin_width, ..., upper (s), each bin half-open
        [a, b), a residence within 1e-6 bin widths below an edge counted on it: the rule of
        the sample histogram (:func:`cfbmarkov.observed.residence.rtd_histogram`), so that
        whole lags on bins of whole lags fall in the bin they start whatever the round-off
        of ``bin_width`` (``docs/definitions.md``, Residence-time distribution).

        Parameters
        ----------
        bin_width : float
            Width of the bins (s).
        upper : float
            Upper edge of the last bin (s).

        Returns
        -------
        edges : ndarray of float64, shape (B + 1,)
            Bin edges (s).
        probability : ndarray of float64, shape (B,)
            Probability per bin (of the resolved mass renormalised).

        Raises
        ------
        InputError
            If ``bin_width`` or ``upper`` is not a positive finite time, the bin is wider than
            ``upper``, or the edges would make more than :data:`~cfbmarkov.limits.MAX_BINS`
            bins.
        """
        bin_width = check_finite(bin_width, "RTD bin width", "s", positive=True)
        upper = check_finite(upper, "RTD histogram's upper edge", "s", positive=True)
        if bin_width > upper:
            raise InputError(f"RTD bin width {bin_width:g} s is wider than the histogram's "
                             f"upper edge {upper:g} s: no bin fits; give an upper edge of at "
                             "least one bin width")
        if upper / bin_width > MAX_BINS:
            raise InputError(f"RTD bins of {bin_width:g} s up to {upper:g} s are "
                             f"{upper / bin_width:.3g} bins, more than {MAX_BINS}; give a "
                             f"bin width of at least {upper / MAX_BINS:.3g} s")
        edges = np.arange(0.0, upper + 0.5 * bin_width, bin_width)
        prob, _ = np.histogram(self.times + 1e-6 * bin_width, bins=edges,
                               weights=self.probability / self.probability.sum())
        return edges, prob


@nb.njit(cache=True)
def _level_exits(v, exit_probability, down_probability, falls):
    """The mass absorbed this lag (level 0's exits); ``falls[g]`` gathers the mass passing
    down from level g. In one fixed order: the same bits on any thread count."""
    n, levels = v.shape
    absorbed = 0.0
    for i in range(n):
        absorbed += v[i, 0] * exit_probability[i]
        for g in range(levels):
            falls[g] += v[i, g] * down_probability[i]
    return absorbed


@nb.njit(cache=True)
def _level_mass(v):
    """The mass left on every state and level, summed level by level."""
    n, levels = v.shape
    remaining = 0.0
    for g in range(levels):
        for j in range(n):
            remaining += v[j, g]
    return remaining


@nb.njit(cache=True, nogil=True)
def _first_passage_levels(down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val,
                          up_ptr, up_idx, up_val, exit_probability, live, state, tol,
                          first, max_steps, out, down_probability, falls):
    """f(k) for k = first + 1 .. by propagating the mass left on the lap-deficit levels,
    without the [S L, S L] matrix (Numba kernel). The mass is held as ``v[i, g]`` (state i,
    level g = 0 .. L-1, the levels of a state side by side); one lag moves it by P_stay
    within a level, P_down one level deeper and P_up one level up (from level 0: the exit).
    The three parts come as CSR of their transposes (rows: destination j), so each non-zero
    is read once a lag and gathers the L levels of its source at once. Mass on a state and
    level from which no exit can be reached (``live`` false) is dropped, as
    :func:`exact_rtd` drops those states. The terms of each destination and level are
    summed in the order of the full matrix's transpose (down passes, stays, up passes): the
    same bits as the full matrix's propagation. One thread: a lag's product is a few
    microseconds of work, less than a parallel region costs to start and join (on a busy
    2-core machine that wait made the exact RTD 10-100 times slower), and the bits are the
    same on any machine (:func:`_first_passage_levels_parallel` for large chains: the same
    bits). ``falls[g]`` (float64 [L]) gathers the mass that passes down from level g
    (``down_probability``: each state's probability of a pass down, P_down's row sums);
    ``falls[L - 1]`` is the mass lost below the deepest level. ``state`` [S, L] holds the
    mass left at lag ``first`` on entry and at the last lag taken on return. Returns the
    number of lags reached (``max_steps`` unless the mass left fell below ``tol`` first)."""
    n, levels = state.shape
    v = state.copy()
    w = np.empty_like(v)
    acc = np.empty(levels)
    reached = max_steps
    for k in range(first, max_steps):
        out[k] = _level_exits(v, exit_probability, down_probability, falls)
        for j in range(n):
            _level_row(j, down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val, up_ptr,
                       up_idx, up_val, live, v, w, acc)
        v, w = w, v
        if _level_mass(v) < tol:
            reached = k + 1
            break
    state[:, :] = v
    return reached


@nb.njit(cache=True, nogil=True)
def _window_landings(down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val, up_ptr,
                     up_idx, up_val, live, start, landings):
    """The records of a window counted from its first frame (Numba kernel): the chain on
    the lap-deficit levels below the window's running maximum, started from ``start``
    ([S, L], all on level 0), in which every pass up from level 0 (a new maximum, a record)
    lands on level 0 again instead of leaving. ``landings[k, j]`` (float64 [M, S]) gets
    the mass that lands in state j by the record of transition k + 1. Parts as
    :func:`_first_passage_levels` (CSR of their transposes)."""
    n, levels = start.shape
    v = start.copy()
    w = np.empty_like(v)
    acc = np.empty(levels)
    for k in range(landings.shape[0]):
        for j in range(n):
            _level_row(j, down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val, up_ptr,
                       up_idx, up_val, live, v, w, acc)
            landed = 0.0
            for q in range(up_ptr[j], up_ptr[j + 1]):      # passes up from level 0
                landed += up_val[q] * v[up_idx[q], 0]
            landings[k, j] = landed
            if live[j, 0]:
                w[j, 0] += landed
        v, w = w, v


@nb.njit(cache=True, nogil=True)
def _exits_backward(up_ptr, up_idx, up_val, stay_ptr, stay_idx, stay_val, down_ptr, down_idx,
                    down_val, live, exit_probability, ends):
    """``ends[k, i]``: from state i on level 0, the probability that the residence ends on
    its (k + 1)-th transition (Numba kernel), b_1 = the exits, b_(k+1) = Q b_k on the
    levels. The parts as CSR of themselves (rows: sources), P_up in the place of
    :func:`_level_row`'s down passes and P_down in that of its up passes: from level g an
    up pass reads level g - 1, a down pass level g + 1."""
    n, levels = live.shape
    b = np.zeros((n, levels))
    w = np.empty_like(b)
    acc = np.empty(levels)
    for i in range(n):
        if live[i, 0]:
            b[i, 0] = exit_probability[i]
    for k in range(ends.shape[0]):
        for i in range(n):
            ends[k, i] = b[i, 0]
        for i in range(n):
            _level_row(i, up_ptr, up_idx, up_val, stay_ptr, stay_idx, stay_val, down_ptr,
                       down_idx, down_val, live, b, w, acc)
        b, w = w, b


@nb.njit(cache=True, parallel=True)
def _first_passage_levels_parallel(down_ptr, down_idx, down_val, stay_ptr, stay_idx,
                                   stay_val, up_ptr, up_idx, up_val, exit_probability, live,
                                   state, tol, first, max_steps, out, down_probability, falls):
    """:func:`_first_passage_levels` with the destinations of each lag shared among the
    threads (each destination's levels summed by one thread in the same order, the sums in
    one thread: the same bits on any thread count). The destinations go in
    :data:`PARALLEL_CHUNKS` blocks, each with its own scratch row of sums."""
    n, levels = state.shape
    v = state.copy()
    w = np.empty_like(v)
    chunks = min(PARALLEL_CHUNKS, n)
    acc = np.empty((chunks, levels))
    reached = max_steps
    for k in range(first, max_steps):
        out[k] = _level_exits(v, exit_probability, down_probability, falls)
        for c in nb.prange(chunks):
            for j in range(c * n // chunks, (c + 1) * n // chunks):
                _level_row(j, down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val,
                           up_ptr, up_idx, up_val, live, v, w, acc[c])
        v, w = w, v
        if _level_mass(v) < tol:
            reached = k + 1
            break
    state[:, :] = v
    return reached


@nb.njit(cache=True, nogil=True)
def _level_system(down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val, up_ptr, up_idx,
                  up_val, live):
    """I - Q on the live (level, state) pairs, as CSC arrays (Numba kernel): Q of
    :func:`deficit_matrix` without forming it, from the CSR of the three parts' transposes
    (rows: destination j, as :func:`_first_passage_levels` reads them) and ``live`` [S, L].
    The pairs are numbered level by level (g S + i) among the live ones; in each column
    (g', j) the rows come in that order: the down passes from level g' - 1, the stays
    (the diagonal 1 - P_stay[j, j] among them) and the up passes from level g' + 1.
    Returns (indptr, indices, data)."""
    n, levels = live.shape
    position = -np.ones(n * levels, np.int64)
    count = 0
    for g in range(levels):
        for i in range(n):
            if live[i, g]:
                position[g * n + i] = count
                count += 1
    bound = count + levels * (down_ptr[n] + stay_ptr[n] + up_ptr[n])
    indptr = np.zeros(count + 1, np.int64)
    indices = np.empty(bound, np.int64)
    data = np.empty(bound)
    k = 0
    for g in range(levels):
        for j in range(n):
            column = position[g * n + j]
            if column < 0:
                continue
            if g >= 1:                                  # down passes from level g - 1
                for q in range(down_ptr[j], down_ptr[j + 1]):
                    row = position[(g - 1) * n + down_idx[q]]
                    if row >= 0:
                        indices[k] = row
                        data[k] = -down_val[q]
                        k += 1
            diagonal = False
            for q in range(stay_ptr[j], stay_ptr[j + 1]):
                i = stay_idx[q]
                if not diagonal and i >= j:
                    diagonal = True
                    indices[k] = column
                    data[k] = 1.0 - (stay_val[q] if i == j else 0.0)
                    k += 1
                    if i == j:
                        continue
                row = position[g * n + i]
                if row >= 0:
                    indices[k] = row
                    data[k] = -stay_val[q]
                    k += 1
            if not diagonal:
                indices[k] = column
                data[k] = 1.0
                k += 1
            if g + 1 < levels:                          # up passes from level g + 1
                for q in range(up_ptr[j], up_ptr[j + 1]):
                    row = position[(g + 1) * n + up_idx[q]]
                    if row >= 0:
                        indices[k] = row
                        data[k] = -up_val[q]
                        k += 1
            indptr[column + 1] = k
    return indptr, indices[:k], data[:k]


@nb.njit(cache=True, nogil=True)
def _live_from_transposes(down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val, up_ptr,
                          up_idx, up_val, levels, targets):
    """The live pairs of :func:`_live_levels` from the parts' transposes (Numba kernel): a
    breadth-first search backwards from the exit states on level 0 (``targets``, bool [S]),
    each transpose's row j listing the sources of destination j. Returns bool [L S], index
    g S + i."""
    n = targets.size
    live = np.zeros(n * levels, np.bool_)
    queue = np.empty(n * levels, np.int64)
    head, tail = 0, 0
    for i in range(n):
        if targets[i]:
            live[i] = True
            queue[tail] = i
            tail += 1
    while head < tail:
        pair = queue[head]
        head += 1
        g, j = pair // n, pair % n
        for part in range(3):
            if part == 0:           # stays: sources on the same level
                ptr, idx, val, source_level = stay_ptr, stay_idx, stay_val, g
            elif part == 1:         # down passes: from the level above (g - 1)
                ptr, idx, val, source_level = down_ptr, down_idx, down_val, g - 1
            else:                   # up passes: from the level below (g + 1)
                ptr, idx, val, source_level = up_ptr, up_idx, up_val, g + 1
            if source_level < 0 or source_level >= levels:
                continue
            for q in range(ptr[j], ptr[j + 1]):
                if val[q] == 0.0:
                    continue
                source = source_level * n + idx[q]
                if not live[source]:
                    live[source] = True
                    queue[tail] = source
                    tail += 1
    return live


@nb.njit(cache=True, inline="always")
def _add_products(dst, a, b):
    """dst[r] += a[r] * b[r] over the chains of a chunk (unit strides: SIMD)."""
    for r in range(dst.size):
        dst[r] += a[r] * b[r]


@nb.njit(cache=True)
def _heads_of_chunk(down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val, up_ptr,
                    up_idx, up_val, exit_probability, live, start, tol, out):
    """:func:`_heads_of_chains` for one chunk (its arrays without the chunk axis)."""
    n, levels, width = start.shape
    v = start.copy()
    w = np.empty_like(v)
    stopped = np.zeros(width, np.bool_)
    absorbed = np.empty(width)
    mass = np.empty(width)
    for k in range(out.shape[0]):
        absorbed[:] = 0.0
        for i in range(n):
            _add_products(absorbed, v[i, 0], exit_probability[i])
        for r in range(width):
            if not stopped[r]:
                out[k, r] = absorbed[r]
        w[:] = 0.0
        for j in range(n):
            for q in range(down_ptr[j], down_ptr[j + 1]):      # from level g - 1
                values, source = down_val[q], v[down_idx[q]]
                for g in range(1, levels):
                    _add_products(w[j, g], values, source[g - 1])
            for q in range(stay_ptr[j], stay_ptr[j + 1]):
                values, source = stay_val[q], v[stay_idx[q]]
                for g in range(levels):
                    _add_products(w[j, g], values, source[g])
            for q in range(up_ptr[j], up_ptr[j + 1]):          # from level g + 1
                values, source = up_val[q], v[up_idx[q]]
                for g in range(levels - 1):
                    _add_products(w[j, g], values, source[g + 1])
            for g in range(levels):
                target, alive = w[j, g], live[j, g]
                for r in range(width):
                    if not alive[r]:
                        target[r] = 0.0
        v, w = w, v
        mass[:] = 0.0
        for g in range(levels):
            for j in range(n):
                row = v[j, g]
                for r in range(width):
                    mass[r] += row[r]
        for r in range(width):
            if mass[r] < tol:
                stopped[r] = True


@nb.njit(cache=True, parallel=True)
def _heads_of_chains(down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val, up_ptr,
                     up_idx, up_val, exit_probability, live, start, tol, out):
    """:func:`_first_passage_levels` for many chains of one sparsity pattern at once
    (Numba kernel): the chains' values side by side, ``C`` chunks of ``W`` chains each
    (``*_val`` [C, nnz, W] on the union of their non-zeros, ``exit_probability`` [C, S, W],
    ``live`` [C, S, L, W], ``start`` [C, S, L, W]), so that each non-zero's index is read
    once a lag for W chains and their arithmetic runs in SIMD. ``out`` [C, steps, W]: the
    mass absorbed at each lag, as that kernel's ``out``, zero after a chain's mass left
    falls below ``tol`` (where that kernel stops). Each chain's sums run in that kernel's
    order, and a chain's zero at a non-zero of another adds nothing: the same bits as
    :func:`_first_passage_levels` chain by chain, on any thread count (the chunks are
    shared among the threads)."""
    for c in nb.prange(start.shape[0]):
        _heads_of_chunk(down_ptr, down_idx, down_val[c], stay_ptr, stay_idx, stay_val[c],
                        up_ptr, up_idx, up_val[c], exit_probability[c], live[c], start[c],
                        tol, out[c])


#: non-zeros times levels above which a lag's product is shared among threads
PARALLEL_LEVEL_WORK = 1_000_000
#: blocks of destinations a lag's product is shared out in (threads take whole blocks)
PARALLEL_CHUNKS = 64


def _live_levels(p_up, p_down, p_stay, levels: int, targets: np.ndarray) -> np.ndarray:
    """The (level, state) pairs of :func:`deficit_matrix`'s Q from which one of ``targets``
    (bool [S L]: exits, all on level 0) can be reached, themselves included (bool [S L],
    index g S + i): :func:`_live_from_transposes` on the parts' transposes, without
    forming Q. Stored zeros are no transitions."""
    s = p_up.shape[0]
    targets = np.asarray(targets, dtype=bool)
    if targets[s:].any():
        raise ValueError("exits lie on level 0 only")
    return _live_from_transposes(*_transposed_parts((p_down, p_stay, p_up)), levels,
                                 np.ascontiguousarray(targets[:s]))


def exact_rtd(matrix: np.ndarray, up_fraction: np.ndarray, down_fraction: np.ndarray, lag: float,
              deficit_levels: int | None = None, tol: float = 1e-10, max_steps: int = 200_000,
              entry: np.ndarray | None = None, entry_flux: np.ndarray | None = None
              ) -> ResidenceTimeDistribution:
    """Exact intrinsic RTD of a chain with transition matrix P and pass fractions.

    A first-passage problem on the states augmented with the lap deficit (see the module
    docstring): the up passes from deficit 0 are absorbing, Q is the transient part.

    Parameters
    ----------
    matrix : ndarray of float64, shape (S, S)
        The transition matrix P.
    up_fraction, down_fraction : ndarray of float64, shape (S, S)
        Fraction of each i -> j transition that passes up through the top / down through
        the bottom.
    lag : float
        The lag (s).
    deficit_levels : int, optional
        K, the deepest lap deficit kept (mass beyond it counts as unresolved). By default
        as deep as the chain's residences fall: from :data:`MIN_DEFICIT_LEVELS`, deepened
        until at most :data:`DEFICIT_TOL` of the residences pass below the deepest level
        kept, or :data:`MAX_DEFICIT_LEVELS` is reached (:func:`deeper_levels`); the mass
        below stays ``unresolved``.
    tol : float, optional
        Stop when the mass not yet absorbed falls below this. Past lag
        :data:`~cfbmarkov.markov.tail_closure.FIRST_TRY` (earlier where less than
        :data:`~cfbmarkov.markov.tail_closure.EARLY_MASS` is left) the tail may be closed by a
        Krylov projection whose bound on its error, at most :data:`CLOSURE_TOL` (or
        ``tol`` where larger), counts as unresolved (0: propagated to the end).
    max_steps : int, optional
        Propagate at most this many lags (the rest counts as unresolved).
    entry : ndarray of float64, shape (S,), optional
        The distribution of the states particles enter in, e.g. the observed one (column
        sums of the up-pass counts); by default the chain's own stationary entry
        distribution, which costs one sparse LU per lap-deficit level and an eigenvector.
    entry_flux : ndarray of float64, shape (S,), optional
        Observed net entries through the inlet per state (landings of up passes minus
        departures of down passes: a particle that falls out of the bottom and comes back
        starts no new residence). Used only where the chain is reducible: when residences
        run in several closed classes (particles that never share a state, say), the
        stationary entry distribution is not unique; each class then gets its own
        stationary entry distribution, weighted by the class's share of the observed net
        entry flux (equal weights where no flux is given).

    Returns
    -------
    ResidenceTimeDistribution
        The intrinsic RTD (``window`` None); its ``deficit_levels`` is the K used.

    Raises
    ------
    InputError
        If P is not a square row-stochastic matrix of finite non-negative entries, the
        pass fractions are not (S, S) in [0, 1] with up + down <= 1 where P is non-zero, or
        the lag is not positive and finite.
    CfbmarkovError
        If the chain has no transition up through the top, or ``entry`` is not a
        non-negative [S] vector with mass on states from which the top can be reached.

    Notes
    -----
    See ``docs/definitions.md`` (Exact RTD of a model).

    References
    ----------
    J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand, Princeton
    (1960) (Ch. III, absorbing chains: absorption probabilities B = (I - Q)^-1 R).
    """
    chain = csr_of(matrix)
    up_fraction, down_fraction = _checked_chain(chain, up_fraction, down_fraction, lag)
    p_up, p_down, p_stay = split_by_pass(chain, up_fraction, down_fraction)
    return rtd_of_split_chain(p_up, p_down, p_stay, lag, deficit_levels, tol, max_steps,
                              entry, entry_flux, chain)


@nb.njit(cache=True)
def _dense_row_counts(matrix, counts):
    """Non-zeros per row of a dense matrix (the first pass of :func:`csr_of`)."""
    for i in range(matrix.shape[0]):
        n = 0
        for j in range(matrix.shape[1]):
            if matrix[i, j] != 0.0:
                n += 1
        counts[i] = n


@nb.njit(cache=True)
def _dense_fill(matrix, indptr, indices, data):
    """The column indices and values of a dense matrix's non-zeros, row by row."""
    for i in range(matrix.shape[0]):
        k = indptr[i]
        for j in range(matrix.shape[1]):
            v = matrix[i, j]
            if v != 0.0:
                indices[k] = j
                data[k] = v
                k += 1


def csr_of(matrix) -> sp.csr_matrix:
    """P as a CSR matrix: a dense float64 array in two Numba passes over its rows (one
    read of the S^2 values each, no index arrays of the whole matrix: a third of the time
    of scipy's conversion through COO on a 1596-state model), anything else by scipy.

    Parameters
    ----------
    matrix : ndarray or scipy.sparse matrix, shape (S, S)

    Returns
    -------
    scipy.sparse.csr_matrix
        Sorted column indices, no explicit zeros (NaN entries are kept, for the checks).
    """
    if (isinstance(matrix, np.ndarray) and matrix.ndim == 2 and matrix.dtype == np.float64
            and matrix.shape[0] == matrix.shape[1]):
        dense = np.ascontiguousarray(matrix)
        counts = np.empty(dense.shape[0], np.int64)
        _dense_row_counts(dense, counts)
        indptr = np.zeros(dense.shape[0] + 1, np.int64)
        np.cumsum(counts, out=indptr[1:])
        indices = np.empty(indptr[-1], np.int64)
        data = np.empty(indptr[-1], np.float64)
        _dense_fill(dense, indptr, indices, data)
        return sp.csr_matrix((data, indices, indptr), shape=dense.shape)
    return sp.csr_matrix(matrix)


def _checked_chain(chain: sp.csr_matrix, up_fraction, down_fraction, lag
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The pass fractions as float64 arrays, once P (its non-zeros: O(nnz)), the fractions on
    them and the lag are checked as :class:`~cfbmarkov.markov.model.MarkovModel` checks
    them: P square, finite, non-negative, rows summing to 1 within 1e-9; the fractions
    (S, S) in [0, 1] with up + down <= 1 where P is non-zero; the lag positive and finite.

    Raises
    ------
    InputError
        Naming the first rule broken.
    """
    s = chain.shape[0]
    if chain.shape != (s, s) or s == 0:
        raise InputError(f"transition matrix of shape {chain.shape}: give a square (S, S) "
                         "matrix")
    if not (isinstance(lag, (int, float, np.number)) and not isinstance(lag, bool)
            and np.isfinite(lag) and lag > 0):
        raise InputError(f"lag {lag!r} s must be a positive finite number")
    check_stochastic(chain.data, np.asarray(chain.sum(axis=1)).ravel())
    fractions = []
    for name, given in (("up_fraction", up_fraction), ("down_fraction", down_fraction)):
        value = np.asarray(given, dtype=np.float64)
        if value.shape != (s, s):
            raise InputError(f"{name} has shape {value.shape}, expected ({s}, {s}) as P")
        fractions.append(value)
    where = np.repeat(np.arange(s), np.diff(chain.indptr)), chain.indices
    check_pass_fractions(fractions[0][where], fractions[1][where])
    return fractions[0], fractions[1]


def window_rtd(p_up, p_down, p_stay, lag: float, window: float, occupancy: np.ndarray,
               deficit_levels: int | None = None,
               intrinsic: ResidenceTimeDistribution | None = None) -> ResidenceTimeDistribution:
    """The RTD a window of ``window`` s observes of a periodic riser's chain, its records
    counted from the window's first frame, as the window's samples are.

    A window's residences are the times between successive records of each particle's lap
    counter, the counter's running maximum taken from its value in the window's first frame
    (:func:`cfbmarkov.observed.residence.residence_times_from_laps`). A particle that fell
    through the bottom before the window starts it below its own past maximum: its next
    passes up are records to the window, not to its history, and the residences between
    them are shorter than its true one. The window's RTD is therefore not the intrinsic
    f(k) weighted by the n_W - k places a residence fits
    (:meth:`ResidenceTimeDistribution.in_window`, which counts true records alone and is
    this function's answer where no particle falls); it is, with the particles started in
    ``occupancy`` on deficit 0 and every record landing on deficit 0 again (a renewal: the
    landings R(s) by the record of lag s, :func:`_window_landings`),

        C(k) = sum_(s = 1 .. n_W - k) R(s) . b_k,    f_W(k) = C(k) / sum C,

    b_k the probability from each landing state of ending k lags later (b_1 = the exits,
    b_(k+1) = Q b_k on the lap-deficit levels: :func:`_exits_backward`), the residences
    that begin and end inside the window. Two propagations of n_W lags; no per-entry work.

    Parameters
    ----------
    p_up, p_down, p_stay : scipy.sparse matrix, shape (S, S)
        P split by pass direction (the direction residences are counted in as "up").
    lag : float
        The lag (s).
    window : float
        The window's length (s), at least two lags.
    occupancy : ndarray of float64, shape (S,)
        Where the particles are at the window's start (non-negative; normalised here): the
        fitting window's particle-frames per state, or the stationary distribution.
    deficit_levels : int, optional
        K, the deepest lap deficit below the running maximum followed (mass falling below
        it is lost from the count); default :data:`WINDOW_DEFICIT_LEVELS`.
    intrinsic : ResidenceTimeDistribution, optional
        The chain's intrinsic RTD, whose ``unresolved``, entry distribution, closed classes
        and deficit figures the result carries (as :meth:`ResidenceTimeDistribution.in_window`).

    Returns
    -------
    ResidenceTimeDistribution
        Probability per lag k = 1 .. n_W - 1, ``window`` set; its ``unresolved`` is the
        share of the residences begun inside the window that do not end in it.

    Raises
    ------
    CfbmarkovError
        If no residence fits in the window, or the chain has no pass up through the top.

    References
    ----------
    ``docs/definitions.md`` (Exact RTD of a model, As a window sees it); J. G. Kemeny and
    J. L. Snell, Finite Markov Chains (1960), Ch. III (absorption by the backward equations).
    """
    p_up, p_down, p_stay = (sp.csr_matrix(part) for part in (p_up, p_down, p_stay))
    s = p_up.shape[0]
    if deficit_levels is None:
        deficit_levels = WINDOW_DEFICIT_LEVELS
    n_window = int(round(window / lag))
    levels = int(deficit_levels) + 1
    exit_probability = np.asarray(p_up.sum(axis=1), dtype=np.float64).ravel()
    if not exit_probability.any():
        raise CfbmarkovError("the model has no transition up through the top: particles never "
                             "leave, so there is no residence time")
    live = _live_levels(p_up, p_down, p_stay, levels, np.concatenate(
        [exit_probability > 0, np.zeros(s * (levels - 1), bool)])).reshape(levels, s)
    live_t = np.ascontiguousarray(live.T)
    occupancy = np.clip(np.asarray(occupancy, dtype=np.float64).ravel(), 0.0, None)
    start = np.zeros((s, levels))
    if occupancy.sum() > 0:
        start[:, 0] = occupancy / occupancy.sum()
    start[~live_t] = 0.0
    if not start.any():
        raise CfbmarkovError("the window's start (its occupancy) holds no particle in a state "
                             "from which the top can be reached: all are in states the chain "
                             "never leaves, so no residence begins")
    steps = max(n_window - 1, 1)
    landings = np.zeros((steps, s))
    _window_landings(*_transposed_parts((p_down, p_stay, p_up)), live_t, start, landings)
    ends = np.zeros((steps, s))
    arrays = []
    for part in (p_up, p_stay, p_down):
        own = part.tocsr().copy()
        own.sort_indices()
        arrays += [own.indptr.astype(np.int64), own.indices.astype(np.int64),
                   own.data.astype(np.float64)]
    _exits_backward(*arrays, live_t, exit_probability, ends)
    # C(k) = R(1 .. n_W - k) . b_k: the landings summed up to n_W - k
    landed = np.cumsum(landings, axis=0)
    k = np.arange(1, steps + 1)
    counts = np.zeros(steps)
    fits = n_window - k >= 1
    counts[fits] = np.einsum("ks,ks->k", landed[n_window - k[fits] - 1], ends[k[fits] - 1])
    if not counts.sum() > 0:
        held = (np.zeros(0, np.int64) if intrinsic is None
                else np.flatnonzero(intrinsic.probability > 0))
        shortest = ("" if held.size == 0 else
                    f": its shortest residence lasts {(held[0] + 1) * lag:g} s; give a "
                    f"window of at least {(held[0] + 2) * lag:g} s")
        raise CfbmarkovError(f"no residence of this model fits in a window of {window:g} s"
                             + shortest)
    # of the residences that begin inside the window, the share that do not end in it (the
    # longer ones, and any that never end)
    begun = float(landings.sum())
    outlasting = max(0.0, 1.0 - float(counts.sum()) / begun) if begun > 0 else 0.0
    base = intrinsic
    return ResidenceTimeDistribution(
        lag, counts / counts.sum(), outlasting,
        np.zeros(s) if base is None else base.entry_distribution, float(window),
        1 if base is None else base.closed_classes,
        deficit_levels=int(deficit_levels),
        deficit_unresolved=0.0 if base is None else base.deficit_unresolved)


def split_by_pass(matrix, up_fraction: np.ndarray, down_fraction: np.ndarray
                  ) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
    """P split by pass direction: P = P_up + P_down + P_stay, on P's non-zeros only.

    Parameters
    ----------
    matrix : ndarray of float64 or scipy.sparse matrix, shape (S, S)
        The transition matrix P.
    up_fraction, down_fraction : ndarray of float64, shape (S, S)
        Fraction of each i -> j transition that passes up through the top / down through
        the bottom.

    Returns
    -------
    tuple of three scipy.sparse.csr_matrix, shape (S, S)
        P_up = P * up, P_down = P * down and the rest P_stay (element-wise), explicit zeros
        removed.
    """
    s = matrix.shape[0]
    chain = sp.csr_matrix(matrix)       # one scan of a dense matrix
    rows = np.repeat(np.arange(s), np.diff(chain.indptr))
    up_part = chain.data * up_fraction[rows, chain.indices]
    down_part = chain.data * down_fraction[rows, chain.indices]
    stay_part = chain.data - up_part - down_part

    def _part(values):      # own copies: eliminate_zeros compacts its arrays in place
        part = sp.csr_matrix((values, chain.indices.copy(), chain.indptr.copy()),
                             shape=(s, s))
        part.eliminate_zeros()
        return part

    return _part(up_part), _part(down_part), _part(stay_part)


def deficit_matrix(p_up, p_down, p_stay, levels: int) -> tuple[sp.csr_matrix, np.ndarray]:
    """Q, the transient part of the chain on (lap-deficit level, state), and its exit
    probabilities (module docstring): level index g = -l, a down pass moves g -> g + 1, an
    up pass g -> g - 1, and an up pass from g = 0 leaves.

    Parameters
    ----------
    p_up, p_down, p_stay : scipy.sparse matrix, shape (S, S)
        P split by pass direction (:func:`split_by_pass`).
    levels : int
        L, the deficit levels kept (``deficit_levels + 1``).

    Returns
    -------
    q : scipy.sparse.csr_matrix, shape (S L, S L)
        Index g * S + i.
    exit_probability : ndarray of float64, shape (S L,)
        The row sums of P_up on level 0, zero elsewhere.
    """
    s = p_up.shape[0]
    lower = sp.diags(np.ones(levels - 1), 1, shape=(levels, levels))
    raise_ = sp.diags(np.ones(levels - 1), -1, shape=(levels, levels))
    q = (sp.kron(sp.identity(levels), p_stay) + sp.kron(lower, p_down)
         + sp.kron(raise_, p_up)).tocsr()
    exit_probability = np.zeros(s * levels)
    exit_probability[:s] = np.asarray(p_up.sum(axis=1)).ravel()
    return q, exit_probability


#: the lap deficits an exact RTD keeps at least (:func:`exact_rtd`)
MIN_DEFICIT_LEVELS = 8
#: the lap deficits :func:`window_rtd` follows by default: more laps than particles fall
#: through the bottom within a window (the cost grows little with them)
WINDOW_DEFICIT_LEVELS = 16
#: the most lap deficits an exact RTD keeps; mass below stays unresolved (and is warned of,
#: with the chain's E(RT) from its lap drift: :func:`drift_residence_time`)
MAX_DEFICIT_LEVELS = 64
#: the share of the residences that may pass below the deepest lap deficit kept
DEFICIT_TOL = 1e-7
#: after the first try, the deepest K :func:`deeper_levels` goes to by the decay that try
#: measured, as a multiple of the first K
MEASURED_DEPTH_FACTOR = 4
#: the largest bound on a closed tail's error accepted (the 1-norm of the error of its
#: probabilities and of its loss below the deepest deficit, summed over its lags): the share
#: of the residences that may pass below the deepest deficit, an error of the same kind
#: (residences whose times are not known)
CLOSURE_TOL = DEFICIT_TOL
#: the unresolved mass that `fit`, `rtd` and `info` warn of (equal to
#: :data:`cfbmarkov.markov.model_summary.UNRESOLVED_LIMIT`, tested; that module stays free of
#: scipy): a loss above it that deeper deficits do not reduce is left there, said, rather
#: than followed to the deepest level
UNRESOLVED_WARNED = 0.01


def deeper_levels(tried: list[tuple[int, float]], tol: float = DEFICIT_TOL,
                  decay: float = float("nan")) -> int:
    """The lap deficits to keep next, from the tries so far: (K, the mass lost below level
    K) pairs, in order.

    The mass a chain's residences lose below level K falls about geometrically with K once
    its deepest excursions dominate, lost(K) ~ c rho^K. After the first try (K =
    :data:`MIN_DEFICIT_LEVELS`) the next K is where the loss would be a tenth of ``tol``
    by the ``decay`` that try measured (rho from its block elimination,
    :func:`cfbmarkov.markov.entry_chain.entry_matrix`), at most :data:`MEASURED_DEPTH_FACTOR`
    times the first K; without
    a decay in (0, 1) it doubles K. From two tries rho is estimated from their losses, and
    the next K is where the loss would be a tenth of ``tol`` (the loss of the shallower
    tries falls a little faster than the deeper ones'), at least 8 deeper than the last,
    at most :data:`MAX_DEFICIT_LEVELS`. Where the loss is above :data:`UNRESOLVED_WARNED`
    and fell by less than a tenth between the two tries, K stays: residences counted
    against the chain's net drift (up passes of a net downflow) keep falling at any depth,
    and their loss stays unresolved mass, warned of above 1 %.

    Parameters
    ----------
    tried : list of (int, float)
        The deficits kept and the mass lost below them, at least one try.
    tol : float, optional
        The loss accepted.
    decay : float, optional
        rho as the last try's block elimination measured it (used after the first try
        only; NaN: unknown).

    Returns
    -------
    int
        The next K; the last one tried where its loss is at most ``tol``, is warned of and
        fell by less than a tenth from the try before, or K is already
        :data:`MAX_DEFICIT_LEVELS`.
    """
    levels, lost = tried[-1]
    if lost <= tol or levels >= MAX_DEFICIT_LEVELS:
        return levels
    deeper = 2 * levels
    if len(tried) == 1 and 0.0 < decay < 1.0:
        deeper = min(MEASURED_DEPTH_FACTOR * levels,
                     levels + max(1, int(np.ceil(np.log(0.1 * tol / lost) / np.log(decay)))))
    if len(tried) >= 2:
        before, lost_before = tried[-2]
        if lost > UNRESOLVED_WARNED and not lost < 0.9 * lost_before:
            return levels       # deeper keeps losing as much: the laps run the other way
        rho = (lost / lost_before) ** (1.0 / (levels - before))
        deeper = levels + max(8, int(np.ceil(np.log(0.1 * tol / lost) / np.log(rho))))
    return min(deeper, MAX_DEFICIT_LEVELS)


def rtd_of_split_chain(p_up, p_down, p_stay, lag: float, deficit_levels: int | None = None,
                       tol: float = 1e-10, max_steps: int = 200_000,
                       entry: np.ndarray | None = None, entry_flux: np.ndarray | None = None,
                       chain=None) -> ResidenceTimeDistribution:
    """:func:`exact_rtd` of a chain given by its parts P_up, P_down, P_stay (scipy.sparse,
    [S, S]; e.g. from :func:`split_by_pass` or, without a dense matrix,
    :meth:`cfbmarkov.markov.estimate.TransitionEstimator.split_chain`). ``chain`` (P, CSR)
    is their sum when omitted. Other parameters, return value and errors as
    :func:`exact_rtd`."""
    p_up, p_down, p_stay = (sp.csr_matrix(part) for part in (p_up, p_down, p_stay))
    if chain is None:
        chain = (p_up + p_down + p_stay).tocsr()
    if deficit_levels is not None:
        return _rtd_on_levels(p_up, p_down, p_stay, lag, int(deficit_levels), tol, max_steps,
                              entry, entry_flux, chain)[0]
    # the depth from the mass each K loses below it, solved for (no propagation; the
    # tries cost a block elimination each), then the RTD propagated once at the K chosen
    levels, tried = MIN_DEFICIT_LEVELS, []
    elimination = DepthElimination(p_up, p_down, p_stay)     # the tries share their steps
    while True:
        start = _start_on_levels(p_up, p_down, p_stay, levels + 1, entry, entry_flux, chain,
                                 with_falls=True, elimination=elimination)
        tried.append((levels, start.lost))
        deeper = deeper_levels(tried, decay=start.decay)
        if deeper == levels:
            break
        levels = deeper
    rtd = _finish_levels(*start.finish_arguments(p_up, p_down, p_stay, tol, max_steps,
                                                 lag))[0]
    if rtd.deficit_unresolved > DEFICIT_TOL and entry is None:
        rtd = replace(rtd, drift_mean=drift_residence_time(p_up, p_down, chain, lag))
    return rtd


def rtd_moments(p_up, p_down, p_stay, lag: float, deficit_levels: int,
                entry: np.ndarray) -> tuple[float, float, float]:
    """The exact RTD's resolved mass, mean and SD on K = ``deficit_levels`` lap deficits
    from a given entry distribution, by three solves with I - Q instead of a propagation
    (:func:`~cfbmarkov.markov.shift_invert.factor_levels`: by the levels' blocks or
    SuperLU).

    With f(k) = s Q^(k-1) e (s the start on level 0, e the exits, Q the chain on the live
    (level, state) pairs, N = (I - Q)^-1): sum f = s N e, sum k f = s N^2 e and
    sum k^2 f = s (2 N^3 - N^2) e (the generating function sum k^2 x^(k-1) =
    (1 + x) / (1 - x)^3). The same RTD as :func:`rtd_of_split_chain` with ``entry`` and
    ``deficit_levels``, which stops where 1e-10 of the mass is left and may close its tail
    with an error of at most :data:`CLOSURE_TOL` of the mass: its mean and SD differ from
    these by that tail and that error alone. For the bootstrap resamples of a model's interval, whose
    RTD per bin is needed only as far as the bins reach (:mod:`cfbmarkov.analysis.bootstrap`).

    Parameters
    ----------
    p_up, p_down, p_stay : scipy.sparse matrix, shape (S, S)
        P split by pass direction (:func:`split_by_pass`).
    lag : float
        The lag (s).
    deficit_levels : int
        K, the deepest lap deficit kept.
    entry : ndarray of float64, shape (S,)
        The entry distribution (as :func:`exact_rtd`'s ``entry``).

    Returns
    -------
    (float, float, float)
        sum f (the mass that leaves through the top), E(RT) and SD(RT) in s.

    Raises
    ------
    CfbmarkovError
        As :func:`exact_rtd`: no up pass, every residence trapped, or a bad entry
        distribution; also where no residence ends.

    References
    ----------
    J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand, Princeton (1960),
    Ch. III (the moments of the absorption time from the fundamental matrix N).
    """
    p_up, p_down, p_stay = (sp.csr_matrix(part) for part in (p_up, p_down, p_stay))
    start = _start_on_levels(p_up, p_down, p_stay, int(deficit_levels) + 1, entry, None, None)
    return _moments_on_levels(p_up, p_down, p_stay, lag, start)


def rtd_moments_and_head(p_up, p_down, p_stay, lag: float, deficit_levels: int,
                         entry: np.ndarray, steps: int
                         ) -> tuple[float, float, float, ResidenceTimeDistribution]:
    """:func:`rtd_moments` and the RTD's first ``steps`` lags (its ``probability``; the
    rest of the mass is ``unresolved``), from one start on the levels and one set of the
    parts' transposes."""
    p_up, p_down, p_stay = (sp.csr_matrix(part) for part in (p_up, p_down, p_stay))
    # (the chain, for the closed classes, is not read with an entry distribution given)
    arrays = _transposed_parts((p_down, p_stay, p_up))
    start = _start_on_levels(p_up, p_down, p_stay, int(deficit_levels) + 1, entry, None, None,
                             arrays=arrays)
    head = _finish_levels(*start.finish_arguments(p_up, p_down, p_stay, 1e-10, int(steps),
                                                  lag), arrays=arrays, closure=False)[0]
    return (*_moments_on_levels(p_up, p_down, p_stay, lag, start, arrays), head)


@dataclass(frozen=True)
class HeadStart:
    """What a chain's RTD head needs from its start on the levels (:func:`heads`): the
    parts' transposes (:func:`_transposed_parts` of P_down, P_stay, P_up), the exit
    probabilities from level 0 and the live pairs and start, [L, S] each."""

    arrays: list
    exit_probability: np.ndarray
    live: np.ndarray
    start: np.ndarray


def rtd_moments_and_start(p_up, p_down, p_stay, lag: float, deficit_levels: int,
                          entry: np.ndarray) -> tuple[float, float, float, HeadStart]:
    """:func:`rtd_moments`, and what :func:`heads` needs to propagate the chain's RTD head
    beside others'."""
    p_up, p_down, p_stay = (sp.csr_matrix(part) for part in (p_up, p_down, p_stay))
    arrays = _transposed_parts((p_down, p_stay, p_up))
    start = _start_on_levels(p_up, p_down, p_stay, int(deficit_levels) + 1, entry, None, None,
                             arrays=arrays)
    return (*_moments_on_levels(p_up, p_down, p_stay, lag, start, arrays),
            HeadStart(arrays, start.exit_probability, start.live, start.start))


#: the fewest and the most chains whose heads :func:`heads` propagates side by side in one
#: chunk; between them, as many as give each Numba thread one chunk, rounded up to a
#: multiple of HEAD_LANES (:func:`head_chunk`)
HEAD_CHUNK = 16
HEAD_CHUNK_MAX = 128
#: the chunk's width is a multiple of this (two AVX2 registers of float64: no loop remainder)
HEAD_LANES = 8


def head_chunk(count: int, threads: int) -> int:
    """The chains per chunk of :func:`heads` for ``count`` chains on ``threads`` threads:
    the chunks as few as :data:`HEAD_CHUNK_MAX` chains a chunk allows, rounded up to a
    multiple of the threads (each thread as many chunks), and the chains shared evenly
    among them, each chunk rounded up to a multiple of :data:`HEAD_LANES`, within
    [:data:`HEAD_CHUNK`, :data:`HEAD_CHUNK_MAX`] (129 chains on one thread: two chunks
    of 72, not of 128 with 127 empty).

    The kernel's cost per chain falls as the chunk widens (each non-zero's index is read
    once a lag for the whole chunk, and the loop over its chains runs longer), an empty
    place in a chunk costs what a chain does, and a thread left without a chunk is lost:
    100 resamples of the paper-scale 3 m/s mle model (228 states on 9 levels, 1001 lags)
    took 1.05 s in two chunks of 56 on two threads against 1.43 s in seven of 16, and
    1.94 s in one chunk of 104 on one thread against 2.43 s in seven of 16 (``python
    benchmarks/interval_cost.py MODEL.h5``, 2026-12-07). Each chain's sums run in the same
    order whatever its chunk (:func:`_heads_of_chains`): the width changes no bit."""
    count, threads = max(int(count), 1), max(int(threads), 1)
    chunks = threads * -(-(-(-count // HEAD_CHUNK_MAX)) // threads)
    width = HEAD_LANES * -(-(-(-count // chunks)) // HEAD_LANES)
    return int(min(max(width, HEAD_CHUNK), HEAD_CHUNK_MAX))


def heads(starts: list[HeadStart], steps: int, tol: float = 1e-10,
          chunk: int | None = None) -> np.ndarray:
    """The first ``steps`` lags of the RTDs of many chains of one state space and depth
    (:func:`rtd_moments_and_start`): f(k) of each, as :func:`rtd_moments_and_head`'s head
    gives it, bit for bit (zero after the lag where its mass left fell below ``tol``),
    propagated side by side on the union of their non-zeros (:func:`_heads_of_chains`).

    Parameters
    ----------
    starts : list of HeadStart
        The chains (at least one), all on S states and L levels.
    steps : int
        Lags propagated.
    tol : float, optional
        The mass left below which a chain's propagation stops.
    chunk : int, optional
        Chains per chunk (default :func:`head_chunk` for Numba's thread count); any width
        gives the same bits.

    Returns
    -------
    ndarray of float64, shape (len(starts), steps)
    """
    import numba

    count = len(starts)
    levels, n = starts[0].live.shape
    width = head_chunk(count, numba.get_num_threads()) if chunk is None else int(chunk)
    chunks = -(-count // width)
    parts = []
    for p in range(3):              # down, stay, up: the union of the chains' non-zeros
        keys = [np.repeat(np.arange(n, dtype=np.int64), np.diff(h.arrays[3 * p])) * n
                + h.arrays[3 * p + 1] for h in starts]
        union = np.unique(np.concatenate(keys))
        values = np.zeros((chunks, union.size, width))
        for k, (h, key) in enumerate(zip(starts, keys)):
            values[k // width, np.searchsorted(union, key), k % width] = \
                h.arrays[3 * p + 2]
        indptr = np.searchsorted(union // n, np.arange(n + 1)).astype(np.int64)
        parts += [indptr, (union % n).astype(np.int64), values]
    exits = np.zeros((chunks, n, width))
    live = np.zeros((chunks, n, levels, width), np.bool_)
    start = np.zeros((chunks, n, levels, width))
    for k, h in enumerate(starts):
        c, r = divmod(k, width)
        exits[c, :, r] = h.exit_probability
        live[c, :, :, r] = h.live.T
        start[c, :, :, r] = h.start.T
    out = np.zeros((chunks, int(steps), width))
    _heads_of_chains(*parts, exits, live, start, float(tol), out)
    return out.transpose(0, 2, 1).reshape(chunks * width, int(steps))[:count]


def _transposed_parts(parts) -> list[np.ndarray]:
    """The CSR arrays (indptr, indices, data) of each part's transpose, sorted, in the
    types of the level kernels: rows are destinations (:func:`_first_passage_levels`)."""
    arrays = []
    for part in parts:
        transposed = sp.csr_matrix(part.T)
        transposed.sort_indices()
        arrays += [transposed.indptr.astype(np.int64), transposed.indices.astype(np.int64),
                   transposed.data.astype(np.float64)]
    return arrays


def _moments_on_levels(p_up, p_down, p_stay, lag: float, start: "_LevelStart",
                       arrays: list[np.ndarray] | None = None) -> tuple[float, float, float]:
    """:func:`rtd_moments` from a start on the levels (``arrays``: the parts' transposes,
    :func:`_transposed_parts` of (P_down, P_stay, P_up), formed here where not given)."""
    if arrays is None:
        arrays = _transposed_parts((p_down, p_stay, p_up))
    live = np.ascontiguousarray(start.live.T)
    indptr, indices, data = _level_system(*arrays, live)
    idx = np.flatnonzero(start.live.ravel())
    # by the levels' blocks where every pair is live (228 states on 9 levels: about 1.5 ms
    # against SuperLU's 4 ms), else SuperLU in the levels' natural order (about half the
    # time of its default column ordering on these chains, whose ordering step costs more
    # than the fill it saves: 6.4 against 10.5 ms)
    factors = factor_levels(indptr, indices, data, live)
    exits = np.zeros(start.live.size)
    exits[:start.exit_probability.size] = start.exit_probability
    with one_blas_thread():
        y1 = factors.solve(exits[idx], trans="N")
        y2 = factors.solve(y1, trans="N")
        y3 = factors.solve(y2, trans="N")
    s = start.start.ravel()[idx]
    total = float(s @ y1)
    if not total > 0:
        raise CfbmarkovError("no residence of the chain ends: its RTD has no mass")
    mean = float(s @ y2) / total
    second = float(s @ (2.0 * y3 - y2)) / total
    return total, lag * mean, lag * float(np.sqrt(max(second - mean * mean, 0.0)))


def drift_residence_time(p_up, p_down, chain, lag: float) -> float | None:
    """A periodic chain's mean residence time from its net lap drift: lag / (pi (P_up -
    P_down) 1), pi the chain's stationary distribution.

    Each residence ends with the lap counter one above its last record, so over a long run
    the records rise as fast as the laps: the mean time between records is the inverse of
    the mean lap gain per lag (Wald's identity for the lap counter of an irreducible chain,
    whose entry states are distributed as :func:`exact_rtd`'s). Exact whatever the depth
    the residences fall to, and cheap (one sparse LU): the check of an exact RTD whose
    residences fall below its deepest lap deficit.

    Parameters
    ----------
    p_up, p_down : scipy.sparse matrix, shape (S, S)
        The chain's parts through the top and the bottom.
    chain : scipy.sparse matrix, shape (S, S)
        P.
    lag : float
        The lag (s).

    Returns
    -------
    float or None
        E(RT) in s, of the closed class that the up passes land in; None where they land
        in several closed classes or in transient states (no single stationary
        distribution of the residences' states), or where the class does not rise on
        average. States outside that class (a state never left that nothing enters, say)
        do not count: no residence reaches them.

    References
    ----------
    A. Wald, "On cumulative sums of random variables", Ann. Math. Statist. 15, 283 (1944);
    S. Asmussen, Applied Probability and Queues, 2nd ed., Springer (2003), Ch. XI (Markov
    additive processes).
    """
    from scipy.sparse.linalg import splu

    chain = sp.csr_matrix(chain)
    p_up, p_down = sp.csr_matrix(p_up), sp.csr_matrix(p_down)
    classes = closed_classes(chain)
    label = -np.ones(chain.shape[0], np.int64)
    for k, members in enumerate(classes):
        label[members] = k
    owners = np.unique(label[np.asarray(p_up.sum(axis=0)).ravel() > 0])
    if owners.size != 1 or owners[0] < 0:     # entries in several classes, or transient
        return None
    members = np.asarray(classes[owners[0]])
    n = members.size
    system = (chain[members][:, members].T - sp.identity(n, format="csr")).tolil()
    system[n - 1, :] = np.ones(n)                       # sum pi = 1 instead of one balance
    rhs = np.zeros(n)
    rhs[-1] = 1.0
    pi = splu(sp.csc_matrix(system)).solve(rhs)
    gain = float(pi @ (np.asarray(p_up[members].sum(axis=1)).ravel()
                       - np.asarray(p_down[members].sum(axis=1)).ravel()))
    return lag / gain if gain > 0 else None


def _rtd_on_levels(p_up, p_down, p_stay, lag: float, deficit_levels: int, tol: float,
                   max_steps: int, entry, entry_flux, chain
                   ) -> tuple[ResidenceTimeDistribution, np.ndarray]:
    """:func:`rtd_of_split_chain` with K = ``deficit_levels`` lap deficits kept; also the
    mass that passed down from each level (float64 [K + 1], the last lost below)."""
    start = _start_on_levels(p_up, p_down, p_stay, deficit_levels + 1, entry, entry_flux,
                             chain)
    return _finish_levels(*start.finish_arguments(p_up, p_down, p_stay, tol, max_steps, lag))


@dataclass(frozen=True)
class _LevelStart:
    """Where the residences start on the lap-deficit levels (:func:`_start_on_levels`)."""

    live: np.ndarray                # bool [L, S]
    exit_probability: np.ndarray    # float64 [S], from level 0
    start: np.ndarray               # float64 [L, S], summing to 1
    entry: np.ndarray               # float64 [S], the entry distribution
    classes: int
    lost: float                     # the mass that falls below level L - 1 (NaN if not asked)
    decay: float = float("nan")     # rho, how fast ``lost`` falls with the depth (NaN: unknown)

    def finish_arguments(self, p_up, p_down, p_stay, tol, max_steps, lag) -> tuple:
        return ((p_down, p_stay, p_up), self.live, self.exit_probability, self.start, tol,
                max_steps, lag, self.entry, self.classes)


def _start_on_levels(p_up, p_down, p_stay, levels: int, entry, entry_flux, chain,
                     with_falls: bool = False, arrays: list[np.ndarray] | None = None,
                     elimination: DepthElimination | None = None) -> _LevelStart:
    """The live (level, state) pairs, the start distribution on level 0 (the given entry
    distribution, or the stationary one of the embedded entry chain), and with
    ``with_falls`` the mass of the residences that falls below the deepest of ``levels``
    levels (:func:`cfbmarkov.markov.entry_chain.entry_matrix`)."""
    s = p_up.shape[0]
    exit_probability = np.zeros(s * levels)
    exit_probability[:s] = np.asarray(p_up.sum(axis=1)).ravel()
    entries = np.flatnonzero(np.asarray(p_up.sum(axis=0)).ravel() > 0)
    if entries.size == 0:
        raise CfbmarkovError("the model has no transition up through the top: particles never "
                             "leave, so there is no residence time; its fitting window saw no "
                             "particle pass the top: fit on a longer window, or check with "
                             "cfbmarkov info the run's height and vertical axis, and whether "
                             "its particles are tracked through the top")
    # keep the states from which an exit can be reached (others trap their mass): one
    # breadth-first search backwards from the exit states
    live = (_live_levels(p_up, p_down, p_stay, levels, exit_probability > 0) if arrays is None
            else _live_from_transposes(*arrays, levels, exit_probability[:s] > 0))
    idx = np.flatnonzero(live)
    position = -np.ones(s * levels, np.int64)
    position[idx] = np.arange(idx.size)
    if not live[entries].any():
        raise TrappedResidences(
            f"every residence is trapped: from none of the {entries.size} state(s) particles "
            "enter through the inlet can the chain reach the top again (they lead to states "
            "that are never left; fit with --connected, or on a longer window)")
    falls = None
    if entry is not None:
        entry = np.asarray(entry, dtype=np.float64)
        if entry.shape != (s,) or entry.min() < 0 or not entry[live[:s]].sum() > 0:
            raise CfbmarkovError("entry distribution must be [S], non-negative, and put mass "
                                 "on states from which the top can be reached")
        start = np.zeros((levels, s))
        start[0, live[:s]] = entry[live[:s]]
        start /= start.sum()
        decay = float("nan")
        if with_falls:
            _, falls, decay = entry_matrix(p_up, p_down, p_stay, live.reshape(levels, s),
                                           entries, with_falls=True, with_decay=True,
                                           elimination=elimination)
        return _LevelStart(live.reshape(levels, s), exit_probability[:s], start,
                           entry / entry.sum(), 1,
                           float(start[0] @ falls) if with_falls else float("nan"), decay)
    # B, the embedded chain of entry states, by block elimination over the levels
    # (markov.entry_chain: no LU of the [S L, S L] matrix), and its stationary distribution
    embedded = entry_matrix(p_up, p_down, p_stay, live.reshape(levels, s), entries,
                            with_falls=with_falls, with_decay=with_falls,
                            elimination=elimination)
    decay = float("nan")
    if with_falls:
        embedded, falls, decay = embedded
    live_entries = live[entries]
    classes = _closed_entry_classes(chain, entries)
    if len(classes) > 1:
        # reducible: one stationary entry distribution per closed class, weighted by the
        # class's observed entry flux (the chain alone cannot say how much flows in each)
        flux = (np.zeros(s) if entry_flux is None
                else np.asarray(entry_flux, dtype=np.float64).ravel())
        label = -np.ones(s, np.int64)
        for k, members in enumerate(closed_classes(chain)):
            label[members] = k
        weights = np.array([max(flux[label == label[entries[c[0]]]].sum(), 0.0)
                            for c in classes])
        weights = weights / weights.sum() if weights.sum() > 0 else np.ones(len(classes))
        weights /= weights.sum()
        nu = np.zeros(entries.size)
        for c, w in zip(classes, weights):
            nu[c] = w * embedded_stationary(embedded[np.ix_(c, c)], live_entries[c])
    else:
        nu = embedded_stationary(embedded, live_entries)
    start = np.zeros(idx.size)
    ok = live[entries]
    start[position[entries[ok]]] = nu[ok]
    if not start.sum() > 0:
        raise TrappedResidences("every residence is trapped: the chain's entries carry no "
                                "stationary mass from which the top can be reached (fit on "
                                "a longer window, with fewer cells, or with --connected)")
    entry = np.zeros(s)
    entry[entries] = nu
    full_start = np.zeros(s * levels)
    full_start[idx] = start
    full_start = full_start.reshape(levels, s)
    return _LevelStart(live.reshape(levels, s), exit_probability[:s], full_start, entry,
                       max(1, len(classes)),
                       float(full_start[0] @ falls) if with_falls else float("nan"), decay)


def open_rtd(absorbing: np.ndarray, exit_probability: np.ndarray, entry: np.ndarray, lag: float,
             tol: float = 1e-10, max_steps: int = 200_000) -> ResidenceTimeDistribution:
    """Exact RTD of an open riser: first passage to the outside from the entry distribution.

    f(k) = e Q^(k-1) r for k = 1, 2, ...: the probability that a particle entering in state j
    (with probability e_j) leaves through the outlet on its k-th transition. Its mean is
    e (I - Q)^-1 1 lags (the fundamental matrix N = (I - Q)^-1).

    Parameters
    ----------
    absorbing : ndarray of float64, shape (S, S)
        Q = diag(1 - r) P, the sub-stochastic matrix among the states.
    exit_probability : ndarray of float64, shape (S,)
        r, the probability of leaving through the outlet within one lag.
    entry : ndarray of float64, shape (S,)
        e, the entry distribution (sums to 1).
    lag : float
        The lag (s).
    tol : float, optional
        Stop when the mass still inside is below this.
    max_steps : int, optional
        Most lags followed; the rest is ``unresolved``.

    Returns
    -------
    ResidenceTimeDistribution
        ``unresolved`` holds the mass that never leaves (traps) or is still inside at
        ``max_steps``.

    Raises
    ------
    TrappedResidences
        If no particle that enters can ever leave.

    References
    ----------
    J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand, Princeton (1960),
    Ch. III (absorbing chains, the fundamental matrix).
    """
    exit_probability = np.ascontiguousarray(exit_probability, dtype=np.float64)
    entry = np.ascontiguousarray(entry, dtype=np.float64)
    result = _finish(sp.csr_matrix(absorbing), exit_probability, entry, tol, max_steps, lag,
                     entry)
    if result.probability.sum() <= 0:
        raise TrappedResidences("no particle that enters the open riser can reach the outlet "
                                "in the model: every residence is trapped (the fitting "
                                "window holds no path from an entry to an exit); fit on a "
                                "longer window, or with fewer cells; where tracks end away "
                                "from the outlet (falls back out through the inlet, out of "
                                "view), the states they end in keep them: import the riser "
                                "from farther below its inlet, or use a state space without "
                                "memory")
    return result


def _closed_entry_classes(chain: sp.csr_matrix, entries: np.ndarray) -> list[np.ndarray]:
    """The closed classes of the graph P_ij > 0 that hold entry states, each as positions
    into ``entries``; transient entry states belong to none (they carry no stationary
    mass). One class: all entries (the irreducible case)."""
    classes = closed_classes(chain)
    if len(classes) <= 1:
        return [np.arange(entries.size)]
    label = -np.ones(chain.shape[0], np.int64)
    for k, members in enumerate(classes):
        label[members] = k
    of_entry = label[entries]
    found = [np.flatnonzero(of_entry == k) for k in range(len(classes))]
    found = [c for c in found if c.size]
    return found if len(found) > 1 else [np.arange(entries.size)]


def _finish(q_live, exit_probability, start, tol, max_steps, lag, entry
            ) -> ResidenceTimeDistribution:
    """f(k) of an open riser's chain: its Q as the one level of :func:`_propagate_levels`
    (no pass down or up between levels), its tail closed as a periodic riser's."""
    n = q_live.shape[0]
    nothing = sp.csr_matrix((n, n))
    arrays = _transposed_parts((nothing, q_live, nothing))
    out = np.zeros(max_steps)
    steps, bound = _propagate_levels(arrays, np.ones((n, 1), np.bool_),
                                     np.ascontiguousarray(start, np.float64).reshape(n, 1),
                                     exit_probability, np.zeros(n), tol, max_steps, out,
                                     np.zeros(1))
    f = out[:steps].copy()   # out[k] = mass absorbed on transition k+1 = P(RT = (k+1) lag)
    return ResidenceTimeDistribution(lag, f, min(1.0, max(0.0, 1.0 - float(f.sum())) + bound),
                                     entry)


def _finish_levels(parts, live, exit_probability, start, tol, max_steps, lag, entry,
                   classes: int, arrays: list[np.ndarray] | None = None,
                   closure: bool = True) -> tuple[ResidenceTimeDistribution, np.ndarray]:
    """:func:`_finish` on the levels: ``parts`` (P_down, P_stay, P_up), ``live`` and
    ``start`` [L, S] (passed to the kernel as [S, L]), ``exit_probability`` [S] (from
    level 0); ``arrays``, the parts' transposes where already formed
    (:func:`_transposed_parts`). Also returns the mass that passed down from each level
    (float64 [L])."""
    if arrays is None:
        arrays = _transposed_parts(parts)
    out = np.zeros(max_steps)
    levels = live.shape[0]
    falls = np.zeros(levels)
    down_probability = np.asarray(parts[0].sum(axis=1), dtype=np.float64).ravel()
    steps, bound = _propagate_levels(arrays, np.ascontiguousarray(live.T),
                                     np.ascontiguousarray(start.T),
                                     np.ascontiguousarray(exit_probability, np.float64),
                                     down_probability, tol, max_steps, out, falls, closure)
    f = out[:steps].copy()   # out[k] = mass absorbed on transition k+1 = P(RT = (k+1) lag)
    unresolved = min(1.0, max(0.0, 1.0 - float(f.sum())) + bound)
    return ResidenceTimeDistribution(lag, f, unresolved, entry, None, classes,
                                     deficit_levels=levels - 1,
                                     deficit_unresolved=float(falls[-1])), falls


def _propagate_levels(arrays, live, start, exit_probability, down_probability, tol: float,
                      max_steps: int, out: np.ndarray, falls: np.ndarray,
                      closure: bool = True) -> tuple[int, float]:
    """f(k) into ``out`` and the passes down into ``falls`` from ``start`` [S, L] on the
    levels (``live`` [S, L]; ``arrays`` the parts' transposes), until the mass left falls
    below ``tol`` or ``max_steps`` lags: lag by lag, its tail closed by a Krylov projection
    (:mod:`cfbmarkov.markov.tail_closure`) from :data:`~cfbmarkov.markov.tail_closure.
    FIRST_TRY` lags on (then at twice as many, and so on; earlier where little mass is
    left, :data:`~cfbmarkov.markov.tail_closure.EARLY_MASS`) where the bound on its error is
    at most :data:`CLOSURE_TOL` (or ``tol`` where larger). Returns the lags reached and
    that bound (0 where no closure was taken). The same bits on any thread count."""
    levels = live.shape[1]
    work = sum(array.size for array in arrays[2::3]) * levels
    kernel = (_first_passage_levels_parallel if work > PARALLEL_LEVEL_WORK
              and nb.get_num_threads() > 1 else _first_passage_levels)
    state = start.copy()
    dimension = (krylov_dimension(int(live.sum()), *live.shape, work + 3 * live.size)
                 if closure and tol > 0 else 0)
    error_tol = max(tol, CLOSURE_TOL)
    reached, stop, tries = 0, (EARLY_STEP if dimension else max_steps), []
    inverse, factored = None, False
    left = 1.0
    while True:
        stop = min(stop, max_steps)
        reached = kernel(*arrays, exit_probability, live, state, tol, reached, stop, out,
                         down_probability, falls)
        if reached < stop or stop >= max_steps or _level_mass(state) < tol:
            return reached, 0.0
        if reached < FIRST_TRY and not tries:
            before, left = left, _level_mass(state)
            # an early try where less than EARLY_MASS is left, unless the last EARLY_STEP
            # lags' decay, continued, ends the propagation before FIRST_TRY (where no try
            # would be made at all: an Arnoldi costs more than the lags it would save)
            if (reached < 2 * EARLY_STEP or left >= EARLY_MASS
                    or left * (left / before) ** ((FIRST_TRY - reached) / EARLY_STEP) < tol):
                stop = min(reached + EARLY_STEP, FIRST_TRY)
                continue
        if reached >= FIRST_TRY and not factored:
            # a long tail: I - Q factored once for all its tries, where worth its cost
            inverse = level_inverse(*_level_system(*arrays, live), live, work + 3 * live.size)
            factored = True
        steps, bound = try_closure(arrays, live, state, exit_probability, down_probability,
                                   reached, tol, error_tol, max_steps, out, falls, dimension,
                                   inverse)
        if steps >= 0:
            return steps, bound
        tries.append((reached, bound))
        stop = next_try(tries, error_tol) if len(tries) < MAX_TRIES else max_steps
