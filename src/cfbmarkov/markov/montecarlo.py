"""Monte Carlo of particles on a Markov chain with lap counting (paper Eq. 7; kernels).

Each particle draws its next state from its row of P by the cumulative rule of Eq. (7) and,
where the transition can pass through the periodic boundary, the direction of the pass
from the fractions observed in the data, which moves its lap counter. The random numbers
are counter-based (:mod:`cfbmarkov._random`), so a run is reproducible bit for bit for a
given seed whatever the number of threads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from cfbmarkov._random import uniform

#: random-number streams: next state, pass direction (x, y and depth placement use 1, 2
#: and 10, :mod:`cfbmarkov.markov.states`)
STREAM_STATE, STREAM_DIRECTION = 0, 3
#: particle-steps of one piece of a run (:func:`run_chain`; about 0.1-0.5 s on 2 cores)
PIECE_PARTICLE_STEPS = 20_000_000

#: streams of coherent moves (:mod:`cfbmarkov.markov.coherence`): whether a particle takes its
#: row's common draw, and the common draw of a row (the open riser uses 4-6, regimes 7)
STREAM_SHARE, STREAM_COMMON = 8, 9


@dataclass(frozen=True)
class SparseChain:
    """Rows of P in compressed form for sampling by the cumulative rule of Eq. (7).

    Cumulative probabilities per row (CSR layout, nonzero entries only), and for each
    nonzero the probability that the transition passes up / down the boundary.

    Attributes
    ----------
    row_start : ndarray of int64, shape (S + 1,)
        Row i's entries are ``row_start[i]:row_start[i + 1]``.
    column : ndarray of int32, shape (nnz,)
        Target state j of each entry.
    cumulative : ndarray of float64, shape (nnz,)
        Cumulative probability within the row; the last entry of each row is exactly 1.
    up_probability, down_probability : ndarray of float64, shape (nnz,)
        Probability that the transition passes up through the top / down through the
        bottom.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 7).
    """

    row_start: np.ndarray    # [S+1] int64
    column: np.ndarray       # [nnz] int32
    cumulative: np.ndarray   # [nnz] float64, the last entry of each row is exactly 1
    up_probability: np.ndarray    # [nnz] float64
    down_probability: np.ndarray  # [nnz] float64

    @classmethod
    def from_matrix(cls, matrix: np.ndarray, up_fraction: np.ndarray, down_fraction: np.ndarray
                    ) -> "SparseChain":
        """Compress a transition matrix and its pass fractions.

        Parameters
        ----------
        matrix : ndarray of float64, shape (S, S)
            Row-stochastic transition matrix P (rows of all zeros keep particles in place).
        up_fraction, down_fraction : ndarray of float64, shape (S, S)
            Fraction of each i -> j transition that passes up / down the boundary.

        Returns
        -------
        SparseChain
        """
        rows, cols = np.nonzero(matrix > 0)
        values = matrix[rows, cols]
        row_start = np.zeros(matrix.shape[0] + 1, np.int64)
        np.cumsum(np.bincount(rows, minlength=matrix.shape[0]), out=row_start[1:])
        cumulative = np.empty_like(values)
        for i in range(matrix.shape[0]):   # per state (S ~ 10^2-10^3), not per particle
            a, b = row_start[i], row_start[i + 1]
            if b > a:
                c = np.cumsum(values[a:b])
                cumulative[a:b] = c / c[-1]
                cumulative[b - 1] = 1.0
        return cls(row_start, cols.astype(np.int32), cumulative,
                   up_fraction[rows, cols].astype(np.float64),
                   down_fraction[rows, cols].astype(np.float64))


@nb.njit(cache=True, inline="always")
def first_above(cumulative, lo, hi, u):
    """The first index in ``lo..hi`` whose cumulative probability exceeds ``u`` (bisection;
    the cumulative rule of Eq. 7); ``hi`` where none does before it."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if cumulative[mid] > u:
            hi = mid
        else:
            lo = mid + 1
    return lo


@nb.njit(cache=True, inline="always")
def state_draw(seed, particle, row, step, coherence):
    """The uniform draw that picks a particle's next state (Eq. 7): its own, or, with
    probability ``coherence``, the draw shared by every particle leaving the same row at
    this step (:mod:`cfbmarkov.markov.coherence`). Without coherence exactly the draw of
    an independent particle."""
    if coherence > 0.0 and uniform(seed, STREAM_SHARE, particle, step) < coherence:
        return uniform(seed, STREAM_COMMON, row, step)
    return uniform(seed, STREAM_STATE, particle, step)


@nb.njit(cache=True, parallel=True)
def monte_carlo_steps(initial_states, initial_laps, row_start, column, cumulative, up_probability,
                      down_probability, row_offset, coherence, n_steps, seed, states_out,
                      laps_out, first_step=0):
    """Advance every particle ``n_steps`` transitions (Numba kernel, parallel over particles).

    Each step draws u in [0, 1) and takes the first entry of the row whose cumulative
    probability exceeds u (Eq. 7); where the transition can pass the boundary a second
    draw decides the direction and moves the lap counter by +1 (up) or -1 (down). A row
    with no nonzero entry keeps the particle where it is.

    Parameters
    ----------
    initial_states, initial_laps : ndarray of int32, shape (N,)
        States and lap counters at the start.
    row_start, column, cumulative, up_probability, down_probability : ndarray
        The arrays of a :class:`SparseChain`.
    row_offset : ndarray of int64, shape (n_steps + 1,)
        Step k draws from row ``row_offset[k] + s`` of the chain (all zeros for one chain;
        a regime model's stacked conditional chains, :mod:`cfbmarkov.markov.regimes`).
    coherence : float
        Probability that a particle takes its row's common draw (0: independent particles;
        :mod:`cfbmarkov.markov.coherence`).
    n_steps : int
        Number of lags to run.
    seed : numpy.uint64
        Seed of the counter-based generator (:func:`cfbmarkov._random.uniform`).
    states_out, laps_out : ndarray of int32, shape (n_steps + 1, N)
        Filled in place; row 0 holds the initial values.
    first_step : int, optional
        The run's step of row 0: the draws of row k are those of step ``first_step + k``,
        so that a run made in pieces (:func:`run_chain`) draws what one piece would.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 7).
    """
    n_particles = initial_states.size
    for p in nb.prange(n_particles):
        s = initial_states[p]
        lap = initial_laps[p]
        states_out[0, p] = s
        laps_out[0, p] = lap
        for k in range(1, n_steps + 1):
            step = first_step + k
            row = row_offset[k] + s
            a = row_start[row]
            b = row_start[row + 1]
            if b > a:
                lo = first_above(cumulative, a, b - 1, state_draw(seed, p, row, step, coherence))
                pu = up_probability[lo]
                pd = down_probability[lo]
                if pu > 0.0 or pd > 0.0:
                    v = uniform(seed, STREAM_DIRECTION, p, step)
                    if v < pu:
                        lap += 1
                    elif v < pu + pd:
                        lap -= 1
                s = column[lo]
            states_out[k, p] = s
            laps_out[k, p] = lap


def run_chain(chain: SparseChain, initial_states, n_steps: int, seed: int, initial_laps=None,
              row_offset=None, coherence: float = 0.0, progress=None
              ) -> tuple[np.ndarray, np.ndarray]:
    """States and laps of a Monte Carlo run from ``initial_states``.

    Parameters
    ----------
    chain : SparseChain
        The chain to sample.
    initial_states : array_like of int, shape (N,)
        States at the start (0 <= s < S; not checked here).
    n_steps : int
        Number of lags to run.
    seed : int
        Seed: the run depends only on (seed, particle, step), whatever the thread count.
    initial_laps : array_like of int, shape (N,), optional
        Lap counters at the start (0 when None).
    row_offset : array_like of int, shape (n_steps + 1,), optional
        Step k draws from row ``row_offset[k] + s`` (a regime model's common regime path
        times S, :mod:`cfbmarkov.markov.regimes`); None: zeros.
    coherence : float, optional
        Probability that a particle takes its row's common draw (:mod:`.coherence`).
    progress : callable, optional
        ``progress(steps)`` is called with the lags run so far after each piece of the run
        (pieces of about :data:`PIECE_PARTICLE_STEPS` particle-steps, between which a
        Ctrl-C is taken).

    Returns
    -------
    states, laps : ndarray of int32, shape (n_steps + 1, N)
        Row 0 holds the initial values.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 7).
    """
    initial_states = np.ascontiguousarray(initial_states, dtype=np.int32)
    n = initial_states.size
    laps0 = (np.zeros(n, np.int32) if initial_laps is None
             else np.ascontiguousarray(initial_laps, dtype=np.int32))
    states = np.empty((n_steps + 1, n), np.int32)
    laps = np.empty((n_steps + 1, n), np.int32)
    offset = (np.zeros(n_steps + 1, np.int64) if row_offset is None
              else np.ascontiguousarray(row_offset, dtype=np.int64))
    # in pieces of about PIECE_PARTICLE_STEPS, so that a Ctrl-C is taken between them (the
    # draws depend on the step, not the piece: the same run in one piece or many)
    piece = max(1, PIECE_PARTICLE_STEPS // max(n, 1))
    states[0], laps[0] = initial_states, laps0
    for k0 in range(0, int(n_steps), piece):
        k1 = min(int(n_steps), k0 + piece)
        monte_carlo_steps(states[k0], laps[k0], chain.row_start, chain.column,
                          chain.cumulative, chain.up_probability, chain.down_probability,
                          offset[k0:k1 + 1], float(coherence), k1 - k0, np.uint64(seed),
                          states[k0:k1 + 1], laps[k0:k1 + 1], k0)
        if progress is not None:
            progress(k1)
    return states, laps
