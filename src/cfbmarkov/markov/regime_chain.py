"""The regime model's Monte Carlo (:mod:`cfbmarkov.markov.regimes`): the regime chain G
read off a model's counts, the chains conditioned on the regime's next value, and one
regime path common to every particle of a run.

All particles share one regime path rho_0, rho_1, ... drawn from G once per run; at step k
every particle moves by the chain conditioned on the regime moving from rho_(k-1) to rho_k
(the formula in :mod:`cfbmarkov.markov.regimes`), so the single-particle marginal is the
product chain while surges and collapses move the whole cloud together.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numba as nb
import numpy as np

from cfbmarkov._random import uniform
from cfbmarkov.markov.montecarlo import SparseChain, first_above

if TYPE_CHECKING:
    from cfbmarkov.markov.regimes import RegimeCells

#: random-number stream of the regime path (the particle streams use 0-6)
STREAM_REGIME = 7


def regime_matrix(counts: np.ndarray, space: "RegimeCells") -> np.ndarray:
    """The regime chain G read off a model's counts.

    Every counted transition of a particle goes from its frame's regime to the next frame's,
    so G[r, r'] is the share of the transitions out of regime r that end in regime r'
    (particle-weighted: frames with more particles present weigh more, which on a periodic
    riser's constant inventory is the frame count itself).

    Parameters
    ----------
    counts : ndarray of int64, shape (S, S)
        Pooled transition counts on the space's states.
    space : RegimeCells
        The state space.

    Returns
    -------
    ndarray of float64, shape (R, R)
        Row-stochastic; a regime never left stays (G[r, r] = 1).
    """
    regime = space.regime_of(np.arange(space.n_states))
    r = space.regimes
    folded = np.zeros((r, r))
    c = np.asarray(counts, dtype=np.float64)
    for a in range(r):            # R x R blocks of the counts (R <= 8)
        rows = c[regime == a]
        for b in range(r):
            folded[a, b] = rows[:, regime == b].sum()
    total = folded.sum(axis=1)
    out = np.divide(folded, total[:, None], out=np.zeros_like(folded), where=total[:, None] > 0)
    out[total == 0, :] = 0.0
    out[total == 0, np.flatnonzero(total == 0)] = 1.0
    return out


def conditional_chain(matrix: np.ndarray, up_fraction: np.ndarray, down_fraction: np.ndarray,
                      space: "RegimeCells") -> SparseChain:
    """The chains conditioned on the regime's next value, stacked for the Monte Carlo.

    Block r' (rows r' S .. r' S + S - 1) is M with the regime moving to r' (module
    docstring): row s holds P[s, (., r', .)] renormalised, or, where P[s] puts no mass on
    regime r', all of P[s] with the regime of every target set to r'. Pass fractions follow
    the transitions (pass-weighted where folded).

    Parameters
    ----------
    matrix : ndarray of float64, shape (S, S)
        The product chain P.
    up_fraction, down_fraction : ndarray of float64, shape (S, S)
        Fractions of each transition passing up through the top / down through the bottom.
    space : RegimeCells
        The state space.

    Returns
    -------
    SparseChain
        With R S rows over S columns.
    """
    s = space.n_states
    n_cells, r = space.n_cells, space.regimes
    d = 2 if space.direction else 1
    p = np.asarray(matrix, dtype=np.float64).reshape(s, n_cells, r, d)
    up = (np.asarray(up_fraction) * matrix).reshape(s, n_cells, r, d)
    down = (np.asarray(down_fraction) * matrix).reshape(s, n_cells, r, d)
    folded, folded_up, folded_down = p.sum(axis=2), up.sum(axis=2), down.sum(axis=2)
    blocks = np.zeros((r, s, n_cells, r, d))
    up_blocks = np.zeros_like(blocks)
    down_blocks = np.zeros_like(blocks)
    for target in range(r):        # R dense blocks (R <= 8), vectorised over states
        part = p[:, :, target, :]
        has = part.reshape(s, -1).sum(axis=1) > 0
        mass = np.where(has[:, None, None], part, folded)
        mass_up = np.where(has[:, None, None], up[:, :, target, :], folded_up)
        mass_down = np.where(has[:, None, None], down[:, :, target, :], folded_down)
        blocks[target, :, :, target, :] = mass
        up_blocks[target, :, :, target, :] = np.divide(mass_up, mass, out=np.zeros_like(mass),
                                                       where=mass > 0)
        down_blocks[target, :, :, target, :] = np.divide(mass_down, mass,
                                                         out=np.zeros_like(mass), where=mass > 0)
    return SparseChain.from_matrix(blocks.reshape(r * s, s), up_blocks.reshape(r * s, s),
                                   down_blocks.reshape(r * s, s))


@nb.njit(cache=True)
def _regime_path(cumulative, start, seed, out):
    """out[0] = start, out[k] drawn from row out[k-1] of G (cumulative rule, Eq. 7)."""
    r = cumulative.shape[1]
    out[0] = start
    for k in range(1, out.size):
        out[k] = first_above(cumulative[out[k - 1]], 0, r - 1, uniform(seed, STREAM_REGIME, 0, k))


def regime_path(regime_chain: np.ndarray, start: int, n_steps: int, seed: int) -> np.ndarray:
    """One path of the regime chain, common to every particle of a Monte Carlo run.

    Parameters
    ----------
    regime_chain : ndarray of float64, shape (R, R)
        The row-stochastic regime chain G.
    start : int
        The regime at step 0.
    n_steps : int
        Number of lags.
    seed : int
        Seed of the counter-based generator (its own stream: the path does not change the
        particles' draws).

    Returns
    -------
    ndarray of int64, shape (n_steps + 1,)
        The regime at each step.
    """
    cumulative = np.cumsum(np.asarray(regime_chain, dtype=np.float64), axis=1)
    cumulative /= np.where(cumulative[:, -1:] > 0, cumulative[:, -1:], 1.0)
    cumulative[:, -1] = 1.0
    out = np.empty(int(n_steps) + 1, np.int64)
    _regime_path(cumulative, int(start), np.uint64(seed), out)
    return out


def start_regime(states: np.ndarray, space: "RegimeCells") -> int:
    """The regime of a frame from its particles' states (they share it; the most common
    where a caller mixed frames), 0 for no particle.

    Parameters
    ----------
    states : ndarray of int, shape (N,)
        States of the particles present (>= 0).
    space : RegimeCells
        The state space.

    Returns
    -------
    int
    """
    states = np.asarray(states)
    states = states[states >= 0]
    if not states.size:
        return 0
    return int(np.argmax(np.bincount(space.regime_of(states), minlength=space.regimes)))


def with_regime(states: np.ndarray, regime: np.ndarray, space: "RegimeCells") -> np.ndarray:
    """States with their regime replaced (cell and direction kept).

    Parameters
    ----------
    states : ndarray of int, shape (M,)
        States of this space.
    regime : ndarray of int, shape (M,)
        The regime each should carry.
    space : RegimeCells
        The state space.

    Returns
    -------
    ndarray of int32, shape (M,)
    """
    d = 2 if space.direction else 1
    states = np.asarray(states, dtype=np.int64)
    return (states - space.regime_of(states) * d + np.asarray(regime) * d).astype(np.int32)


__all__ = ["STREAM_REGIME", "conditional_chain", "regime_matrix", "regime_path", "start_regime",
           "with_regime"]
