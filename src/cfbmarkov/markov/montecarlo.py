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

#: random-number streams: next state, x and y placement (states.py), pass direction
STREAM_STATE, STREAM_DIRECTION = 0, 3


@dataclass(frozen=True)
class SparseChain:
    """Rows of P in compressed form for sampling: cumulative probabilities per row, and for
    each nonzero the probability that the transition passes up / down the boundary."""

    row_start: np.ndarray    # [S+1] int64
    column: np.ndarray       # [nnz] int32
    cumulative: np.ndarray   # [nnz] float64, the last entry of each row is exactly 1
    up_probability: np.ndarray    # [nnz] float64
    down_probability: np.ndarray  # [nnz] float64

    @classmethod
    def from_matrix(cls, matrix: np.ndarray, up_fraction: np.ndarray, down_fraction: np.ndarray
                    ) -> "SparseChain":
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


@nb.njit(cache=True, parallel=True)
def monte_carlo_steps(initial_states, initial_laps, row_start, column, cumulative, up_probability,
                   down_probability, n_steps, seed, states_out, laps_out):
    """Advance every particle n_steps transitions (kernel).

    Writes states_out/laps_out [n_steps+1, N] (row 0 = the initial values). A row with no
    nonzero entry keeps the particle where it is.
    """
    n_particles = initial_states.size
    for p in nb.prange(n_particles):
        s = initial_states[p]
        lap = initial_laps[p]
        states_out[0, p] = s
        laps_out[0, p] = lap
        for k in range(1, n_steps + 1):
            a = row_start[s]
            b = row_start[s + 1]
            if b > a:
                u = uniform(seed, STREAM_STATE, p, k)
                lo = a
                hi = b - 1
                while lo < hi:             # first entry with cumulative > u (Eq. 7)
                    mid = (lo + hi) >> 1
                    if cumulative[mid] > u:
                        hi = mid
                    else:
                        lo = mid + 1
                pu = up_probability[lo]
                pd = down_probability[lo]
                if pu > 0.0 or pd > 0.0:
                    v = uniform(seed, STREAM_DIRECTION, p, k)
                    if v < pu:
                        lap += 1
                    elif v < pu + pd:
                        lap -= 1
                s = column[lo]
            states_out[k, p] = s
            laps_out[k, p] = lap


def run_chain(chain: SparseChain, initial_states, n_steps: int, seed: int, initial_laps=None
              ) -> tuple[np.ndarray, np.ndarray]:
    """States and laps [n_steps+1, N] of a Monte Carlo run from ``initial_states``."""
    initial_states = np.ascontiguousarray(initial_states, dtype=np.int32)
    n = initial_states.size
    laps0 = (np.zeros(n, np.int32) if initial_laps is None
             else np.ascontiguousarray(initial_laps, dtype=np.int32))
    states = np.empty((n_steps + 1, n), np.int32)
    laps = np.empty((n_steps + 1, n), np.int32)
    monte_carlo_steps(initial_states, laps0, chain.row_start, chain.column, chain.cumulative,
                   chain.up_probability, chain.down_probability, int(n_steps),
                   np.uint64(seed), states, laps)
    return states, laps
