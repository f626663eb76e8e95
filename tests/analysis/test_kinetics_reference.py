"""The reference side of the kinetics: a property integrated along generated paths equals a
direct per-particle integration written plainly here."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cfbmarkov.analysis.cell_fields import wall_distance, window_cell_fields
from cfbmarkov.analysis.kinetics_reference import integrate_along_paths
from cfbmarkov.markov import discretize
from cfbmarkov.markov.states import CellGrid
from cfbmarkov.synthetic import RiserFlow, write_open_run, write_run
from cfbmarkov.trajectories import Trajectories

FLOW = RiserFlow(columns=6, rows=10, lag=0.02, persistence=False, rise_velocity=2.0,
                 fall_velocity=-2.0)


def _maps(space, lag):
    """A zone-dependent first-order rate: wall columns 10x slower than the core."""
    col = space.cell_of_state % space.columns
    k = np.where((col == 0) | (col == space.columns - 1), 0.5, 5.0)
    a = np.exp(-k * lag)
    return a, 1.0 - a


def _plain_periodic(states, laps, times, a, b, v0, reset):
    """Per particle, frame by frame: advance, then at each new lap level record and reset."""
    exits = []
    n_frames, n = states.shape
    bed = np.zeros(n_frames)
    values = np.full((n_frames, n), v0)
    for p in range(n):
        v, top, last = v0, laps[0, p], math.nan
        bed[0] += v / n
        values[0, p] = v
        for k in range(1, n_frames):
            v = a[states[k - 1, p]] * v + b[states[k - 1, p]]
            while laps[k, p] > top:
                top += 1
                if not reset or not math.isnan(last):
                    exits.append((times[k], p, v, times[k] - last))
                last = times[k]
                if reset:
                    v = v0
            bed[k] += v / n
            values[k, p] = v
    exits.sort(key=lambda e: (e[0], e[1]))
    return exits, bed, values


@pytest.mark.parametrize("reset", [True, False])
def test_periodic_paths_equal_a_plain_integration(tmp_path, reset):
    path = write_run(tmp_path / "run.h5", FLOW, 200, 2.0, seed=3)
    space = CellGrid(FLOW.columns, FLOW.rows, FLOW.width, FLOW.height)
    lag = 2 * FLOW.lag                          # every second frame
    discrete = discretize(path, space, lag, (0.2, 1.8), keep_positions=True)
    a, b = _maps(space, lag)
    got = integrate_along_paths(discrete, a, b, 0.0, reset=reset, name="X")
    states, laps, times = discrete.states[::2], discrete.laps[::2], discrete.times[::2]
    exits, bed, values = _plain_periodic(states, laps, times, a, b, 0.0, reset)
    assert got.count == len(exits) > 10
    np.testing.assert_allclose(got.exit_values, [e[2] for e in exits], rtol=0, atol=1e-13)
    np.testing.assert_allclose(got.exit_times, [e[0] for e in exits])
    if reset:
        np.testing.assert_allclose(got.residence_times, [e[3] for e in exits])
    np.testing.assert_allclose(got.bed_mean, bed, atol=1e-13)
    assert got.times.size == times.size
    # a Monte Carlo run's stored values stand in for the integrated ones: the same exits
    full = np.zeros(discrete.states.shape)
    full[::2] = values
    full[1::2] = np.nan                            # frames between lags are never read
    stored = integrate_along_paths(discrete, a, b, 0.0, reset=reset, stored=full)
    np.testing.assert_allclose(stored.exit_values, got.exit_values, atol=1e-13)
    np.testing.assert_allclose(stored.bed_mean, got.bed_mean, atol=1e-13)


def test_open_paths_equal_a_plain_integration(tmp_path):
    path = write_open_run(tmp_path / "open.h5", FLOW, 50, 2.0, seed=4)
    space = CellGrid(FLOW.columns, FLOW.rows, FLOW.width, FLOW.height)
    discrete = discretize(path, space, FLOW.lag, (0.0, 2.0), keep_positions=True)
    a, b = _maps(space, FLOW.lag)
    got = integrate_along_paths(discrete, a, b, 0.0, reset=True, name="X")
    y = discrete.vertical
    present = np.isfinite(y)
    band, height = FLOW.height / FLOW.rows, FLOW.height
    exits = []
    returns = 0
    for p in range(y.shape[1]):
        # inside at the first frame: in a residence whose entry is unknown (-inf)
        v, entered, last_y = 0.0, -math.inf if present[0, p] else math.nan, y[0, p]
        for k in range(1, y.shape[0]):
            # no lag advanced where it goes out of view away from the outlet (no transition)
            if present[k - 1, p] and (present[k, p] or last_y >= height - band):
                v = a[discrete.states[k - 1, p]] * v + b[discrete.states[k - 1, p]]
            if present[k, p] and not present[k - 1, p] and y[k, p] <= band:
                if math.isnan(entered):
                    entered, v = discrete.times[k], 0.0
                else:                                       # a return within a residence
                    returns += 1
            elif present[k - 1, p] and not present[k, p] and last_y >= height - band:
                if math.isfinite(entered):
                    exits.append((discrete.times[k], p, v))
                entered = math.nan
            if present[k, p]:
                last_y = y[k, p]
    exits.sort(key=lambda e: (e[0], e[1]))
    assert got.count == len(exits) > 10 and returns > 0
    np.testing.assert_allclose(got.exit_values, [e[2] for e in exits], atol=1e-13)


def test_a_return_through_the_inlet_continues_the_residence_and_its_value(tmp_path):
    """An open riser's particle that enters, falls back out through the inlet, returns and
    leaves through the outlet makes one residence (as its residence time counts it): a
    uniform rate's conversion at the exit is that of its time inside, not restarted at the
    return (which gave 1 - exp(-k 0.3 s) for a residence of 0.7 s)."""
    from cfbmarkov.trajectory_writer import write_trajectories

    lag, height = 0.05, 1.0
    times = lag * np.arange(21)
    # present 0.1-0.25 s rising from the inlet, out 0.3-0.45 s, back at the inlet 0.5 s,
    # rising to the outlet, gone from 0.85 s
    y = np.full(times.size, 0.05)
    present = np.zeros(times.size, bool)
    for k, t in enumerate(times):
        if 0.1 - 1e-9 <= t <= 0.25 + 1e-9:
            present[k], y[k] = True, 0.05 + (t - 0.1)
        elif 0.5 - 1e-9 <= t <= 0.8 + 1e-9:
            present[k], y[k] = True, 0.05 + 3.0 * (t - 0.5)
    y = np.minimum(y, 0.99)
    positions = np.stack([np.full(times.size, 0.05), y], axis=1)[:, None, :]
    path = write_trajectories(tmp_path / "open.h5", times, positions, width=0.1,
                              height=height, present=present[:, None], boundary="open")
    space = CellGrid(1, 10, 0.1, height)
    discrete = discretize(path, space, lag, (0.0, 1.0), keep_positions=True)
    k = 2.0
    a = np.full(space.n_states, math.exp(-k * lag))
    got = integrate_along_paths(discrete, a, 1.0 - a, 0.0, reset=True)
    assert got.count == 1
    np.testing.assert_allclose(got.residence_times, [0.75])     # 0.1 s to the exit at 0.85 s
    # lags advanced from 0.1 to 0.25 and 0.5 to 0.85 s: none over the lag it went out of
    # view in (0.25-0.3 s), which the chain counts no transition for either (a review
    # found the reference 0.6285 against the chain's 0.5507 on such falls)
    inside = 0.15 + 0.35
    np.testing.assert_allclose(got.exit_values, [1.0 - math.exp(-k * inside)], atol=1e-12)


@pytest.mark.parametrize("reset", [True, False], ids=["entry", "carried"])
def test_a_particle_seen_again_away_from_the_inlet_after_its_exit_restarts_at_entry(
        tmp_path, reset):
    """A particle that left through the outlet and is seen again mid-riser (a tracer found
    again above the inlet) is in a residence whose entry was not seen: in the bed's means
    it carries the entry value, as a particle never seen before does, not the value it
    left with (0.8347 here); a carried property keeps its value."""
    from cfbmarkov.trajectory_writer import write_trajectories

    times = np.round(0.1 * np.arange(30), 10)
    y = np.full(30, np.nan)
    y[2:11] = 0.05 + 0.1 * np.arange(9)       # enters at 0.2 s, rises to the top row
    y[10] = 0.95
    y[15:21] = 0.5                            # seen again mid-riser 1.5-2.0 s
    present = np.isfinite(y)
    pos = np.stack([np.where(present, 0.05, np.nan), y], -1)[:, None, :]
    path = write_trajectories(tmp_path / "again.h5", times, pos, width=0.1, height=1.0,
                              present=present[:, None], boundary="open")
    space = CellGrid(1, 10, 0.1, 1.0)
    discrete = discretize(path, space, 0.1, (0.0, 2.9), keep_positions=True)
    k = 2.0
    a = np.full(10, math.exp(-k * 0.1))
    got = integrate_along_paths(discrete, a, 1 - a, 0.0, reset=reset)
    left = 1.0 - math.exp(-k * 0.9)                         # 0.2 s to the exit at 1.1 s
    np.testing.assert_allclose(got.exit_values, [left], atol=1e-12)
    again = np.flatnonzero(np.isclose(got.times, 1.5))[0]
    start = 0.0 if reset else left
    expected = 1.0 - (1.0 - start) * np.exp(-k * 0.1 * np.arange(6))
    np.testing.assert_allclose(got.bed_mean[again:again + 6], expected, atol=1e-12)


def test_uniform_rate_exit_values_follow_the_residence_time(tmp_path):
    path = write_run(tmp_path / "run.h5", FLOW, 40, 2.0, seed=5)
    space = CellGrid(FLOW.columns, FLOW.rows, FLOW.width, FLOW.height)
    discrete = discretize(path, space, FLOW.lag, (0.0, 2.0), keep_positions=True)
    k = 2.0
    a = np.full(space.n_states, math.exp(-k * FLOW.lag))
    got = integrate_along_paths(discrete, a, 1.0 - a, 0.0, reset=True)
    np.testing.assert_allclose(got.exit_values, 1.0 - np.exp(-k * got.residence_times),
                               atol=1e-12)


def test_cell_fields_of_a_window(tmp_path):
    path = write_run(tmp_path / "run.h5", FLOW, 80, 1.0, seed=6)
    space = CellGrid(FLOW.columns, FLOW.rows, FLOW.width, FLOW.height)
    with Trajectories(path) as traj:
        fields = window_cell_fields(traj, space, (0.0, 1.0))
        cells = np.concatenate([
            np.bincount(np.minimum((traj.positions(i)[:, 1] / FLOW.height * FLOW.rows)
                                   .astype(int), FLOW.rows - 1) * FLOW.columns
                        + np.minimum((traj.positions(i)[:, 0] / FLOW.width * FLOW.columns)
                                     .astype(int), FLOW.columns - 1), minlength=60)[None]
            for i in range(traj.n_frames)])
    assert fields["relative"]                     # no particle diameter in the file
    np.testing.assert_allclose(fields["solids_fraction"], cells.mean(0) / cells.mean(), rtol=1e-12)
    np.testing.assert_allclose(wall_distance(space)[:4], [0.0075, 0.0225, 0.0375, 0.0375])
    # core rises, wall falls
    v = fields["vertical_velocity"].reshape(FLOW.rows, FLOW.columns)
    assert np.nanmean(v[:, 2:4]) > 0 > np.nanmean(v[:, [0, 5]])


def test_history_counts_every_exit_in_the_window_with_its_whole_path(tmp_path):
    """With a history the exits are every exit inside the window, each followed back to its
    entry before the window where need be: they include residences longer than the window
    lets a residence wholly inside it be, equal the plain integration over the longer span
    restricted to the window's exits, and sample the residences fairly (their mean lies
    above the wholly-inside one and near the fitted chain's exact exit mean)."""
    from cfbmarkov.analysis.kinetics_reference import reference_kinetics
    from cfbmarkov.kinetics import ByCell, FirstOrder, Kinetics, Property
    from cfbmarkov.markov import fit_model
    from cfbmarkov.markov.kinetics_exact import exact_kinetics

    path = write_run(tmp_path / "run.h5", FLOW, 150, 6.0, seed=11)
    space = CellGrid(FLOW.columns, FLOW.rows, FLOW.width, FLOW.height)
    window = (3.0, 4.0)
    model = fit_model(path, space, FLOW.lag, window, "mle")
    col = np.arange(space.n_cells) % space.columns
    k = np.where((col == 0) | (col == space.columns - 1), 0.5, 5.0)
    table = np.column_stack([col, np.arange(space.n_cells) // space.columns,
                             np.zeros(space.n_cells), k])
    kin = Kinetics((Property("X", FirstOrder(), {"rate": ByCell(table, "t", "t")}),))
    sk = kin.per_state(space)
    inside = reference_kinetics(path, model, sk, window)["X"]
    assert reference_kinetics(path, model, sk, window, history=0.0)["X"].count == inside.count
    back = reference_kinetics(path, model, sk, window, history=3.0)["X"]
    assert back.count > inside.count
    assert np.all((back.exit_times > window[0]) & (back.exit_times <= window[1] + 1e-9))
    assert np.isfinite(back.residence_times).all()
    # some residences began before the window: longer than a wholly-inside one could be
    assert np.any(back.residence_times > back.exit_times - window[0] + 1e-9)
    # the plain integration over the whole 0-4 s span, its exits inside the window
    discrete = discretize(path, space, FLOW.lag, (0.0, 4.0), keep_positions=True)
    a, b = sk.over(FLOW.lag)
    rows = slice(None, None, discrete.lag_frames)
    exits, _, _ = _plain_periodic(discrete.states[rows], discrete.laps[rows],
                                  discrete.times[rows], a[0], b[0], 0.0, True)
    plain = [e for e in exits if e[0] > window[0] + 1e-9]
    np.testing.assert_allclose(back.exit_values, [e[2] for e in plain], atol=1e-13)
    # a short history: the exits whose residence began before it are left out and counted
    short = reference_kinetics(path, model, sk, window, history=0.2)["X"]
    part = discretize(path, space, FLOW.lag, (2.8, 4.0), keep_positions=True)
    laps = part.laps[slice(None, None, part.lag_frames)]
    times = part.times[slice(None, None, part.lag_frames)]
    first_record = [times[np.argmax(laps[:, p] > laps[0, p])] for p in range(laps.shape[1])
                    if (laps[:, p] > laps[0, p]).any()]
    censored = sum(t > window[0] + 1e-9 for t in first_record)
    assert short.exits_censored == censored > 0
    assert short.count < back.count
    # the wholly-inside exits favour short residences; the exits followed back do not
    assert back.residence_times.mean() > inside.residence_times.mean()
    exact = exact_kinetics(model, sk)["X"].exit_mean
    assert abs(back.exit_mean - exact) < abs(inside.exit_mean - exact)
    assert abs(back.exit_mean - exact) < 4 * back.exit_se + 0.01 * exact
    with pytest.raises(Exception, match="history"):
        reference_kinetics(path, model, sk, window, history=-1.0)


def _direction_path(tmp_path, rows, n_frames, window, k):
    """A first-order conversion at rate k along one particle's open-riser path on a
    cells-direction chain of 1 x 4 cells (0.09 x 0.95 m), lag 0.1 s: ``rows`` its row from
    the frame at 0.2 s (-1: out of view)."""
    from cfbmarkov.markov.spaces import state_space_from_name
    from cfbmarkov.trajectory_writer import write_trajectories

    frames = np.full((n_frames, 1), -1)
    frames[2:2 + len(rows), 0] = rows
    present = frames >= 0
    y = np.where(present, (frames + 0.5) * 0.95 / 4, np.nan)
    path = write_trajectories(tmp_path / "open.h5", np.round(0.1 * np.arange(n_frames), 10),
                              np.stack([np.where(present, 0.02, np.nan), y], -1), width=0.09,
                              height=0.95, present=present, boundary="open")
    space = state_space_from_name("cells-direction", 1, 4, 0.09, 0.95)
    discrete = discretize(path, space, 0.1, window, keep_positions=True)
    a = np.full(space.n_states, math.exp(-k * 0.1))
    return integrate_along_paths(discrete, a, 1.0 - a, 0.0, reset=True)


def test_a_return_with_a_memory_advances_no_lag_before_its_first_state(tmp_path):
    """A direction memory's first state comes a lag after a particle is seen: at an entry
    that lag is integrated with the first state's law (the chain's entry delay), but back
    in view after a fall the chain counts no transition until its first state, as over the
    fall, and the paths hold the value there too (not a lag more of reaction)."""
    k = 2.0
    got = _direction_path(tmp_path, [0, 0, 1, -1, -1, 0, 1, 2, 3], 14, (0.1, 1.3), k)
    assert got.count == 1
    # lags advanced: the entry's first (no state yet), two to the fall, none over the fall
    # nor back before the first state, two rising and the exit's: 5 of the 0.9 s observed
    np.testing.assert_allclose(got.residence_times, [0.9])
    np.testing.assert_allclose(got.exit_values, [1.0 - math.exp(-k * 0.5)], atol=1e-12)


def test_a_return_the_memory_chain_never_had_a_state_before_is_its_entry(tmp_path):
    """A one-frame stay before the fall has no direction state: the chain's first state
    comes after the return, where it enters the particle, carrying that lag with the first
    state's law; the paths do the same (they had held the value over it: the conversion
    0.593 against the chain's exact 0.667 on a deterministic path)."""
    k = 2.0
    got = _direction_path(tmp_path, [0, -1, -1, 0, 1, 2, 3], 12, (0.1, 1.1), k)
    assert got.count == 1
    # the lag back in view before the first state, two rising and the exit's: 4 lags
    np.testing.assert_allclose(got.exit_values, [1.0 - math.exp(-k * 0.4)], atol=1e-12)


def test_a_particle_back_in_view_that_leaves_then_reappears_carries_its_first_lag(tmp_path):
    """Back in view within its residence (out of view mid-riser), the particle leaves
    through the outlet before its memory gives it a state, and is seen again mid-riser: a
    residence whose entry was not seen, whose first lag is carried with its first state's
    law as a particle's first seen anywhere (the flag 'back in view' is cleared at the
    exit, so that lag is not held)."""
    k = 2.0
    rows = [0, 1, 2, -1, 3, -1, -1, 1, 2, 3]
    got = _direction_path(tmp_path, rows, 14, (0.1, 1.3), k)
    again = np.flatnonzero(np.isclose(got.times, 0.9))[0]        # seen again at 0.9 s
    assert got.bed_mean[again] == 0.0                            # the entry value
    np.testing.assert_allclose(got.bed_mean[again + 1], 1.0 - math.exp(-k * 0.1), atol=1e-12)
