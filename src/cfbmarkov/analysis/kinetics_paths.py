"""Kernels of the reference side of the kinetics: a property integrated along observed
particle paths (``docs/definitions.md``, Properties along observed paths).

Every particle carries a value v. Over each lag, with the state s of the lag's first frame
held, the linear relaxation dv/dt = k_s (v_inf,s - v) is integrated exactly: the update is
affine, v' = a_s v + b_s with a_s = exp(-k_s lag) and b_s = v_inf,s (1 - a_s) (the maps
:meth:`cfbmarkov.kinetics.StateKinetics.over` gives). A residence ends at an exit (a
periodic riser: a record pass up through the top as :mod:`cfbmarkov.observed.residence`
defines it; an open riser: a vanishing within ``band`` of the outlet), whose value is the
one after the lag that crosses it; with ``reset`` the value restarts at ``v0`` at each
entry (the same record pass, or an appearance within ``band`` of the inlet).

The kernels are pure functions on arrays (numba), no I/O; per frame they also accumulate
the bed's mean value and its sums per cell.

Layout (T frames one lag apart, N particles, S states, C cells)::

    states   int32   [T, N]   state (-1: absent or undefined: the value is held)
    laps     int64   [T, N]   lap counter (periodic riser; sign-flipped for net downflow)
    present  bool    [T, N]   open riser: the particle is in the frame
    vertical float64 [T, N]   open riser: its height where first seen (m), the first frame
                              present since the lag's frame before, read on every frame of
                              the file (:func:`~cfbmarkov.observed.residence.lag_face_heights`)
    last_vertical    [T, N]   open riser: its height where last seen (m), the last frame
                              present before the lag's next frame
    a, b     float64 [S]      the lag's affine map per state
    bed_cells int64  [T, N]   the cell a particle counts in for the bed's means (-1: not
                              in the bed); an open riser's particle present without a
                              state (the lag before a state with memory) counts in the
                              cell where it is
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _bed(k, bed_cells, value, bed_mean, cell_sum, cell_count):
    """Frame ``k``'s mean value over the particles in the bed (a cell >= 0) and its sums
    per cell."""
    total = 0.0
    n = 0
    for p in range(bed_cells.shape[1]):
        c = bed_cells[k, p]
        if c >= 0:
            total += value[p]
            n += 1
            cell_sum[c] += value[p]
            cell_count[c] += 1
    bed_mean[k] = total / n if n > 0 else np.nan


@nb.njit(cache=True)
def integrate_periodic(times, states, laps, a, b, v0, reset, value, stored, use_stored,
                       bed_cells, exit_value, exit_time, exit_residence, bed_mean,
                       cell_sum, cell_count):
    """Integrate a property along the paths of a periodic riser; return the exits written.

    ``value`` [N] holds the values in the first frame and is advanced in place. Every frame
    in which a particle's lap counter exceeds its running maximum since the first frame
    records an exit (once per new level), with the time since its previous record as the
    residence time (NaN before its first record: its entry is unknown), then, with
    ``reset``, an entry at ``v0``. ``exit_*`` must hold the number of records;
    ``bed_mean`` [T], ``cell_sum`` and ``cell_count`` [C] are filled over the particles
    whose ``bed_cells`` is a cell. With
    ``use_stored``, the values of ``stored`` [T, N] (a Monte Carlo run's) stand in each
    frame instead of the integrated ones; an exit's value is then the lag's map of the
    stored value in the frame before it.
    """
    n_frames, n_particles = states.shape
    if use_stored and n_frames > 0:
        for p in range(n_particles):
            value[p] = stored[0, p]
    running_max = np.empty(n_particles, np.int64)
    last_record = np.full(n_particles, np.nan)
    for p in range(n_particles):
        running_max[p] = laps[0, p]
    n_out = 0
    if n_frames > 0:
        _bed(0, bed_cells, value, bed_mean, cell_sum, cell_count)
    for k in range(1, n_frames):
        t = times[k]
        for p in range(n_particles):
            s = states[k - 1, p]
            if s >= 0:
                value[p] = a[s] * value[p] + b[s]
            level = laps[k, p]
            while level > running_max[p]:
                running_max[p] += 1
                exit_value[n_out] = value[p]
                exit_time[n_out] = t
                exit_residence[n_out] = t - last_record[p]
                n_out += 1
                last_record[p] = t
                if reset:
                    value[p] = v0
            if use_stored:
                value[p] = stored[k, p]
        _bed(k, bed_cells, value, bed_mean, cell_sum, cell_count)
    return n_out


@nb.njit(cache=True)
def integrate_open(times, states, present, vertical, last_vertical, band, height, a, b, v0,
                   reset, value, stored, use_stored, bed_cells, exit_value, exit_time,
                   exit_residence, bed_mean, cell_sum, cell_count):
    """Integrate a property along the paths of an open riser; return the exits written.

    A particle present in frame k - 1 in a state advances over the lag to frame k. An entry
    is a frame where it is present, was absent before, lies within ``band`` of the inlet and
    is in no residence (then, with ``reset``, its value restarts at ``v0``), ``vertical``
    holding the height where it was first seen (a frame between the lag's, may be); a
    particle
    present without a state (a state space with memory: the lag before its first state)
    advances over that lag with its next state's law; an exit a frame
    where it is absent, was present before and was last seen (``last_vertical``: the height
    at the last frame present before this one) within ``band`` of the outlet, recorded with the
    time since its entry (NaN where the entry was not seen). A return through the inlet
    within a residence (after falling back out, or out of view) continues it, its value
    held from its last frame before it went out of view to its return (no transition of
    the chain counts that time either), as the residence times of
    :func:`cfbmarkov.observed.residence.open_residence_times` count it; so does that of a
    particle inside at the first frame (its entry unknown). A particle absent in the first
    frame is not an entry there. One seen again away from the inlet after it left through
    the outlet is in a residence whose entry was not seen: with ``reset`` its value
    restarts at ``v0`` there, as a particle's that was never seen before starts at its
    start value (not the value it left with). ``exit_*`` must hold one slot per particle-frame that can be an
    exit. ``stored`` and ``use_stored`` as for :func:`integrate_periodic`.
    """
    n_frames, n_particles = states.shape
    if use_stored and n_frames > 0:
        for p in range(n_particles):
            value[p] = stored[0, p]
    entered = np.full(n_particles, np.nan)
    last_height = np.full(n_particles, np.nan)
    back = np.zeros(n_particles, np.bool_)   # back in view within a residence, no state yet
    had_state = np.zeros(n_particles, np.bool_)  # in a state since its residence began
    left = np.zeros(n_particles, np.bool_)   # left through the outlet, not entered since
    for p in range(n_particles):
        if present[0, p]:
            last_height[p] = last_vertical[0, p]
            entered[p] = -np.inf        # inside at the start: in a residence, its entry unknown
    n_out = 0
    if n_frames > 0:
        _bed(0, bed_cells, value, bed_mean, cell_sum, cell_count)
    for k in range(1, n_frames):
        t = times[k]
        for p in range(n_particles):
            now = present[k, p]
            before = present[k - 1, p]
            if before and states[k - 1, p] >= 0:
                had_state[p] = True                 # the chain has it in this residence
            # the lag in which a particle goes out of view away from the outlet (a fall
            # back through the inlet, out of view) is no transition of the chain: its value
            # is held from its last frame, as over the frames it is out of view
            if before and (now or last_height[p] >= height - band):
                s = states[k - 1, p]
                if s >= 0:
                    back[p] = False
                elif now and not back[p]:
                    # first seen without the history a state with memory needs: its first
                    # lag with its first state's law, as the chain's exact answer takes it
                    # (not back after a fall or out of view: the chain counts no transition
                    # until its first state there, as over the time it was out of view)
                    s = states[k, p]
                if s >= 0:
                    value[p] = a[s] * value[p] + b[s]
            if now and not before and vertical[k, p] <= band and np.isnan(entered[p]):
                entered[p] = t
                back[p] = had_state[p] = left[p] = False
                if reset:
                    value[p] = v0
            elif now and not before and left[p]:
                left[p] = False             # seen again away from the inlet: entry unseen
                if reset:
                    value[p] = v0
            elif now and not before and not np.isnan(entered[p]):
                # back in view: the chain counts no lag before its first state there where
                # it had the particle in a state in this residence; where it had none (a
                # stay before the fall too short for a memory's history) the return is the
                # chain's entry, whose first lag it carries with the first state's law
                back[p] = had_state[p]
            elif before and not now and last_height[p] >= height - band:
                exit_value[n_out] = value[p]
                exit_time[n_out] = t
                exit_residence[n_out] = t - entered[p] if np.isfinite(entered[p]) else np.nan
                n_out += 1
                entered[p] = np.nan
                had_state[p] = back[p] = False
                left[p] = True
            if now:
                last_height[p] = last_vertical[k, p]
                if use_stored:
                    value[p] = stored[k, p]
        _bed(k, bed_cells, value, bed_mean, cell_sum, cell_count)
    return n_out


def records_bound(laps: np.ndarray) -> int:
    """Upper bound on the exits of :func:`integrate_periodic`: new lap levels reached.

    Parameters
    ----------
    laps : ndarray of int, shape (T, N)
        Lap counters.

    Returns
    -------
    int
    """
    if laps.shape[0] == 0:
        return 0
    return int(np.maximum(laps.max(axis=0).astype(np.int64) - laps[0].astype(np.int64),
                          0).sum())


__all__ = ["integrate_open", "integrate_periodic", "records_bound"]
