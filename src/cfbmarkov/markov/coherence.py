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

instead of q_s. Two fits of the coherence on the fitting window (``docs/method.md``, The cluster model):

- *pairs* (:func:`estimate_coherence`): matching that probability to the pairs of
  particles observed in one state at t and their states at t + tau,

      rho^2 = (same - sum_s pairs_s q_s) / (sum_s pairs_s - sum_s pairs_s q_s),

  with ``pairs_s`` the pairs of particles in state s at t and ``same`` those of them also
  in one state at t + tau, over every frame pair of the window; clipped to [0, 1]. It
  matches one lag's joint moves; a cluster's particles stay together over many lags, which
  the chain cannot track, so the snapshots of a model with this rho are less clustered
  than the flow (paper-scale runs: a cluster index 51-68 % below the CFD-DEM's at 8 m/s);
- *snapshots* (:func:`calibrate_coherence`, what ``coherent=True`` fits): the rho whose
  Monte Carlo snapshots, run for 120 lags (3 s at the paper's 0.025 s) from the window's
  first complete frame, show the window's own mean cluster index (the index of dispersion
  of the cell counts, :func:`~cfbmarkov.observed.clusters.snapshot_cluster_index`): the
  cluster measure itself is matched, as a model's free parameter is matched to a moment of
  the data in indirect inference (C. Gourieroux, A. Monfort and E. Renault, "Indirect
  inference", J. Appl. Econometrics 8, S85 (1993)). The index grows monotonically with rho
  (more particles move together), so a bracketing search (regula falsi) finds it in a few
  short runs.

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


#: Monte Carlo steps of one trial of :func:`calibrate_coherence` (lags)
CALIBRATION_STEPS = 120
#: ... of which the first ones are left out of the index (the start frame is the data's)
CALIBRATION_BURN_IN = 10
#: the largest coherence tried (rho = 1 moves every particle of a state as one, for ever)
MAX_COHERENCE = 0.98
#: the first trial above 0 (the paper-scale runs' calibrated rho: 0.6-0.8)
FIRST_GUESS = 0.7


def calibrate_coherence(model, data, *, steps: int = CALIBRATION_STEPS, seed: int = 0,
                        tolerance: float = 0.05) -> float:
    """The coherence whose Monte Carlo snapshots match the window's cluster index
    (module docstring, *snapshots*).

    The target is the mean over the window's frames of the index of dispersion of the
    particles' cell counts (the model's cells, ``state_space.cell_of_state``). A trial
    runs ``steps`` lags of the model with coherence rho from the window's first frame in
    which every particle present has a state, with a fixed seed, and takes the mean index
    over its frames after ``CALIBRATION_BURN_IN``. rho = 0 is returned where the
    independent chain is already as clustered as the window, ``MAX_COHERENCE`` where even
    that is not enough; between them (first trials ``FIRST_GUESS``, then half-way to
    ``MAX_COHERENCE`` and ``MAX_COHERENCE`` while the index is too low), regula falsi
    (Illinois) on the logarithm of the index (nearer a straight line in rho than the index)
    until it is within ``tolerance`` (relative) of the target, at most 14 trials.

    Parameters
    ----------
    model : MarkovModel
        The fitted chain (its coherence is ignored).
    data : DiscreteTrajectories or sequence of them
        The fitting window's discrete trajectories (of a periodic riser); the first window
        gives the start frame, all give the target.
    steps : int, optional
        Lags per trial (more than ``CALIBRATION_BURN_IN``).
    seed : int, optional
        Seed of the trials (the same for every rho, so that the index is a smooth function
        of rho).
    tolerance : float, optional
        Relative tolerance on the index.

    Returns
    -------
    float
        rho in [0, ``MAX_COHERENCE``].

    Raises
    ------
    InputError
        For too few steps, a state space of one cell, or a window without a frame in which
        every particle present has a state, or without two particles.
    """
    from cfbmarkov.observed.clusters import snapshot_cluster_index
    from cfbmarkov.markov.discrete import as_discrete_list

    if int(steps) <= CALIBRATION_BURN_IN:
        raise InputError(f"the coherence's calibration needs more than {CALIBRATION_BURN_IN} "
                         f"steps ({steps})")
    windows = as_discrete_list(data)
    cell_of_state = np.asarray(model.state_space.cell_of_state, dtype=np.int64)
    n_cells = int(cell_of_state.max()) + 1
    if n_cells < 2:
        raise InputError("coherent moves (--coherent) need at least 2 cells: their coherence "
                         "is calibrated on how unevenly the particles fill the cells; give "
                         "more cells (--cells)")
    observed = []
    for window in windows:
        states = np.asarray(window.states)
        complete = (states >= 0).all(axis=1)
        if complete.any():
            observed.append(snapshot_cluster_index(states[complete], n_cells, cell_of_state))
    first = np.asarray(windows[0].states)
    full = np.flatnonzero((first >= 0).all(axis=1))
    if full.size == 0 or not observed or first.shape[1] < 2:
        raise InputError("the coherence's calibration needs a frame of the fitting window in "
                         "which every particle has a state, and two particles")
    values = np.concatenate(observed)
    target = float(np.nanmean(values))
    if not target > 0.0:            # particles spread evenly (or no index): no clustering
        return 0.0
    start = first[full[0]]

    def index(rho: float) -> float:
        # the model itself where it already has this rho (the first trial, rho = 0): what
        # it derives for its Monte Carlo is then kept and carried to the other trials
        trial = model if rho == model.coherence else model.with_coherence(rho)
        run, _ = trial.monte_carlo(start, int(steps), seed=seed)
        return float(np.nanmean(snapshot_cluster_index(run[CALIBRATION_BURN_IN + 1:], n_cells,
                                                       cell_of_state)))

    def miss(rho: float) -> float:          # log of the trial's index over the target's
        return float(np.log(max(index(rho), 1e-12) / target))

    lo, f_lo = 0.0, miss(0.0)
    if f_lo >= 0.0:
        return 0.0
    hi, f_hi = FIRST_GUESS, miss(FIRST_GUESS)
    if abs(f_hi) <= tolerance:
        return FIRST_GUESS
    for upper in (0.5 * (FIRST_GUESS + MAX_COHERENCE), MAX_COHERENCE):
        if f_hi >= 0.0:
            break
        lo, f_lo = hi, f_hi
        hi, f_hi = upper, miss(upper)
    if f_hi <= 0.0:
        return MAX_COHERENCE
    side = 0
    rho = lo
    for _ in range(10):
        rho = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        f = miss(rho)
        if abs(f) <= tolerance:
            break
        if f < 0.0:
            lo, f_lo = rho, f
            if side == -1:
                f_hi *= 0.5
            side = -1
        else:
            hi, f_hi = rho, f
            if side == 1:
                f_lo *= 0.5
            side = 1
    return float(rho)


__all__ = ["calibrate_coherence", "estimate_coherence"]
