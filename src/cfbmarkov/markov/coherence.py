"""Coherent moves: particles that share a state move together (the cluster model).

A cluster is a patch of solids that moves as one. A chain whose particles draw their moves
independently spreads any patch over the cells its rows reach within a few lags, so its
snapshots relax to the time-averaged profile and lose the clusters, whatever its state
space. Here the particles leaving the same state at the same step share part of their
randomness: each takes, with probability rho (the *coherence*), the one uniform draw of its
state for that step instead of its own, and picks its next state from it by the cumulative
rule (Eq. 7) (:func:`~cfbmarkov.markov.montecarlo.state_draw`). Each particle on its own
still draws from its row of P (a uniform draw is a uniform draw), so every single-particle
figure, the exact RTD and the propagated maps are those of the chain; only the joint motion
changes: two particles of one state land in the same next state with probability

    rho^2 + (1 - rho^2) q_s,    q_s = sum_j P_sj^2

instead of q_s. The coherence is fitted on the fitting window by matching that probability
to the pairs of particles observed in one state at t and their states at t + tau:

    rho^2 = (same - sum_s pairs_s q_s) / (sum_s pairs_s - sum_s pairs_s q_s),

with ``pairs_s`` the pairs of particles in state s at t and ``same`` those of them also in
one state at t + tau, over every frame pair of the window; clipped to [0, 1] (``docs/method.md``,
The cluster model).

References
----------
Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in Circulating
Fluidized Bed Risers", Processes 13(3), 614 (2025), doi:10.3390/pr13030614 (Sect. 4: the
model cannot reproduce clusters).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.limits import check_memory


@nb.njit(cache=True)
def _pair_counts(states, lag_frames, n_states, pairs_per_state, cnt, ns, keys, touched):
    """Pairs of particles in one state at t (added to ``pairs_per_state``) and, returned,
    those also in one state at t + lag, over every frame pair (absent: state < 0)."""
    n_frames, n = states.shape
    same = 0.0
    for t in range(n_frames - lag_frames):
        n_keys = 0
        n_touched = 0
        for p in range(n):
            s = states[t, p]
            j = states[t + lag_frames, p]
            if s < 0 or j < 0:
                continue
            key = s * n_states + j
            if cnt[key] == 0:
                keys[n_keys] = key
                n_keys += 1
            cnt[key] += 1
            if ns[s] == 0:
                touched[n_touched] = s
                n_touched += 1
            ns[s] += 1
        for q in range(n_keys):
            c = cnt[keys[q]]
            same += 0.5 * c * (c - 1)
            cnt[keys[q]] = 0
        for q in range(n_touched):
            c = ns[touched[q]]
            pairs_per_state[touched[q]] += 0.5 * c * (c - 1)
            ns[touched[q]] = 0
    return same


def estimate_coherence(data, transition_matrix: np.ndarray) -> float:
    """The coherence rho of discrete trajectories for a fitted chain (module docstring).

    Parameters
    ----------
    data : DiscreteTrajectories or sequence of them
        The fitting window's discrete trajectories.
    transition_matrix : ndarray of float64, shape (S, S)
        The chain fitted on them.

    Returns
    -------
    float
        rho in [0, 1]; 0 where no state ever held two particles at once.

    Raises
    ------
    InputError
        If the S x S pair table would not fit in memory.
    """
    from cfbmarkov.markov.discrete import as_discrete_list

    p = np.asarray(transition_matrix, dtype=np.float64)
    n_states = p.shape[0]
    check_memory(4.0 * n_states * n_states, f"the coherence's pair table ({n_states}^2 state "
                 "pairs)", "fit without --coherent")
    cnt = np.zeros(n_states * n_states, np.int32)
    ns = np.zeros(n_states, np.int64)
    pairs = np.zeros(n_states)
    same = 0.0
    for window in as_discrete_list(data):
        states = np.ascontiguousarray(window.states)
        keys = np.empty(states.shape[1], np.int64)
        touched = np.empty(states.shape[1], np.int64)
        same += _pair_counts(states, int(window.lag_frames), n_states, pairs, cnt, ns, keys,
                             touched)
    q = (p * p).sum(axis=1)
    expected = float(pairs @ q)
    total = float(pairs.sum())
    if total - expected <= 0:
        return 0.0
    rho2 = (same - expected) / (total - expected)
    if not np.isfinite(rho2):
        raise InputError("the coherence could not be formed (non-finite pair counts)")
    return float(np.sqrt(min(max(rho2, 0.0), 1.0)))


__all__ = ["estimate_coherence"]
