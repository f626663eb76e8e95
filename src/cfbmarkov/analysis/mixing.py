"""Radial mixing by halves of the riser (the paper's Fig. 10-11).

At the start of the analysis window the particles are split into two *tracer groups* by
their position: the *left tracer group* holds the particles with x < W/2, the right tracer
group the rest (the figures draw them purple and green, as the paper does). The mixing
curve is the number of particles of the left tracer group that lie at x < W/2, divided by
the total number of particles, against time. It starts at the left group's share of all
particles and, when the bed is well mixed, approaches (left group's share) x (share of all
particles on the left).

For a model whose positions are drawn inside cells, x < W/2 is the same as a cell column
< m/2 when the number of columns m is even (with m odd the middle column straddles the axis
and mixing by halves is undefined; :func:`cfbmarkov.analysis.compare.compare_runs` refuses
it). :func:`model_mixing_curve` gives a model's expected mixing curve from given initial
states, and the Monte Carlo standard deviation of a prediction's curve about it, without
sampling (the mixing band of ``docs/definitions.md``, Intervals).

References
----------
docs/definitions.md, section "mixing".
"""

from __future__ import annotations

import numba as nb
import numpy as np

from cfbmarkov.boundary import Boundary
from cfbmarkov.errors import InputError
from cfbmarkov.frame_times import window_pair


def left_tracer_group(x, half_width: float) -> np.ndarray:
    """Members of the left tracer group in one frame.

    Parameters
    ----------
    x : array_like, shape (N,)
        Horizontal particle positions, m.
    half_width : float
        Half the riser width W/2, m.

    Returns
    -------
    numpy.ndarray of bool, shape (N,)
        True where x < W/2 (a particle exactly on the axis belongs to the right group).
    """
    return np.asarray(x) < half_width


def mixing_curve(x, half_width: float, left_group: np.ndarray | None = None) -> np.ndarray:
    """Mixing curve of a block of frames.

    Parameters
    ----------
    x : array_like, shape (T, N)
        Horizontal particle positions, m, frame by frame.
    half_width : float
        Half the riser width W/2, m.
    left_group : array_like of bool, shape (N,), optional
        The left tracer group; by default the particles with x < W/2 in the first frame.

    Returns
    -------
    numpy.ndarray, shape (T,)
        Fraction of all N particles that belong to the left tracer group and lie at
        x < W/2 (dimensionless).

    Raises
    ------
    InputError
        When ``x`` is not 2D, holds no particle, or ``left_group`` has the wrong shape.

    References
    ----------
    docs/definitions.md, section "mixing"; the paper's Fig. 11.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2:
        raise InputError(f"x must have shape (T, N), got {x.shape}")
    t, n = x.shape
    if n == 0:
        raise InputError("mixing curve of no particles")
    if left_group is None:
        if t == 0:
            return np.zeros(0)
        left_group = x[0] < half_width
    left_group = np.asarray(left_group, dtype=bool)
    if left_group.shape != (n,):
        raise InputError(f"left tracer group mask has shape {left_group.shape}, expected ({n},)")
    return np.count_nonzero(x[:, left_group] < half_width, axis=1) / n


def mixing_curve_of(traj, window: tuple[float, float], block: int = 64, tracers=None,
                    counts: bool = False):
    """Mixing curve of a trajectory file over a window.

    Parameters
    ----------
    traj : cfbmarkov.trajectories.Trajectories
        An open trajectory file.
    window : (float, float)
        Analysis window (start, stop), s. The left tracer group is taken from the window's
        first frame.
    block : int, optional
        Frames read per block.
    tracers : ndarray of int64, optional
        A file with absences (an open riser): the ids of the tracers among the particles
        present at the window's first frame (default all of them).
    counts : bool, optional
        Also return the tracers present at each frame.

    Returns
    -------
    times : numpy.ndarray, shape (T,)
        Frame times, s.
    fraction : numpy.ndarray, shape (T,)
        The mixing curve of :func:`mixing_curve` (dimensionless).
    present : numpy.ndarray of int64, shape (T,)
        With ``counts``: the tracers present at each frame (every particle of a file
        without absences).

    Raises
    ------
    InputError
        When the window is empty, leaves the file's frames or holds no frame.

    References
    ----------
    ``docs/definitions.md`` (Mixing);
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Figs. 10-11.
    """
    traj.require_supported("the mixing curve", three_d=True, absent=True,
                           open_boundary=True)     # the across coordinate only
    frames = traj.window(*window_pair(window))
    half = 0.5 * traj.width
    if traj.has_absences:
        times, fraction, present = _mixing_of_present(
            traj, frames, half, block, None if tracers is None else np.isin(traj.ids, tracers))
        return (times, fraction, present) if counts else (times, fraction)
    left_group = None
    times, parts = [], []
    for t, positions, _ in traj.iter_frames(frames, block=block):
        x = positions[..., 0]
        if left_group is None:
            left_group = x[0] < half
        times.append(t)
        parts.append(mixing_curve(x, half, left_group))
    times, fraction = np.concatenate(times).astype(np.float64), np.concatenate(parts)
    if counts:
        return times, fraction, np.full(times.size, traj.n_particles, dtype=np.int64)
    return times, fraction


def _mixing_of_present(traj, frames: slice, half: float, block: int, chosen=None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mixing curve where particles come and go (``docs/definitions.md``, Mixing in an
    open riser): the particles present at the window's first frame (those of them marked in
    ``chosen``, where given) are the tracers; at each frame the fraction of those still
    present that belong to the left group and lie at x < W/2 (NaN once none is left), and
    the tracers present at each frame."""
    cohort = left = None
    times, parts, present_counts = [], [], []
    for i in range(frames.start, frames.stop, block):
        rows = slice(i, min(i + block, frames.stop))
        x = traj.positions(rows)[..., 0]
        present = traj.present(rows)
        if cohort is None:
            cohort = present[0].copy() if chosen is None else present[0] & chosen
            left = cohort & (np.where(cohort, x[0], np.inf) < half)
        still = present & cohort
        inside = still & left & (np.where(still, x, np.inf) < half)
        count = still.sum(axis=1)
        parts.append(np.divide(inside.sum(axis=1), count, out=np.full(count.size, np.nan),
                               where=count > 0))
        present_counts.append(count.astype(np.int64))
        times.append(traj.times[rows])
    return (np.concatenate(times).astype(np.float64), np.concatenate(parts),
            np.concatenate(present_counts))


def _left_states(space) -> np.ndarray:
    """Indicator (float64, shape (S,)) of the states whose cell column is < m/2."""
    columns = int(space.columns)
    if columns % 2:
        raise InputError(f"the model's state space has an odd column count ({columns}): mixing "
                         "by halves (x < W/2) is undefined, as the middle column's cells "
                         f"straddle W/2; fit with an even count (--cells {columns + 1}xROWS)")
    column = np.asarray(space.cell_of_state, dtype=np.int64) % columns
    return (column < columns // 2).astype(np.float64)


@nb.njit(cache=True)
def _propagated_mixing(indptr, indices, data, left_states, n_left, n_all, total, is_open,
                       steps, mean, var):
    """The loop of :func:`model_mixing_curve` (Numba kernel): h_k = P^k 1_left (and, open,
    g_k = Q^k 1) by one sparse product per lag over the CSR rows of the matrix, with the
    curve's mean and variance at each k written into ``mean`` and ``var`` [steps + 1]."""
    n = left_states.size
    h = left_states.copy()
    g = np.ones(n)
    h_next = np.empty(n)
    g_next = np.empty(n)
    for k in range(steps + 1):
        if k:
            for i in range(n):
                acc_h = 0.0
                acc_g = 0.0
                for q in range(indptr[i], indptr[i + 1]):
                    acc_h += data[q] * h[indices[q]]
                    if is_open:
                        acc_g += data[q] * g[indices[q]]
                h_next[i] = acc_h
                g_next[i] = acc_g
            h, h_next = h_next, h
            if is_open:
                g, g_next = g_next, g
        expected = 0.0
        spread = 0.0
        for i in range(n):
            expected += n_left[i] * h[i]
            spread += n_left[i] * h[i] * (1.0 - h[i])
        if not is_open:
            mean[k] = expected / total
            var[k] = spread / (total * total)
            continue
        present_k = 0.0
        cross = 0.0
        scatter = 0.0
        for i in range(n):
            present_k += n_all[i] * g[i]
            cross += n_left[i] * h[i] * (1.0 - g[i])
            scatter += n_all[i] * g[i] * (1.0 - g[i])
        if present_k <= 1e-12 * total:
            mean[k] = np.nan
            var[k] = np.nan
            continue
        f = expected / present_k
        mean[k] = f
        var[k] = max(spread - 2.0 * f * cross + f * f * scatter, 0.0) / (present_k * present_k)


def model_mixing_curve(model, states, left_group, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """A Markov model's expected mixing curve from given initial states, and the Monte Carlo
    standard deviation of a prediction's curve about it.

    Each particle moves independently by the model's transition matrix P, so a tracer that
    starts in state s lies in the left half (a cell column < m/2) k lags later with
    probability h_k[s], h_k = P^k 1_left (backward propagation: one sparse product per lag
    whatever the number of particles, in a Numba kernel). With n_s the left tracer group's members starting in
    state s and N particles,

        M(k) = sum_s n_s h_k[s] / N,   Var = sum_s n_s h_k[s] (1 - h_k[s]) / N^2,

    the variance being that of a Monte Carlo run (Eq. 7) from these states. An open riser's
    model propagates by its absorbing matrix Q = diag(1 - r) P: with g_k = Q^k 1 (still
    present), the curve is the ratio of the expected left-group tracers present at x < W/2
    to the expected tracers present (``docs/definitions.md``, Mixing in an open riser), its
    variance that of the ratio to first order (delta method).

    Parameters
    ----------
    model : cfbmarkov.markov.MarkovModel
        The model (its transition matrix, state space and, for an open riser, exit
        probabilities). Its state space needs an even number of columns m.
    states : array_like of int, shape (N,)
        The particles' states at the window start (-1: absent, an open riser's particle not
        in the riser; it is no tracer).
    left_group : array_like of bool, shape (N,)
        The left tracer group (x < W/2 at the window start).
    steps : int
        Lags to propagate (>= 0).

    Returns
    -------
    mean : numpy.ndarray of float64, shape (steps + 1,)
        The expected mixing curve at k = 0 .. steps lags after the start (fraction of all
        particles; of the tracers still present in an open riser, NaN once none is
        expected to be left).
    sd : numpy.ndarray of float64, shape (steps + 1,)
        The standard deviation of a Monte Carlo run's curve about ``mean`` (same unit).

    Raises
    ------
    InputError
        For an odd column count, arrays of the wrong shape, states outside the state space,
        no tracer, or negative ``steps``.

    References
    ----------
    ``docs/definitions.md`` (Mixing; Intervals); J. G. Kemeny and J. L. Snell, Finite Markov
    Chains, Van Nostrand (1960), Ch. II (the k-step probabilities P^k).
    """
    import scipy.sparse as sp

    left_states = _left_states(model.state_space)
    n_states = left_states.size
    states = np.asarray(states)
    left_group = np.asarray(left_group, dtype=bool)
    if states.ndim != 1 or left_group.shape != states.shape:
        raise InputError(f"initial states {states.shape} and left tracer group "
                         f"{left_group.shape} must be two arrays of shape (N,)")
    if int(steps) < 0:
        raise InputError(f"steps {steps} must be >= 0")
    states = states.astype(np.int64)
    present = states >= 0
    if states.size and states.max() >= n_states:
        raise InputError("initial states outside the model's state space")
    if not present.any():
        raise InputError("mixing curve of no tracer (no particle present at the start)")
    is_open = Boundary(model.boundary).is_open
    matrix = sp.csr_matrix(model.absorbing_matrix if is_open else model.transition_matrix)
    n_left = np.bincount(states[present & left_group], minlength=n_states).astype(np.float64)
    n_all = np.bincount(states[present], minlength=n_states).astype(np.float64)
    total = float(present.sum())
    mean = np.empty(int(steps) + 1)
    var = np.empty(int(steps) + 1)
    _propagated_mixing(matrix.indptr.astype(np.int64), matrix.indices.astype(np.int64),
                       matrix.data.astype(np.float64), left_states.astype(np.float64), n_left,
                       n_all, total, bool(is_open), int(steps), mean, var)
    return mean, np.sqrt(np.maximum(var, 0.0))


__all__ = ["left_tracer_group", "mixing_curve", "mixing_curve_of", "model_mixing_curve"]
