"""Estimators of the transition matrix (paper Eq. 2-4; SPEC section 2).

An estimator is configured with a state space and a lag, then ``fit(trajectories)`` returns
an immutable :class:`~cfbmarkov.markov.model.MarkovModel`:

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

import os
from contextlib import nullcontext
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable

import numba as nb
import numpy as np
import scipy.sparse as sp

from cfbmarkov.errors import InputError
from cfbmarkov.markov.states import StateSpace
from cfbmarkov.trajectories import Trajectories

if TYPE_CHECKING:
    from cfbmarkov.markov.model import MarkovModel


@nb.njit(cache=True)
def count_transitions(states, y, lag_frames, height, n_states, counts, counts_up, counts_down,
                      frame_average, occupied_frames, with_frame_average=True):
    """Accumulate transition counts of discrete trajectories (kernel).

    states int32 [T, N], y float64 [T, N] (m). For every frame pair (t, t+lag) adds to
    ``counts[i, j]`` (pooled), ``counts_up``/``counts_down`` (passes up through the top /
    down through the bottom, minimal image on y), ``frame_average[i, j] += N_ij(t)/N_i(t)``
    (the sum of the per-frame matrices of Eq. 2) and ``occupied_frames[i] += 1`` where
    N_i(t) > 0 (``with_frame_average=False``: ``frame_average`` is left alone, for the
    pooled estimator). Returns the number of frame pairs.
    """
    n_frames, n_particles = states.shape
    half = 0.5 * height
    occupancy = np.zeros(n_states, dtype=np.int64)
    pairs = 0
    for t in range(n_frames - lag_frames):
        occupancy[:] = 0
        for p in range(n_particles):
            occupancy[states[t, p]] += 1
        for i in range(n_states):
            if occupancy[i] > 0:
                occupied_frames[i] += 1
        for p in range(n_particles):
            i = states[t, p]
            j = states[t + lag_frames, p]
            counts[i, j] += 1
            if with_frame_average:
                frame_average[i, j] += 1.0 / occupancy[i]
            dy = y[t + lag_frames, p] - y[t, p]
            if dy < -half:
                counts_up[i, j] += 1
            elif dy > half:
                counts_down[i, j] += 1
        pairs += 1
    return pairs


@dataclass(frozen=True)
class TransitionCounts:
    """Everything an estimator gathers from the data before it forms P."""

    counts: np.ndarray           # [S, S] int64, pooled
    counts_up: np.ndarray        # [S, S] int64, passes up through the top
    counts_down: np.ndarray      # [S, S] int64, passes down through the bottom
    frame_average_sum: np.ndarray | None  # [S, S] float64, sum over frames of P'(t)
    occupied_frames: np.ndarray  # [S] int64, frames in which each state was occupied
    frame_pairs: int             # number of frame pairs (t, t+lag) counted

    @property
    def n_transitions(self) -> int:
        return int(self.counts.sum())


def count_states(states: np.ndarray, y: np.ndarray, lag_frames: int, height: float,
                 n_states: int, frame_average: bool = True) -> TransitionCounts:
    """Transition counts of discrete trajectories already in memory: ``states`` int32 [T, N]
    and ``y`` (m) [T, N] of the same frames (the kernel :func:`count_transitions`).
    ``frame_average=False`` skips the sum of the per-frame matrices that only the paper's
    estimator needs (its field is then None)."""
    counts = np.zeros((n_states, n_states), np.int64)
    up = np.zeros((n_states, n_states), np.int64)
    down = np.zeros((n_states, n_states), np.int64)
    frame_sum = (np.zeros((n_states, n_states), np.float64) if frame_average
                 else np.zeros((1, 1), np.float64))
    occupied = np.zeros(n_states, np.int64)
    pairs = count_transitions(np.ascontiguousarray(states, dtype=np.int32),
                              np.ascontiguousarray(y, dtype=np.float64), int(lag_frames),
                              float(height), n_states, counts, up, down, frame_sum, occupied,
                              bool(frame_average))
    return TransitionCounts(counts, up, down, frame_sum if frame_average else None, occupied,
                            pairs)


def gather_counts(space: StateSpace, data, lag: float, window: tuple[float, float] | None
                  ) -> tuple[TransitionCounts, dict]:
    """Count transitions of one trajectory file (path or :class:`Trajectories`) or several."""
    runs = data if isinstance(data, (list, tuple)) else [data]
    s = space.n_states
    counts = np.zeros((s, s), np.int64)
    up = np.zeros((s, s), np.int64)
    down = np.zeros((s, s), np.int64)
    frame_sum = np.zeros((s, s), np.float64)
    occupied = np.zeros(s, np.int64)
    pairs = 0
    sources = []
    for run in runs:
        own = not isinstance(run, Trajectories)
        traj = Trajectories(run) if own else run
        try:
            _check_domain(space, traj)
            lag_frames = traj.lag_frames(lag)
            frames = traj.window(*window) if window is not None else slice(0, traj.n_frames)
            start, stop, _ = frames.indices(traj.n_frames)
            if stop - start <= lag_frames:
                raise InputError(f"window {_fmt_window(window)} of {traj.path} holds fewer than "
                                 f"two frames one lag ({lag:g} s) apart")
            first = start - space.memory_lags * lag_frames
            if first < 0:
                raise InputError(f"state space {space.kind} needs {space.memory_lags} lag(s) of "
                                 f"history before the window start")
            positions = traj.positions(slice(first, stop))
            velocities = traj.velocities(slice(first, stop)) if space.needs_velocity else None
            if space.needs_velocity and velocities is None:
                raise InputError(f"state space {space.kind} needs velocities; {traj.path} has none")
            states = space.discretize(positions, velocities, lag_frames)
            offset = start - first
            states = np.ascontiguousarray(states[offset:])
            y = np.ascontiguousarray(positions[offset:, :, 1])
            pairs += count_transitions(states, y, lag_frames, traj.height, s, counts, up, down,
                                       frame_sum, occupied)
            sources.append(str(traj.path))
        finally:
            if own:
                traj.close()
    gathered = TransitionCounts(counts, up, down, frame_sum, occupied, pairs)
    return gathered, {"source": sources[0] if len(sources) == 1 else sources}


def _fmt_window(window) -> str:
    return "(all)" if window is None else f"{window[0]:g}:{window[1]:g} s"


def _check_domain(space: StateSpace, traj: Trajectories) -> None:
    if not (np.isclose(space.width, traj.width) and np.isclose(space.height, traj.height)):
        raise InputError(f"state space covers {space.width:g} x {space.height:g} m but "
                         f"{traj.path} is {traj.width:g} x {traj.height:g} m")


class TransitionEstimator:
    """Base estimator: configure with a state space and a lag (s), then :meth:`fit`."""

    name: str = ""

    def __init__(self, state_space: StateSpace, lag: float = 0.025):
        if not lag > 0:
            raise InputError(f"lag {lag:g} s must be positive")
        self.state_space = state_space
        self.lag = float(lag)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.state_space!r}, lag={self.lag:g})"

    def transition_matrix(self, counts: TransitionCounts) -> np.ndarray:
        raise NotImplementedError

    def fit(self, data, window: tuple[float, float] | None = None):
        """Fit on a trajectory file (path or :class:`Trajectories`), or a list of them,
        using the frames of ``window`` = (A, B) in s (all frames when None)."""

        counts, info = gather_counts(self.state_space, data, self.lag, window)
        return self.fit_counts(counts, window=window, source=info["source"])

    def chain(self, counts: TransitionCounts
              ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
        """The stochastic matrix and, where states were filled from their cell, the pass
        fractions (None: the counts give them) that :meth:`fit_counts` puts in a model."""
        matrix = self.transition_matrix(counts)
        unvisited = np.flatnonzero(counts.counts.sum(axis=1) == 0)
        fractions = _fill_from_cells(matrix, counts, self.state_space, unvisited)
        stuck = unvisited[matrix[unvisited].sum(axis=1) == 0]
        matrix[stuck, :] = 0.0
        matrix[stuck, stuck] = 1.0
        return matrix, fractions

    def fit_counts(self, counts: TransitionCounts, window=None, source="") -> "MarkovModel":
        from cfbmarkov.markov.model import MarkovModel

        matrix, fractions = self.chain(counts)
        return MarkovModel(
            transition_matrix=matrix, counts=counts.counts, counts_up=counts.counts_up,
            counts_down=counts.counts_down, state_space=self.state_space, lag=self.lag,
            estimator=self.name, window=tuple(window) if window is not None else None,
            source=os.fspath(source) if isinstance(source, (str, os.PathLike)) else list(source),
            frame_pairs=counts.frame_pairs, pass_fractions=fractions)


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
    """``mle``: P_ij = C_ij / sum_j C_ij from the pooled counts."""

    name = "mle"

    def transition_matrix(self, counts):
        c = counts.counts.astype(np.float64)
        rows = c.sum(axis=1, keepdims=True)
        return np.divide(c, rows, out=np.zeros_like(c), where=rows > 0)


class PaperEstimator(TransitionEstimator):
    """``paper``: average of the per-frame row-normalised matrices P'(t_c), Eq. (2)-(4)."""

    name = "paper"

    def transition_matrix(self, counts):
        if counts.frame_average_sum is None:
            raise InputError("the paper's estimator needs the per-frame matrices; these counts "
                             "were gathered without them")
        if counts.frame_pairs == 0:
            return np.zeros_like(counts.frame_average_sum)
        plain_average = counts.frame_average_sum / counts.frame_pairs   # Eq. (4)
        rows = plain_average.sum(axis=1, keepdims=True)
        return np.divide(plain_average, rows, out=np.zeros_like(plain_average), where=rows > 0)


ESTIMATORS: dict[str, type[TransitionEstimator]] = {
    "paper": PaperEstimator, "mle": MaximumLikelihoodEstimator}


def estimator_from_name(name: str, state_space: StateSpace, lag: float = 0.025
                        ) -> TransitionEstimator:
    try:
        return ESTIMATORS[name](state_space, lag)
    except KeyError:
        raise InputError(f"unknown estimator '{name}' (choose from {', '.join(ESTIMATORS)})") from None


def discrete_trajectories(space: StateSpace, runs: Iterable, window=None) -> list[np.ndarray]:
    """Per-particle state sequences (list of int32 arrays) of the window, e.g. for deeptime."""
    out = []
    for run in runs:
        with (Trajectories(run) if not isinstance(run, Trajectories) else nullcontext(run)) as t:
            frames = t.window(*window) if window is not None else slice(None)
            states = space.discretize(t.positions(frames), t.velocities(frames))
            out.extend(np.ascontiguousarray(states.T))
    return out


