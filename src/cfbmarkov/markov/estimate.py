"""Estimators of the transition matrix (paper Eq. 2-4; ``docs/definitions.md``, States and
transitions).

An estimator is configured with a state space and a lag, then ``fit(discrete)`` on
discrete trajectories (:mod:`cfbmarkov.markov.discrete`) returns an immutable
:class:`~cfbmarkov.markov.model.MarkovModel`:

- :class:`PaperEstimator` (``paper``): the plain average over the frames t_c of the
  row-normalised per-frame matrices P'(t_c), Eq. (2)-(4), a row of P'(t_c) being all zero
  when its cell is empty at t_c. Such a plain average has row sums equal to the fraction of
  frames in which the cell was occupied; each row is divided by its sum so that P is
  stochastic, which equals averaging P' over the frames in which the cell was occupied.
- :class:`MaximumLikelihoodEstimator` (``mle``): pooled counts C_ij / sum_j C_ij, the
  maximum-likelihood non-reversible estimate.

Both count every pair of frames (t, t + lag) with A <= t and t + lag <= B for every particle
(sliding window) and record the direction of each transition through the periodic boundary
by the minimal-image rule on y. A state with no outgoing transition in the window keeps its
particles in place (P_ii = 1) when it is the only state of its cell (cells); in a state
space with memory it moves as the other states of its cell did (their pooled counts). The
model lists such states.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba as nb
import numpy as np
import scipy.sparse as sp

from cfbmarkov.errors import InputError
from cfbmarkov.markov.connectivity import largest_connected_set, restrict_to_set
from cfbmarkov.markov.discrete import as_discrete_list, discretize
from cfbmarkov.markov.states import StateSpace

if TYPE_CHECKING:
    from cfbmarkov.markov.model import MarkovModel


@nb.njit(cache=True)
def _frame_occupancy(states, t, lag_frames, occupancy):
    """occupancy[i] = N_i(t), the particles in state i at frame t whose frame t + lag is
    present too (Numba; ``occupancy`` [S] is overwritten)."""
    occupancy[:] = 0
    for p in range(states.shape[1]):
        i = states[t, p]
        if i >= 0 and states[t + lag_frames, p] >= 0:
            occupancy[i] += 1


@nb.njit(cache=True)
def _count_kernel(states, vertical, lag_frames, height, n_states, counts, counts_up,
                  counts_down, frame_average, occupied_frames, with_frame_average):
    """Accumulate the transition counts of discrete trajectories (Numba kernel).

    ``states`` int32 [T, N] (-1: absent), ``vertical`` float64 [T, N] heights (m). For
    every frame pair (t, t + lag) whose two ends are present, adds to ``counts[i, j]``
    (pooled), ``counts_up`` / ``counts_down`` (passes up through the top / down through the
    bottom: the height dropped / rose by more than H/2, the minimal-image rule),
    ``frame_average[i, j] += N_ij(t) / N_i(t)`` (the sum of the per-frame matrices P'(t)
    of the paper's Eq. 2; skipped unless ``with_frame_average``) and
    ``occupied_frames[i] += 1`` where N_i(t) > 0. Returns the number of frame pairs.
    """
    n_frames, n_particles = states.shape
    half = 0.5 * height
    occupancy = np.zeros(n_states, dtype=np.int64)
    pairs = 0
    for t in range(n_frames - lag_frames):
        _frame_occupancy(states, t, lag_frames, occupancy)
        for i in range(n_states):
            if occupancy[i] > 0:
                occupied_frames[i] += 1
        for p in range(n_particles):
            i = states[t, p]
            j = states[t + lag_frames, p]
            if i < 0 or j < 0:
                continue
            counts[i, j] += 1
            if with_frame_average:
                frame_average[i, j] += 1.0 / occupancy[i]
            dy = vertical[t + lag_frames, p] - vertical[t, p]
            if dy < -half:
                counts_up[i, j] += 1
            elif dy > half:
                counts_down[i, j] += 1
        pairs += 1
    return pairs


@nb.njit(cache=True, parallel=True)
def _sparse_count_kernel(states, vertical, lag_frames, height, n_states, with_frame_average,
                         occupied_frames, chunks):
    """The counts of :func:`_count_kernel` in compressed sparse rows (Numba kernel, parallel).

    Each transition is first placed in the row of its start state (a counting sort by i,
    frames in time order), then each row is gathered with a scratch marker over the
    destinations, so the work and memory are O(transitions + S + non-zeros), never S x S;
    the per-frame sums of the paper's Eq. 2 run in the same (time) order as the dense
    kernel's. The threads share the frames in consecutive chunks (a row's slots for chunk c
    follow those of chunks before it, so every row keeps the time order) and then the rows;
    the result is the same for any thread count and any ``chunks`` (the number of frame and
    row chunks, the caller's thread count: asking Numba for it here would make the kernel
    uncacheable). Returns ``indptr`` [S + 1], ``indices``
    int32, the values of ``counts``, ``counts_up``, ``counts_down`` (int64) and of the
    frame-average sum (float64; empty unless ``with_frame_average``) on that one pattern
    (explicit zeros kept in up and down, destinations of a row unsorted), and the number of
    frame pairs; ``occupied_frames`` [S] is updated."""
    n_frames, n_particles = states.shape
    half = 0.5 * height
    pairs = max(n_frames - lag_frames, 0)
    chunks = max(1, min(chunks, pairs))
    first_frame = np.empty(chunks + 1, np.int64)
    for c in range(chunks + 1):
        first_frame[c] = pairs * c // chunks
    histogram = np.zeros((chunks, n_states), np.int64)     # transitions from i per chunk
    for c in nb.prange(chunks):
        for t in range(first_frame[c], first_frame[c + 1]):
            for p in range(n_particles):
                i = states[t, p]
                if i >= 0 and states[t + lag_frames, p] >= 0:
                    histogram[c, i] += 1
    start = np.zeros(n_states + 1, np.int64)
    slot = np.empty((chunks, n_states), np.int64)   # next free slot of row i for chunk c
    total = 0
    for i in range(n_states):
        start[i] = total
        for c in range(chunks):
            slot[c, i] = total
            total += histogram[c, i]
    start[n_states] = total
    destination = np.empty(total, np.int32)
    kind = np.empty(total, np.int8)             # 0: stays, 1: up through the top, 2: down
    weight = np.empty(total if with_frame_average else 0, np.float64)
    occupied = np.zeros((chunks, n_states), np.int64)
    for c in nb.prange(chunks):
        occupancy = np.zeros(n_states, np.int64)
        last_frame = -np.ones(n_states, np.int64)   # the last frame state i was occupied in
        for t in range(first_frame[c], first_frame[c + 1]):
            if with_frame_average:      # N_i(t) first: the weights 1 / N_i(t) of Eq. 2
                _frame_occupancy(states, t, lag_frames, occupancy)
            for p in range(n_particles):
                i = states[t, p]
                j = states[t + lag_frames, p]
                if i < 0 or j < 0:
                    continue
                if last_frame[i] != t:
                    last_frame[i] = t
                    occupied[c, i] += 1
                q = slot[c, i]
                slot[c, i] += 1
                destination[q] = j
                dy = vertical[t + lag_frames, p] - vertical[t, p]
                kind[q] = 1 if dy < -half else (2 if dy > half else 0)
                if with_frame_average:
                    weight[q] = 1.0 / occupancy[i]
    for c in range(chunks):
        for i in range(n_states):
            occupied_frames[i] += occupied[c, i]
    # gather each row in place at its own slots (a row has at most as many non-zeros as
    # transitions), the rows shared in consecutive chunks, then compact
    indices = np.empty(total, np.int32)
    counts = np.zeros(total, np.int64)
    up = np.zeros(total, np.int64)
    down = np.zeros(total, np.int64)
    average = np.zeros(total if with_frame_average else 0, np.float64)
    row_nonzeros = np.zeros(n_states, np.int64)
    for c in nb.prange(chunks):
        where = -np.ones(n_states, np.int64)        # position of destination j in its row
        for i in range(n_states * c // chunks, n_states * (c + 1) // chunks):
            row_start = start[i]
            nnz = row_start
            for q in range(start[i], start[i + 1]):
                j = destination[q]
                k = where[j]
                if k < row_start:
                    k = nnz
                    where[j] = k
                    indices[k] = j
                    nnz += 1
                counts[k] += 1
                if kind[q] == 1:
                    up[k] += 1
                elif kind[q] == 2:
                    down[k] += 1
                if with_frame_average:
                    average[k] += weight[q]
            row_nonzeros[i] = nnz - row_start
    indptr = np.zeros(n_states + 1, np.int64)
    for i in range(n_states):
        k = indptr[i]
        for q in range(start[i], start[i] + row_nonzeros[i]):   # k <= q: a forward move
            indices[k] = indices[q]
            counts[k] = counts[q]
            up[k] = up[q]
            down[k] = down[q]
            if with_frame_average:
                average[k] = average[q]
            k += 1
        indptr[i + 1] = k
    nnz = indptr[n_states]
    return (indptr, indices[:nnz], counts[:nnz], up[:nnz], down[:nnz],
            average[:nnz] if with_frame_average else average, pairs)


@nb.njit(cache=True)
def _open_kernel(states, vertical, lag_frames, band, height, exits, entries, vanished,
                 appeared):
    """Count what crosses the faces of an open riser (Numba kernel).

    For every frame pair (t, t + lag) of a particle: present then absent is an exit
    (``exits[i] += 1``) when its height at t lies within ``band`` (one cell) of the outlet
    face at H, else a disappearance (``vanished[i]``); absent then present is an entry
    (``entries[j] += 1``) when its height at t + lag lies within ``band`` of the inlet face
    at 0, else an appearance (``appeared[j]``). Returns nothing; arrays are updated.
    """
    n_frames, n_particles = states.shape
    for t in range(n_frames - lag_frames):
        for p in range(n_particles):
            i = states[t, p]
            j = states[t + lag_frames, p]
            if i >= 0 and j < 0:
                if vertical[t, p] >= height - band:
                    exits[i] += 1
                else:
                    vanished[i] += 1
            elif i < 0 and j >= 0:
                if vertical[t + lag_frames, p] <= band:
                    entries[j] += 1
                else:
                    appeared[j] += 1


@dataclass(frozen=True)
class FaceCounts:
    """What crossed the faces of an open riser (``docs/definitions.md``, Open risers).

    Attributes
    ----------
    exits : ndarray of int64, shape (S,)
        Transitions from each state to the outside through the outlet face (present, then
        absent one lag later, within one cell of the outlet).
    entries : ndarray of int64, shape (S,)
        Entries through the inlet face into each state (absent, then present within one
        cell of the inlet).
    vanished, appeared : ndarray of int64, shape (S,)
        Tracks that ended or began elsewhere (out of a camera's view, a gap): not counted
        as transitions, exits or entries (censored).
    """

    exits: np.ndarray
    entries: np.ndarray
    vanished: np.ndarray
    appeared: np.ndarray

    def __add__(self, other: "FaceCounts") -> "FaceCounts":
        return FaceCounts(self.exits + other.exits, self.entries + other.entries,
                          self.vanished + other.vanished, self.appeared + other.appeared)


@dataclass(frozen=True)
class TransitionCounts:
    """Everything an estimator gathers from the data before it forms P.

    Attributes
    ----------
    counts : ndarray of int64, shape (S, S)
        Pooled transition counts C_ij. With ``count_transitions(..., sparse=True)`` this and
        the other [S, S] fields are ``scipy.sparse.csr_array`` instead.
    counts_up, counts_down : ndarray of int64, shape (S, S)
        The transitions among them that passed up through the top / down through the
        bottom of the periodic riser.
    frame_average_sum : ndarray of float64, shape (S, S), or None
        Sum over the frame pairs of the per-frame row-normalised matrices P'(t) (paper
        Eq. 2-4); None where it was not gathered (only the paper's estimator needs it).
    occupied_frames : ndarray of int64, shape (S,)
        Frame pairs in which each state was occupied.
    frame_pairs : int
        Number of frame pairs (t, t + lag) counted.
    faces : FaceCounts or None
        Exits and entries of an open riser; None for a periodic one.
    """

    counts: np.ndarray
    counts_up: np.ndarray
    counts_down: np.ndarray
    frame_average_sum: np.ndarray | None
    occupied_frames: np.ndarray
    frame_pairs: int
    faces: FaceCounts | None = None

    @property
    def n_transitions(self) -> int:
        """Total number of transitions counted, sum of C_ij."""
        return int(self.counts.sum())

    def __add__(self, other: "TransitionCounts") -> "TransitionCounts":
        """The counts of two sets of data together (e.g. the training blocks of a fold)."""
        averages = (None if self.frame_average_sum is None or other.frame_average_sum is None
                    else self.frame_average_sum + other.frame_average_sum)
        faces = (None if self.faces is None or other.faces is None
                 else self.faces + other.faces)
        return TransitionCounts(self.counts + other.counts, self.counts_up + other.counts_up,
                                self.counts_down + other.counts_down, averages,
                                self.occupied_frames + other.occupied_frames,
                                self.frame_pairs + other.frame_pairs, faces)


def count_transitions(data, frame_average: bool = True, sparse: bool = False
                      ) -> TransitionCounts:
    """Count the transitions of discrete trajectories.

    Parameters
    ----------
    data : DiscreteTrajectories or sequence of them
        The windows to count (all in one state space, at one lag).
    frame_average : bool
        Also sum the per-frame matrices P'(t) that only the paper's estimator needs
        (``frame_average_sum`` is None otherwise).
    sparse : bool, optional
        Hold the [S, S] arrays as ``scipy.sparse.csr_array`` (memory and work grow with the
        transitions and non-zeros, never with S x S; what cross-validation over large state
        spaces uses, with :meth:`TransitionEstimator.split_chain`). Models are fitted from
        dense counts.

    Returns
    -------
    TransitionCounts

    Raises
    ------
    InputError
        If ``data`` is empty or not discrete trajectories, or the windows differ in state
        space or lag.

    Notes
    -----
    Every frame pair (t, t + lag) of every particle is counted (sliding window); a pair
    with an absent end is skipped. A pass through the periodic boundary is told by the
    minimal-image rule on y (``docs/definitions.md``, Pass direction).
    """
    windows = as_discrete_list(data)
    s = windows[0].state_space.n_states
    if sparse:
        return _count_sparse(windows, frame_average)
    counts = np.zeros((s, s), np.int64)
    up = np.zeros((s, s), np.int64)
    down = np.zeros((s, s), np.int64)
    frame_sum = np.zeros((s, s) if frame_average else (1, 1), np.float64)
    occupied = np.zeros(s, np.int64)
    pairs = 0
    faces = _new_faces(windows)
    for window, states, vertical in _window_arrays(windows, faces):
        pairs += _count_kernel(states, vertical, int(window.lag_frames), float(window.height),
                               s, counts, up, down, frame_sum, occupied, bool(frame_average))
    return TransitionCounts(counts, up, down, frame_sum if frame_average else None, occupied,
                            pairs, faces)


def _new_faces(windows) -> FaceCounts | None:
    """Empty face counts for windows of an open riser; None for a periodic one."""
    s = windows[0].state_space.n_states
    return (FaceCounts(*(np.zeros(s, np.int64) for _ in range(4)))
            if windows[0].boundary == "open" else None)


def _window_arrays(windows, faces: FaceCounts | None):
    """Each window with its states (int32) and heights (float64) as contiguous arrays, after
    checking that it shares the first one's state space, lag and boundary; an open riser's
    face crossings are added to ``faces`` on the way."""
    space = windows[0].state_space
    open_riser = windows[0].boundary == "open"
    for window in windows:
        if window.state_space != space or not window.matches_lag(windows[0].lag):
            raise InputError("discrete trajectories counted together must share the state "
                             "space and the lag")
        if (window.boundary == "open") != open_riser:
            raise InputError("discrete trajectories counted together must share the boundary "
                             "(periodic or open)")
        states = np.ascontiguousarray(window.states, dtype=np.int32)
        vertical = np.ascontiguousarray(window.vertical, dtype=np.float64)
        if open_riser:
            _open_kernel(states, vertical, int(window.lag_frames), face_band(space),
                         float(window.height), faces.exits, faces.entries, faces.vanished,
                         faces.appeared)
        yield window, states, vertical


def _count_sparse(windows, frame_average: bool) -> TransitionCounts:
    """:func:`count_transitions` with scipy.sparse CSR arrays (one window at a time)."""
    s = windows[0].state_space.n_states
    faces = _new_faces(windows)
    total = None
    for window, states, vertical in _window_arrays(windows, faces):
        occupied = np.zeros(s, np.int64)
        indptr, indices, counts, up, down, average, pairs = _sparse_count_kernel(
            states, vertical, int(window.lag_frames), float(window.height), s,
            bool(frame_average), occupied, nb.get_num_threads())
        # sort each row's destinations once; the four value arrays follow the same order
        order = sp.csr_array((np.arange(indices.size, dtype=np.int64), indices, indptr),
                             shape=(s, s))
        order.sort_indices()
        permutation, sorted_indices, sorted_indptr = order.data, order.indices, order.indptr

        matrices = [sp.csr_array((values[permutation], sorted_indices.copy(),
                                  sorted_indptr.copy()), shape=(s, s))
                    for values in ((counts, up, down, average) if frame_average
                                   else (counts, up, down))]
        part = TransitionCounts(*matrices[:3], matrices[3] if frame_average else None,
                                occupied, int(pairs))
        total = part if total is None else total + part
    return dataclasses.replace(total, faces=faces)     # the faces of every window, once


def open_chain(counts: TransitionCounts) -> dict:
    """The open riser's part of a model from its counts (pooled, maximum likelihood).

    Each state i leaves to the outside with probability r_i = X_i / (sum_j C_ij + X_i)
    (X: exits through the outlet); otherwise it moves by the row-stochastic P (the
    transition matrix given that it stays), so the sub-stochastic matrix of the open chain
    is Q = diag(1 - r) P. Entries through the inlet give the entry distribution
    e_j = N_j / sum N and the inflow, entries per lag. Tracks that vanish or appear away
    from the faces are censored: neither transitions nor exits nor entries.

    Parameters
    ----------
    counts : TransitionCounts
        Counts of an open riser (``faces`` not None).

    Returns
    -------
    dict
        ``boundary``, ``exit_probability`` [S], ``exit_counts`` [S], ``entry_counts`` [S],
        ``inflow_per_lag`` and ``censored_tracks`` (vanished, appeared) for
        :class:`~cfbmarkov.markov.model.MarkovModel`.

    References
    ----------
    J. G. Kemeny and J. L. Snell, Finite Markov Chains (1960), Ch. III (absorbing chains).
    """
    faces = counts.faces
    stayed = counts.counts.sum(axis=1).astype(np.float64)
    total = stayed + faces.exits
    exit_probability = np.divide(faces.exits, total, out=np.zeros(total.size), where=total > 0)
    return {"boundary": "open", "exit_probability": exit_probability,
            "exit_counts": faces.exits.copy(), "entry_counts": faces.entries.copy(),
            "inflow_per_lag": float(faces.entries.sum()) / max(counts.frame_pairs, 1),
            "censored_tracks": (int(faces.vanished.sum()), int(faces.appeared.sum()))}


def face_band(space: StateSpace) -> float:
    """How close to a face (m) a particle must vanish or appear to have crossed it: one
    cell height, H / rows (``docs/definitions.md``, Open risers).

    Parameters
    ----------
    space : StateSpace
        A cell-based state space (with ``height`` and ``rows``).

    Returns
    -------
    float
    """
    return float(space.height) / int(space.rows)


class TransitionEstimator:
    """Base estimator: configure with a state space and a lag (s), then :meth:`fit`.

    Parameters
    ----------
    state_space : StateSpace
        The states of the models it fits.
    lag : float, optional
        The lag tau (s), positive.
    connected : bool, optional
        Remove the transitions that leave the largest strongly connected set of the counts
        (and renormalise those rows), as deeptime and PyEMMA do by default: a state first
        entered in the window's last frame then traps no particle. Off by default (the
        paper's chain keeps every observed transition).
    coherent : bool, optional
        Also fit the coherence of the particles' moves (the cluster model,
        :mod:`cfbmarkov.markov.coherence`), for a periodic riser: calibrated so that the
        model's Monte Carlo snapshots show the window's cluster index
        (:func:`~cfbmarkov.markov.coherence.calibrate_coherence`); off by default
        (independent particles, the paper's).

    Attributes
    ----------
    name : str
        The estimator's name (``paper``, ``mle``), recorded in its models; a class
        attribute.

    Raises
    ------
    InputError
        If ``lag`` is not positive.

    Notes
    -----
    See ``docs/definitions.md`` (Estimators; Unvisited states).
    """

    name: str = ""

    def __init__(self, state_space: StateSpace, lag: float = 0.025, connected: bool = False,
                 coherent: bool = False):
        from cfbmarkov.limits import check_fit

        if not (np.isfinite(lag) and lag > 0):
            raise InputError(f"lag {lag:g} s must be a positive finite number")
        check_fit(state_space)          # refuse before counting: the dense [S, S] arrays
        self.state_space = state_space
        self.lag = float(lag)
        self.connected = bool(connected)
        self.coherent = bool(coherent)

    def __repr__(self) -> str:
        extra = (", connected=True" if self.connected else "") + (
            ", coherent=True" if self.coherent else "")
        return f"{type(self).__name__}({self.state_space!r}, lag={self.lag:g}{extra})"

    def transition_matrix(self, counts: TransitionCounts) -> np.ndarray:
        """The estimate of P from the counts, before unvisited states are filled.

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered by :func:`count_transitions`.

        Returns
        -------
        ndarray of float64, shape (S, S)
            Rows of states never left are all zero.

        Raises
        ------
        NotImplementedError
            In the base class: the subclasses implement it.
        """
        raise NotImplementedError

    def fit(self, data) -> "MarkovModel":
        """Fit on discrete trajectories (arrays in, model out, as deeptime's estimators).

        Parameters
        ----------
        data : DiscreteTrajectories or sequence of them
            Made by :func:`cfbmarkov.markov.discretize` with this estimator's state space
            and lag (or use :func:`cfbmarkov.markov.fit_model` to fit from a file).

        Returns
        -------
        MarkovModel

        Raises
        ------
        InputError
            If ``data`` is not discrete trajectories, or was made with another state space
            or lag, or holds no transition.
        """
        windows = as_discrete_list(data)
        fitted = windows[0].state_space
        if fitted != self.state_space and self.state_space.accepts(fitted):
            # an unfitted regime space: the discretisation fitted its edges on the window
            return type(self)(fitted, self.lag, self.connected, self.coherent).fit(windows)
        for window in windows:
            if window.state_space != self.state_space:
                raise InputError(f"discrete trajectories are in {window.state_space.describe()}"
                                 f", the estimator's state space is "
                                 f"{self.state_space.describe()}")
            if not window.matches_lag(self.lag):
                raise InputError(f"discrete trajectories have a lag of {window.lag:g} s "
                                 f"({window.lag_frames} frames), the estimator's is "
                                 f"{self.lag:g} s")
        if self.name == "paper" and windows[0].boundary == "open":
            raise InputError("the paper's estimator (Eq. 2-4) averages per-frame matrices of a "
                             "closed (periodic) riser; fit an open riser with --estimator mle")
        if self.coherent and windows[0].boundary == "open":
            raise InputError("coherent moves (--coherent) are fitted for periodic risers only "
                             "yet; fit an open riser without it")
        counts = count_transitions(windows, frame_average=self.name == "paper")
        from cfbmarkov.markov.model import hand_over

        hand_over(counts.counts, counts.counts_up, counts.counts_down)   # counted for it alone
        sources = [w.source for w in windows]
        model = self.fit_counts(counts, window=windows[0].window,
                                source=sources[0] if len(sources) == 1 else sources)
        if self.coherent:
            from cfbmarkov.markov.coherence import calibrate_coherence

            model = model.with_coherence(calibrate_coherence(model, windows))
        return model

    def chain(self, counts: TransitionCounts
              ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
        """The stochastic matrix and pass fractions that :meth:`fit_counts` puts in a model.

        A state never left in the counts moves as the other states of its cell did (their
        pooled counts); where its whole cell was never left it stays in place (P_ii = 1).

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered by :func:`count_transitions`.

        Returns
        -------
        matrix : ndarray of float64, shape (S, S)
            The row-stochastic transition matrix P.
        fractions : tuple of two ndarrays of shape (S, S), or None
            (up, down) fractions of each i -> j transition that passed the boundary, where
            states were filled from their cell; None: the counts give them.
        """
        matrix = self.transition_matrix(counts)
        unvisited = np.flatnonzero(counts.counts.sum(axis=1) == 0)
        fractions = _fill_from_cells(matrix, counts, self.state_space, unvisited)
        stuck = unvisited[matrix[unvisited].sum(axis=1) == 0]
        matrix[stuck, :] = 0.0
        matrix[stuck, stuck] = 1.0
        if self.connected:      # deeptime's default: no transition leaves the largest set
            matrix = restrict_to_set(matrix, largest_connected_set(counts.counts))
        return matrix, fractions

    def split_chain(self, counts: TransitionCounts) -> tuple[sp.csr_matrix, sp.csr_matrix,
                                                              sp.csr_matrix]:
        """The chain that :meth:`chain` forms, split by pass direction, without any dense
        [S, S] array: P_up, P_down and P_stay with P = P_up + P_down + P_stay (what
        :func:`cfbmarkov.markov.first_passage.rtd_of_split_chain` takes).

        A transition's share of P is split as its counts were (P_ij C^up_ij / C_ij, ...); a
        state never left takes its cell's pooled counts, and stays in place where its whole
        cell was never left, as in :meth:`chain`.

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered by :func:`count_transitions`, sparse (``sparse=True``) or dense.

        Returns
        -------
        tuple of three scipy.sparse.csr_matrix, shape (S, S)
            P_up, P_down, P_stay. Equal to :func:`cfbmarkov.markov.first_passage.split_by_pass` of
            :meth:`chain`'s matrix and fractions up to rounding (tested).
        """
        if self.connected:      # the largest connected set: through the dense chain
            from cfbmarkov.markov.first_passage import split_by_pass

            dense = _densified(counts)
            matrix, fractions = self.chain(dense)
            up, down = fractions if fractions is not None else pass_fractions(dense)
            return split_by_pass(matrix, up, down)
        c = sp.csr_matrix(counts.counts, dtype=np.float64)
        moves = {"up": sp.csr_matrix(counts.counts_up, dtype=np.float64),
                 "down": sp.csr_matrix(counts.counts_down, dtype=np.float64)}
        moves["stay"] = c - moves["up"] - moves["down"]
        weights = self._sparse_weights(counts, c)
        totals = np.asarray(weights.sum(axis=1)).ravel()
        scale = np.divide(1.0, totals, out=np.zeros_like(totals), where=totals > 0)
        matrix = sp.diags(scale) @ weights
        inverse = c.copy()
        inverse.data = 1.0 / inverse.data
        share = matrix.multiply(inverse)                  # P_ij / C_ij on the counted pairs
        parts = {name: sp.csr_matrix(share.multiply(values)) for name, values in moves.items()}
        # states never left: their cell's pooled counts, or in place
        space = self.state_space
        n = space.n_states
        unvisited = np.flatnonzero(np.asarray(c.sum(axis=1)).ravel() == 0)
        cell = np.asarray(space.cell_of_state)
        fill = np.zeros(0, np.int64)
        if unvisited.size and np.unique(cell).size != cell.size:
            needed = np.unique(cell[unvisited])
            slot = -np.ones(space.n_cells, np.int64)
            slot[needed] = np.arange(needed.size)
            members = np.flatnonzero(slot[cell] >= 0)
            indicator = sp.csr_matrix((np.ones(members.size), (slot[cell[members]], members)),
                                      shape=(needed.size, n))
            pooled_totals = np.asarray((indicator @ c).sum(axis=1)).ravel()
            fill = unvisited[pooled_totals[slot[cell[unvisited]]] > 0]
            chosen = sp.csr_matrix((1.0 / pooled_totals[slot[cell[fill]]],
                                    (fill, slot[cell[fill]])), shape=(n, needed.size))
            for name, values in moves.items():
                parts[name] = (parts[name] + chosen @ (indicator @ values)).tocsr()
        stuck = np.setdiff1d(unvisited, fill)
        if stuck.size:
            parts["stay"] = (parts["stay"] + sp.csr_matrix(
                (np.ones(stuck.size), (stuck, stuck)), shape=(n, n))).tocsr()
        for part in parts.values():
            part.eliminate_zeros()
        return parts["up"], parts["down"], parts["stay"]

    def _sparse_weights(self, counts: TransitionCounts, pooled: sp.csr_matrix) -> sp.csr_matrix:
        """The rows that :meth:`transition_matrix` normalises, as a sparse matrix (the pooled
        counts; the paper's estimator overrides it)."""
        return pooled

    def fit_counts(self, counts: TransitionCounts, window=None, source="") -> "MarkovModel":
        """Form the model from counts already gathered (e.g. by cross-validation).

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered with this estimator's state space and lag.
        window : tuple of float, optional
            The fitting window (A, B) in s, recorded in the model.
        source : str, os.PathLike or list, optional
            Where the data came from, recorded in the model.

        Returns
        -------
        MarkovModel

        Raises
        ------
        InputError
            If the counts do not fit the state space, or (paper estimator) were gathered
            without the per-frame matrices.
        """
        from cfbmarkov.markov.model import MarkovModel, hand_over

        matrix, fractions = self.chain(counts)
        hand_over(matrix, *(fractions or ()))       # made here for this model alone
        open_flow = {}
        if counts.faces is not None:
            open_flow = open_chain(counts)
        return MarkovModel(**open_flow,
            transition_matrix=matrix, counts=counts.counts, counts_up=counts.counts_up,
            counts_down=counts.counts_down, state_space=self.state_space, lag=self.lag,
            estimator=self.name, window=tuple(window) if window is not None else None,
            source=os.fspath(source) if isinstance(source, (str, os.PathLike)) else list(source),
            frame_pairs=counts.frame_pairs, pass_fractions=fractions, connected=self.connected)


def _fill_from_cells(matrix: np.ndarray, counts: TransitionCounts, space: StateSpace,
                     unvisited: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """In a state space with several states per cell, a state never left in the window
    (e.g. a rare velocity class) moves as the other states of its cell did: its row of P
    and its pass fractions are those of the cell's pooled counts. Fills ``matrix`` in place
    and returns the pass fractions (None when nothing was filled; then the counts give
    them). States whose whole cell was never left stay in place (P_ii = 1) as for cells."""
    cell = np.asarray(space.cell_of_state)
    if unvisited.size == 0 or np.unique(cell).size == cell.size:
        return None
    # pool the rows of the cells that need it: a sparse (cells x states) indicator times
    # the counts (np.add.at over a dense S x S array was most of an auto fit's time)
    needed = np.unique(cell[unvisited])
    slot = -np.ones(space.n_cells, np.int64)
    slot[needed] = np.arange(needed.size)
    members = np.flatnonzero(slot[cell] >= 0)
    indicator = sp.csr_matrix((np.ones(members.size), (slot[cell[members]], members)),
                              shape=(needed.size, cell.size))
    pooled = indicator @ counts.counts.astype(np.float64)
    totals = pooled.sum(axis=1)
    c = counts.counts.astype(np.float64)
    up = np.divide(counts.counts_up, c, out=np.zeros_like(c), where=c > 0)
    down = np.divide(counts.counts_down, c, out=np.zeros_like(c), where=c > 0)
    fill = unvisited[totals[slot[cell[unvisited]]] > 0]
    if fill.size == 0:
        return None
    rows = pooled[slot[cell[fill]]]
    matrix[fill] = rows / rows.sum(axis=1)[:, None]
    pooled_up = indicator @ counts.counts_up.astype(np.float64)
    pooled_down = indicator @ counts.counts_down.astype(np.float64)
    up[fill] = np.divide(pooled_up[slot[cell[fill]]], rows, out=np.zeros_like(rows),
                         where=rows > 0)
    down[fill] = np.divide(pooled_down[slot[cell[fill]]], rows, out=np.zeros_like(rows),
                           where=rows > 0)
    return up, down


class MaximumLikelihoodEstimator(TransitionEstimator):
    """``mle``: P_ij = C_ij / sum_j C_ij from the pooled counts.

    The maximum-likelihood estimate of a non-reversible chain. Parameters as for
    :class:`TransitionEstimator`.

    References
    ----------
    J.-H. Prinz et al., "Markov models of molecular kinetics: generation and
    validation", J. Chem. Phys. 134, 174105 (2011) (the non-reversible maximum-likelihood estimate).
    """

    name = "mle"

    def transition_matrix(self, counts):
        """P_ij = C_ij / sum_j C_ij (rows of states never left: zero).

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered by :func:`count_transitions`.

        Returns
        -------
        ndarray of float64, shape (S, S)
        """
        c = counts.counts.astype(np.float64)
        rows = c.sum(axis=1, keepdims=True)
        return np.divide(c, rows, out=np.zeros_like(c), where=rows > 0)


class PaperEstimator(TransitionEstimator):
    """``paper``: average of the per-frame row-normalised matrices P'(t_c), Eq. (2)-(4).

    Parameters as for :class:`TransitionEstimator`. The plain average has row sums equal to
    the fraction of frames in which a state was occupied; each row is divided by its sum,
    which equals averaging P' over the frames in which the state was occupied.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 2-4).
    """

    name = "paper"

    def transition_matrix(self, counts):
        """The average of the per-frame matrices P'(t), rows renormalised.

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered with ``frame_average=True``.

        Returns
        -------
        ndarray of float64, shape (S, S)

        Raises
        ------
        InputError
            If the counts were gathered without the per-frame matrices.
        """
        if counts.frame_average_sum is None:
            raise InputError("the paper's estimator needs the per-frame matrices; these counts "
                             "were gathered without them")
        if counts.frame_pairs == 0:
            return np.zeros_like(counts.frame_average_sum)
        plain_average = counts.frame_average_sum / counts.frame_pairs   # Eq. (4)
        rows = plain_average.sum(axis=1, keepdims=True)
        return np.divide(plain_average, rows, out=np.zeros_like(plain_average), where=rows > 0)


    def _sparse_weights(self, counts, pooled):
        if counts.frame_average_sum is None:
            raise InputError("the paper's estimator needs the per-frame matrices; these counts "
                             "were gathered without them")
        return sp.csr_matrix(counts.frame_average_sum, dtype=np.float64)


def pass_fractions(counts: TransitionCounts) -> tuple[np.ndarray, np.ndarray]:
    """The fractions of each i -> j transition that passed up through the top and down
    through the bottom, C^up_ij / C_ij and C^down_ij / C_ij (0 where C_ij = 0).

    Parameters
    ----------
    counts : TransitionCounts
        Dense counts.

    Returns
    -------
    (ndarray, ndarray) of float64, shape (S, S)
    """
    c = counts.counts.astype(np.float64)
    return (np.divide(counts.counts_up, c, out=np.zeros_like(c), where=c > 0),
            np.divide(counts.counts_down, c, out=np.zeros_like(c), where=c > 0))


def _densified(counts: TransitionCounts) -> TransitionCounts:
    """Dense copies of sparse counts (dense counts as they are)."""
    if not sp.issparse(counts.counts):
        return counts
    dense = lambda m: None if m is None else m.toarray()  # noqa: E731
    return TransitionCounts(dense(counts.counts), dense(counts.counts_up),
                            dense(counts.counts_down), dense(counts.frame_average_sum),
                            counts.occupied_frames, counts.frame_pairs, counts.faces)


ESTIMATORS: dict[str, type[TransitionEstimator]] = {
    "paper": PaperEstimator, "mle": MaximumLikelihoodEstimator}


def estimator_from_name(name: str, state_space: StateSpace, lag: float = 0.025,
                        connected: bool = False, coherent: bool = False
                        ) -> TransitionEstimator:
    """An estimator by name.

    Parameters
    ----------
    name : {"paper", "mle"}
        A key of ``ESTIMATORS``.
    state_space : StateSpace
        The states of the models it fits.
    lag : float, optional
        The lag (s).
    connected : bool, optional
        Restrict to the largest strongly connected set (see :class:`TransitionEstimator`).
    coherent : bool, optional
        Also fit the coherence of the moves (see :class:`TransitionEstimator`).

    Returns
    -------
    TransitionEstimator

    Raises
    ------
    InputError
        For an unknown name or a lag that is not positive.
    """
    try:
        return ESTIMATORS[name](state_space, lag, connected, coherent)
    except KeyError:
        raise InputError(f"unknown estimator '{name}' (choose from {', '.join(ESTIMATORS)})") from None


def fit_model(source, state_space: StateSpace, lag: float,
              window: tuple[float, float] | None = None, estimator: str = "mle",
              connected: bool = False, coherent: bool = False) -> "MarkovModel":
    """Fit a model on a trajectory file: :func:`~cfbmarkov.markov.discretize`, then the
    estimator's ``fit`` (the one convenience wrapper that takes a file).

    Parameters
    ----------
    source : str, os.PathLike or Trajectories
        The trajectory file (path or open).
    state_space : StateSpace
        The states.
    lag : float
        The lag (s), a whole multiple of the file's frame interval.
    window : tuple of float, optional
        The fitting window (A, B) in s; None: every frame.
    estimator : {"paper", "mle"}
        Paper Eq. 2-4, or the pooled maximum-likelihood estimate.
    connected : bool, optional
        Restrict to the largest strongly connected set (see :class:`TransitionEstimator`).
    coherent : bool, optional
        Also fit the coherence of the moves (see :class:`TransitionEstimator`).

    Returns
    -------
    MarkovModel

    Raises
    ------
    InputError
        On an unreadable file, a window outside the data, a lag that is not a whole number
        of frames, a state space that does not fit the file, or an unknown estimator.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 2-4, the paper estimator).
    """
    fitter = estimator_from_name(estimator, state_space, lag, connected, coherent)
    return fitter.fit(discretize(source, state_space, lag, window))
