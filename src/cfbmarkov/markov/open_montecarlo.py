"""Monte Carlo of an open riser (kernels): particles present at the start move by the chain,
leave through the outlet with their state's exit probability, and new particles enter
through the inlet at the fitted inflow rate with states drawn from the entry distribution
(``docs/definitions.md``, Open risers).

Every draw is counter-based (:mod:`cfbmarkov._random`): the number entering at step k is a
function of (seed, k), a newcomer's state of (seed, its index), a particle's moves of
(seed, particle, step). A run is therefore the same bit for bit for a given seed whatever
the number of threads.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from cfbmarkov._random import uniform
from cfbmarkov.markov import montecarlo
from cfbmarkov.markov.montecarlo import SparseChain, first_above, state_draw

#: random-number streams of the open riser (the periodic ones use 0-3)
STREAM_EXIT, STREAM_INFLOW, STREAM_ENTRY = 4, 5, 6


@nb.njit(cache=True)
def _inflow(seed, mean, n_steps, out):
    """Poisson(``mean``) entries at steps 1..n_steps by inversion of one uniform each
    (Knuth's sequential search on the CDF; ``mean`` is a few per lag)."""
    for k in range(1, n_steps + 1):
        u = uniform(seed, STREAM_INFLOW, 0, k)
        p = math.exp(-mean)
        cdf = p
        n = 0
        while u >= cdf and n < 100000:
            n += 1
            p *= mean / n
            cdf += p
        out[k] = n


@nb.njit(cache=True)
def _entry_states(seed, cumulative, first, out):
    """States of the newcomers ``first``, ``first + 1``, ... drawn from the entry
    distribution (its cumulative sums)."""
    for q in range(out.size):
        out[q] = first_above(cumulative, 0, cumulative.size - 1,
                             uniform(seed, STREAM_ENTRY, first + q, 0))


@nb.njit(cache=True, parallel=True)
def open_steps(initial_states, start_step, exit_probability, row_start, column, cumulative,
               row_offset, coherence, first, last, seed, states_out):
    """Advance every particle over the steps ``first`` .. ``last`` (Numba, parallel over
    particles): each lag it leaves through the outlet with probability r_s (then it is
    absent, -1, for good), else it takes the first entry of its row of P whose cumulative
    probability exceeds a uniform draw (Eq. 7).

    Parameters
    ----------
    initial_states : ndarray of int32, shape (N,)
        State of each particle at its start step.
    start_step : ndarray of int64, shape (N,)
        The step at which it is first present (0: present at the start; k: entered then).
    exit_probability : ndarray of float64, shape (S,)
        r.
    row_start, column, cumulative : ndarray
        The arrays of a :class:`~cfbmarkov.markov.montecarlo.SparseChain` of P.
    row_offset : ndarray of int64, shape (n_steps + 1,)
        Step k draws from row ``row_offset[k] + s`` (zeros for one chain; a regime model's
        common path times S).
    coherence : float
        Probability that a particle takes its row's common draw
        (:func:`~cfbmarkov.markov.montecarlo.state_draw`).
    first, last : int
        The steps filled (0 <= first <= last <= n_steps); for ``first`` > 0 the row
        ``first - 1`` is read as filled. The draws of step k depend on (seed, particle, k)
        alone, so a run made in pieces (:func:`run_open_chain`) draws what one piece would.
    seed : numpy.uint64
        Seed of the counter-based generator.
    states_out : ndarray of int32, shape (n_steps + 1, N)
        Rows ``first`` .. ``last`` filled in place (-1 where a particle is absent).
    """
    for p in nb.prange(initial_states.size):
        if first == 0 or start_step[p] >= first:
            s = initial_states[p]
        else:
            s = states_out[first - 1, p]
        for k in range(first, last + 1):
            if k < start_step[p]:
                states_out[k, p] = -1
                continue
            if k > start_step[p] and s >= 0:
                if uniform(seed, STREAM_EXIT, p, k) < exit_probability[s]:
                    s = -1
                else:
                    row = row_offset[k] + s
                    a = row_start[row]
                    b = row_start[row + 1]
                    if b > a:
                        s = column[first_above(cumulative, a, b - 1,
                                               state_draw(seed, p, row, k, coherence))]
            states_out[k, p] = s


def run_open_chain(chain: SparseChain, exit_probability: np.ndarray, entry: np.ndarray,
                   inflow_per_lag: float, initial_states, n_steps: int, seed: int,
                   row_offset=None, retag=None, coherence: float = 0.0, progress=None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """States of an open riser's Monte Carlo run.

    Parameters
    ----------
    chain : SparseChain
        P, the transitions of particles that stay.
    exit_probability : ndarray of float64, shape (S,)
        r.
    entry : ndarray of float64, shape (S,)
        The entry distribution.
    inflow_per_lag : float
        Mean number entering per lag (Poisson).
    initial_states : array_like of int, shape (N0,)
        States of the particles present at the start.
    n_steps : int
        Lags to run.
    seed : int
        Seed of the counter-based generator.
    row_offset : array_like of int, shape (n_steps + 1,), optional
        Step k draws from row ``row_offset[k] + s`` of the chain (a regime model's common
        path times S); None: zeros.
    retag : callable, optional
        ``retag(states, steps)`` gives the newcomers' states given their drawn states and
        entry steps (a regime model sets the regime of the path at entry).
    coherence : float, optional
        Probability that a particle takes its row's common draw.
    progress : callable, optional
        ``progress(steps)`` is called with the lags run so far after each piece of the run
        (pieces of about :data:`~cfbmarkov.markov.montecarlo.PIECE_PARTICLE_STEPS`
        particle-steps, between which a Ctrl-C is taken).

    Returns
    -------
    states : ndarray of int32, shape (n_steps + 1, N0 + M)
        -1 where absent; the M newcomers follow the N0 initial particles in order of entry.
    start_step : ndarray of int64, shape (N0 + M,)
        The step at which each is first present.
    """
    initial_states = np.ascontiguousarray(initial_states, dtype=np.int32)
    entries = np.zeros(n_steps + 1, np.int64)
    _inflow(np.uint64(seed), float(inflow_per_lag), int(n_steps), entries)
    m = int(entries.sum())
    newcomers = np.empty(m, np.int32)
    cumulative = np.cumsum(entry)
    cumulative = cumulative / cumulative[-1]
    _entry_states(np.uint64(seed), cumulative, 0, newcomers)
    entry_steps = np.repeat(np.arange(n_steps + 1), entries)
    if retag is not None:
        newcomers = retag(newcomers, entry_steps)
    states0 = np.concatenate([initial_states, newcomers]).astype(np.int32)
    start = np.concatenate([np.zeros(initial_states.size, np.int64), entry_steps])
    offset = (np.zeros(n_steps + 1, np.int64) if row_offset is None
              else np.ascontiguousarray(row_offset, dtype=np.int64))
    states = np.empty((n_steps + 1, states0.size), np.int32)
    exit_probability = np.ascontiguousarray(exit_probability, dtype=np.float64)
    # in pieces, so that a Ctrl-C is taken between them (the same bits in one or many)
    piece = max(1, montecarlo.PIECE_PARTICLE_STEPS // max(states0.size, 1))
    for first in range(0, int(n_steps) + 1, piece):
        last = min(int(n_steps), first + piece - 1)
        open_steps(states0, start, exit_probability, chain.row_start, chain.column,
                   chain.cumulative, offset, float(coherence), first, last, np.uint64(seed),
                   states)
        if progress is not None:
            progress(last)
    return states, start
